"""The test set's sensed track (data/testset_sensed.py): the ideal track's scenes with every
depth image through a sensor model, everything else the ideal track's own; its own manifest
and hash; the leaderboard and evaluate-predictor keep both tracks."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clutterbench.data.testset_load import load
from clutterbench.data.testset_sensed import export_sensed, sensed_tracks, track_dir
from clutterbench.errors import ClutterbenchError
from clutterbench.io import save_npz
from clutterbench.observation import CameraModel
from clutterbench.sim.config import CameraConfig
from clutterbench.sim.sensor import focal_px, observation_rng, preset, sense
from clutterbench.support.scorecard import leaderboard, score, write_row

ROOT = Path(__file__).resolve().parents[2]
PUBLISHED = ROOT / "data/published/testset"
CAMERA = CameraConfig(image_size=128, fovy_deg=42.0)
SCENES = 6


@pytest.fixture(scope="module")
def published() -> dict:
    return load(PUBLISHED)


def _ideal(root: Path, ts: dict) -> Path:
    """The published set's first SCENES scenes as an ideal track of their own in root."""
    arrays = {k: v[:SCENES] for k, v in ts.items() if k != "manifest"}
    root.mkdir(parents=True)
    save_npz(root / "scenes.npz", arrays)
    manifest = {k: v for k, v in ts["manifest"].items() if k != "files"}
    manifest["sha256"] = hashlib.sha256((root / "scenes.npz").read_bytes()).hexdigest()
    (root / "manifest.json").write_text(json.dumps(manifest))
    (root / "load_testset.py").write_bytes((PUBLISHED / "load_testset.py").read_bytes())
    return root


def _bytes(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(root.iterdir())}


def test_the_sensed_track_is_the_ideal_one_with_only_its_depth_sensed(tmp_path, published):
    ideal_dir = _ideal(tmp_path / "testset", published)
    before = _bytes(ideal_dir)
    manifest = export_sensed(ideal_dir, "d415", CAMERA)
    out = tmp_path / "testset_sensed" / "d415"
    assert track_dir(ideal_dir, "d415") == out and track_dir(ideal_dir, "ideal") == ideal_dir
    assert _bytes(ideal_dir) == before  # the ideal track is left as it was
    ideal, sensed = load(ideal_dir), load(out)  # load: its sha256 is its manifest's
    assert sorted(sensed) == sorted(ideal)
    for key in ideal:
        if key in ("depth_m", "manifest"):
            continue
        assert sensed[key].dtype == ideal[key].dtype, key
        assert np.array_equal(sensed[key], ideal[key], equal_nan=sensed[key].dtype.kind == "f")
    d, z = sensed["depth_m"], ideal["depth_m"]
    assert d.dtype == np.float32 and d.shape == z.shape
    for s in range(SCENES):  # every image sensed, and noticeably so
        assert (d[s] != z[s]).mean() > 0.2, s
    # each image exactly as observe() senses a picture: seeded by the image itself
    f = focal_px(CAMERA.image_size, CAMERA.fovy_deg)
    cam = CameraModel(K=np.array([[f, 0, 64], [0, f, 64], [0, 0, 1.0]]), T_world_from_cam=np.eye(4))
    assert np.array_equal(d[2], sense(z[2], cam, preset("d415"), observation_rng(0, z[2])))
    sha = hashlib.sha256((out / "scenes.npz").read_bytes()).hexdigest()
    assert manifest["sha256"] == sensed["manifest"]["sha256"] == sha != ideal["manifest"]["sha256"]
    assert manifest["sensing"] == "d415" and "sensing" not in ideal["manifest"]
    assert manifest["sensed_from"]["sha256"] == ideal["manifest"]["sha256"]
    rest = {k: v for k, v in manifest.items() if k not in ("sha256", "sensing", "sensed_from")}
    assert rest.pop("arrays")["depth_m"] != ideal["manifest"]["arrays"]["depth_m"]
    assert rest == {k: v for k, v in ideal["manifest"].items() if k not in ("sha256", "arrays")}
    assert (out / "load_testset.py").read_bytes() == before["load_testset.py"]
    assert sensed_tracks(ideal_dir) == {"d415": sha}
    export_sensed(ideal_dir, "d415", CAMERA)  # a rerun writes the very same bytes
    assert hashlib.sha256((out / "scenes.npz").read_bytes()).hexdigest() == sha
    with pytest.raises(ClutterbenchError, match="not the ideal depth"):
        export_sensed(ideal_dir, "ideal", CAMERA)


def _flat(depth, masks, cam, i):
    return np.full(len(masks), 0.5)


def _tracks(tmp_path: Path, published: dict) -> tuple[dict, dict]:
    ideal_dir = _ideal(tmp_path / "data/published/testset", published)
    export_sensed(ideal_dir, "d415", CAMERA)
    return load(ideal_dir), load(track_dir(ideal_dir, "d415"))


def test_the_leaderboard_ranks_each_track_apart_and_drops_none(tmp_path, published):
    from clutterbench.envs.board import rewrite_leaderboard

    ideal, sensed = _tracks(tmp_path, published)
    board = tmp_path / "reports/leaderboard"
    write_row(score(ideal, _flat, "flat", "one half"), board / "baselines")
    only_ideal = leaderboard(board, board, ideal["manifest"]["sha256"])
    ideal_csv = (board / "leaderboard.csv").read_text()
    card = score(sensed, _flat, "flat", "one half")
    assert card["sensing"] == "d415" and card["testset_sha256"] == sensed["manifest"]["sha256"]
    write_row(card, board / "baselines", "flat@d415")
    write_row(score(sensed, _flat, "sensed_only", ""), board / "submitted", "sensed_only@d415")
    tracks = sensed_tracks(tmp_path / "data/published/testset")
    table = leaderboard(board, board, ideal["manifest"]["sha256"], tracks)
    assert table.equals(only_ideal) and (board / "leaderboard.csv").read_text() == ideal_csv
    text = (board / "leaderboard.md").read_text()
    ideal_part, _, sensed_part = text.partition("## Sensed track: d415")
    assert "| flat |" in ideal_part and "sensed_only" not in ideal_part
    assert "| flat |" in sensed_part and "| sensed_only |" in sensed_part
    assert sensed["manifest"]["sha256"][:12] in sensed_part
    d415 = (board / "leaderboard_d415.csv").read_text()
    assert "flat" in d415 and "sensed_only" in d415
    # a sensed row of another version of the track is not ranked beside this one's
    stale = score(sensed, _flat, "stale", "") | {"testset_sha256": "0" * 64}
    write_row(stale, board / "submitted", "stale@d415")
    rewrite_leaderboard(board)  # finds the sensed track beside the project's test set
    assert (board / "leaderboard.md").read_text() == text


def test_evaluate_predictor_scores_either_track(tmp_path, published):
    ideal, sensed = _tracks(tmp_path, published)
    ideal_dir = tmp_path / "data/published/testset"
    cli = [sys.executable, "-m", "clutterbench.cli.__main__", "evaluate-predictor"]
    example = str(ROOT / "docs/examples/example_predictor.py")
    args = [example, "--testset", str(ideal_dir), "--out", str(tmp_path / "board")]
    for extra in ([], ["--track", "d415"]):
        out = subprocess.run([*cli, *args, *extra], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
    rows = tmp_path / "board/submitted"
    on_ideal = json.loads((rows / "example_predictor.json").read_text())
    on_sensed = json.loads((rows / "example_predictor@d415.json").read_text())
    assert on_ideal["testset_sha256"] == ideal["manifest"]["sha256"] and "sensing" not in on_ideal
    assert on_sensed["testset_sha256"] == sensed["manifest"]["sha256"]
    assert on_sensed["sensing"] == "d415"
    text = (tmp_path / "board/leaderboard.md").read_text()
    assert text.count("| example_predictor |") == 2 and "## Sensed track: d415" in text
    for bad, says in (("structured_light", "no such track"), ("nope", "one of")):
        out = subprocess.run([*cli, *args, "--track", bad], capture_output=True, text=True)
        assert out.returncode == 2 and says in out.stderr, out.stderr
        assert out.stderr.strip().count("\n") == 0
    sensed_dir = str(track_dir(ideal_dir, "d415"))
    out = subprocess.run([*cli, example, "--testset", sensed_dir], capture_output=True, text=True)
    assert out.returncode == 2 and "a sensed track; --testset names the ideal" in out.stderr


def test_publish_testset_publishes_the_sensed_track_beside_the_ideal_one(tmp_path, published):
    from clutterbench.data.testset_pins import pin_problems

    ideal, sensed = _tracks(tmp_path, published)
    src = tmp_path / "data/published/testset"
    dst = tmp_path / "pub/testset"
    cli = [sys.executable, "-m", "clutterbench.cli.__main__", "publish-testset"]
    out = subprocess.run(
        [*cli, "--testset", str(src), "--to", str(dst)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in dst.parent.iterdir()) == ["testset", "testset_sensed"]
    assert load(dst)["manifest"]["sha256"] == ideal["manifest"]["sha256"]
    assert sensed_tracks(dst) == {"d415": sensed["manifest"]["sha256"]}
    assert pin_problems(dst) == [] and pin_problems(track_dir(dst, "d415")) == []
