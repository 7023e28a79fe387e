"""The ch. 4 risk index (eq. 4.1) and the argmin choice (eq. 4.2) on hand-made prediction maps."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.data.labels import PULL_CLASSES
from clutterbench.planning.ch4.risk import (
    CLASSES,
    PairChoice,
    candidate_pairs,
    choose_safest_pair,
    choose_support_for_target,
    random_pair,
    risk_from_labels,
    risk_index,
    soft_collapse,
)

E, S, C, B = (CLASSES.index(k) for k in "ESCB")
H = W = 4


def one_hot(labels: np.ndarray) -> np.ndarray:
    """(A, H, W) class maps -> (A, 4, H, W) probabilities 0.9 on the class, the rest shared."""
    probs = np.full((labels.shape[0], 4, *labels.shape[1:]), 0.1 / 3)
    np.put_along_axis(probs, labels[:, None], 0.9, axis=1)
    return probs


def with_collapse(pixels: int) -> np.ndarray:
    """(H, W) class map: E and S one pixel each, `pixels` pixels of C, the rest B."""
    labels = np.full(H * W, B)
    labels[0], labels[1], labels[2 : 2 + pixels] = E, S, C
    return labels.reshape(H, W)


def test_classes_are_the_network_label_order():
    # The planner indexes the network's output channels: they must be the training labels'.
    assert CLASSES == PULL_CLASSES and (B, E, S, C) == (0, 1, 2, 3)


def test_risk_index_by_hand():
    # Candidate 0: 3 of 16 pixels collapse -> 3 / 16.
    # Candidate 1: as 0, but 4 pixels are undecided (no class above 0.4): out of the union,
    # 3 / 12.
    # Candidate 2: as 0, but 2 background pixels are also 0.45 collapse (two regions): in the
    # union once, in R_C: 5 / 16.
    labels = np.stack([with_collapse(3)] * 3)
    probs = one_hot(labels)
    probs[1, :, 3, :] = 0.3
    probs[1, C, 3, :] = 0.1
    probs[2, :, 3, :2] = 0.05
    probs[2, [B, C], 3, :2] = 0.45
    assert risk_index(probs).tolist() == [3 / 16, 3 / 12, 5 / 16]
    # The threshold is the thesis' 0.4: at 0.46 the 0.45 pixels fall out of every region.
    assert risk_index(probs[2:], threshold=0.46)[0] == pytest.approx(3 / 14)


def test_no_region_at_all_is_infinitely_risky():
    probs = np.full((2, 4, H, W), 0.25)  # undecided everywhere: 0 / 0
    probs[1] = one_hot(with_collapse(1)[None])[0]
    risks = risk_index(probs)
    assert risks[0] == np.inf and risks[1] == 1 / 16
    assert choose_safest_pair([(0, 1), (1, 0)], risks) == PairChoice(1, 0, 1 / 16)


def test_risk_from_labels_is_the_collapse_fraction():
    labels = np.stack([with_collapse(0), with_collapse(5), np.full((H, W), C)])
    assert risk_from_labels(labels).tolist() == [0.0, 5 / 16, 1.0]
    # Where every pixel is in exactly one region, the two readings agree.
    assert np.array_equal(risk_from_labels(labels), risk_index(one_hot(labels)))


def test_the_two_readings_differ_where_regions_overlap_or_leave_gaps():
    probs = one_hot(with_collapse(3)[None])
    probs[0, :, 3, :] = 0.3  # undecided; argmax calls them B, not C
    probs[0, C, 3, :] = 0.1
    assert risk_index(probs)[0] == 3 / 12
    assert risk_from_labels(probs.argmax(axis=1))[0] == 3 / 16


def test_argmin_picks_the_pair_with_the_least_collapse():
    pairs = candidate_pairs([0, 1, 2])  # (0,1) (0,2) (1,0) (1,2) (2,0) (2,1)
    collapse_px = [5, 2, 7, 4, 9, 3]
    risks = risk_index(one_hot(np.stack([with_collapse(n) for n in collapse_px])))
    assert choose_safest_pair(pairs, risks) == PairChoice(0, 2, 2 / 16)


def test_ties_go_to_the_first_candidate():
    pairs = candidate_pairs([4, 7, 9])
    risks = [0.5, 0.2, 0.3, 0.2, 0.2, 0.9]
    assert choose_safest_pair(pairs, risks) == PairChoice(4, 9, 0.2)
    assert choose_safest_pair(pairs[::-1], risks[::-1]) == PairChoice(9, 4, 0.2)


def test_ten_objects_give_ninety_ordered_pairs():
    ids = list(range(10, 20))
    pairs = candidate_pairs(ids)
    assert len(pairs) == 90 and len(set(pairs)) == 90
    assert all(x != s and x in ids and s in ids for x, s in pairs)
    assert pairs[:3] == [(10, 11), (10, 12), (10, 13)]
    with_none = candidate_pairs(ids, with_no_support=True)
    assert len(with_none) == 100 and with_none[:2] == [(10, None), (10, 11)]
    assert candidate_pairs([3]) == [] and candidate_pairs([3], with_no_support=True) == [(3, None)]
    with pytest.raises(ValueError, match="distinct"):
        candidate_pairs([1, 2, 1])


def test_mode_b_chooses_only_among_the_targets_pairs():
    pairs = candidate_pairs([0, 1, 2], with_no_support=True)
    # (0,None) (0,1) (0,2) (1,None) (1,0) (1,2) (2,None) (2,0) (2,1)
    risks = [0.6, 0.4, 0.4, 0.0, 0.1, 0.1, 0.5, 0.3, 0.05]
    assert choose_safest_pair(pairs, risks) == PairChoice(1, None, 0.0)
    assert choose_support_for_target(0, pairs, risks) == PairChoice(0, 1, 0.4)
    assert choose_support_for_target(2, pairs, risks) == PairChoice(2, 1, 0.05)
    with pytest.raises(ValueError, match="target 5"):
        choose_support_for_target(5, pairs, risks)


def test_choice_refuses_mismatched_or_missing_risks():
    pairs = candidate_pairs([0, 1])
    with pytest.raises(ValueError, match="2 candidate pairs"):
        choose_safest_pair(pairs, [0.1])
    with pytest.raises(ValueError, match="NaN"):
        choose_safest_pair(pairs, [np.nan, 0.1])
    with pytest.raises(ValueError, match="no candidate"):
        choose_safest_pair([], [])


def test_random_pair_is_seeded_and_covers_every_pair():
    pairs = candidate_pairs([0, 1, 2])
    draws = [random_pair(pairs, np.random.default_rng(7)) for _ in range(3)]
    assert draws[0] == draws[1] == draws[2]
    rng = np.random.default_rng(0)
    assert {random_pair(pairs, rng) for _ in range(200)} == set(pairs)
    with pytest.raises(ValueError, match="no candidate"):
        random_pair([], rng)


def test_equal_risks_go_to_the_least_expected_collapse():
    # Both candidates claim no C pixel above 0.4 (r_c = 0), but the second one's collapse
    # probability is lower everywhere: the tie-break takes it; without one, the first wins.
    probs = one_hot(np.stack([with_collapse(0)] * 3))
    probs[0, C] += 0.3
    probs[1, C] += 0.1
    probs[2, C] += 0.2
    probs /= probs.sum(axis=1, keepdims=True)
    pairs = [(0, 1), (1, 0), (2, 0)]
    risks = risk_index(probs)
    assert risks.tolist() == [0.0, 0.0, 0.0]
    soft = soft_collapse(probs)
    assert soft[1] < soft[2] < soft[0]
    assert choose_safest_pair(pairs, risks) == PairChoice(0, 1, 0.0)
    assert choose_safest_pair(pairs, risks, soft) == PairChoice(1, 0, 0.0)
    assert choose_support_for_target(2, pairs, risks, soft) == PairChoice(2, 0, 0.0)
    # The risk still comes first: a lower r_c beats a lower tie-break.
    assert choose_safest_pair(pairs, [0.1, 0.2, 0.0], soft) == PairChoice(2, 0, 0.0)
