"""A box head trained on a sensor's masks from depth (support.box_head.sensed_masks: depth):
each scene's segments take the truth of the boxes their grasps take, none between two segments
of one box, and a segment that grasps no box is left out."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.perception import seen as seen_module
from clutterbench.perception.seen import SeenSegments
from clutterbench.sim.config import CameraConfig
from clutterbench.support.evaluate import Scene, segmented_scene

H = W = 16


def _scene() -> Scene:
    """Boxes 1, 3 and 4 visible side by side in columns 0-4, 5-9, 10-15; pulling 1 moves 3."""
    masks = np.zeros((3, H, W), bool)
    masks[0, :, :5], masks[1, :, 5:10], masks[2, :, 10:] = True, True, True
    moved = np.zeros((3, 3), bool)
    moved[0, 1] = True
    contact = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], bool)
    return Scene(
        index=0,
        family="random",
        depth_m=np.full((H, W), 0.6, np.float32),
        ids=[1, 3, 4],
        masks=masks,
        moved=moved,
        contact=contact,
        n_objects=5,
        moved_by={"pull": moved | moved.T | np.eye(3, dtype=bool)},  # a pulled box moves
    )


def test_segments_take_the_truth_of_the_boxes_their_grasps_take(monkeypatch):
    def fake(obs, roi, n_boxes, min_pixels, params=None):
        # box 1 split in two (its own id and alias 5), box 3 whole, box 4 a segment that grasps
        # no box (id 6), the rest unseen
        instance = np.zeros((H, W), np.uint8)
        instance[:8, :5], instance[8:, :5], instance[:, 5:10], instance[:, 10:] = 2, 6, 4, 7
        assert n_boxes == 5 and (obs.instance[:, :5] == 2).all()
        seen = type(obs)(obs.depth_m, instance, obs.camera)
        return SeenSegments(obs=seen, grasps={1: 1, 5: 1, 3: 3, 6: None})

    monkeypatch.setattr(seen_module, "see_segments", fake)
    out = segmented_scene(_scene(), CameraConfig(image_size=H), min_pixels=5)
    assert out.ids == [1, 3, 5]
    assert [int(m.sum()) for m in out.masks] == [40, 80, 40]
    # 1 -> 3 and its alias 5 -> 3 keep the truth of box 1 -> box 3; 1 and 5 have none between
    assert out.moved.tolist() == [[False, True, False], [False, False, False], [False, True, False]]
    assert out.contact.tolist() == [[False, True, False], [True, False, True], [False, True, False]]
    assert out.moved_by["pull"].tolist() == [[0, 1, 0], [1, 0, 1], [0, 1, 0]]
    assert out.true_edges == {(1, 3), (5, 3)}


def test_small_segments_are_left_out(monkeypatch):
    def fake(obs, roi, n_boxes, min_pixels, params=None):
        instance = np.zeros((H, W), np.uint8)
        instance[:, :5], instance[0, 5:7] = 2, 4  # box 3 seen in 2 pixels only
        seen = type(obs)(obs.depth_m, instance, obs.camera)
        return SeenSegments(obs=seen, grasps={1: 1, 3: 3})

    monkeypatch.setattr(seen_module, "see_segments", fake)
    out = segmented_scene(_scene(), CameraConfig(image_size=H), min_pixels=5)
    assert out.ids == [1] and out.moved.shape == (1, 1) and not out.moved.any()


@pytest.mark.parametrize(
    ("preset", "masks", "expected"),
    [
        ("ideal", "depth", ["a", "b"]),  # the exact-depth head keeps the simulator's masks
        ("d415", "instance", ["a", "b"]),
        ("d415", "depth", ["a'", "b'"]),
        ("d415", "both", ["a", "b", "a'", "b'"]),
    ],
)
def test_a_sensed_head_trains_on_the_masks_it_names(monkeypatch, preset, masks, expected):
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.noise import TrainSensingConfig
    from clutterbench.support import box_run
    from clutterbench.support.config import BoxHeadConfig

    monkeypatch.setattr(box_run, "segmented_scene", lambda sc, camera, min_pixels: sc + "'")
    bh = BoxHeadConfig(sensing=TrainSensingConfig(preset, 0.2), sensed_masks=masks)
    assert box_run.as_seen(["a", "b"], bh, SimConfig(), 20) == expected
