"""Load the pull-consequence test set with numpy alone (this file is copied into the artifact
as load_testset.py; it imports nothing of clutterbench).

    import sys; sys.path.insert(0, "data/testset")
    import load_testset
    ts = load_testset.load("data/testset")       # checks the manifest's hash
    for scene, pulled, masks, truth in load_testset.pairs(ts, "pull_collapse"):
        ...  # ts["depth_m"][scene], masks (K, H, W) of the visible boxes, truth (K,) bool

Schema: manifest.json `arrays` (every array, its shape and meaning) and `labels` (how each
label kind is read from the arrays); the camera in manifest.json `camera`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np

SCHEMA_VERSION = 2
LABEL_KINDS = ("pull_collapse", "pull_moved", "deletion_moved", "deletion_collapse")


def load(path: str | Path) -> dict:
    """Every array of scenes.npz and the manifest (under "manifest"); refuses a file whose
    hash or schema version is not the manifest's."""
    root = Path(path)
    manifest = json.loads((root / "manifest.json").read_text())
    if manifest.get("schema_version") != SCHEMA_VERSION:
        raise ValueError(
            f"{root}: schema {manifest.get('schema_version')}, loader {SCHEMA_VERSION}"
        )
    data = (root / "scenes.npz").read_bytes()
    if hashlib.sha256(data).hexdigest() != manifest["sha256"]:
        raise ValueError(f"{root / 'scenes.npz'}: its sha256 is not the manifest's")
    with np.load(root / "scenes.npz", allow_pickle=False) as z:
        out = {k: z[k] for k in z.files}
    out["manifest"] = manifest
    return out


def labels(ts: dict, kind: str) -> np.ndarray:
    """(S, N, N) bool: label[s, x, y] = box y is marked when box x of scene s is pulled out
    (`pull_*`) or deleted (`deletion_moved`); the diagonal is False."""
    t = ts["manifest"]["thresholds"]
    if kind == "pull_collapse":
        out = (
            (np.nan_to_num(ts["pull_drop_m"]) > t["drop_m"])
            | (np.nan_to_num(ts["pull_tilt_deg"]) > t["tilt_deg"])
            | ts["pull_left_shelf"]
        )
    elif kind == "pull_moved":
        out = (np.nan_to_num(ts["pull_displacement_m"]) > t["moved_m"]) | ts["pull_left_shelf"]
    elif kind == "deletion_moved":
        out = np.nan_to_num(ts["deletion_displacement_m"]) > t["moved_m"]
    elif kind == "deletion_collapse":
        out = (
            (np.nan_to_num(ts["deletion_drop_m"]) > t["drop_m"])
            | (np.nan_to_num(ts["deletion_tilt_deg"]) > t["tilt_deg"])
            | ts["deletion_left_shelf"]
        )
    else:
        raise ValueError(f"label kind {kind!r}: one of {LABEL_KINDS}")
    n = out.shape[1]
    return out & ~np.eye(n, dtype=bool)[None]


def visible(ts: dict, scene: int) -> list[int]:
    """The boxes of a scene with at least manifest `min_pixels` visible pixels (box k is
    instance id k + 1), the ones a predictor is asked about."""
    n = int(ts["n_objects"][scene])
    counts = np.bincount(ts["instance"][scene].ravel(), minlength=256)[1 : n + 1]
    return [int(k) for k in np.flatnonzero(counts >= ts["manifest"]["min_pixels"])]


def pairs(ts: dict, kind: str) -> Iterator[tuple[int, int, np.ndarray, np.ndarray]]:
    """(scene, pulled box's position among the visible, masks (K, H, W) bool of the visible
    boxes, truth (K,) bool of `kind` for each of them) for every visible box of every scene
    with two or more visible boxes."""
    lab = labels(ts, kind)
    for s in range(len(ts["n_objects"])):
        ids = visible(ts, s)
        if len(ids) < 2:
            continue
        masks = np.stack([ts["instance"][s] == k + 1 for k in ids])
        for i, x in enumerate(ids):
            yield s, i, masks, lab[s, x, ids]
