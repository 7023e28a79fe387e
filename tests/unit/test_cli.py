"""`clutterbench scene ...` on the committed three-box stack (tests/data/stack3.json)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest
from click.testing import Result
from typer.testing import CliRunner

from clutterbench.cli import app, common
from clutterbench.logs.mcap_episode import read_episode
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.spec import SceneSpec

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
BOX_H_M = 0.020

runner = CliRunner()


@pytest.fixture(autouse=True)
def _isolated_cwd(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # No params.yaml from the repository: physics defaults, as stack3.json was made with.
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(common, "PACKAGE_REPO", tmp_path / "no-repo")


def _act(*args: str) -> dict:
    result = runner.invoke(app, ["scene", "act", str(STACK3), *args])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def _by_index(out: dict) -> dict[int, dict]:
    return {o["index"]: o for o in out["objects"]}


def test_stack3_spec_is_three_stacked_boxes() -> None:
    spec = SceneSpec.load(STACK3)
    assert spec.n == 3
    z = spec.poses[:, 2]
    assert z == pytest.approx([0.01, 0.03, 0.05], abs=1e-3)


def test_removing_bottom_box_drops_the_two_above() -> None:
    out = _act("--remove", "0")
    assert (out["action"], out["target"], out["support"]) == ("remove", 0, None)
    assert out["threshold_m"] == pytest.approx(0.005)
    objs = _by_index(out)
    assert objs[0] == {"index": 0, "displacement_m": None, "moved": None}
    for i in (1, 2):
        assert objs[i]["moved"] is True
        assert objs[i]["displacement_m"] == pytest.approx(BOX_H_M, abs=0.003)


def test_removing_top_box_moves_nothing() -> None:
    objs = _by_index(_act("--remove", "2"))
    assert objs[2]["displacement_m"] is None and objs[2]["moved"] is None
    for i in (0, 1):
        assert objs[i]["moved"] is False
        assert objs[i]["displacement_m"] < 0.005


def test_support_holds_the_stack_above() -> None:
    out = _act("--remove", "0", "--support", "1")
    assert out["support"] == 1
    objs = _by_index(out)
    assert objs[1] == {"index": 1, "displacement_m": 0.0, "moved": False}
    assert objs[2]["moved"] is False


@pytest.mark.parametrize(
    "args",
    [
        ["--remove", "3"],
        ["--remove", "-1"],
        ["--remove", "0", "--support", "7"],
        ["--remove", "1", "--support", "1"],
    ],
)
def test_bad_index_is_a_one_line_error(args: list[str]) -> None:
    result = runner.invoke(app, ["scene", "act", str(STACK3), *args])
    assert result.exit_code == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")


def test_missing_spec_is_an_error(tmp_path: Path) -> None:
    result = runner.invoke(app, ["scene", "act", str(tmp_path / "nope.json"), "--remove", "0"])
    assert result.exit_code == 2
    assert result.stderr.startswith("error: scene spec not found")


def test_show_writes_two_panel_png(tmp_path: Path) -> None:
    out = tmp_path / "scene.png"
    result = runner.invoke(app, ["scene", "show", str(STACK3), "--out", str(out)])
    assert result.exit_code == 0, result.output
    image = cv2.imread(str(out))
    assert image is not None
    assert image.shape[1] > image.shape[0]
    assert [p.name for p in tmp_path.iterdir()] == ["scene.png"]  # no temp file left


def test_act_writes_mcap_episode(tmp_path: Path) -> None:
    path = tmp_path / "ep.mcap"
    out = _act("--remove", "0", "--mcap", str(path))
    assert [o["moved"] for o in out["objects"]] == [None, True, True]
    episode = read_episode(path)
    topics = episode["topics"]
    assert topics["/tf"] == 2
    assert topics["/camera/depth"] == 2 and topics["/camera/instance"] == 2
    assert topics["/planner/decision"] == 1
    outcome = episode["metadata"]["outcome"]
    assert outcome["moved_count"] == "2" and outcome["moved"] == "1,2"


def test_make_writes_a_settled_stack(tmp_path: Path) -> None:
    path = tmp_path / "stack2.json"
    result = runner.invoke(
        app, ["scene", "make", str(path), "--stack", "2", "--size-mm", "30", "80", "60"]
    )
    assert result.exit_code == 0, result.output
    spec = SceneSpec.load(path)
    assert spec.n == 2
    assert spec.sizes_m.ravel().tolist() == pytest.approx([0.06, 0.08, 0.03] * 2)
    assert spec.poses[:, 2] == pytest.approx([0.015, 0.045], abs=1e-3)
    assert spec.poses[:, 0] == pytest.approx(spec.shelf.depth_m / 2, abs=1e-3)


def test_make_rejects_a_stack_taller_than_the_shelf(tmp_path: Path) -> None:
    result = runner.invoke(app, ["scene", "make", str(tmp_path / "x.json"), "--stack", "20"])
    assert result.exit_code == 2
    assert result.stderr.startswith("error: ")
    assert not (tmp_path / "x.json").exists()


def test_physics_config_from_params_yaml(tmp_path: Path) -> None:
    assert common.physics_config() == PhysicsConfig()
    (tmp_path / "params.yaml").write_text(
        "base: {scale: tiny}\nsim:\n  physics:\n    timestep_s: 0.002\n"
    )
    assert common.physics_config().timestep_s == 0.002


def test_plan_prints_inferred_and_true_support_and_executes(tmp_path):
    """`clutterbench plan` on the 3-box stack: the physics truth is bottom -> middle -> top,
    the JSON carries the extraction order and the bimanual option, --execute judges it."""
    import torch

    from clutterbench.models import build_model
    from clutterbench.models.checkpoint import save_checkpoint
    from clutterbench.models.collapse_map import CollapseMapConfig
    from clutterbench.models.vgg import VGGConfig

    torch.manual_seed(0)
    cfg = CollapseMapConfig(
        input_size=128, encoder=VGGConfig(width=0.125), decoder_channels=(32, 16, 16, 8, 8)
    )
    model = tmp_path / "best.pt"
    save_checkpoint(model, "collapse_map", build_model("collapse_map", cfg), {"epoch": 0})
    thresholds = tmp_path / "thresholds.json"
    params = {
        "rule": "coverage",
        "prob_threshold": 0.5,
        "score_threshold": 0.3,
        "bbox_margin_px": 2,
        "adjacency_iou": 0.0,
    }
    thresholds.write_text(json.dumps({"chosen": {"coverage": params}}))
    spec = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
    args = [
        "plan",
        str(spec),
        "--target",
        "0",
        "--model",
        str(model),
        "--thresholds",
        str(thresholds),
        "--rule",
        "coverage",
        "--execute",
        "--planner",
        "oracle",
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    truth = {(e["supporter"], e["supported"]) for e in out["true_edges"]}
    assert truth == {(0, 1), (1, 2)}
    assert out["extraction_order"][-1] == 0 and set(out["bimanual"]) == {
        "hold",
        "pull",
        "steps_to_target",
    }
    # The oracle takes the stack down from the top: three clean steps.
    assert [s["box"] for s in out["execute"]["steps"]] == [2, 1, 0]
    assert out["execute"]["success"] is True
    bad = CliRunner().invoke(app, [*args[:3], "7", *args[4:]])
    assert bad.exit_code == 2 and "--target 7" in bad.output


# -- entering from anywhere: version, default paths, outputs ---------------------------------------
def _one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    return lines[0]


def test_version_is_the_installed_package_version() -> None:
    import importlib.metadata

    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == f"clutterbench {importlib.metadata.version('clutterbench')}"


@pytest.mark.parametrize(
    "args",
    [
        ["scene", "show", str(STACK3), "--out", "{dir}"],
        ["scene", "act", str(STACK3), "--remove", "0", "--mcap", "{dir}"],
        ["scene", "make", "{dir}", "--stack", "2"],
        ["scene", "get", "ch6", "0", "--out", "{dir}"],
        ["plan", str(STACK3), "--target", "0", "--execute", "--mcap", "{dir}"],
    ],
)
def test_an_output_path_that_is_a_directory_is_refused_up_front(tmp_path: Path, args) -> None:
    out = tmp_path / "out"
    out.mkdir()
    line = _one_error_line(runner.invoke(app, [a.format(dir=out) for a in args]))
    assert f"{out}: is a directory; give a file name" in line
    assert list(out.iterdir()) == []


def test_project_root_is_found_from_a_subdirectory(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "params.yaml").write_text(
        "base: {scale: tiny}\nsim:\n  physics:\n    timestep_s: 0.002\n"
    )
    sub = tmp_path / "a" / "b"
    sub.mkdir(parents=True)
    monkeypatch.chdir(sub)
    assert common.project_root() == tmp_path.resolve()
    assert common.physics_config().timestep_s == 0.002


def test_project_root_falls_back_to_the_package_repository(tmp_path: Path, monkeypatch) -> None:
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "dvc.yaml").write_text("stages: {}\n")
    monkeypatch.setattr(common, "PACKAGE_REPO", repo)
    assert common.project_root() == repo
    monkeypatch.setattr(common, "PACKAGE_REPO", tmp_path / "not-a-repo")
    assert common.project_root() is None


def test_plan_names_the_flag_of_a_missing_default_file(tmp_path: Path) -> None:
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    line = _one_error_line(runner.invoke(app, ["plan", str(STACK3), "--target", "0"]))
    model = tmp_path.resolve() / "models" / "cp_focal" / "best.pt"
    assert line.startswith(f"error: --model {model}: not found; pass --model PATH")
    model.parent.mkdir(parents=True)
    model.write_bytes(b"")
    line = _one_error_line(runner.invoke(app, ["plan", str(STACK3), "--target", "0"]))
    assert line.startswith("error: --thresholds ")
    assert "reports/support/thresholds.json: not found; pass --thresholds PATH" in line
    args = ["plan", str(STACK3), "--target", "0", "--thresholds", str(tmp_path)]
    line = _one_error_line(runner.invoke(app, args))
    assert line == f"error: --thresholds {tmp_path}: is a directory, not a file"


# -- scene make --family, scene get ---------------------------------------------------------------
def test_make_family_writes_a_settled_scene_of_that_family(tmp_path: Path) -> None:
    args = ["--family", "pile", "--seed", "3", "--n-objects", "5", "--catalogue", "same"]
    for name in ("a.json", "b.json"):
        result = runner.invoke(app, ["scene", "make", str(tmp_path / name), *args])
        assert result.exit_code == 0, result.output
    spec = SceneSpec.load(tmp_path / "a.json")
    assert (spec.family, spec.n) == ("pile", 5)
    assert spec.meta["seed"] == 3 and spec.meta["catalogue"] == "same"
    assert spec.type_ids is not None and (spec.type_ids == 0).all()  # the one 'same' size
    assert (tmp_path / "a.json").read_text() == (tmp_path / "b.json").read_text()  # seeded


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--family", "heap"], "--family heap: not one of shelved, stacked, random"),
        (["--family", "pile", "--catalogue", "odd"], "--catalogue odd: not one of same"),
        (["--family", "pile", "--n-objects", "0"], "--n-objects 0: must be between 1 and 30"),
        (["--family", "pile", "--seed", "-1"], "--seed -1: must be >= 0"),
        (["--family", "pile", "--stack", "2"], "give one of --stack N or --family F"),
        ([], "give one of --stack N or --family F"),
    ],
)
def test_make_refuses_bad_options_with_one_line(tmp_path: Path, args, message) -> None:
    line = _one_error_line(runner.invoke(app, ["scene", "make", str(tmp_path / "x.json"), *args]))
    assert message in line
    assert not (tmp_path / "x.json").exists()


MINI_PARAMS = """\
base: {seed: 0, scale: tiny}
sim: {}
generate:
  shard_size: 1
  workers: 1
  max_attempts: 30
  datasets:
    mini: {n_scenes: 2, families: {stacked: 1}, n_objects: [2, 3], catalogue: various}
"""


def test_scene_get_reads_the_shard_or_regenerates_the_same_scene(
    tmp_path: Path, monkeypatch
) -> None:
    from clutterbench.config import load_base, load_params, load_section
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.generate import generate_dataset
    from clutterbench.sim.config import SimConfig

    (tmp_path / "params.yaml").write_text(MINI_PARAMS)
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    params = load_params(tmp_path / "params.yaml")
    gen = load_section(GenerateConfig, "generate", params)
    data = tmp_path / "data" / "generate" / "mini"
    generate_dataset(
        "mini",
        gen.datasets["mini"],
        gen,
        load_section(SimConfig, "sim", params),
        load_base(params).seed,
        data,
    )
    sub = tmp_path / "elsewhere"
    sub.mkdir()
    monkeypatch.chdir(sub)  # the project is found above the working directory

    stored = runner.invoke(app, ["scene", "get", "mini", "1", "--out", "stored.json"])
    assert stored.exit_code == 0, stored.output
    assert "from " in stored.stdout and "shard-00001.npz" in stored.stdout
    (data / "shard-00001.npz").unlink()
    again = runner.invoke(app, ["scene", "get", "mini", "1", "--out", "again.json"])
    assert again.exit_code == 0, again.output
    assert "regenerated from seed 0" in again.stdout
    assert (sub / "stored.json").read_text() == (sub / "again.json").read_text()
    spec = SceneSpec.load(sub / "again.json")
    assert spec.meta == {"attempt": spec.meta["attempt"], "dataset": "mini", "index": 1, "seed": 0}

    for args, message in (
        (["nope", "0"], "DATASET nope: no such dataset (known: mini)"),
        (["mini", "2"], "INDEX 2: dataset mini has scenes 0..1"),
    ):
        line = _one_error_line(runner.invoke(app, ["scene", "get", *args, "--out", "x.json"]))
        assert message in line


def test_a_spec_not_at_rest_gets_one_warning_naming_the_box(tmp_path):
    """The top box of the stack lifted 50 mm: it falls with no action. `scene act` warns once,
    naming box 2 and how far it moved, and still runs (exit 0); the resting stack gets none."""
    raw = json.loads(STACK3.read_text())
    raw["boxes"][2]["pose"][2] += 0.05
    floating = tmp_path / "floating.json"
    floating.write_text(json.dumps(raw))
    result = runner.invoke(app, ["scene", "act", str(floating), "--remove", "0"])
    assert result.exit_code == 0, result.output
    (line,) = [ln for ln in result.output.splitlines() if ln.startswith("warning:")]
    assert "box 2 moves 5" in line and "not at rest" in line
    calm = runner.invoke(app, ["scene", "act", str(STACK3), "--remove", "0"])
    assert "warning:" not in calm.output


@pytest.mark.parametrize("planner", ["oracle", "random"])
def test_plan_runs_the_oracle_and_random_planners_without_a_checkpoint(tmp_path, planner):
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")  # a project without models or reports
    args = ["plan", str(STACK3), "--target", "2", "--execute", "--planner", planner]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    out = json.loads(result.output.strip().splitlines()[-1])
    assert out["inferred_edges"] is None and out["true_edges"]
    assert out["execute"]["planner"] == planner and out["execute"]["steps"]


def test_yamakuzushi_plays_one_game_and_prints_each_slide() -> None:
    result = runner.invoke(app, ["yamakuzushi", "--seed", "3", "--variant", "random"])
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in result.output.splitlines() if line.startswith("{")]
    head = lines[-1]
    assert head["seed"] == 3 and head["condition"] == "random"
    assert len(lines) - 1 == head["slides"] >= 1
    assert head["pieces_removed"] == sum(s["success"] for s in lines[:-1])


def test_yamakuzushi_unknown_variant_is_a_one_line_error() -> None:
    result = runner.invoke(app, ["yamakuzushi", "--variant", "best"])
    assert result.exit_code == 2
    assert "--variant 'best'" in result.output and len(result.output.strip().splitlines()) == 1


def test_yamakuzushi_validate_plays_each_threshold_on_validation_piles(tmp_path: Path) -> None:
    import torch

    from clutterbench.models.slide_convnet import (
        SlideConvNet,
        SlideConvNetConfig,
        save_slide_convnet,
    )
    from clutterbench.trials.ch3.config import Ch3Config

    size = Ch3Config().scan.crop_px
    model = tmp_path / "slide.pt"
    torch.manual_seed(0)
    save_slide_convnet(model, SlideConvNet(SlideConvNetConfig(input_size=size)).eval(), {})
    args = ["yamakuzushi-validate", "--games", "1", "--model", str(model)]
    result = runner.invoke(app, [*args, "--min-probability", "1", "--min-probability", "0"])
    assert result.exit_code == 0, result.output
    rows = {line.split(":")[0]: line for line in result.output.splitlines() if ": " in line}
    assert "per slide 0/0" in rows["min_probability 1"]  # nothing is that likely: no slide
    assert "per slide 0/0" not in rows["min_probability 0"]  # every piece is worth a slide


def test_yamakuzushi_validate_rejects_a_probability_outside_0_1() -> None:
    result = runner.invoke(app, ["yamakuzushi-validate", "--min-probability", "1.5"])
    assert result.exit_code == 2
    assert "--min-probability 1.5" in result.output
    assert len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "agent, message",
    [
        ("no_colon", "MODULE:FACTORY"),
        ("no_such_module_xyz:make", "cannot import"),
        ("docs/examples/none.py:make", "no file"),
        ("clutterbench.envs.agents:no_such_factory", "no callable"),
    ],
)
def test_evaluate_agent_refuses_a_bad_agent_in_one_line(agent: str, message: str) -> None:
    result = runner.invoke(app, ["evaluate-agent", agent, "--episodes", "1"])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]


def test_an_agent_that_raises_is_one_line_or_its_trace_with_traceback(tmp_path: Path) -> None:
    """An exception in the agent's act(): one line naming the agent, the episode and the
    exception; --traceback: the agent's whole trace, then that line."""
    agent = tmp_path / "broken_agent.py"
    agent.write_text(
        "def make(env):\n    def act(obs):\n        return {}['no_such_key']\n    return act\n"
    )
    args = ["evaluate-agent", f"{agent}:make", "--episodes", "1", "--first", "2"]
    args += ["--scale", "tiny", "--out", str(tmp_path / "out")]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0] == "error: agent make, episode 2: act() raised KeyError: 'no_such_key'"
    result = runner.invoke(app, [*args, "--traceback"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("Traceback") and "in act" in result.stderr
    assert lines[-1] == "error: agent make, episode 2: act() raised KeyError: 'no_such_key'"


def _run_agent_returning(tmp_path: Path, action: str) -> Result:
    agent = tmp_path / "odd_agent.py"
    agent.write_text(f"def make(env):\n    return lambda obs: {action}\n")
    args = ["evaluate-agent", f"{agent}:make", "--episodes", "1", "--scale", "tiny"]
    return runner.invoke(app, [*args, "--out", str(tmp_path / "out")])


def test_an_agent_returning_a_string_is_refused_in_one_line(tmp_path: Path) -> None:
    """act() -> "pull box 2": one line naming what it returned and what an action is."""
    result = _run_agent_returning(tmp_path, repr("pull box 2"))
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: agent make, episode 0: action refused: ")
    assert "'pull box 2'" in lines[0] and "box to pull" in lines[0]


def test_an_agent_returning_a_dict_with_wrong_keys_is_refused_naming_the_keys(
    tmp_path: Path,
) -> None:
    """act() -> {"box": 1}: refused naming the keys an action dict has, not as NaN."""
    result = _run_agent_returning(tmp_path, repr({"box": 1}))
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "NaN" not in lines[0] and "{'box': 1}" in lines[0]
    assert "'pull'" in lines[0] and "'hold'" in lines[0]


def test_evaluate_agent_writes_records_and_summary(tmp_path: Path) -> None:
    """The random agent of docs/environments-guide.md, one tiny episode: records, summary."""
    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "random_agent.py"
    agent = f"{example}:make_agent"
    args = ["evaluate-agent", agent, "--episodes", "1", "--scale", "tiny", "--out", str(tmp_path)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    out = tmp_path / "make_agent"
    records = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
    summary = json.loads((out / "summary.json").read_text())
    assert len(records) == 1 and records[0]["stream"] == "ch6_3_10"
    assert summary["success_n"] == 1 and "strict_success_k" in summary


def test_replenish_places_a_box_and_judges_it_without_a_checkpoint(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")  # a project without models or reports
    args = ["replenish", str(STACK3), "--box", "60,40,80", "--planner", "random", "--execute"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    out = json.loads(result.output.strip().splitlines()[-1])
    assert out["box_mm"] == [60.0, 40.0, 80.0] and out["planner"] == "random"
    assert out["execute"]["steps"] and "success" in out["execute"]


def test_replenish_refuses_a_bad_box_in_one_line():
    result = runner.invoke(app, ["replenish", str(STACK3), "--box", "60,x,80"])
    assert result.exit_code != 0
    assert result.output.strip().splitlines() == [
        "error: --box 60,x,80: expected W,D,H in mm, e.g. 100,120,30"
    ]


def test_evaluate_agent_adds_a_leaderboard_row_paired_with_the_trials(tmp_path, monkeypatch):
    """--leaderboard: the agent's rates and, against a trials condition on the same stream and
    episodes, the episodes won only by each (here: a planner that succeeded where the agent
    did not), in agents/NAME.json and the leaderboard's planner section."""
    from clutterbench.trials.core.records import write_records

    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "random_agent.py"
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    args = ["evaluate-agent", f"{example}:make_agent", "--episodes", "1", "--scale", "tiny"]
    first = runner.invoke(app, [*args, "--out", str(tmp_path / "a")])
    assert first.exit_code == 0, first.output
    rec = json.loads((tmp_path / "a/make_agent/records.jsonl").read_text().splitlines()[0])
    other = {"episode": 0, "stream": rec["stream"], "condition": "oracle", "planner": "oracle"}
    other |= {"success": not rec["success"], "strict_success": not rec["strict_success"]}
    write_records(tmp_path / "reports/trials/oracle/records.jsonl", [other])
    result = runner.invoke(app, [*args, "--leaderboard", "--out", str(tmp_path / "b")])
    assert result.exit_code == 0, result.output
    card = json.loads((tmp_path / "reports/leaderboard/agents/make_agent.json").read_text())
    pair = card["success_paired"]["oracle"]
    assert card["success"]["n"] == 1 and pair["episodes"] == 1
    assert (pair["only_agent"], pair["only_baseline"]) == ((1, 0) if rec["success"] else (0, 1))
    board = (tmp_path / "reports/leaderboard/leaderboard.md").read_text()
    assert "## Planners on the benchmark streams" in board and "| make_agent |" in board
    assert "make_agent against each planner" in board and "| oracle |" in board
