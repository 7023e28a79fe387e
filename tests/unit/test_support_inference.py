"""Support relations from collapse maps (thesis 6.2.2, eqs. 6.2-6.4) on hand-drawn 8x8 scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clutterbench.planning.ch6.support import (
    SceneEvidence,
    SupportEdge,
    SupportParams,
    choose_support_params,
    collapse_score,
    edge_precision_recall,
    grown_bbox_iou,
    infer_support,
    mask_bboxes,
    oracle_heatmaps,
    overlap_scores,
    pseudo_contact,
    support_contact,
    support_matrix,
    support_scores,
    surface_gaps,
    sweep_support,
    true_support_edges,
)

HW = (8, 8)


def rect(rows: tuple[int, int], cols: tuple[int, int], value: float | bool = True) -> np.ndarray:
    """(8, 8) array with `value` on rows [r0, r1) x cols [c0, c1), 0 elsewhere."""
    out = np.zeros(HW, dtype=np.float32 if isinstance(value, float) else bool)
    out[rows[0] : rows[1], cols[0] : cols[1]] = value
    return out


def stack_scene() -> tuple[np.ndarray, np.ndarray, list[int]]:
    """A vertical stack (image row 0 is the top): bottom 10, middle 11, top 12, cols 2:6."""
    masks = np.stack([rect((6, 8), (2, 6)), rect((4, 6), (2, 6)), rect((2, 4), (2, 6))])
    heatmaps = np.stack(
        [
            rect((2, 6), (2, 6), 0.9),  # bottom removed: middle and top fall
            rect((2, 4), (2, 6), 0.9),  # middle removed: top falls
            np.zeros(HW, np.float32),  # top removed: nothing falls
        ]
    )
    return heatmaps, masks, [10, 11, 12]


def test_mask_bboxes_are_half_open_and_minus_one_when_empty():
    masks = np.stack([rect((2, 4), (1, 6)), np.zeros(HW, bool)])
    np.testing.assert_array_equal(mask_bboxes(masks), [[1, 2, 6, 4], [-1, -1, -1, -1]])


def test_overlap_scores_hand_computed():
    collapse_area = rect((0, 4), (0, 4))  # 16 px
    masks = np.stack([rect((2, 4), (2, 6)), rect((6, 8), (6, 8)), np.zeros(HW, bool)])
    iou, coverage = overlap_scores(collapse_area, masks)
    # mask 0: 8 px, 4 inside R_C -> IoU 4 / (8 + 16 - 4) = 0.2, coverage 4 / 8 = 0.5
    np.testing.assert_allclose(iou, [0.2, 0.0, 0.0])
    np.testing.assert_allclose(coverage, [0.5, 0.0, 0.0])


@pytest.mark.parametrize("rule", ["iou", "coverage"])
def test_support_scores_hand_computed_and_match_overlap_scores(rule):
    masks = np.stack([rect((0, 4), (0, 4)), rect((2, 4), (2, 6)), rect((6, 8), (0, 2))])
    heatmaps = np.stack(
        [
            rect((2, 4), (2, 4), 0.8),  # R_C(0): 4 px, all inside mask 1
            rect((0, 4), (0, 4), 0.6) + rect((4, 8), (0, 8), 0.5),  # 0.5 is not > 0.5
            np.zeros(HW, np.float32),
        ]
    )
    scores = support_scores(heatmaps, masks, 0.5, rule)
    assert np.isnan(np.diag(scores)).all()
    # Row 0: R_C(0) is 4 px, all inside mask 1 (8 px): IoU 4 / 8, coverage 4 / 8.
    # Row 1: R_C(1) is exactly mask 0 (the 0.5 band is not > 0.5, so mask 2 stays out).
    expected = {(0, 1): 0.5, (0, 2): 0.0, (1, 0): 1.0, (1, 2): 0.0, (2, 0): 0.0, (2, 1): 0.0}
    for (a, b), value in expected.items():
        assert scores[a, b] == pytest.approx(value)
    for a in range(3):
        iou, coverage = overlap_scores(heatmaps[a] > 0.5, masks)
        row = iou if rule == "iou" else coverage
        others = [b for b in range(3) if b != a]
        np.testing.assert_allclose(scores[a, others], row[others])


def test_support_scores_iou_and_coverage_differ_where_hand_computed():
    masks = np.stack([rect((0, 2), (0, 2)), rect((4, 6), (0, 2))])  # 4 px each
    heatmaps = np.stack([rect((3, 7), (0, 2), 1.0), np.zeros(HW, np.float32)])  # R_C: 8 px
    assert support_scores(heatmaps, masks, 0.5, "iou")[0, 1] == pytest.approx(4 / 8)
    assert support_scores(heatmaps, masks, 0.5, "coverage")[0, 1] == pytest.approx(1.0)


def test_grown_bbox_iou_hand_computed():
    # Touching boxes, cols 0:3 and 3:6, rows 2:5; grown by 2 and clipped to the 8x8 image:
    # cols 0:5 and 1:8, rows 0:7 -> 4 * 7 / (35 + 49 - 28) = 0.5
    boxes = mask_bboxes(np.stack([rect((2, 5), (0, 3)), rect((2, 5), (3, 6))]))
    np.testing.assert_allclose(grown_bbox_iou(boxes, 0, HW), [[1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(grown_bbox_iou(boxes, 2, HW), [[1.0, 0.5], [0.5, 1.0]])
    # An empty box (-1) grown by 2 would reach pixel (0, 0); it still overlaps nothing.
    with_empty = np.array([[0, 0, 2, 2], [-1, -1, -1, -1]])
    np.testing.assert_allclose(grown_bbox_iou(with_empty, 2, HW), [[1.0, 0.0], [0.0, 1.0]])


def test_pseudo_contact_touching_vs_far_apart_and_margin():
    touching = np.stack([rect((2, 5), (0, 3)), rect((2, 5), (3, 6))])
    assert not pseudo_contact(touching, 0, 0.0).any()  # touching boxes do not overlap
    np.testing.assert_array_equal(pseudo_contact(touching, 2, 0.0), [[False, True], [True, False]])
    assert not pseudo_contact(touching, 2, 0.5).any()  # IoU 0.5 is not > 0.5
    far = np.stack([rect((0, 2), (0, 2)), rect((6, 8), (6, 8)), np.zeros(HW, bool)])
    assert not pseudo_contact(far, 2, 0.0).any()  # grown to 0:4 and 4:8: they only touch
    assert pseudo_contact(far, 3, 0.0)[0, 1]
    assert not pseudo_contact(far, 8, 0.0)[:, 2].any()  # an empty mask touches nothing


def test_support_matrix_threshold_contact_and_mutual_support():
    contact = ~np.eye(3, dtype=bool)
    contact[0, 2] = contact[2, 0] = False
    scores = np.array([[np.nan, 0.6, 0.9], [0.8, np.nan, 0.4], [0.7, 0.7, np.nan]])
    supp = support_matrix(scores, contact, 0.5)
    # 0<->1 both above: keep the higher 1->0; 1->2 below threshold; 0-2 not in contact
    np.testing.assert_array_equal(supp, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    tie = np.array([[np.nan, 0.7], [0.7, np.nan]])
    np.testing.assert_array_equal(
        support_matrix(tie, ~np.eye(2, dtype=bool), 0.5), [[0, 1], [0, 0]]
    )


def test_infer_support_on_a_vertical_stack_uses_contact():
    heatmaps, masks, ids = stack_scene()
    params = SupportParams("coverage", 0.5, 0.5, bbox_margin_px=1, adjacency_iou=0.1)
    # Bottom's collapse area covers the top too, but the top does not touch the bottom.
    assert infer_support(heatmaps, masks, ids, params) == [
        SupportEdge(10, 11, 1.0),
        SupportEdge(11, 12, 1.0),
    ]
    wide = SupportParams("coverage", 0.5, 0.5, bbox_margin_px=4, adjacency_iou=0.0)
    pairs = {(e.supporter, e.supported) for e in infer_support(heatmaps, masks, ids, wide)}
    assert pairs == {(10, 11), (10, 12), (11, 12)}
    iou_rule = SupportParams("iou", 0.5, 0.4, bbox_margin_px=1, adjacency_iou=0.1)
    # R_C(bottom) = 16 px, middle 8 px inside it: IoU 0.5
    assert [e.score for e in infer_support(heatmaps, masks, ids, iou_rule)] == [0.5, 1.0]


def test_collapse_score_is_eq_6_2():
    heatmap = rect((0, 3), (0, 8), 0.9)
    assert collapse_score(heatmap, rect((2, 6), (0, 2)), 0.5) == pytest.approx(2 / 8)
    assert collapse_score(heatmap, rect((2, 6), (0, 2)), 0.95) == 0.0
    assert collapse_score(heatmap, np.zeros(HW, bool), 0.5) == 0.0


def test_oracle_heatmaps_and_true_edges_recover_the_stack():
    _, masks, ids = stack_scene()
    moved = np.array([[1, 1, 1], [0, 1, 1], [0, 0, 1]], dtype=bool)  # diagonal ignored
    maps = oracle_heatmaps(moved, masks)
    assert maps.dtype == np.float32
    np.testing.assert_array_equal(maps[0], (masks[1] | masks[2]).astype(np.float32))
    np.testing.assert_array_equal(maps[1], masks[2].astype(np.float32))
    np.testing.assert_array_equal(maps[2], np.zeros(HW, np.float32))
    contact = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], dtype=bool)
    assert true_support_edges(moved, contact) == {(0, 1), (1, 2)}
    params = SupportParams("coverage", 0.5, 0.5, bbox_margin_px=1, adjacency_iou=0.1)
    pairs = {(e.supporter, e.supported) for e in infer_support(maps, masks, ids, params)}
    assert pairs == {(ids[x], ids[y]) for x, y in true_support_edges(moved, contact)}


def test_true_support_edges_needs_symmetric_contact():
    with pytest.raises(ValueError, match="contact"):
        true_support_edges(np.ones((2, 2), bool), np.array([[0, 1], [0, 0]], dtype=bool))


def test_edge_precision_recall_eqs_6_3_6_4():
    precision, recall = edge_precision_recall({(1, 2), (2, 3)}, {(1, 2), (3, 4), (5, 6)})
    assert (precision, recall) == (pytest.approx(0.5), pytest.approx(1 / 3))
    precision, recall = edge_precision_recall(set(), {(1, 2)})
    assert math.isnan(precision) and recall == 0.0
    precision, recall = edge_precision_recall({(1, 2)}, set())
    assert precision == 0.0 and math.isnan(recall)
    assert all(math.isnan(v) for v in edge_precision_recall(set(), set()))


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("rule", {"rule": "area"}),
        ("prob_threshold", {"prob_threshold": 1.5}),
        ("score_threshold", {"score_threshold": -0.1}),
        ("adjacency_iou", {"adjacency_iou": 2.0}),
        ("bbox_margin_px", {"bbox_margin_px": -1}),
        ("bbox_margin_px", {"bbox_margin_px": 1.5}),
    ],
)
def test_support_params_reject_bad_values(field, kwargs):
    good = {"rule": "iou", "prob_threshold": 0.5, "score_threshold": 0.5}
    good |= {"bbox_margin_px": 2, "adjacency_iou": 0.1}
    with pytest.raises(ValueError, match=field):
        SupportParams(**(good | kwargs))


def sweep_scenes() -> list[SceneEvidence]:
    heatmaps, masks, ids = stack_scene()
    # A fourth box beside the middle one; bottom's map spills over half of it (a false edge
    # that a score threshold of 0.6 or an adjacency IoU of 0.2 removes).
    side = rect((4, 6), (6, 8))
    masks = np.concatenate([masks, side[None]])
    heatmaps = np.concatenate([heatmaps, np.zeros((1, *HW), np.float32)])
    heatmaps[0] += rect((4, 5), (6, 8), 0.9)
    stack = SceneEvidence(heatmaps, masks, [*ids, 13], {(10, 11), (11, 12)})
    # Two boxes side by side; box 0's map puts a 0.5 over box 1, which does not fall.
    pair_masks = np.stack([rect((4, 8), (0, 3)), rect((4, 8), (3, 6))])
    pair_maps = np.stack([rect((4, 8), (3, 6), 0.5), np.zeros(HW, np.float32)])
    pair = SceneEvidence(pair_maps, pair_masks, [0, 1], set())
    return [stack, pair]


def test_sweep_support_agrees_with_infer_support_and_choice_is_the_best():
    scenes = sweep_scenes()
    sweep = sweep_support(scenes, "coverage", [0.3, 0.7], [0.2, 0.6], [0, 1, 4], [0.0, 0.2])
    assert len(sweep) == 2 * 2 * 3 * 2
    for row in sweep.itertuples():
        params = SupportParams(
            row.rule, row.prob_threshold, row.score_threshold, row.bbox_margin_px, row.adjacency_iou
        )
        prs, tp, fp, fn = [], 0, 0, 0
        for sc in scenes:
            edges = infer_support(sc.heatmaps, sc.masks, sc.ids, params)
            predicted = {(e.supporter, e.supported) for e in edges}
            prs.append(edge_precision_recall(predicted, sc.true_edges))
            tp += len(predicted & sc.true_edges)
            fp += len(predicted - sc.true_edges)
            fn += len(sc.true_edges - predicted)
        precision, recall = np.array(prs).T
        assert (row.tp, row.fp, row.fn) == (tp, fp, fn)
        defined = ~np.isnan(precision)
        np.testing.assert_allclose(
            row.precision, precision[defined].mean() if defined.any() else np.nan
        )
        assert row.scenes_precision_defined == int(defined.sum())
        assert row.scenes_recall_defined == 1  # the pair scene has no true edge
        np.testing.assert_allclose(row.recall, np.nanmean(recall))
    chosen = choose_support_params(sweep, "coverage")
    # f1 = 1 only at prob 0.7 (the pair's 0.5 is out), margin 1, and score 0.6 or adjacency
    # 0.2 (the side box out); the tie goes to the smallest thresholds in column order.
    assert chosen == SupportParams("coverage", 0.7, 0.2, bbox_margin_px=1, adjacency_iou=0.2)
    best = sweep.loc[
        (sweep.prob_threshold == 0.7)
        & (sweep.score_threshold == 0.2)
        & (sweep.bbox_margin_px == 1)
        & (sweep.adjacency_iou == 0.2)
    ]
    assert float(best.f1.iloc[0]) == sweep.f1.max() == 1.0
    assert sweep.loc[sweep.bbox_margin_px == 0, "f1"].isna().all()  # no contact: no edges


def test_choose_support_params_needs_a_defined_f1():
    sweep = sweep_support(sweep_scenes(), "iou", [0.5], [0.5], [0], [0.0])
    with pytest.raises(ValueError, match="rule"):
        choose_support_params(sweep, "iou")
    with pytest.raises(ValueError, match="rule"):
        choose_support_params(sweep, "coverage")


def test_the_held_object_does_not_count_in_the_collapse_score():
    """Eq. 6.2 during a bimanual pull: the object the other arm holds cannot collapse, so its
    share of R_C is left out (Fig. 6.7 (d))."""
    from clutterbench.observation import CameraModel, Observation
    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner

    instance = np.zeros(HW, np.uint8)
    instance[2:6, 0:4] = 1  # box 0: pulled
    instance[2:6, 4:8] = 2  # box 1: beside it, wholly inside R_C
    instance[6:8, 0:4] = 3  # box 2: under it, a quarter inside R_C
    camera = CameraModel(np.eye(3), np.eye(4))
    obs = Observation(np.ones(HW, np.float32), instance, camera)
    heat = np.zeros(HW, np.float32)
    heat[2:6, 4:8] = 1.0
    heat[6, 0] = 1.0
    params = SupportParams("coverage", 0.5, 0.3, 2, 0.0)
    planner = CollapseGraphPlanner(lambda depth, masks: heat[None], params, 0.3, 1)
    assert planner.collapse_score(obs, 0) == pytest.approx(1.0)
    assert planner.collapse_score(obs, 0, hold=1) == pytest.approx(1 / 8)


def _plane_points(depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) points of an orthographic view: x, y = pixel index in cm, z = depth (m)."""
    v, u = np.mgrid[0 : depth.shape[0], 0 : depth.shape[1]].astype(np.float64)
    return np.stack([u * 0.01, v * 0.01, depth], axis=-1)


def test_surface_gaps_tell_touching_faces_from_a_box_far_behind():
    """Three boxes side by side in the image: 0 and 1 meet at the same depth (touching); 2
    borders 1 in the image but lies 10 cm behind it; 0 and 2 are far apart in the image."""
    masks = np.zeros((3, 8, 12), bool)
    masks[0, :, 0:4], masks[1, :, 4:8], masks[2, :, 8:12] = True, True, True
    depth = np.full((8, 12), 0.5)
    depth[:, 8:12] = 0.6
    gaps = surface_gaps(_plane_points(depth), masks)
    assert gaps[0, 1] == pytest.approx(0.01) and gaps[1, 0] == gaps[0, 1]
    assert gaps[1, 2] == pytest.approx(np.hypot(0.01, 0.1))
    assert np.isinf(gaps[0, 2]) and np.all(np.diag(gaps) == 0.0)
    params = SupportParams("coverage", 0.5, 0.3, 2, 0.0, max_gap_m=0.05)
    contact = support_contact(masks, params, gaps)
    assert contact[0, 1] and not contact[1, 2] and not contact[0, 2]
    thesis = support_contact(masks, SupportParams("coverage", 0.5, 0.3, 2, 0.0), gaps)
    assert thesis[0, 1] and thesis[1, 2]  # the bounding-box rule alone takes both
    with pytest.raises(ValueError, match="max_gap_m"):
        support_contact(masks, params, None)
    with pytest.raises(ValueError, match="max_gap_m"):
        SupportParams("coverage", 0.5, 0.3, 2, 0.0, max_gap_m=0.0)


def test_the_sweep_chooses_the_gap_test_that_removes_a_false_edge():
    """Box 2 collapses when 1 is removed but does not touch it (10 cm behind): only the gap
    test keeps the false edge 1 -> 2 out, so the sweep picks a max_gap_m."""
    masks = np.zeros((3, 8, 12), bool)
    masks[0, :, 0:4], masks[1, :, 4:8], masks[2, :, 8:12] = True, True, True
    depth = np.full((8, 12), 0.5)
    depth[:, 8:12] = 0.6
    gaps = surface_gaps(_plane_points(depth), masks)
    heat = np.zeros((3, 8, 12), np.float32)
    heat[0][masks[1]] = 1.0  # removing 0 collapses 1 (true: they touch)
    heat[1][masks[2]] = 1.0  # removing 1 moves 2 (not a support: no contact)
    scene = SceneEvidence(heat, masks, [0, 1, 2], {(0, 1)}, gaps)
    sweep = sweep_support([scene], "coverage", [0.5], [0.3], [2], [0.0], [None, 0.05])
    assert list(sweep["precision"]) == [0.5, 1.0]
    assert choose_support_params(sweep, "coverage").max_gap_m == 0.05
