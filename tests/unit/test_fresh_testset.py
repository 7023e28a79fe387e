"""Fresh scenes (`--fresh N`): drawn from a seed of their own, kept apart from every project
stream, labelled by the test set's own code, scored, and their rows saying so; the same for
an agent's fresh episodes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from clutterbench.cli import app
from clutterbench.config import load_base, load_params, load_section
from clutterbench.data.testset_fresh import allocate, check_apart, draw_seed, stream_seed
from clutterbench.data.testset_load import load
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from clutterbench.support.scorecard import score, write_row
from clutterbench.support.testset_fresh import fresh_testset
from clutterbench.trials.config import TrialsConfig
from tests.unit.test_testset_scorecard import _write_testset

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "docs/examples"
runner = CliRunner()


def test_fresh_scenes_come_in_the_reference_set_s_proportions():
    sources = {"benchmark:a": 200, "benchmark:b": 200, "benchmark:c": 200, "ds": 200}
    assert allocate(sources, 200) == dict.fromkeys(sources, 50)
    assert allocate(sources, 3) == {"benchmark:a": 1, "benchmark:b": 1, "benchmark:c": 1}
    assert allocate({"x": 1, "y": 3}, 7) == {"x": 2, "y": 5}
    with pytest.raises(ClutterbenchError, match="at least one"):
        allocate(sources, 0)


def test_a_fresh_seed_is_drawn_unless_given_and_its_stream_seed_carries_a_tag():
    drawn = {draw_seed(None) for _ in range(3)}
    assert len(drawn) == 3 and all(0 <= s < 2**63 and w == "os.urandom" for s, w in drawn)
    assert draw_seed(7) == (7, "given")
    with pytest.raises(ClutterbenchError, match="--seed"):
        draw_seed(-1)
    assert stream_seed(7) == stream_seed(7) != stream_seed(8)
    assert 0 <= stream_seed(0) < 2**63 and stream_seed(0) != 0


def test_fresh_streams_refuse_to_meet_a_project_stream():
    params = load_params(ROOT / "params.yaml")
    check_apart(params, 0, 7, ["ch6_test", "ch6_3_5"])  # the project's own params: apart
    clash = {"generate": {"datasets": {"fresh/ch6_test": {}}}}
    with pytest.raises(ClutterbenchError, match="meets the project's stream fresh/ch6_test"):
        check_apart(clash, 0, 7, ["ch6_test"])
    with pytest.raises(ClutterbenchError, match="base.seed"):
        check_apart({}, stream_seed(7), 7, ["ch6_test"])


def _tiny_project(root: Path) -> dict:
    """A project of the repository's params at tiny scale, one core, no benchmark artifact
    (fresh scenes are never in it), and a reference test set of one dataset scene and one
    stream start in its camera."""
    from clutterbench.data.testset import camera_matrix
    from clutterbench.sim.config import SimConfig

    params = load_params(ROOT / "params.yaml")
    params["base"] = {**params["base"], "scale": "tiny", "cores": 1}
    params["benchmark"] = {**(params.get("benchmark") or {}), "manifest_sha256": None}
    (root / "params.yaml").write_text(yaml.safe_dump(params))
    (root / "dvc.yaml").write_text("stages: {}\n")
    sim = load_section(SimConfig, "sim", load_params(root / "params.yaml"))
    ref = _write_testset(root / "ref")
    manifest = read_json(ref / "manifest.json")
    manifest["camera"] = {"K": camera_matrix(sim.camera), "image_size": sim.camera.image_size}
    manifest["sources"] = {"benchmark:ch6_3_5": 1, "ch6_test": 1}
    write_json(ref / "manifest.json", manifest)
    return load_params(root / "params.yaml")


def test_evaluate_predictor_fresh_labels_new_scenes_and_says_so_in_its_row(tmp_path, monkeypatch):
    """--fresh 2 --seed 7: two scenes labelled now (the test set's code, fresh streams) in a
    set that loads; the row names the seed; the leaderboard's `scored on` column tells it
    from a published row; the same seed draws the same set again."""
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import label_scene
    from clutterbench.sim.config import SimConfig

    params = _tiny_project(tmp_path)
    monkeypatch.chdir(tmp_path)
    board, sets = tmp_path / "board", tmp_path / "sets"
    flat = score(load(tmp_path / "ref"), lambda d, m, c, i: np.full(len(m), 0.5), "flat", "")
    write_row(flat, board / "baselines")
    args = ["evaluate-predictor", str(EXAMPLES / "example_predictor.py"), "--testset", "ref"]
    args += ["--out", str(board), "--fresh", "2", "--seed", "7", "--fresh-dir", str(sets)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "seed 7 (given)" in result.output
    ts = load(sets / "7")
    fresh = ts["manifest"]["fresh"]
    assert (fresh["seed"], fresh["stream_seed"], fresh["scenes"]) == (7, stream_seed(7), 2)
    assert sorted(ts["source"]) == ["benchmark:fresh/ch6_3_5", "fresh/ch6_test"]
    card = read_json(board / "fresh/predictor-example_predictor.json")
    assert card["scored_on"]["seed"] == 7
    assert card["scored_on"]["sha256"] == ts["manifest"]["sha256"]
    text = (board / "leaderboard.md").read_text()
    assert "| example_predictor | fresh 2 scenes, seed 7 (--seed) |" in text
    assert f"| flat | published (sha {flat['testset_sha256'][:12]}) |" in text
    # not the scene the project's own stream draws at that index
    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    ours = label_scene("ch6_test", gen.datasets["ch6_test"], sim, load_base(params).seed, 0, 30)
    k = list(ts["source"]).index("fresh/ch6_test")
    assert not np.array_equal(ours.depth_m, ts["depth_m"][k])
    trials = load_section(TrialsConfig, "trials", params)
    again = fresh_testset(params, trials, tmp_path / "ref", 2, 7, tmp_path / "again")
    assert again["sha256"] == ts["manifest"]["sha256"]


def test_evaluate_predictor_fresh_on_a_sensed_track_senses_the_fresh_set(tmp_path, monkeypatch):
    """--fresh 2 --track d415: the fresh set labelled as ever, then sensed beside it
    (<seed>_sensed/d415); the row is scored on the sensed one and ranked in the d415 section."""
    _tiny_project(tmp_path)
    monkeypatch.chdir(tmp_path)
    board, sets = tmp_path / "board", tmp_path / "sets"
    args = ["evaluate-predictor", str(EXAMPLES / "example_predictor.py"), "--testset", "ref"]
    args += ["--out", str(board), "--fresh", "2", "--seed", "7", "--fresh-dir", str(sets)]
    result = runner.invoke(app, [*args, "--track", "d415"])
    assert result.exit_code == 0, result.output
    ideal, sensed = load(sets / "7"), load(sets / "7_sensed" / "d415")
    assert sensed["manifest"]["sensing"] == "d415"
    assert np.array_equal(ideal["instance"], sensed["instance"])
    assert not np.array_equal(ideal["depth_m"], sensed["depth_m"])
    card = read_json(board / "fresh/predictor-example_predictor@d415.json")
    assert card["sensing"] == "d415" and card["scored_on"]["sha256"] == sensed["manifest"]["sha256"]
    _, _, section = (board / "leaderboard.md").read_text().partition("## Sensed track: d415")
    assert "| example_predictor | fresh 2 scenes, seed 7 (--seed) |" in section


def test_evaluate_agent_fresh_runs_episodes_of_a_fresh_stream(tmp_path, monkeypatch):
    """--fresh 1 --seed 5: episode 0 of fresh/ch6_3_10 (not the published episode 0), drawn
    with the fresh stream seed; its row names the seed and pairs with no planner."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    agent = f"{EXAMPLES / 'random_agent.py'}:make_agent"
    base = ["evaluate-agent", agent, "--scale", "tiny"]
    published = runner.invoke(app, [*base, "--episodes", "1", "--out", str(tmp_path / "p")])
    assert published.exit_code == 0, published.output
    args = [*base, "--fresh", "1", "--seed", "5", "--leaderboard", "--out", str(tmp_path / "f")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "seed 5 (given)" in result.output
    first = [(tmp_path / d / "make_agent/records.jsonl").read_text() for d in ("p", "f")]
    mine, theirs = (json.loads(text.splitlines()[0]) for text in reversed(first))
    assert (mine["stream"], mine["seed"]) == ("fresh/ch6_3_10", stream_seed(5))
    assert mine["scene"] != theirs["scene"] and theirs["stream"] == "ch6_3_10"
    card = read_json(tmp_path / "reports/leaderboard/fresh/agent-make_agent.json")
    assert card["scored_on"]["seed"] == 5 and card["success_paired"] == {}
    text = (tmp_path / "reports/leaderboard/leaderboard.md").read_text()
    assert "| make_agent | fresh 1 scenes, seed 5 (--seed) | fresh/ch6_3_10 |" in text
