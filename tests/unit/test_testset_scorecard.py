"""The pull-consequence test set's numpy-only loader, the scorer and evaluate-predictor."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clutterbench.data.testset_load import SCHEMA_VERSION, labels, load, pairs
from clutterbench.errors import ClutterbenchError
from clutterbench.io import save_npz
from clutterbench.support.scorecard import leaderboard, per_box, scene_rows, score, write_row

ROOT = Path(__file__).resolve().parents[2]


def _write_testset(root: Path, scenes: int = 4) -> Path:
    """Scenes of three boxes in a row: pulling box 0 collapses box 1, nothing else."""
    n, h = 3, 12
    inst = np.zeros((scenes, h, h), np.uint8)
    inst[:, 2:10, 0:4], inst[:, 2:10, 4:8], inst[:, 2:10, 8:12] = 1, 2, 3
    nan = np.full((scenes, n, n), np.nan)
    drop = np.zeros((scenes, n, n))
    drop[:, 0, 1] = 0.05
    arrays = {
        "depth_m": np.ones((scenes, h, h), np.float32) + np.arange(scenes)[:, None, None],
        "instance": inst,
        "n_objects": np.full(scenes, n),
        "family": np.array(["random"] * scenes),
        "scene_index": np.arange(scenes),
        "source": np.array(["ds"] * scenes),
        "contact": np.zeros((scenes, n, n), bool),
        "pull_displacement_m": np.where(drop > 0, 0.05, 0.0),
        "pull_drop_m": drop,
        "pull_tilt_deg": np.zeros((scenes, n, n)),
        "pull_left_shelf": np.zeros((scenes, n, n), bool),
        "deletion_displacement_m": nan,
        "deletion_drop_m": nan,
        "deletion_tilt_deg": nan,
        "deletion_left_shelf": np.zeros((scenes, n, n), bool),
    }
    root.mkdir(parents=True)
    save_npz(root / "scenes.npz", arrays)
    manifest = {
        "schema_version": SCHEMA_VERSION,
        "sha256": hashlib.sha256((root / "scenes.npz").read_bytes()).hexdigest(),
        "camera": {"K": np.eye(3).tolist(), "image_size": h},
        "thresholds": {"moved_m": 0.005, "drop_m": 0.01, "tilt_deg": 15.0},
        "min_pixels": 5,
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    (root / "load_testset.py").write_text(
        (ROOT / "src/clutterbench/data/testset_load.py").read_text()
    )
    return root


def test_scene_rows_are_each_drawn_scene_s_rows_in_draw_order():
    first, sizes = np.array([0, 3, 4, 9]), np.array([3, 1, 5, 2])
    pick = np.array([2, 0, 2, 3, 1])
    expected = np.concatenate([np.arange(first[i], first[i] + sizes[i]) for i in pick])
    assert np.array_equal(scene_rows(first[pick], sizes[pick]), expected)


def test_the_loader_needs_numpy_alone_and_refuses_a_changed_file(tmp_path):
    root = _write_testset(tmp_path / "ts")
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import load_testset as t; "
        "ts = t.load(sys.argv[1]); "
        "assert not any(m.startswith('clutterbench') or m == 'torch' for m in sys.modules); "
        "print(sum(1 for _ in t.pairs(ts, 'pull_collapse')))"
    )
    out = subprocess.run(
        [sys.executable, "-I", "-c", code, str(root)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "12"  # 4 scenes x 3 pulled boxes
    ts = load(root)
    lab = labels(ts, "pull_collapse")
    assert lab[:, 0, 1].all() and lab.sum() == 4
    assert [t.tolist() for _, i, _, t in pairs(ts, "pull_collapse")][:3] == [
        [False, True, False],
        [False, False, False],
        [False, False, False],
    ]
    (root / "scenes.npz").write_bytes((root / "scenes.npz").read_bytes() + b"x")
    with pytest.raises(ValueError, match="sha256"):
        load(root)


def test_a_perfect_predictor_scores_one_and_a_constant_one_half(tmp_path):
    ts = load(_write_testset(tmp_path / "ts"))

    def perfect(depth, masks, cam, i):
        return np.array([0.0, 1.0, 0.0]) if i == 0 else np.zeros(3)

    card = score(ts, perfect, "perfect", "knows")
    assert card["pull_collapse"]["auroc"] == 1.0 and card["pull_collapse"]["recall"] == 1.0
    assert card["pairs"] == 24 and card["pull_collapse"]["positives"] == 4
    flat = score(ts, lambda d, m, c, i: np.full(len(m), 0.5), "flat", "")
    assert flat["pull_collapse"]["auroc"] == 0.5
    write_row(card, tmp_path / "board" / "baselines")
    write_row(flat, tmp_path / "board" / "submitted")
    table = leaderboard(tmp_path / "board", tmp_path / "board", ts["manifest"]["sha256"])
    assert list(table["predictor"]) == ["perfect", "flat"]
    assert "perfect" in (tmp_path / "board" / "leaderboard.md").read_text()


def test_a_pixel_map_is_read_per_box_and_a_bad_answer_is_one_line():
    masks = np.zeros((2, 4, 4), bool)
    masks[0, :, :2], masks[1, :, 2:] = True, True
    heat = np.zeros((4, 4))
    heat[:, 2:] = 0.8
    probs, got = per_box(heat, masks)
    assert probs.tolist() == pytest.approx([0.0, 0.8]) and got is heat
    for bad, match in (
        (np.zeros(3), "shape"),
        (np.array([0.2, 1.5]), "outside"),
        ("yes", "not numbers"),
    ):
        with pytest.raises(ClutterbenchError, match=match):
            per_box(bad, masks)


def test_evaluate_predictor_scores_the_example_and_refuses_a_broken_module(tmp_path):
    root = _write_testset(tmp_path / "ts")
    cli = [sys.executable, "-m", "clutterbench.cli.__main__", "evaluate-predictor"]
    example = str(ROOT / "docs/examples/example_predictor.py")
    args = ["--testset", str(root), "--out", str(tmp_path / "board")]
    out = subprocess.run([*cli, example, *args], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "board/submitted/example_predictor.json").exists()
    assert "example_predictor" in (tmp_path / "board/leaderboard.md").read_text()
    broken = tmp_path / "broken.py"
    broken.write_text("def predict(depth_m, masks, camera_K, pulled):\n    return 'no'\n")
    out = subprocess.run([*cli, str(broken), *args], capture_output=True, text=True)
    assert out.returncode == 2 and out.stderr.strip().count("\n") == 0, out.stderr
    assert "not numbers" in out.stderr and "scene 0 (ds scene 0), pulled box 0" in out.stderr


def test_a_predictor_s_error_names_the_scene_and_the_pulled_box(tmp_path):
    """Whatever a predictor raises or returns wrong: one line naming the scene (its index, its
    source and index there) and the pulled box (its id, its position among the masks)."""
    ts = load(_write_testset(tmp_path / "ts"))

    def fails_late(depth, masks, cam, i):
        if float(depth[0, 0]) == 3.0 and i == 1:  # scene 2, its second box
            raise ZeroDivisionError("no\nroom")
        return np.zeros(len(masks))

    with pytest.raises(ClutterbenchError) as err:
        score(ts, fails_late, "late", "")
    assert str(err.value) == (
        "predictor late, scene 2 (ds scene 2), pulled box 1 (pulled=1 of 3 masks): "
        "raised ZeroDivisionError: no room"
    )

    def wrong_shape(depth, masks, cam, i):
        return np.zeros(2) if float(depth[0, 0]) == 2.0 and i == 2 else np.zeros(len(masks))

    with pytest.raises(ClutterbenchError) as err:
        score(ts, wrong_shape, "shape", "")
    assert str(err.value).startswith(
        "predictor shape, scene 1 (ds scene 1), pulled box 2 (pulled=2 of 3 masks): "
        "returned shape (2,)"
    )


def test_parts_of_different_box_counts_are_padded_as_a_shard_is():
    from clutterbench.data.testset import concat_padded

    def part(n: int, source: str) -> dict:
        return {
            "n_objects": np.array([n]),
            "source": np.array([source]),
            "sizes_m": np.ones((1, n, 3), np.float32),
            "contact": np.ones((1, n, n), bool),
            "pull_drop_m": np.zeros((1, n, n)),
            "pull_displacement_m": np.zeros((1, n, n)),
        }

    out = concat_padded([part(5, "a"), part(3, "b")])
    assert out["pull_drop_m"].shape == (2, 5, 5) and out["source"].tolist() == ["a", "b"]
    assert (
        np.isnan(out["pull_drop_m"][1, 3:, :]).all()
        and not np.isnan(out["pull_drop_m"][1, :3, :3]).any()
    )
    assert (out["sizes_m"][1, 3:] == 0).all() and not out["contact"][1, 3:].any()


def test_a_per_scene_baseline_answers_a_scenes_boxes_from_one_call():
    from clutterbench.support.baselines import per_scene

    calls = []

    def answer_all(depth, masks, _cam):
        calls.append(float(depth[0, 0]))
        return np.arange(len(masks))[:, None] * np.ones(len(masks)) / 10

    predict = per_scene(answer_all)
    masks = np.zeros((3, 4, 4), bool)
    for scene in (1.0, 2.0):
        depth = np.full((4, 4), scene, np.float32)
        assert [predict(depth, masks, None, i)[0] for i in range(3)] == [0.0, 0.1, 0.2]
    assert calls == [1.0, 2.0]


def test_the_run_s_own_test_set_comes_first_then_the_published_copy(tmp_path, monkeypatch):
    from clutterbench.cli.predictors import PUBLISHED, TESTSET, testset_dir

    (tmp_path / "params.yaml").write_text("base: {}\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ClutterbenchError, match="no test set: neither"):
        testset_dir(None)
    _write_testset(tmp_path / PUBLISHED)
    assert testset_dir(None) == tmp_path / PUBLISHED
    _write_testset(tmp_path / TESTSET)
    assert testset_dir(None) == tmp_path / TESTSET
    with pytest.raises(ClutterbenchError, match="no manifest"):
        testset_dir(tmp_path / "elsewhere")


def test_publish_testset_copies_a_set_that_loads_and_refuses_a_broken_one(tmp_path):
    from clutterbench.cli.predictors import load_testset
    from clutterbench.data.testset_load import load
    from clutterbench.data.testset_pins import pin_problems

    src = _write_testset(tmp_path / "ts")
    dst = tmp_path / "published" / "testset"
    cli = [sys.executable, "-m", "clutterbench.cli.__main__", "publish-testset"]
    for _ in range(2):  # a second publication replaces the first whole
        out = subprocess.run(
            [*cli, "--testset", str(src), "--to", str(dst)], capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr
    assert load(dst)["manifest"]["sha256"] == load(src)["manifest"]["sha256"]
    assert sorted(p.name for p in dst.parent.iterdir()) == ["testset"]
    # the published manifest pins every file of the set, its loader included
    assert sorted(load(dst)["manifest"]["files"]) == ["load_testset.py", "scenes.npz"]
    assert pin_problems(dst) == []
    loader = dst / "load_testset.py"
    loader.write_text(loader.read_text() + "# changed\n")
    with pytest.raises(ClutterbenchError, match="load_testset.py: sha256 .* pinned"):
        load_testset(dst)
    loader.write_text(loader.read_text().removesuffix("# changed\n"))
    (src / "scenes.npz").write_bytes(b"not the manifest's")
    out = subprocess.run(
        [*cli, "--testset", str(src), "--to", str(dst)], capture_output=True, text=True
    )
    assert out.returncode == 2 and "sha256" in out.stderr and out.stderr.strip().count("\n") == 0
    assert load(dst)["manifest"]["sha256"]  # the published copy is untouched


def test_the_about_cell_is_the_docstrings_first_sentence_whole():
    from clutterbench.cli.predictors import first_sentence

    doc = """A box collapses when its lowest pixel is above the pulled
    box's top. Nothing else is used.

    More words."""
    assert (
        first_sentence(doc)
        == "A box collapses when its lowest pixel is above the pulled box's top."
    )
    assert first_sentence("") == ""


def test_an_agent_row_keeps_the_predictor_rows_of_the_published_test_set(tmp_path):
    """A clone with only the published copy: adding a planner's row rewrites the leaderboard
    with the predictor table still in it."""
    from clutterbench.envs.board import agent_card, write_agent_row

    ts = load(_write_testset(tmp_path / "data/published/testset"))
    board = tmp_path / "reports/leaderboard"
    write_row(score(ts, lambda d, m, c, i: np.full(len(m), 0.5), "flat", ""), board / "baselines")
    records = [{"stream": "s", "episode": 0, "success": True, "strict_success": False}]
    about = {"kind": "agent", "name": "a", "first_episode": 0}
    write_agent_row(agent_card(records, about, tmp_path / "reports/trials"), board)
    text = (board / "leaderboard.md").read_text()
    assert "| flat |" in text and "| a |" in text


def test_the_agent_board_and_evaluate_predictor_look_for_the_same_test_sets():
    from clutterbench.cli.predictors import PUBLISHED, TESTSET
    from clutterbench.envs.board import TESTSET_DIRS

    assert TESTSET_DIRS == (TESTSET, PUBLISHED)
