"""The arrangement detector (thesis 5.2.1): output shapes, decoding of hand-made heads, training
targets, its training depth (parametric noise or a sensor, detector.sensing), checkpoint round
trip and one-line refusals of checkpoints it cannot use."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from clutterbench.collapse.config import TrainSensingConfig
from clutterbench.collapse.detector import (
    ArrangementDetector,
    DetectorParams,
    detector_loss,
    heatmap_targets,
    shift_image,
    train_detector,
    training_batch,
)
from clutterbench.data.arrangement import ArrangementSet
from clutterbench.errors import ClutterbenchError
from clutterbench.models.checkpoint import save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.detector import (
    STRIDE,
    ArrangementNet,
    DetectorConfig,
    decode,
    load_detector,
    save_detector,
)
from clutterbench.models.vgg import VGGConfig
from clutterbench.perception.boxes import ARRANGEMENT_CLASSES, Detection
from clutterbench.sim.noise import add_depth_noise
from clutterbench.sim.sensor import SensedAugmentation, focal_px, preset

SIZE = 64
CFG = DetectorConfig(input_size=SIZE, widths=(4, 4, 8, 8, 8), neck_channels=8)


def tiny_net(seed: int = 0) -> ArrangementNet:
    torch.manual_seed(seed)
    return ArrangementNet(CFG).eval()


def depth_images(n: int) -> np.ndarray:
    return np.random.default_rng(0).uniform(0.5, 0.8, (n, SIZE, SIZE)).astype(np.float32)


def test_forward_shapes():
    out = tiny_net()(torch.from_numpy(depth_images(3))[:, None])
    grid = SIZE // STRIDE
    assert out["heatmap"].shape == (3, len(ARRANGEMENT_CLASSES), grid, grid)
    assert out["size"].shape == (3, 2, grid, grid) and out["offset"].shape == (3, 2, grid, grid)
    with pytest.raises(ValueError, match=r"\(B, 1, 64, 64\)"):
        tiny_net()(torch.zeros(1, 1, 32, 32))


def hand_made_heads(grid: int = 16) -> dict[str, torch.Tensor]:
    """One confident C^r peak at cell (x 5, y 3) of size 20 x 10 px, offset (0.25, 0.5), and a
    weak C^v peak elsewhere."""
    heat = torch.full((1, 4, grid, grid), -10.0)
    heat[0, 2, 3, 5] = 3.0  # sigmoid 0.953
    heat[0, 1, 10, 10] = -2.0  # sigmoid 0.119
    size = torch.zeros(1, 2, grid, grid)
    size[0, :, 3, 5] = torch.log(torch.tensor([20.0, 10.0]))
    offset = torch.zeros(1, 2, grid, grid)
    offset[0, :, 3, 5] = torch.tensor([0.25, 0.5])
    return {"heatmap": heat, "size": size, "offset": offset}


def test_decode_hand_made_heads():
    [(boxes, scores, classes)] = decode(hand_made_heads(), score_threshold=0.3)
    assert boxes.shape == (1, 4) and scores.shape == (1,) and classes.tolist() == [2]
    assert boxes[0] == pytest.approx([5.25 * STRIDE, 3.5 * STRIDE, 20.0, 10.0], abs=1e-5)
    assert scores[0] == pytest.approx(torch.sigmoid(torch.tensor(3.0)).item(), abs=1e-6)
    [(boxes, scores, classes)] = decode(hand_made_heads(), score_threshold=0.1)
    assert classes.tolist() == [2, 1] and np.all(np.diff(scores) < 0)  # best first


def test_targets_peak_at_the_centre_and_invert_decoding():
    classes, boxes = [np.array([3])], [np.array([[21.0, 14.0, 20.0, 10.0]], np.float32)]
    t = heatmap_targets(classes, boxes, 4, SIZE // STRIDE, alpha=0.54)
    assert t["heatmap"].shape == (1, 4, 16, 16) and t["heatmap"][0, :3].max() == 0.0
    assert t["heatmap"][0, 3, 3, 5] == 1.0 and (t["heatmap"][0, 3] == 1.0).sum() == 1
    assert t["mask"][0].sum() == 1.0 and t["mask"][0, 3, 5] == 1.0
    assert t["offset"][0, :, 3, 5] == pytest.approx([0.25, 0.5])
    # targets as network outputs decode back to the box (logits: a peak where heat is 1)
    heads = {
        "heatmap": torch.from_numpy(np.where(t["heatmap"] == 1.0, 5.0, -5.0)),
        "size": torch.from_numpy(t["size"]),
        "offset": torch.from_numpy(t["offset"]),
    }
    [(decoded, _, cls)] = decode(heads, 0.3)
    assert cls.tolist() == [3] and decoded[0] == pytest.approx(boxes[0][0], abs=1e-4)
    tensors = {k: torch.from_numpy(v) for k, v in t.items()}
    loss = detector_loss(heads, tensors, DetectorParams(net=CFG))
    assert float(loss) < 0.01  # perfect heads cost (almost) nothing


def test_shift_moves_image_and_boxes_together_and_cuts_at_the_border():
    depth = np.zeros((16, 16), np.float32)
    depth[4:8, 2:6] = 0.5  # a 4 x 4 patch, box centre (4, 6)
    boxes = np.array([[4.0, 6.0, 4.0, 4.0], [1.0, 8.0, 2.0, 4.0]], np.float32)
    out, moved, kept = shift_image(depth, boxes, 3, -2)
    assert out.shape == depth.shape and np.array_equal(out[2:6, 5:9], depth[4:8, 2:6])
    assert np.all(out[-2:] == out[-3])  # the uncovered rows repeat the edge
    assert kept.tolist() == [True, True] and moved[0].tolist() == [7.0, 4.0, 4.0, 4.0]
    # moved 3 px left, the second box keeps 0 of its 2 px width: dropped
    _, moved, kept = shift_image(depth, boxes, -3, 0)
    assert kept.tolist() == [True, False] and moved.tolist() == [[1.5, 6.0, 3.0, 4.0]]
    _, same, _ = shift_image(depth, boxes, 0, 0)
    assert np.array_equal(same, boxes)


def test_detect_returns_detections_and_applies_the_thresholds():
    net = tiny_net()
    detector = ArrangementDetector(net, score_threshold=0.0, nms_iou=0.45)
    dets = detector.detect(depth_images(1)[0])
    assert dets and all(isinstance(d, Detection) for d in dets)
    assert all(d.cls in ARRANGEMENT_CLASSES and d.box.shape == (4,) for d in dets)
    assert [d.score for d in dets] == sorted((d.score for d in dets), reverse=True)
    assert len(ArrangementDetector(net, score_threshold=1.0).detect(depth_images(1)[0])) == 0
    with pytest.raises(ClutterbenchError, match="takes 64x64 depth images, got 128x128"):
        detector.detect(np.zeros((128, 128), np.float32))
    with pytest.raises(ClutterbenchError, match="float32"):
        detector.detect(np.zeros((SIZE, SIZE)))


def test_checkpoint_round_trip(tmp_path):
    net = tiny_net(seed=3)
    path = tmp_path / "best.pt"
    save_detector(path, net, {"score_threshold": 0.2, "nms_iou": 0.5, "epoch": 7})
    again, meta = load_detector(path)
    assert again.cfg == CFG and meta["epoch"] == 7
    for k, v in net.state_dict().items():
        assert torch.equal(v, again.state_dict()[k]), k
    loaded = ArrangementDetector.from_checkpoint(path)
    assert (loaded.score_threshold, loaded.nms_iou) == (0.2, 0.5)
    assert ArrangementDetector.from_checkpoint(path, score_threshold=0.4).score_threshold == 0.4
    images = depth_images(2)
    direct = ArrangementDetector(net, 0.2, 0.5).raw_batch(images)
    for (b1, s1, c1), (b2, s2, c2) in zip(direct, loaded.raw_batch(images)):
        assert np.array_equal(b1, b2) and np.array_equal(s1, s2) and np.array_equal(c1, c2)
    save_detector(tmp_path / "again.pt", again, meta)
    assert (tmp_path / "again.pt").read_bytes() == path.read_bytes()  # bytes: weights + config


def test_foreign_and_broken_checkpoints_are_one_line(tmp_path):
    collapse = tmp_path / "collapse.pt"
    net = CollapseMapNet(CollapseMapConfig(input_size=64, encoder=VGGConfig(width=0.125)))
    save_checkpoint(collapse, "collapse_map", net, {})
    with pytest.raises(ClutterbenchError, match="not a clutterbench detector checkpoint"):
        ArrangementDetector.from_checkpoint(collapse)
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"truncated")
    with pytest.raises(ClutterbenchError, match="unreadable") as err:
        ArrangementDetector.from_checkpoint(broken)
    assert "\n" not in str(err.value)
    with pytest.raises(ClutterbenchError, match="not found"):
        ArrangementDetector.from_checkpoint(tmp_path / "missing.pt")
    # weights saved under another config than the one stored beside them
    payload = torch.load(collapse, weights_only=True)
    good = tmp_path / "good.pt"
    save_detector(good, tiny_net(), {})
    mixed = torch.load(good, weights_only=True) | {"state_dict": payload["state_dict"]}
    torch.save(mixed, tmp_path / "mixed.pt")
    with pytest.raises(ClutterbenchError, match="do not fit its config"):
        ArrangementDetector.from_checkpoint(tmp_path / "mixed.pt")


def arrangement(n: int = 3) -> ArrangementSet:
    """`n` scenes of two boxes on a table (depth steps for a sensor's shadows and edges)."""
    depth = np.full((n, SIZE, SIZE), 0.7, np.float32)
    depth[:, 20:40, 10:28], depth[:, 24:44, 36:54] = 0.55, 0.6
    boxes = np.array([[19.0, 30.0, 18.0, 20.0], [45.0, 34.0, 18.0, 20.0]], np.float32)
    classes = [np.array([0, 1]) for _ in range(n)]
    return ArrangementSet(np.arange(n), np.array(["random"] * n), depth, classes, [boxes] * n)


def test_ideal_sensing_is_the_parametric_noise_with_the_same_draws():
    data, idx, p = arrangement(), np.arange(3), DetectorParams(net=CFG)
    augment = p.augmentation(42.0)
    assert augment is p.noise_model
    assert dataclasses.replace(p, noise=False).augmentation(42.0) is None
    x, targets = training_batch(data, idx, p, np.random.default_rng(7), augment)
    rng, depths, boxes = np.random.default_rng(7), [], []  # the batch as before sensing
    for i in idx:
        dx, dy = rng.integers(-p.shift_px, p.shift_px + 1, size=2)
        depth, box, _ = shift_image(data.depth_m[i], data.boxes_px[i], int(dx), int(dy))
        depths.append(add_depth_noise(depth, p.noise_model, rng))
        boxes.append(box)
    assert torch.equal(x, torch.from_numpy(np.stack(depths))[:, None])
    t = heatmap_targets(data.classes, boxes, 4, SIZE // STRIDE, p.gaussian_alpha)
    assert all(np.array_equal(targets[k].numpy(), t[k]) for k in t)


def test_a_sensing_preset_passes_the_training_depth_through_the_sensor():
    data, idx = arrangement(), np.arange(3)
    ideal = DetectorParams(net=CFG, shift_px=0)
    p = dataclasses.replace(ideal, sensing=TrainSensingConfig(preset="d415"))
    augment = p.augmentation(42.0)
    assert isinstance(augment, SensedAugmentation) and augment.sensor == preset("d415")
    assert augment.fx_px == pytest.approx(focal_px(SIZE, 42.0))
    x, _ = training_batch(data, idx, p, np.random.default_rng(7), augment)
    again, _ = training_batch(data, idx, p, np.random.default_rng(7), p.augmentation(42.0))
    noised, _ = training_batch(data, idx, ideal, np.random.default_rng(7), ideal.noise_model)
    assert torch.equal(x, again) and not torch.equal(x, noised)
    x, noised, exact = x[:, 0].numpy(), noised[:, 0].numpy(), data.depth_m
    assert x.dtype == np.float32 and np.isfinite(x).all()
    holes, dropped = ((x == 0) & (exact > 0)).sum(), ((noised == 0) & (exact > 0)).sum()
    assert holes > 3 * max(dropped, 1)  # shadows and missing steps, not 0.5% dropout


def test_the_detector_records_the_sensing_it_trained_with(tmp_path, monkeypatch):
    from clutterbench.collapse import detector as module

    data = arrangement(4)
    monkeypatch.setattr(module, "_train_val_splits", lambda p, paths: (data, data, SIZE))
    paths = module.DetectorPaths(tmp_path, tmp_path, tmp_path, tmp_path, tmp_path / "t.json")
    kwargs = dict(net=CFG, epochs=1, batch_size=2, precision="fp32", channels_last=False)
    for sensing in ("ideal", "d415"):
        p = DetectorParams(**kwargs, sensing=TrainSensingConfig(preset=sensing))
        _, summary = train_detector(p, 0, paths)
        params = load_detector(tmp_path / "best.pt")[1]["params"]
        if sensing == "ideal":  # as before the switch: no field anywhere
            assert "sensing" not in summary and "sensing" not in params
        else:
            assert summary["sensing"] == {"preset": "d415", "spread": 0.2}
            assert params["sensing"] == summary["sensing"]
