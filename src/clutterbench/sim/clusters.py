"""Arrangement clusters of a settled scene (thesis 5.2.1, Fig. 5.3): which boxes form a
cluster, its class C^h / C^v / C^r / C^l from the settled tilt, and its image bounding box.

Pure functions of poses, sizes, contact pairs and the instance image. Frames: the shelf
frame (y to the camera's left, z up), so a box whose top leans toward -y leans to the
image's right.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from clutterbench.sim.geometry import quat_to_matrix

CLASSES = ("C^h", "C^v", "C^r", "C^l")
"""Thesis 5.2.1: stacked, shelved, disorganized leaning right, leaning left (image sides)."""
LEAN_DEG = 10.0
"""A standing cluster whose mean tilt exceeds this leans (C^r / C^l); else it is C^v."""


def box_tilt(size_m: np.ndarray, quat: np.ndarray) -> tuple[bool, float]:
    """(lying flat, lean in degrees) of one box.

    The box's local axis closest to vertical is its "up" axis. The box lies flat when that
    axis is its thinnest one (a stacked box); otherwise it stands, and its lean is the angle
    of the up axis from vertical in the image plane (y-z): positive when the top is toward
    +y, the camera's left.
    """
    R = quat_to_matrix(quat)
    up_k = int(np.argmax(np.abs(R[2])))  # which local axis points most vertically
    flat = bool(np.argmin(size_m) == up_k)
    up = R[:, up_k] * np.sign(R[2, up_k])
    return flat, float(np.degrees(np.arctan2(up[1], up[2])))


def classify_cluster(sizes_m: np.ndarray, quats: np.ndarray) -> str:
    """Thesis 5.2.1 class of a cluster from its boxes' settled poses.

    Mostly flat boxes -> C^h; standing boxes whose mean lean is beyond LEAN_DEG -> C^l (top
    toward the image's left) or C^r; else C^v. A single box is C^v (thesis 5.2.1: "in the
    case of a single object, it will be classified as C^v") unless it stands tilted beyond
    LEAN_DEG: then it is C^r / C^l by its lean, as the leaning object of thesis Fig. 5.9
    ("the diagonal direction of the bounding box" gives its inclination, 5.3.2), an obstacle
    to set upright rather than a row to place beside. A single flat box stays C^v.
    """
    tilts = [box_tilt(s, q) for s, q in zip(sizes_m, quats)]
    if len(tilts) == 1:
        flat, lean = tilts[0]
        if flat or abs(lean) <= LEAN_DEG:
            return "C^v"
        return "C^l" if lean > 0 else "C^r"
    flat = [f for f, _ in tilts]
    if sum(flat) * 2 > len(flat):
        return "C^h"
    lean = float(np.mean([a for f, a in tilts if not f]))
    if abs(lean) <= LEAN_DEG:
        return "C^v"
    return "C^l" if lean > 0 else "C^r"


def assign_clusters(
    n: int, seed_groups: Sequence[Sequence[int]], contacts: Sequence[tuple[int, int]]
) -> np.ndarray:
    """(n,) cluster id of every box: each box in exactly one cluster.

    The groups a family arranged (a stack, a row) seed the clusters. A box in no group (a
    randomly posed one) joins the cluster it touches most in the settled scene; boxes that
    touch no cluster form clusters of their own by contact. Ids are numbered in order of
    each cluster's lowest box index, so they do not depend on how groups were listed.
    """
    label = np.full(n, -1, dtype=np.int64)
    for g, members in enumerate(seed_groups):
        for i in members:
            if label[i] < 0:
                label[i] = g
    neighbours: list[list[int]] = [[] for _ in range(n)]
    for a, b in contacts:
        neighbours[a].append(b)
        neighbours[b].append(a)
    changed = True
    while changed:  # grow seeded clusters through contacts, lowest index first
        changed = False
        for i in range(n):
            if label[i] >= 0:
                continue
            touching = [label[j] for j in neighbours[i] if label[j] >= 0]
            if touching:
                votes = np.bincount(touching)
                label[i] = int(np.argmax(votes))
                changed = True
    next_id = len(seed_groups)
    for i in range(n):  # the rest: connected components among themselves
        if label[i] >= 0:
            continue
        stack, label[i] = [i], next_id
        while stack:
            for j in neighbours[stack.pop()]:
                if label[j] < 0:
                    label[j] = next_id
                    stack.append(j)
        next_id += 1
    order = {}
    for i in range(n):
        order.setdefault(int(label[i]), len(order))
    return np.array([order[int(c)] for c in label], dtype=np.int64)


def cluster_bbox_px(instance: np.ndarray, members: Sequence[int]) -> np.ndarray:
    """Thesis eq. (5.1) B = (x, y, w, h): centre and size in pixels of the visible pixels of
    the cluster's boxes; zeros if none of them is visible."""
    assert instance.dtype == np.uint8, "instance must be uint8 ids, 0 = background"
    mask = np.isin(instance, np.asarray(members, dtype=np.int64) + 1)
    if not mask.any():
        return np.zeros(4, dtype=np.float32)
    rows, cols = np.nonzero(mask)
    x0, x1, y0, y1 = cols.min(), cols.max() + 1, rows.min(), rows.max() + 1
    return np.array([(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0], dtype=np.float32)


def scene_clusters(
    sizes_m: np.ndarray,
    poses: np.ndarray,
    seed_groups: Sequence[Sequence[int]],
    contacts: Sequence[tuple[int, int]],
    instance: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cluster_of (N,), class index per cluster (C,) into CLASSES, bbox (C, 4))."""
    n = len(sizes_m)
    cluster_of = assign_clusters(n, seed_groups, contacts)
    k = int(cluster_of.max()) + 1 if n else 0
    classes = np.zeros(k, dtype=np.int64)
    boxes = np.zeros((k, 4), dtype=np.float32)
    for c in range(k):
        members = np.nonzero(cluster_of == c)[0]
        classes[c] = CLASSES.index(classify_cluster(sizes_m[members], poses[members, 3:]))
        boxes[c] = cluster_bbox_px(instance, members)
    return cluster_of, classes, boxes
