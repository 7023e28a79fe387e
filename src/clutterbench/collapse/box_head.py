"""Per-box pull predictions: for one depth image, the visible boxes' masks and a box to be
pulled, the probability that the trials' pull collapses each other box, that it moves it, and
that the two boxes touch (the edge of Table 6.2 is a pull outcome *and* a contact).

The collapse predictor answers per pixel; the ch. 6 planner asks per box. Between them sat a
rule with five thresholds (pixel probability, coverage score, box margin, adjacency IoU,
surface gap) that caps the support graph even when fed perfect maps. The box head replaces
that rule: a small network over features of each (pulled box, other box) pair, learned on
the per-box pull outcomes the ch. 6 dataset holds (pullout_*, contact):

- what the collapse predictor's three heads (deletion, pull, pull_collapse) put on the other
  box: mean, max and the share above 1/2 of each head's map;
- where the two boxes are from the depth image alone: their closest visible surfaces
  (back-projected depth), the IoU of their grown image boxes, their areas, the offset of
  their centroids, their depth difference, how far one's image box lies above or below the
  other's, their horizontal overlap or gap, and how many boxes are visible.

The collapse predictor is frozen: the box head is trained after it, so the pixel heads (and
every row that reads them) stay as they were. This module is torch and numpy only; the
stage (stages/box_head.py) feeds it scenes (support/evaluate.py `Scene`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from clutterbench.errors import ClutterbenchError

HEAD_FEATURES = ("mean", "max", "share")
"""What each collapse-predictor head's map gives a box: its mean over the box's visible
pixels, its maximum there, and the share of those pixels above 1/2."""
GEOMETRY = (
    "gap_m",
    "grown_iou",
    "log_area_other",
    "log_area_pulled",
    "dy",
    "dx",
    "abs_dx",
    "depth_diff_m",
    "above",
    "below",
    "h_overlap",
    "h_gap",
    "visible",
)
"""The pair's geometry from the depth image and the masks (`pair_features`)."""
OUTPUTS = ("pull_collapse", "pull", "contact")
"""What the box head predicts for (pulled x, other y): the pull of x collapses y (the
trials' collapse-free criterion), it moves y beyond the label threshold or off the shelf,
x and y touch in the settled scene."""
EDGE_HEADS = ("pull", "pull_collapse")
"""Pull label kinds whose support edges (outcome and contact) the box head scores."""
MAX_GAP_M = 0.2
"""Surface gaps are clipped here (inf: the masks never come close)."""
GROWN_MARGIN_PX = 4
"""Image boxes are grown by this many pixels before their IoU is taken."""


def feature_names(heads: Sequence[str]) -> tuple[str, ...]:
    return tuple(f"{h}_{f}" for h in heads for f in HEAD_FEATURES) + GEOMETRY


def _grown_iou(masks: np.ndarray, margin: int) -> np.ndarray:
    k, h, w = masks.shape
    rows, cols = masks.any(axis=2), masks.any(axis=1)
    y0, y1 = rows.argmax(1), h - rows[:, ::-1].argmax(1)
    x0, x1 = cols.argmax(1), w - cols[:, ::-1].argmax(1)
    b = np.stack([x0 - margin, y0 - margin, x1 + margin, y1 + margin], 1).astype(np.float64)
    b[:, [0, 2]] = b[:, [0, 2]].clip(0, w)
    b[:, [1, 3]] = b[:, [1, 3]].clip(0, h)
    ix = (np.minimum(b[:, None, 2], b[None, :, 2]) - np.maximum(b[:, None, 0], b[None, :, 0])).clip(
        0
    )
    iy = (np.minimum(b[:, None, 3], b[None, :, 3]) - np.maximum(b[:, None, 1], b[None, :, 1])).clip(
        0
    )
    inter = ix * iy
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area[:, None] + area[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _extents(masks: np.ndarray) -> tuple[np.ndarray, ...]:
    """(K,) top, bottom, left, right image rows / columns of each mask (half-open, float)."""
    _, h, w = masks.shape
    rows, cols = masks.any(axis=2), masks.any(axis=1)
    top, bottom = rows.argmax(1), h - rows[:, ::-1].argmax(1)
    left, right = cols.argmax(1), w - cols[:, ::-1].argmax(1)
    return tuple(a.astype(np.float32) for a in (top, bottom, left, right))


def _masked_peaks(p: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(X, C, Y) float32: each map's largest value inside each mask, at least 0 (0 where a
    mask is empty). p: (X, C, P) maps; masks: (Y, P) bool. Each mask gathers only its own
    pixels: the same maxima as masking every map with every mask, at 1 / Y of the work."""
    x, c, _ = p.shape
    peak = np.zeros((x, c, len(masks)), np.float32)
    for y, mask in enumerate(masks):
        if mask.any():
            peak[:, :, y] = p[:, :, mask].max(-1)
    return peak.clip(0.0)


def pair_features(
    probs: np.ndarray, masks: np.ndarray, depth_m: np.ndarray, gaps_m: np.ndarray
) -> np.ndarray:
    """(K, K, F) float32 features of every ordered pair (pulled x, other y) of one scene.

    probs: (K, C, H, W) the collapse predictor's maps with box x pulled (C heads, in the
    order of the checkpoint's `heads`); masks: (K, H, W) bool visible masks; depth_m (H, W);
    gaps_m: (K, K) closest visible surface distance (support.surface_gaps; inf: far)."""
    k, c, h, w = probs.shape
    assert masks.shape == (k, h, w) and masks.dtype == np.bool_, "masks must be (K, H, W) bool"
    assert gaps_m.shape == (k, k), "gaps_m must be (K, K)"
    flat = masks.reshape(k, -1).astype(np.float32)
    area = flat.sum(1).clip(1.0)
    p = probs.reshape(k, c, -1).astype(np.float32)
    mean = np.einsum("xcp,yp->xcy", p, flat) / area
    share = np.einsum("xcp,yp->xcy", (p > 0.5).astype(np.float32), flat) / area
    peak = _masked_peaks(p, masks.reshape(k, -1))
    head = np.stack([mean, peak, share], axis=-1)  # (x, c, y, 3)
    head = head.transpose(0, 2, 1, 3).reshape(k, k, c * len(HEAD_FEATURES))
    yy, xx = np.mgrid[0:h, 0:w]
    cy = (flat @ yy.ravel().astype(np.float32)) / area / h
    cx = (flat @ xx.ravel().astype(np.float32)) / area / w
    depth = np.array([np.median(depth_m[m]) if m.any() else 0.0 for m in masks], np.float32)
    top, bottom, left, right = _extents(masks)
    width = (right - left).clip(1.0)
    overlap = np.minimum(right[:, None], right[None, :]) - np.maximum(left[:, None], left[None, :])
    geo = np.stack(
        [
            np.minimum(np.nan_to_num(gaps_m, nan=MAX_GAP_M, posinf=MAX_GAP_M), MAX_GAP_M),
            _grown_iou(masks, GROWN_MARGIN_PX),
            np.broadcast_to(np.log1p(area)[None, :], (k, k)),
            np.broadcast_to(np.log1p(area)[:, None], (k, k)),
            cy[None, :] - cy[:, None],
            cx[None, :] - cx[:, None],
            np.abs(cx[None, :] - cx[:, None]),
            depth[None, :] - depth[:, None],
            (top[:, None] - bottom[None, :]) / h,  # > 0: y's bottom edge above x's top
            (top[None, :] - bottom[:, None]) / h,  # > 0: y's top edge below x's bottom
            overlap.clip(0.0) / np.minimum(width[:, None], width[None, :]),
            (-overlap).clip(0.0) / w,
            np.full((k, k), k / 10.0),
        ],
        axis=-1,
    )
    return np.concatenate([head, geo], axis=-1).astype(np.float32)


def pair_labels(moved_by: dict[str, np.ndarray], contact: np.ndarray) -> np.ndarray:
    """(K, K, len(OUTPUTS)) float32 labels of one scene from its per-head truth (x pulled, y
    marked) and its contact matrix."""
    return np.stack([moved_by[o] if o != "contact" else contact for o in OUTPUTS], -1).astype(
        np.float32
    )


def off_diagonal(a: np.ndarray) -> np.ndarray:
    """The (K * (K - 1), ...) rows of a (K, K, ...) pair array, x != y, row-major."""
    k = a.shape[0]
    keep = ~np.eye(k, dtype=bool)
    return a[keep]


class BoxHead(nn.Module):
    """Standardised pair features -> one logit per OUTPUTS."""

    def __init__(self, n_features: int, hidden: int):
        super().__init__()
        self.register_buffer("mean", torch.zeros(n_features))
        self.register_buffer("std", torch.ones(n_features))
        self.net = nn.Sequential(
            nn.Linear(n_features, hidden),
            nn.ReLU(),
            nn.Linear(hidden, hidden),
            nn.ReLU(),
            nn.Linear(hidden, len(OUTPUTS)),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net((x - self.mean) / self.std)


@dataclasses.dataclass(frozen=True)
class BoxHeadMeta:
    """What a box-head checkpoint was trained on; checked before it is used."""

    cp_model: str
    """The collapse predictor whose maps it reads (train.models key)."""
    heads: tuple[str, ...]
    """Those maps' heads, in channel order."""
    features: tuple[str, ...]
    hidden: int
    image_size: int


def save_box_head(model: BoxHead, meta: BoxHeadMeta, path: Path) -> None:
    from clutterbench.io import atomic_path

    with atomic_path(path) as tmp:
        torch.save({"state_dict": model.state_dict(), "meta": dataclasses.asdict(meta)}, tmp)


def load_box_head(path: Path, cp_model: str | None = None) -> tuple[BoxHead, BoxHeadMeta]:
    """The box head of `path`; one line when it is missing, unreadable, or (`cp_model`)
    was trained on another collapse predictor's maps."""
    if not Path(path).is_file():
        raise ClutterbenchError(f"{path}: no box-head checkpoint (run: dvc repro box_head)")
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
        meta = BoxHeadMeta(
            **{k: tuple(v) if isinstance(v, list) else v for k, v in raw["meta"].items()}
        )
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the same error
        raise ClutterbenchError(
            f"{path}: not a box-head checkpoint ({type(exc).__name__})"
        ) from None
    if meta.features != feature_names(meta.heads):
        raise ClutterbenchError(f"{path}: its features are not this version's; rerun box_head")
    if cp_model is not None and meta.cp_model != cp_model:
        raise ClutterbenchError(
            f"{path}: trained on {meta.cp_model}'s maps, asked to read {cp_model}'s; rerun box_head"
        )
    model = BoxHead(len(meta.features), meta.hidden)
    model.load_state_dict(raw["state_dict"])
    return model.eval(), meta


@torch.no_grad()
def predict_pairs(model: BoxHead, features: np.ndarray) -> np.ndarray:
    """(..., F) features -> (..., len(OUTPUTS)) probabilities."""
    x = torch.from_numpy(np.ascontiguousarray(features, dtype=np.float32))
    return (
        torch.sigmoid(model(x.reshape(-1, x.shape[-1]))).numpy().reshape(*features.shape[:-1], -1)
    )


def edge_probability(probs: np.ndarray, head: str) -> np.ndarray:
    """(K, K) probability of the support edge (x, y) under pull label kind `head`: the pull
    of x marks y, and x and y touch (the two outputs' product)."""
    return probs[..., OUTPUTS.index(head)] * probs[..., OUTPUTS.index("contact")]
