"""Labels derived at load time from a scene's instance image and removal / pull tensors."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

PULL_CLASSES = ("B", "E", "S", "C")
"""Thesis Fig. 4.4 classes, by label value: background, extracted object, supported object,
collapsing region. Collapse is the last class (the networks' collapse channel)."""
CLASS_B, CLASS_E, CLASS_S, CLASS_C = range(len(PULL_CLASSES))
OUTPUT_CHANNELS = {1: (1,), 2: (1, len(PULL_CLASSES))}
"""Network input masks -> the output channels their labels can train: one target mask ->
a collapse map (1); extraction + support masks (pull labels) -> a collapse map (1) or the
four classes of thesis Fig. 4.4."""
LABEL_KINDS = ("deletion", "pull", "pull_collapse")
"""What a collapse map of box x marks: `deletion`, the boxes that move when x is
lifted out and the rest settles (the removal matrix, the thesis' labels); `pull`, the boxes
that move or leave the shelf when the trials' executor pulls x out (the pullout_* arrays of a
dataset generated with pull_outcomes: true); `pull_collapse`, of those only the boxes that
collapse by the trials' collapse-free criterion (leave the shelf, drop or tip beyond
trials.collapse_free)."""
PULL_ARRAYS = ("pullout_displacement_m", "pullout_left_shelf")
"""The shard arrays the pull labels are read from."""
PULL_COLLAPSE_ARRAYS = ("pullout_drop_m", "pullout_tilt_deg", "pullout_left_shelf")
"""The shard arrays the pull-collapse labels are read from."""
LABEL_ARRAYS = {
    "deletion": ("removal_m",),
    "pull": PULL_ARRAYS,
    "pull_collapse": PULL_COLLAPSE_ARRAYS,
}
"""Label kind -> the shard arrays its labels are read from."""


def moved_matrix(removal_m: np.ndarray, threshold_m: float) -> np.ndarray:
    """M[x, y] = box y moved more than `threshold_m` when x was removed (x == y: False).

    Thesis 5.2.2 (6.4 mm) and 6.2.1 (5.0 mm): an object moved when its centre moved more
    than the threshold once the scene settled again.
    """
    assert removal_m.ndim == 2 and removal_m.shape[0] == removal_m.shape[1]
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(removal_m, nan=0.0) > threshold_m


def pull_moved_matrix(
    displacement_m: np.ndarray, left_shelf: np.ndarray, threshold_m: float
) -> np.ndarray:
    """M[x, y] = box y moved more than `threshold_m` or left the shelf when the trials'
    executor pulled x out (x == y: False). The definition of the truth maps of the pull
    (trials/ch6/truth_maps.py), so a pull label and a pull-truth map mean the same thing; a NaN
    displacement is no move."""
    assert displacement_m.ndim == 2 and displacement_m.shape[0] == displacement_m.shape[1]
    assert left_shelf.shape == displacement_m.shape and left_shelf.dtype == bool
    with np.errstate(invalid="ignore"):
        moved = (np.nan_to_num(displacement_m, nan=0.0) > threshold_m) | left_shelf
    np.fill_diagonal(moved, False)
    return moved


def pull_collapse_matrix(
    drop_m: np.ndarray,
    tilt_deg: np.ndarray,
    left_shelf: np.ndarray,
    collapse_free: tuple[float, float],
) -> np.ndarray:
    """M[x, y] = box y collapsed when the trials' executor pulled x out: it left the shelf,
    or its centre dropped more than `collapse_free`[0] metres, or it tipped more than
    `collapse_free`[1] degrees (x == y: False). The collapse-free criterion's notion
    (criteria.py `collapsed`, thresholds trials.collapse_free), so these labels mean
    what a trial calls a collapse; a NaN is no collapse."""
    assert drop_m.ndim == 2 and drop_m.shape[0] == drop_m.shape[1]
    assert tilt_deg.shape == drop_m.shape == left_shelf.shape and left_shelf.dtype == bool
    max_drop_m, max_tilt_deg = collapse_free
    with np.errstate(invalid="ignore"):
        fell = (np.nan_to_num(drop_m, nan=0.0) > max_drop_m) | (
            np.nan_to_num(tilt_deg, nan=0.0) > max_tilt_deg
        )
    out = fell | left_shelf
    np.fill_diagonal(out, False)
    return out


def label_matrix(
    kind: str,
    row: Callable[[str], np.ndarray],
    n: int,
    threshold_m: float,
    collapse_free: tuple[float, float] | None = None,
) -> np.ndarray:
    """(n, n) bool matrix of one scene under label kind `kind` (LABEL_KINDS): M[x, y] = the
    map of box x marks box y. row(key) is the scene's shard array `key` (LABEL_ARRAYS[kind]);
    `collapse_free` (drop_m, tilt_deg) is needed by pull_collapse only."""
    arrays = [row(k)[:n, :n] for k in LABEL_ARRAYS[kind]]
    if kind == "deletion":
        return moved_matrix(arrays[0], threshold_m)
    if kind == "pull":
        return pull_moved_matrix(*arrays, threshold_m)
    if kind == "pull_collapse":
        assert collapse_free is not None, "pull_collapse labels need trials.collapse_free"
        return pull_collapse_matrix(*arrays, collapse_free)
    raise ValueError(f"unknown label kind {kind!r}")


def target_mask(instance: np.ndarray, target: int) -> np.ndarray:
    """Binary mask (uint8) of box `target` (instance ids are box index + 1)."""
    assert instance.dtype == np.uint8, "instance must be uint8 ids, 0 = background"
    return (instance == target + 1).astype(np.uint8)


def collapse_mask(instance: np.ndarray, moved_row: np.ndarray) -> np.ndarray:
    """Binary mask of every box marked in `moved_row` (thesis Fig. 5.5 collapse mask)."""
    assert instance.dtype == np.uint8, "instance must be uint8 ids, 0 = background"
    lut = np.zeros(256, dtype=np.uint8)
    lut[1 : 1 + len(moved_row)] = moved_row.astype(np.uint8)
    return lut[instance]


def support_edges(removal_m: np.ndarray, threshold_m: float) -> list[tuple[int, int]]:
    """Ground-truth support relations SUPP(x, y): removing x moves y (thesis 6.2.2)."""
    m = moved_matrix(removal_m, threshold_m)
    return [(int(x), int(y)) for x, y in zip(*np.nonzero(m))]


def ch4_class_map(
    instance: np.ndarray,
    extract: int,
    support: int,
    displacement_m: np.ndarray,
    threshold_m: float,
) -> np.ndarray:
    """(H, W) uint8 label map of one (extract, support) pull, thesis Fig. 4.4: E = pixels of
    box `extract`, S = pixels of box `support`, C = pixels of every other box whose
    displacement exceeds `threshold_m`, B = everything else.

    displacement_m: (N,) metres moved by each box in that pull (pull_m[x, s, :N]; NaN for
    the extracted and the held box)."""
    assert instance.dtype == np.uint8, "instance must be uint8 ids, 0 = background"
    assert displacement_m.ndim == 1, "displacement_m is one pull's (N,) displacements"
    n = len(displacement_m)
    assert 0 <= extract < n and 0 <= support < n and extract != support
    with np.errstate(invalid="ignore"):
        moved = np.nan_to_num(displacement_m, nan=0.0) > threshold_m
    lut = np.full(256, CLASS_B, dtype=np.uint8)
    lut[1 : 1 + n][moved] = CLASS_C
    lut[1 + extract], lut[1 + support] = CLASS_E, CLASS_S
    return lut[instance]
