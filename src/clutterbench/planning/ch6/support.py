"""Support relations from collapse heatmaps and object masks (thesis 6.2.2).

K visible objects of one scene: `masks` (K, H, W) bool, `ids` the K box ids the mask indices
belong to, `heatmaps` (K, H, W) float in [0, 1] where heatmaps[k] is the collapse probability
map predicted when box ids[k] is removed. SUPP(x, y), "x supports y", means removing x makes y
fall. Score matrices are indexed [supporter index, supported index].
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence

import numpy as np
import pandas as pd

from clutterbench.perception.gaps import surface_gaps  # noqa: F401  (re-exported)

RULES = ("iou", "coverage")
"""iou: |R_O ∩ R_C| / |R_O ∪ R_C| (thesis 6.2.2); coverage: |R_O ∩ R_C| / |R_O| (eq. 6.2)."""

_MAX_PIXELS = 2**24
"""float32 counts pixels exactly up to here (the matmul in `support_scores` relies on it)."""


@dataclasses.dataclass(frozen=True)
class SupportParams:
    """The thresholds of the support rule (thesis 6.2.2)."""

    rule: str
    """"iou" (thesis: |R_O ∩ R_C| / |R_O ∪ R_C|) or "coverage" (eq. 6.2: |R_O ∩ R_C| / |R_O|)."""
    prob_threshold: float
    """Collapse area R_C = heatmap > prob_threshold."""
    score_threshold: float
    """An edge where the rule's score > score_threshold."""
    bbox_margin_px: int
    """Each object's bounding box is grown by this many pixels on every side."""
    adjacency_iou: float
    """Pseudo-direct contact where the IoU of the grown boxes > adjacency_iou."""
    max_gap_m: float | None = None
    """... and (unless None, the thesis' rule alone) where the closest visible surface points
    of the two objects, back-projected from the depth image, are nearer than this."""

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"rule: {self.rule!r} is not one of {RULES}")
        for name in ("prob_threshold", "score_threshold", "adjacency_iou"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}: {value} is outside [0, 1]")
        if self.max_gap_m is not None and not self.max_gap_m > 0.0:
            raise ValueError(f"max_gap_m: {self.max_gap_m} is not > 0 (or null)")
        margin = self.bbox_margin_px
        if not isinstance(margin, int | np.integer) or isinstance(margin, bool) or margin < 0:
            raise ValueError(f"bbox_margin_px: {margin!r} is not an integer >= 0")


@dataclasses.dataclass(frozen=True)
class SupportEdge:
    """One inferred relation SUPP(supporter, supported)."""

    supporter: int
    """Box id of the supporting object (removing it makes `supported` fall)."""
    supported: int
    """Box id of the supported object."""
    score: float
    """The rule's score of `supported` against the supporter's collapse area."""


@dataclasses.dataclass
class SceneEvidence:
    """One validation scene for choosing the support thresholds."""

    heatmaps: np.ndarray
    """(K, H, W) float32 collapse probability; heatmaps[k] predicted with box ids[k] removed."""
    masks: np.ndarray
    """(K, H, W) bool visible object masks."""
    ids: list[int]
    """Box id of each mask index."""
    true_edges: set[tuple[int, int]]
    """Physics truth: (supporter, supported) box-id pairs."""
    gaps_m: np.ndarray | None = None
    """(K, K) `surface_gaps` of the scene (needed when a swept max_gap_m is not None)."""


def _check_masks(masks: np.ndarray) -> None:
    assert masks.ndim == 3 and masks.dtype == np.bool_, "masks must be (K, H, W) bool"


def _check_heatmaps(heatmaps: np.ndarray, masks: np.ndarray) -> None:
    _check_masks(masks)
    assert heatmaps.shape == masks.shape, "heatmaps and masks must both be (K, H, W)"
    assert np.issubdtype(heatmaps.dtype, np.floating), "heatmaps must be float probabilities"


def mask_bboxes(masks: np.ndarray) -> np.ndarray:
    """(K, 4) int [x0, y0, x1, y1) half-open pixel boxes of (K, H, W) bool masks; all -1 for
    an empty mask."""
    _check_masks(masks)
    k, h, w = masks.shape
    rows, cols = masks.any(axis=2), masks.any(axis=1)
    boxes = np.stack(
        [
            cols.argmax(axis=1),
            rows.argmax(axis=1),
            w - cols[:, ::-1].argmax(axis=1),
            h - rows[:, ::-1].argmax(axis=1),
        ],
        axis=1,
    ).astype(np.int64)
    boxes[~rows.any(axis=1)] = -1
    return boxes.reshape(k, 4)


def grown_bbox_iou(bboxes: np.ndarray, margin_px: int, shape_hw: tuple[int, int]) -> np.ndarray:
    """(K, K) IoU of the boxes grown by `margin_px` on every side and clipped to the image;
    diagonal 1, 0 against an empty (-1) box."""
    assert bboxes.ndim == 2 and bboxes.shape[1] == 4, "bboxes must be (K, 4)"
    assert margin_px >= 0, "margin must be >= 0 pixels"
    h, w = shape_hw
    empty = (bboxes < 0).all(axis=1)
    grown = bboxes.astype(np.int64) + np.array([-margin_px, -margin_px, margin_px, margin_px])
    x0, x1 = np.clip(grown[:, 0], 0, w), np.clip(grown[:, 2], 0, w)
    y0, y1 = np.clip(grown[:, 1], 0, h), np.clip(grown[:, 3], 0, h)
    area = ((x1 - x0) * (y1 - y0)).astype(np.float64)
    ix = np.clip(np.minimum(x1[:, None], x1[None]) - np.maximum(x0[:, None], x0[None]), 0, None)
    iy = np.clip(np.minimum(y1[:, None], y1[None]) - np.maximum(y0[:, None], y0[None]), 0, None)
    inter = (ix * iy).astype(np.float64)
    inter[empty, :] = 0.0
    inter[:, empty] = 0.0
    union = area[:, None] + area[None] - inter
    iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)
    np.fill_diagonal(iou, 1.0)
    return iou


def _gap_contact(
    contact: np.ndarray, gaps_m: np.ndarray | None, max_gap_m: float | None
) -> np.ndarray:
    if max_gap_m is None:
        return contact
    if gaps_m is None:
        raise ValueError("max_gap_m is set but no surface gaps were given (need the depth)")
    assert gaps_m.shape == contact.shape, "gaps_m must be (K, K) as the masks"
    return contact & (gaps_m < max_gap_m)


def support_contact(
    masks: np.ndarray, params: SupportParams, gaps_m: np.ndarray | None = None
) -> np.ndarray:
    """(K, K) bool pseudo-direct contact under `params`: grown boxes overlap (thesis 6.2.2)
    and, where params.max_gap_m is set, the visible surfaces come that close (`gaps_m`)."""
    contact = pseudo_contact(masks, params.bbox_margin_px, params.adjacency_iou)
    return _gap_contact(contact, gaps_m, params.max_gap_m)


def _contact_from_iou(box_iou: np.ndarray, empty: np.ndarray, adjacency_iou: float) -> np.ndarray:
    # Grown empty boxes have IoU 0; the guard keeps them out for any adjacency_iou.
    contact = (box_iou > adjacency_iou) & ~empty[:, None] & ~empty[None]
    np.fill_diagonal(contact, False)
    return contact


def pseudo_contact(masks: np.ndarray, margin_px: int, adjacency_iou: float) -> np.ndarray:
    """(K, K) bool pseudo-direct contact (thesis 6.2.2): the IoU of the objects' boxes grown by
    `margin_px` exceeds `adjacency_iou`; symmetric, diagonal False, empty masks never."""
    box_iou = grown_bbox_iou(mask_bboxes(masks), margin_px, masks.shape[1:])
    return _contact_from_iou(box_iou, ~masks.any(axis=(1, 2)), adjacency_iou)


def overlap_scores(collapse_area: np.ndarray, masks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(iou (K,), coverage (K,)) float64 of each object area R_O against the collapse area R_C
    ((H, W) bool): |R_O ∩ R_C| / |R_O ∪ R_C| and |R_O ∩ R_C| / |R_O|; 0 for an empty mask."""
    _check_masks(masks)
    assert collapse_area.dtype == np.bool_ and collapse_area.shape == masks.shape[1:]
    inter = (masks & collapse_area).sum(axis=(1, 2)).astype(np.float64)
    area_o = masks.sum(axis=(1, 2)).astype(np.float64)
    union = area_o + float(collapse_area.sum()) - inter
    iou = np.divide(inter, union, out=np.zeros_like(inter), where=area_o > 0)
    coverage = np.divide(inter, area_o, out=np.zeros_like(inter), where=area_o > 0)
    return iou, coverage


def support_scores(
    heatmaps: np.ndarray, masks: np.ndarray, prob_threshold: float, rule: str
) -> np.ndarray:
    """(K, K) float64 S[a, b] = the rule's score of mask b against R_C(a) = heatmaps[a] >
    prob_threshold; 0 for an empty mask b, diagonal NaN."""
    _check_heatmaps(heatmaps, masks)
    if rule not in RULES:
        raise ValueError(f"rule: {rule!r} is not one of {RULES}")
    k = masks.shape[0]
    assert masks.shape[1] * masks.shape[2] < _MAX_PIXELS, "image too large for float32 counts"
    # Pixel counts are integers below 2**24, so the float32 matmul counts them exactly.
    r_c = (heatmaps > prob_threshold).reshape(k, -1).astype(np.float32)
    r_o = masks.reshape(k, -1).astype(np.float32)
    inter = (r_c @ r_o.T).astype(np.float64)
    area_c, area_o = r_c.sum(axis=1, dtype=np.float64), r_o.sum(axis=1, dtype=np.float64)
    has_o = np.broadcast_to(area_o[None] > 0, inter.shape)
    if rule == "iou":
        denom = area_c[:, None] + area_o[None] - inter  # |R_O ∪ R_C|, thesis 6.2.2
    else:
        denom = np.broadcast_to(area_o[None], inter.shape)  # |R_O|, thesis eq. (6.2)
    scores = np.divide(inter, denom, out=np.zeros_like(inter), where=has_o)
    np.fill_diagonal(scores, np.nan)
    return scores


def _resolve_mutual(candidate: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Where both [a, b] and [b, a] are candidates keep only the higher score (tie: the lower
    supporter index), thesis 6.2.3; works on stacks (..., K, K) of candidates."""
    k = scores.shape[-1]
    mutual = candidate & np.swapaxes(candidate, -1, -2)
    scores_t = np.swapaxes(scores, -1, -2)
    row_after_col = np.arange(k)[:, None] > np.arange(k)[None]
    loses = (scores < scores_t) | ((scores == scores_t) & row_after_col)
    return candidate & ~(mutual & loses)


def support_matrix(scores: np.ndarray, contact: np.ndarray, score_threshold: float) -> np.ndarray:
    """(K, K) bool SUPP[a, b]: score above the threshold and pseudo-direct contact, with mutual
    support resolved to the higher score (thesis 6.2.3)."""
    assert scores.shape == contact.shape and contact.dtype == np.bool_
    candidate = (np.nan_to_num(scores, nan=-np.inf) > score_threshold) & contact
    np.fill_diagonal(candidate, False)
    return _resolve_mutual(candidate, scores)


def infer_support(
    heatmaps: np.ndarray,
    masks: np.ndarray,
    ids: Sequence[int],
    params: SupportParams,
    gaps_m: np.ndarray | None = None,
) -> list[SupportEdge]:
    """Support relations of one scene (thesis 6.2.2, 6.2.3), sorted by (supporter, supported).
    `gaps_m`: the scene's `surface_gaps`, needed when params.max_gap_m is set."""
    if len(ids) != masks.shape[0] or len(set(ids)) != len(ids):
        raise ValueError(f"ids: need {masks.shape[0]} distinct box ids, got {list(ids)}")
    scores = support_scores(heatmaps, masks, params.prob_threshold, params.rule)
    contact = support_contact(masks, params, gaps_m)
    supp = support_matrix(scores, contact, params.score_threshold)
    edges = [
        SupportEdge(int(ids[a]), int(ids[b]), float(scores[a, b])) for a, b in np.argwhere(supp)
    ]
    return sorted(edges, key=lambda e: (e.supporter, e.supported))


def collapse_score(heatmap: np.ndarray, mask: np.ndarray, prob_threshold: float) -> float:
    """cp = area(R_C ∩ R_O) / area(R_O) of one object (thesis eq. (6.2)); 0 for an empty mask."""
    assert heatmap.shape == mask.shape and heatmap.ndim == 2, "heatmap and mask must be (H, W)"
    _, coverage = overlap_scores(heatmap > prob_threshold, mask[None].astype(bool))
    return float(coverage[0])


def oracle_heatmaps(moved: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(K, H, W) float32 oracle collapse maps: map a is 1.0 on the mask of every box b with
    moved[a, b] (b moved when a was removed; diagonal ignored), else 0."""
    _check_masks(masks)
    k = masks.shape[0]
    assert moved.shape == (k, k) and moved.dtype == np.bool_, "moved must be (K, K) bool"
    moved_off = moved & ~np.eye(k, dtype=bool)
    covered = moved_off.astype(np.float32) @ masks.reshape(k, -1).astype(np.float32)
    return (covered > 0).reshape(masks.shape).astype(np.float32)


def edge_precision_recall(
    predicted: set[tuple[int, int]], true: set[tuple[int, int]]
) -> tuple[float, float]:
    """(precision, recall) of support edges, thesis eqs. (6.3), (6.4); NaN where the
    denominator (|E_HYP| or |E_GT|) is 0."""
    hits = len(predicted & true)
    precision = hits / len(predicted) if predicted else float("nan")
    recall = hits / len(true) if true else float("nan")
    return precision, recall


def true_support_edges(moved: np.ndarray, contact: np.ndarray) -> set[tuple[int, int]]:
    """Physics truth SUPP(x, y): y moved when x was removed and x, y touch; (K, K) arrays
    indexed by box index, returns (x, y) index pairs with x != y."""
    assert moved.shape == contact.shape and moved.ndim == 2, "moved, contact must be (K, K)"
    if not np.array_equal(contact, contact.T):
        raise ValueError("contact: the contact matrix must be symmetric")
    supp = moved.astype(bool) & contact.astype(bool) & ~np.eye(moved.shape[0], dtype=bool)
    return {(int(x), int(y)) for x, y in np.argwhere(supp)}


def _true_matrix(scene: SceneEvidence) -> np.ndarray:
    index = {box: k for k, box in enumerate(scene.ids)}
    truth = np.zeros((len(scene.ids),) * 2, dtype=bool)
    for x, y in scene.true_edges:
        if x in index and y in index:
            truth[index[x], index[y]] = True
    return truth


def _nanmean(values: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """(mean over the defined values, count of defined values); NaN where none is defined."""
    defined = ~np.isnan(values)
    count = defined.sum(axis=axis)
    total = np.where(defined, values, 0.0).sum(axis=axis)
    mean = np.divide(total, count, out=np.full(total.shape, np.nan), where=count > 0)
    return mean, count


def sweep_support(
    scenes: Sequence[SceneEvidence],
    rule: str,
    prob_thresholds: Sequence[float],
    score_thresholds: Sequence[float],
    margins_px: Sequence[int],
    adjacency_ious: Sequence[float],
    max_gaps_m: Sequence[float | None] = (None,),
) -> pd.DataFrame:
    """Edge precision / recall (thesis eqs. 6.3, 6.4) of the support rule at every grid point.

    One row per (prob_threshold, score_threshold, bbox_margin_px, adjacency_iou, max_gap_m,
    the contact grid flattened in `contact_grid` order): precision and
    recall are means over the scenes where they are defined, f1 their harmonic mean (0 if both
    are 0, NaN if either is undefined); tp / fp / fn are pooled over the scenes. A true edge
    with an invisible box counts as missed.
    """
    if not scenes:
        raise ValueError("scenes: need at least one validation scene")
    contact_grid = list(itertools.product(margins_px, adjacency_ious, max_gaps_m))
    grid = list(itertools.product(prob_thresholds, score_thresholds, contact_grid))
    if not grid:
        raise ValueError("sweep grid is empty: every threshold list needs a value")
    for p, s, (m, a, g) in grid:
        SupportParams(rule, p, s, m, a, g)  # validates every value once
    score_thr = np.asarray(score_thresholds, dtype=np.float64)
    n_p, n_s, n_c = len(prob_thresholds), len(score_thresholds), len(contact_grid)
    tp = np.zeros((n_p, n_s, n_c, len(scenes)), dtype=np.int64)
    n_pred = np.zeros_like(tp)
    n_true = np.array([len(sc.true_edges) for sc in scenes], dtype=np.int64)
    for i_sc, sc in enumerate(scenes):
        truth = _true_matrix(sc)
        bboxes, empty = mask_bboxes(sc.masks), ~sc.masks.any(axis=(1, 2))
        box_ious = {m: grown_bbox_iou(bboxes, m, sc.masks.shape[1:]) for m in margins_px}
        contacts = [
            _gap_contact(_contact_from_iou(box_ious[m], empty, a), sc.gaps_m, g)
            for m, a, g in contact_grid
        ]
        for i_p, p in enumerate(prob_thresholds):
            scores = support_scores(sc.heatmaps, sc.masks, p, rule)
            above = np.nan_to_num(scores, nan=-np.inf)[None] > score_thr[:, None, None]
            for i_c, contact in enumerate(contacts):
                supp = _resolve_mutual(above & contact, scores)  # (S, K, K)
                tp[i_p, :, i_c, i_sc] = (supp & truth).sum(axis=(1, 2))
                n_pred[i_p, :, i_c, i_sc] = supp.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        precision_sc = np.where(n_pred > 0, tp / n_pred, np.nan)  # thesis eq. (6.3)
        recall_sc = np.where(n_true > 0, tp / n_true, np.nan)  # thesis eq. (6.4)
    precision, n_prec = _nanmean(precision_sc, axis=-1)
    recall, n_rec = _nanmean(recall_sc, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        f1 = np.where(precision + recall > 0, 2 * precision * recall / (precision + recall), 0.0)
    f1 = np.where(np.isnan(precision) | np.isnan(recall), np.nan, f1)
    tp_all, pred_all = tp.sum(axis=-1), n_pred.sum(axis=-1)
    rows = []
    for idx in np.ndindex(n_p, n_s, n_c):
        i_p, i_s, i_c = idx
        margin, adjacency, gap = contact_grid[i_c]
        rows.append(
            {
                "rule": rule,
                "prob_threshold": float(prob_thresholds[i_p]),
                "score_threshold": float(score_thresholds[i_s]),
                "bbox_margin_px": int(margin),
                "adjacency_iou": float(adjacency),
                "max_gap_m": gap,
                "precision": float(precision[idx]),
                "recall": float(recall[idx]),
                "f1": float(f1[idx]),
                "scenes_precision_defined": int(n_prec[idx]),
                "scenes_recall_defined": int(n_rec[idx]),
                "tp": int(tp_all[idx]),
                "fp": int(pred_all[idx] - tp_all[idx]),
                "fn": int(n_true.sum() - tp_all[idx]),
            }
        )
    return pd.DataFrame(rows)


def choose_support_params(sweep: pd.DataFrame, rule: str) -> SupportParams:
    """The grid point of `rule` with the highest f1; ties: higher precision, then the smallest
    prob_threshold, score_threshold, bbox_margin_px, adjacency_iou, then no gap test before
    the largest max_gap_m (in that order)."""
    rows = sweep[(sweep["rule"] == rule) & sweep["f1"].notna()]
    if rows.empty:
        raise ValueError(f"rule: no sweep row of rule {rule!r} has a defined f1")
    rows = rows.assign(_gap=rows["max_gap_m"].fillna(np.inf) if "max_gap_m" in rows else np.inf)
    keys = [
        "f1",
        "precision",
        "prob_threshold",
        "score_threshold",
        "bbox_margin_px",
        "adjacency_iou",
        "_gap",
    ]
    best = rows.sort_values(
        keys, ascending=[False, False, True, True, True, True, False], kind="mergesort"
    )
    row = best.iloc[0]
    gap = float(row["_gap"])
    return SupportParams(
        rule=rule,
        prob_threshold=float(row["prob_threshold"]),
        score_threshold=float(row["score_threshold"]),
        bbox_margin_px=int(row["bbox_margin_px"]),
        adjacency_iou=float(row["adjacency_iou"]),
        max_gap_m=None if np.isinf(gap) else gap,
    )
