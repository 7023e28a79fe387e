"""The pull-consequence test set as a standalone artifact (stage testset): the ch6_test
scenes' depth images, instance masks, the camera, the box list and, per (scene, pulled box),
what physics says happens to every other box when that box is pulled out by the trials'
executor and when it is deleted. A manifest names every array, its meaning, the label
thresholds and the sha256 of the arrays' file; `load_testset.py` beside it loads it with
numpy alone (clutterbench/data/testset_load.py)."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.data.shards import ShardStore, iter_shards
from clutterbench.data.testset_load import LABEL_KINDS, SCHEMA_VERSION
from clutterbench.errors import ClutterbenchError
from clutterbench.io import save_npz, write_json
from clutterbench.sim.config import CameraConfig

SOURCE = {
    "depth_m": "depth_m",
    "instance": "instance",
    "n_objects": "n_objects",
    "family": "family",
    "scene_index": "scene_index",
    "sizes_m": "sizes_m",
    "poses": "poses",
    "contact": "contact",
    "pull_displacement_m": "pullout_displacement_m",
    "pull_drop_m": "pullout_drop_m",
    "pull_tilt_deg": "pullout_tilt_deg",
    "pull_left_shelf": "pullout_left_shelf",
    "deletion_displacement_m": "removal_m",
}
"""Test-set array -> the dataset shard array it is copied from."""
ARRAYS = {
    "depth_m": "(S, H, W) float32: depth along the optical axis, metres; 0 where nothing was hit",
    "instance": "(S, H, W) uint8: instance ids, 0 background, box k is k + 1",
    "n_objects": "(S,) int: boxes in the scene (N = the largest)",
    "family": "(S,) str: the scene family",
    "scene_index": "(S,) int: the scene's index in its dataset",
    "sizes_m": "(S, N, 3) float32: each box's extents, metres (not for predictors: truth)",
    "poses": "(S, N, 7) float64: each box's settled pose, x y z qw qx qy qz, shelf frame "
    "(not for predictors: truth)",
    "contact": "(S, N, N) bool: boxes x and y touch in the settled scene",
    "pull_displacement_m": "(S, N, N) float64: [s, x, y] how far box y's centre moved when box "
    "x was pulled out by the trials' executor (raise 3 mm, pull 2 cm increments), the scene "
    "settled; NaN on the diagonal and past n_objects",
    "pull_drop_m": "(S, N, N) float64: ... how far box y's centre dropped",
    "pull_tilt_deg": "(S, N, N) float64: ... how far box y tipped, degrees",
    "pull_left_shelf": "(S, N, N) bool: ... box y left the shelf",
    "deletion_displacement_m": "(S, N, N) float64: [s, x, y] how far box y's centre moved when "
    "box x was deleted (lifted out) and the rest settled: the thesis' labels",
}
LABELS = {
    "pull_collapse": "pulling x collapses y: y left the shelf, dropped more than drop_m or "
    "tipped more than tilt_deg (the trials' collapse-free criterion)",
    "pull_moved": "pulling x moves y more than moved_m or off the shelf",
    "deletion_moved": "deleting x moves y more than moved_m (the thesis' collapse labels)",
}


def camera_matrix(camera: CameraConfig) -> list[list[float]]:
    """The 3 x 3 pinhole intrinsics the depth images were rendered with (principal point at
    the centre, f = (H / 2) / tan(fovy / 2))."""
    h = w = camera.image_size
    f = (h / 2) / float(np.tan(np.deg2rad(camera.fovy_deg) / 2))
    return [[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]]


def export_testset(
    gen_dir: Path,
    dataset: str,
    camera: CameraConfig,
    thresholds: dict[str, float],
    min_pixels: int,
    out: Path,
) -> dict[str, Any]:
    """Write out/{scenes.npz, manifest.json, load_testset.py} from every scene of `dataset`;
    thresholds: moved_m, drop_m, tilt_deg. Returns the manifest."""
    parts: dict[str, list[np.ndarray]] = {k: [] for k in SOURCE}
    keys = tuple(SOURCE.values())
    missing = [k for k in keys if k not in ShardStore(gen_dir, dataset).array_names()]
    if missing:
        raise ClutterbenchError(
            f"dataset '{dataset}' lacks {missing[0]} for the test set; generate it with "
            f"generate.datasets.{dataset}.pull_outcomes: true"
        )
    for arrays in iter_shards(gen_dir, dataset, keys):
        for name, src in SOURCE.items():
            parts[name].append(arrays[src])
    if not parts["depth_m"]:
        raise ClutterbenchError(f"dataset '{dataset}': no scenes for the test set")
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    out.mkdir(parents=True, exist_ok=True)
    save_npz(out / "scenes.npz", arrays)  # byte-identical for identical arrays
    digest = hashlib.sha256((out / "scenes.npz").read_bytes()).hexdigest()
    manifest = {
        "schema_version": SCHEMA_VERSION,
        "name": "clutterbench pull-consequence test set",
        "dataset": dataset,
        "scenes": int(len(arrays["n_objects"])),
        "max_boxes": int(arrays["pull_displacement_m"].shape[1]),
        "sha256": digest,
        "camera": {
            "K": camera_matrix(camera),
            "image_size": camera.image_size,
            "frame": "x right, y down, z along the optical axis",
        },
        "thresholds": dict(thresholds),
        "min_pixels": int(min_pixels),
        "arrays": ARRAYS,
        "labels": {k: LABELS[k] for k in LABEL_KINDS},
        "load": "load_testset.py (numpy alone): load(dir), labels(ts, kind), pairs(ts, kind)",
    }
    write_json(out / "manifest.json", manifest)
    shutil.copyfile(Path(__file__).with_name("testset_load.py"), out / "load_testset.py")
    return manifest
