"""The chapter 4 planner on the network's class maps (thesis eqs. 4.1, 4.2): every candidate
(extract, support) pair of segments through the B / E / S / C network in batches, its risk
index r_c, the safest pair, or the safest support of a given target. Used by the ch. 4 trials
and by the ch. 6 single-step baseline; sees only the depth image and the masks."""

from __future__ import annotations

from typing import Any

import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.masks import Segmentation
from clutterbench.planning.ch4.risk import (
    Pair,
    PairChoice,
    candidate_pairs,
    choose_safest_pair,
    choose_support_for_target,
    risk_index,
    soft_collapse,
)


# -- the network: (depth, extraction mask, support mask) -> B / E / S / C -------------------
def class_probs(predictor: Any, depth_m: np.ndarray, pair_masks: np.ndarray) -> np.ndarray:
    """(A, 2, H, W) extraction + support masks of A candidates on one depth image -> (A, 4,
    H, W) float32 class probabilities in the network's label order (planning.risk.CLASSES),
    in batches of the predictor's batch size."""
    import torch

    from clutterbench.collapse.predict import scene_logits

    assert pair_masks.ndim == 4 and pair_masks.shape[1] == 2, "pair masks must be (A, 2, H, W)"
    depth = np.ascontiguousarray(depth_m, dtype=np.float32)
    logits = scene_logits(predictor, depth, pair_masks.astype(np.float32, copy=False))
    if logits.shape[1] != 4:
        raise ValueError(
            f"the ch. 4 planner needs a 4-class network (B/E/S/C), this one has "
            f"{logits.shape[1]} output channels"
        )
    return torch.softmax(logits.float(), dim=1).numpy()


def pair_masks(seg: Segmentation, pairs: list[Pair]) -> np.ndarray:
    """(A, 2, H, W) float32 extraction and support masks of candidate pairs of segment indices."""
    out = np.zeros((len(pairs), 2, *seg.masks.shape[1:]), dtype=np.float32)
    for a, (x, s) in enumerate(pairs):
        out[a, 0] = seg.masks[x]
        if s is not None:
            out[a, 1] = seg.masks[s]
    return out


def plan_risk(
    predictor: Any,
    obs: Observation,
    seg: Segmentation,
    target: int | None,
    pixel_threshold: float,
) -> tuple[PairChoice, list[Pair], np.ndarray, np.ndarray]:
    """Eqs. (4.1), (4.2) on segment indices: every ordered pair (target None) or every support
    of `target`, batched through the network -> (choice, candidates, risks, class probs).
    Equal risks go to the least mean P(C) (planning.risk.soft_collapse)."""
    ks = list(range(len(seg.ids)))
    if target is None:
        pairs = candidate_pairs(ks)
    else:
        pairs = [(target, s) for s in ks if s != target]
    probs = class_probs(predictor, obs.depth_m, pair_masks(seg, pairs))
    risks = risk_index(probs, pixel_threshold)
    # r_c ties often (at 0 when no pixel reaches the threshold); the expected collapsing
    # area decides among equal risks, the candidate order after that.
    soft = soft_collapse(probs)
    if target is None:
        choice = choose_safest_pair(pairs, risks, soft)
    else:
        choice = choose_support_for_target(target, pairs, risks, soft)
    return choice, pairs, risks, probs
