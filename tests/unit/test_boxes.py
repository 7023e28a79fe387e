"""Arrangement boxes (thesis 5.2.1, eq. 5.1): IoU, per-class NMS, ground truth from clusters,
VOC average precision, on hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.collapse.detection_metrics import class_pr, mean_ap, voc_ap
from clutterbench.perception.boxes import (
    ARRANGEMENT_CLASSES,
    Detection,
    box_iou,
    corners_px,
    detections_from_clusters,
    nms,
)
from clutterbench.sim.clusters import CLASSES


def test_classes_are_the_simulators():
    assert ARRANGEMENT_CLASSES == CLASSES


def test_corners_from_centre_and_size():
    assert corners_px(np.array([[10.0, 20.0, 4.0, 6.0]])).tolist() == [[8.0, 17.0, 12.0, 23.0]]


def test_box_iou_hand_computed():
    a = np.array([[5.0, 5.0, 10.0, 10.0]])  # [0, 10] x [0, 10]
    b = np.array(
        [
            [5.0, 5.0, 10.0, 10.0],  # the same box
            [10.0, 5.0, 10.0, 10.0],  # [5, 15] x [0, 10]: 50 / 150
            [20.0, 20.0, 4.0, 4.0],  # apart
            [5.0, 5.0, 5.0, 5.0],  # inside, a quarter of the area
            [15.0, 5.0, 10.0, 10.0],  # touching along an edge
        ]
    )
    iou = box_iou(a, b)
    assert iou.shape == (1, 5)
    assert iou[0].tolist() == pytest.approx([1.0, 1 / 3, 0.0, 0.25, 0.0])
    assert np.allclose(box_iou(b, a).T, iou)
    assert box_iou(np.zeros((0, 4)), a).shape == (0, 1)
    assert box_iou(np.zeros((1, 4)), np.zeros((1, 4)))[0, 0] == 0.0  # empty boxes


def test_nms_drops_same_class_overlap_above_threshold_only():
    boxes = np.array(
        [
            [5.0, 5.0, 10.0, 10.0],
            [6.0, 5.0, 10.0, 10.0],  # IoU 9/11 = 0.82 with box 0
            [10.0, 5.0, 10.0, 10.0],  # IoU 1/3 with box 0: kept
            [5.0, 5.0, 10.0, 10.0],  # same place as 0 but another class: kept
        ]
    )
    scores = np.array([0.9, 0.95, 0.5, 0.3])
    classes = np.array([0, 0, 0, 1])
    kept = nms(boxes, scores, classes, 0.45)
    assert kept.tolist() == [1, 2, 3]  # box 0 loses to the better-scoring box 1
    # the threshold is strict: IoU exactly at it is kept
    assert nms(boxes[[0, 2]], np.array([0.9, 0.8]), np.array([0, 0]), 1 / 3).tolist() == [0, 1]


def test_nms_never_keeps_two_same_class_boxes_above_045():
    rng = np.random.default_rng(0)
    boxes = np.concatenate([rng.uniform(20, 40, (30, 2)), rng.uniform(5, 20, (30, 2))], axis=1)
    scores, classes = rng.random(30), rng.integers(0, 2, 30)
    kept = nms(boxes, scores, classes, 0.45)
    assert np.all(np.diff(scores[kept]) <= 0)  # best first
    iou = box_iou(boxes[kept], boxes[kept])
    same = classes[kept][:, None] == classes[kept][None, :]
    np.fill_diagonal(same, False)
    assert not np.any(iou[same] > 0.45)
    # every dropped box overlaps a better-scoring kept one of its class
    for i in set(range(30)) - set(kept.tolist()):
        rivals = [k for k in kept if classes[k] == classes[i] and scores[k] >= scores[i]]
        assert box_iou(boxes[[i]], boxes[rivals]).max() > 0.45


def test_detections_from_clusters_skip_padding_and_invisible():
    classes = np.array([2, 0, 3, -1], dtype=np.int8)
    boxes = np.array([[10, 12, 4, 6], [0, 0, 0, 0], [30, 30, 8, 8], [0, 0, 0, 0]], dtype=np.float32)
    dets = detections_from_clusters(classes, boxes)
    assert [d.cls for d in dets] == ["C^r", "C^l"]
    assert all(d.score == 1.0 for d in dets)
    assert dets[0].box.tolist() == [10, 12, 4, 6] and dets[0].box.dtype == np.float64
    with pytest.raises(AssertionError):
        Detection("C^x", np.zeros(4), 1.0)


def test_voc_ap_hand_computed():
    # 2 truth boxes; detections TP, FP, TP: recall .5, .5, 1; precision 1, .5, 2/3
    assert voc_ap(np.array([0.5, 0.5, 1.0]), np.array([1.0, 0.5, 2 / 3])) == pytest.approx(
        0.5 * 1.0 + 0.5 * 2 / 3
    )
    assert voc_ap(np.array([1.0]), np.array([1.0])) == 1.0
    assert voc_ap(np.zeros(0), np.zeros(0)) == 0.0


def test_class_pr_matches_each_truth_once():
    truth = [(np.array([[5.0, 5, 10, 10], [30, 30, 10, 10]]), np.array([0, 0]))]
    dets = [
        (
            np.array([[5.0, 5, 10, 10], [6, 5, 10, 10], [50, 50, 5, 5], [30, 31, 10, 10]]),
            np.array([0.9, 0.8, 0.7, 0.6]),
            np.array([0, 0, 0, 0]),
        )
    ]
    pr = class_pr(dets, truth, 0)
    assert pr.tp.tolist() == [True, False, False, True]  # the duplicate is a false positive
    assert pr.ap() == pytest.approx(0.5 + 0.5 * 0.5)
    assert pr.at_score(0.75) == (0.5, 0.5)
    m, prs = mean_ap(dets, truth, n_classes=2)
    assert m == pytest.approx(0.75) and np.isnan(prs[1].ap())  # class 1 has no truth


def test_pr_rows_keep_the_true_positives_and_the_last_detection():
    from clutterbench.collapse.detection_metrics import ClassPR, pr_rows

    pr = ClassPR(3, np.array([0.9, 0.8, 0.7, 0.6]), np.array([True, False, True, False]))
    none = ClassPR(0, np.zeros(0), np.zeros(0, bool))
    rows = pr_rows([pr, none, none, none])
    assert [(r["class"], r["score"]) for r in rows] == [("C^h", 0.9), ("C^h", 0.7), ("C^h", 0.6)]
    assert [r["recall"] for r in rows] == pytest.approx([1 / 3, 2 / 3, 2 / 3])
    assert [r["precision"] for r in rows] == pytest.approx([1.0, 2 / 3, 0.5])
