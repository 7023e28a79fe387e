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
from clutterbench.sim.config import CameraConfig, PhysicsConfig

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
    "deletion_drop_m": "(S, N, N) float64: ... how far box y's centre dropped (the deletion "
    "replayed from the settled start by the test set's stage)",
    "deletion_tilt_deg": "(S, N, N) float64: ... how far box y tipped, degrees",
    "deletion_left_shelf": "(S, N, N) bool: ... box y left the shelf",
    "source": "(S,) str: where the scene comes from: the ch6_test dataset, or a ch. 6 table "
    "stream's benchmark start (benchmark:<stream>, data/benchmark)",
    "target": "(S,) int: a benchmark start's episode target (the box the trial must extract); "
    "-1 for a dataset scene",
}
LABELS = {
    "pull_collapse": "pulling x collapses y: y left the shelf, dropped more than drop_m or "
    "tipped more than tilt_deg (the trials' collapse-free criterion)",
    "pull_moved": "pulling x moves y more than moved_m or off the shelf",
    "deletion_moved": "deleting x moves y more than moved_m (the thesis' collapse labels)",
    "deletion_collapse": "deleting x collapses y: y left the shelf, dropped more than drop_m or "
    "tipped more than tilt_deg",
}


def camera_matrix(camera: CameraConfig) -> list[list[float]]:
    """The 3 x 3 pinhole intrinsics the depth images were rendered with (principal point at
    the centre, f = (H / 2) / tan(fovy / 2))."""
    h = w = camera.image_size
    f = (h / 2) / float(np.tan(np.deg2rad(camera.fovy_deg) / 2))
    return [[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]]


def dataset_arrays(gen_dir: Path, dataset: str) -> dict[str, np.ndarray]:
    """Every scene of a generated dataset (with pull outcomes) in the test set's arrays;
    `source` the dataset's name, `target` -1 (every box is pulled)."""
    keys = tuple(SOURCE.values())
    missing = [k for k in keys if k not in ShardStore(gen_dir, dataset).array_names()]
    if missing:
        raise ClutterbenchError(
            f"dataset '{dataset}' lacks {missing[0]} for the test set; generate it with "
            f"generate.datasets.{dataset}.pull_outcomes: true"
        )
    parts: dict[str, list[np.ndarray]] = {k: [] for k in SOURCE}
    for arrays in iter_shards(gen_dir, dataset, keys):
        for name, src in SOURCE.items():
            parts[name].append(arrays[src])
    if not parts["depth_m"]:
        raise ClutterbenchError(f"dataset '{dataset}': no scenes for the test set")
    out = {k: np.concatenate(v) for k, v in parts.items()}
    out["source"] = np.array([dataset] * len(out["n_objects"]))
    out["target"] = np.full(len(out["n_objects"]), -1, np.int16)
    return out


def labelled_arrays(scenes: list[tuple[Any, str, int, int]]) -> dict[str, np.ndarray]:
    """(LabelledScene with pull outcomes, source, index, target) of given starts (the
    benchmark scenes) in the test set's arrays."""
    n_max = max(sc.spec.n for sc, *_ in scenes)
    s = len(scenes)
    out: dict[str, np.ndarray] = {
        "depth_m": np.stack([sc.depth_m for sc, *_ in scenes]).astype(np.float32),
        "instance": np.stack([sc.instance for sc, *_ in scenes]).astype(np.uint8),
        "n_objects": np.array([sc.spec.n for sc, *_ in scenes], np.int16),
        "family": np.array([sc.spec.family for sc, *_ in scenes]),
        "scene_index": np.array([i for _, _, i, _ in scenes], np.int64),
        "sizes_m": np.zeros((s, n_max, 3), np.float32),
        "poses": np.zeros((s, n_max, 7), np.float64),
        "contact": np.zeros((s, n_max, n_max), bool),
        "source": np.array([src for _, src, _, _ in scenes]),
        "target": np.array([t for *_, t in scenes], np.int16),
    }
    for key in ("pull_displacement_m", "pull_drop_m", "pull_tilt_deg", "deletion_displacement_m"):
        out[key] = np.full((s, n_max, n_max), np.nan)
    out["pull_left_shelf"] = np.zeros((s, n_max, n_max), bool)
    for k, (sc, *_) in enumerate(scenes):
        n, po = sc.spec.n, sc.pull_outcome
        out["sizes_m"][k, :n] = sc.spec.sizes_m
        out["poses"][k, :n] = sc.spec.poses
        for a, b in sc.contacts:
            out["contact"][k, a, b] = out["contact"][k, b, a] = True
        out["deletion_displacement_m"][k, :n, :n] = sc.removal_m
        out["pull_displacement_m"][k, :n, :n] = po.displacement_m
        out["pull_drop_m"][k, :n, :n] = po.drop_m
        out["pull_tilt_deg"][k, :n, :n] = po.tilt_deg
        out["pull_left_shelf"][k, :n, :n] = po.left_shelf
    return out


def concat_padded(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The parts' scenes in one set of arrays, the per-box axes padded to the largest box
    count (NaN, False, 0: as past n_objects in a shard)."""
    n_max = max(p["pull_displacement_m"].shape[1] for p in parts)
    out = {}
    for key in parts[0]:
        padded = []
        for p in parts:
            a = p[key]
            if key in PER_BOX_AXES:
                pad = [(0, 0)] * a.ndim
                for ax in PER_BOX_AXES[key]:
                    pad[ax] = (0, n_max - a.shape[ax])
                a = np.pad(a, pad, constant_values=np.nan if key in NAN_PADDED else 0)
            padded.append(a)
        out[key] = np.concatenate(padded)
    return out


NAN_PADDED = {
    "pull_displacement_m",
    "pull_drop_m",
    "pull_tilt_deg",
    "deletion_displacement_m",
    "deletion_drop_m",
    "deletion_tilt_deg",
}
"""Outcome arrays: NaN past a scene's boxes, as in a shard (the others: 0 or False)."""
PER_BOX_AXES = {
    "sizes_m": (1,),
    "poses": (1,),
    "contact": (1, 2),
    "pull_displacement_m": (1, 2),
    "pull_drop_m": (1, 2),
    "pull_tilt_deg": (1, 2),
    "pull_left_shelf": (1, 2),
    "deletion_displacement_m": (1, 2),
    "deletion_drop_m": (1, 2),
    "deletion_tilt_deg": (1, 2),
    "deletion_left_shelf": (1, 2),
}


def deletion_outcomes(arrays: dict[str, np.ndarray], physics: PhysicsConfig) -> dict[str, Any]:
    """Every scene's deletions replayed from its settled start (its sizes and poses, each box
    lifted out of a fresh world and the rest settled, as the labels were made): per (x, y),
    box y's drop, tilt and whether it left the shelf, added to `arrays`. Returns how many of
    the replayed displacements equal the stored labels bit for bit (they do on the CPU that
    generated them)."""
    from clutterbench.progress import progress_bar
    from clutterbench.sim.geometry import tilt_change_deg
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.spec import SceneSpec

    s, n_max = arrays["deletion_displacement_m"].shape[:2]
    drop, tilt = np.full((s, n_max, n_max), np.nan), np.full((s, n_max, n_max), np.nan)
    left = np.zeros((s, n_max, n_max), bool)
    equal = total = 0
    with progress_bar("testset: deletions", total=s) as advance:
        for k in range(s):
            n = int(arrays["n_objects"][k])
            spec = SceneSpec(
                sizes_m=arrays["sizes_m"][k, :n].astype(np.float64), poses=arrays["poses"][k, :n]
            )
            for x in range(n):
                world = BoxWorld.from_spec(spec, physics)
                start = world.poses()
                disp = world.lift_out(x).displacement_m
                end, on = world.poses(), world.shelf.contains(world.positions())
                for y in range(n):
                    if y == x:
                        continue
                    drop[k, x, y] = float(start[y, 2] - end[y, 2])
                    tilt[k, x, y] = tilt_change_deg(start[y, 3:], end[y, 3:])
                    left[k, x, y] = not bool(on[y])
                    total += 1
                    equal += bool(disp[y] == arrays["deletion_displacement_m"][k, x, y])
            advance(1)
    arrays |= {"deletion_drop_m": drop, "deletion_tilt_deg": tilt, "deletion_left_shelf": left}
    return {"displacements_equal": equal, "of": total}


def export_testset(
    parts: list[dict[str, np.ndarray]],
    camera: CameraConfig,
    thresholds: dict[str, float],
    min_pixels: int,
    out: Path,
    physics: PhysicsConfig,
) -> dict[str, Any]:
    """Write out/{scenes.npz, manifest.json, load_testset.py} from the parts' scenes
    (dataset_arrays, labelled_arrays) and their deletions' outcomes (deletion_outcomes,
    `physics`); thresholds: moved_m, drop_m, tilt_deg. Returns the manifest."""
    arrays = concat_padded(parts)
    replay = deletion_outcomes(arrays, physics)
    out.mkdir(parents=True, exist_ok=True)
    save_npz(out / "scenes.npz", arrays)  # byte-identical for identical arrays
    digest = hashlib.sha256((out / "scenes.npz").read_bytes()).hexdigest()
    sources = {str(k): int(v) for k, v in zip(*np.unique(arrays["source"], return_counts=True))}
    manifest = {
        "schema_version": SCHEMA_VERSION,
        "name": "clutterbench pull-consequence test set",
        "sources": sources,
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
        "deletion_replay": replay,
        "arrays": ARRAYS,
        "labels": {k: LABELS[k] for k in LABEL_KINDS},
        "load": "load_testset.py (numpy alone): load(dir), labels(ts, kind), pairs(ts, kind)",
    }
    write_json(out / "manifest.json", manifest)
    shutil.copyfile(Path(__file__).with_name("testset_load.py"), out / "load_testset.py")
    return manifest
