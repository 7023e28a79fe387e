"""The arrangement detector (thesis 5.2.1): training, evaluation and inference.

Training: CenterNet's recipe on the ch5_arrangement clusters: a Gaussian per cluster centre
on its class's heatmap (focal loss), L1 on log size and centre offset at the centre cell,
AdamW with a one-cycle schedule (10% warm-up, cosine decay), depth noise and random shifts,
and NO left-right flip (a flip turns C^r into C^l, thesis 5.2.1). The epoch with the best
mAP@0.5 on the val split is kept (early stopping on it). Evaluation: VOC AP per class on
the test split, through the same `ArrangementDetector` a planner uses. Wall times go to a
timing file outside dvc's outputs, so a rerun leaves every tracked output byte-identical.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from clutterbench.collapse.config import TrainSensingConfig, depth_augmentation
from clutterbench.collapse.detection_metrics import ClassPR, Dets, Truth, mean_ap
from clutterbench.config import as_dict, bounded
from clutterbench.data.arrangement import ArrangementSet, load_arrangement_split
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.logs.csv_log import CsvLog
from clutterbench.models.common import fold_batchnorm
from clutterbench.models.detector import (
    STRIDE,
    ArrangementNet,
    DetectorConfig,
    decode,
    load_detector,
    save_detector,
)
from clutterbench.perception.boxes import ARRANGEMENT_CLASSES, Detection, nms
from clutterbench.precision import check_precision, resolve_precision
from clutterbench.progress import progress_bar
from clutterbench.sim.noise import DepthAugmentation, DepthNoiseConfig
from clutterbench.sim.sensor import sense_images

SCORE_THRESHOLD = 0.30
"""Thesis 5.2.1: confidence threshold of a detection."""
NMS_IOU = 0.45
"""Thesis 5.2.1: IoU above which the weaker of two same-class boxes is suppressed."""
LOG_COLUMNS = ("epoch", "train_loss", "val_map50", *(f"val_ap_{c}" for c in ARRANGEMENT_CLASSES))


@dataclasses.dataclass(frozen=True)
class DetectorParams:
    """The `detector` section of params.yaml."""

    dataset: str = "ch5_arrangement"
    """Generated dataset whose train split trains, val split selects and test split scores."""
    net: DetectorConfig = DetectorConfig()
    """Network (models/detector.py)."""
    batch_size: int = bounded(16, ge=1)
    """Images per step."""
    lr: float = bounded(0.002, gt=0.0)
    """AdamW peak learning rate (one cycle: warm-up from lr / 10, cosine decay to lr / 100)."""
    weight_decay: float = bounded(0.01, ge=0.0)
    """AdamW weight decay."""
    epochs: int = bounded(28, ge=1)
    """Most epochs."""
    patience: int = bounded(10, ge=1)
    """Stop after this many epochs without a better val mAP@0.5."""
    size_weight: float = bounded(1.0, ge=0.0)
    """Weight of the L1 loss on log box size (the heatmap loss has weight 1)."""
    offset_weight: float = bounded(1.0, ge=0.0)
    """Weight of the L1 loss on the centre's sub-cell offset."""
    gaussian_alpha: float = bounded(0.54, gt=0.0, le=1.0)
    """Heatmap Gaussian sigma = alpha * box side / 6 (TTFNet's elliptic Gaussian)."""
    precision: str = "auto"
    """Training under bfloat16 autocast: auto (where the CPU runs it natively, else fp32),
    fp32 or bf16 (clutterbench.precision; evaluation and inference stay float32)."""
    channels_last: bool = True
    """Channels-last memory layout while training (faster convolutions on the CPU)."""
    shift_px: int = bounded(8, ge=0)
    """Training images are shifted by up to this many pixels each way (edges repeated, boxes
    moved with them); never flipped."""
    noise: bool = True
    """Add simulated sensor noise (sim.noise) to training depth."""
    noise_model: DepthNoiseConfig = DepthNoiseConfig()
    """That noise."""
    sensing: TrainSensingConfig = TrainSensingConfig()
    """A sensor model instead of that noise, as train.sensing (ideal: the noise above)."""
    score_threshold: float = bounded(SCORE_THRESHOLD, ge=0.0, le=1.0)
    """Confidence threshold of a detection at use (thesis 5.2.1: 0.30)."""
    nms_iou: float = bounded(NMS_IOU, gt=0.0, le=1.0)
    """Per-class NMS IoU threshold (thesis 5.2.1: 0.45)."""
    eval_score_threshold: float = bounded(0.01, ge=0.0, le=1.0)
    """AP and PR curves use every detection down to this score (VOC practice)."""
    match_iou: float = bounded(0.5, gt=0.0, le=1.0)
    """A detection is correct when it overlaps an unmatched truth box of its class this much
    (mAP@0.5)."""
    max_detections: int = bounded(50, ge=1)
    """Most heatmap peaks decoded per image."""
    figure_samples: int = bounded(6, ge=1)
    """Test images in figure.png (thesis Fig. 5.3)."""

    def __post_init__(self) -> None:
        check_precision(self.precision, "detector.precision")

    def augmentation(self, fovy_deg: float) -> DepthAugmentation | None:
        """What training depth passes through: None (noise: false), noise_model, or the
        sensing preset's model (focal length: sim.camera's fovy_deg at net.input_size)."""
        return depth_augmentation(
            self.noise, self.noise_model, self.sensing, self.net.input_size, fovy_deg
        )


class ArrangementDetector:
    """Clusters of a depth image, classified C^h / C^v / C^r / C^l (thesis 5.2.1)."""

    def __init__(
        self,
        model: ArrangementNet,
        score_threshold: float = SCORE_THRESHOLD,
        nms_iou: float = NMS_IOU,
        max_detections: int = 50,
    ):
        self.cfg = model.cfg
        self.model = fold_batchnorm(model)  # an eval-mode copy with BN folded into the convs
        self.score_threshold, self.nms_iou = score_threshold, nms_iou
        self.max_detections = max_detections

    @classmethod
    def from_checkpoint(cls, path: Path, **overrides: float) -> ArrangementDetector:
        """The detector saved by the detector stage, with the thresholds it was evaluated
        with (params detector.score_threshold, nms_iou) unless overridden."""
        model, meta = load_detector(Path(path))
        kwargs = {k: meta[k] for k in ("score_threshold", "nms_iou", "max_detections") if k in meta}
        return cls(model, **(kwargs | overrides))

    def detect(self, depth_m: np.ndarray, score_threshold: float | None = None) -> list[Detection]:
        """Detections of one (H, W) float32 depth image in metres, best first."""
        return self.detect_batch(np.asarray(depth_m)[None], score_threshold)[0]

    def detect_batch(
        self, depth_m: np.ndarray, score_threshold: float | None = None
    ) -> list[list[Detection]]:
        """detect() of each of (B, H, W) images."""
        dets = self.raw_batch(depth_m, score_threshold)
        return [
            [Detection(ARRANGEMENT_CLASSES[int(c)], b, float(s)) for b, s, c in zip(*d)]
            for d in dets
        ]

    def raw_batch(self, depth_m: np.ndarray, score_threshold: float | None = None) -> list[Dets]:
        """Per image (boxes (K, 4), scores (K,), class indices (K,)) after per-class NMS."""
        size = self.cfg.input_size
        if depth_m.dtype != np.float32 or depth_m.ndim != 3:
            raise ClutterbenchError("depth must be (B, H, W) or (H, W) float32 metres")
        if depth_m.shape[1:] != (size, size):
            raise ClutterbenchError(
                f"the detector takes {size}x{size} depth images, got "
                f"{depth_m.shape[1]}x{depth_m.shape[2]}; retrain it at this image size"
            )
        threshold = self.score_threshold if score_threshold is None else score_threshold
        with torch.no_grad():
            out = self.model(torch.from_numpy(np.ascontiguousarray(depth_m))[:, None])
        result = []
        for boxes, scores, classes in decode(out, threshold, self.max_detections):
            keep = nms(boxes, scores, classes, self.nms_iou)
            result.append((boxes[keep], scores[keep], classes[keep]))
        return result


# -- training targets and loss ----------------------------------------------------------------
def heatmap_targets(
    classes: Sequence[np.ndarray],
    boxes_px: Sequence[np.ndarray],
    n_classes: int,
    grid: int,
    alpha: float,
) -> dict[str, np.ndarray]:
    """Dense targets on the stride-4 grid: heatmap (S, C, G, G) with an elliptic Gaussian
    (sigma = alpha * side / 6, in cells) peaking at 1 on each cluster's centre cell, and at
    those cells log size (S, 2, G, G), offset (S, 2, G, G) and a mask (S, G, G)."""
    s = len(classes)
    heat = np.zeros((s, n_classes, grid, grid), np.float32)
    size = np.zeros((s, 2, grid, grid), np.float32)
    offset = np.zeros((s, 2, grid, grid), np.float32)
    mask = np.zeros((s, grid, grid), np.float32)
    ys, xs = np.mgrid[0:grid, 0:grid].astype(np.float32)
    for i, (cls, boxes) in enumerate(zip(classes, boxes_px)):
        for c, (x, y, w, h) in zip(cls, boxes):
            cx, cy = min(int(x / STRIDE), grid - 1), min(int(y / STRIDE), grid - 1)
            sx = max(alpha * w / STRIDE / 6, 0.5)
            sy = max(alpha * h / STRIDE / 6, 0.5)
            g = np.exp(-((xs - cx) ** 2) / (2 * sx**2) - (ys - cy) ** 2 / (2 * sy**2))
            np.maximum(heat[i, c], g, out=heat[i, c])
            size[i, :, cy, cx] = np.log([w, h])
            offset[i, :, cy, cx] = (x / STRIDE - cx, y / STRIDE - cy)
            mask[i, cy, cx] = 1.0
    return {"heatmap": heat, "size": size, "offset": offset, "mask": mask}


def focal_heatmap_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """CenterNet's penalty-reduced focal loss (alpha 2, beta 4), per centre."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = target.eq(1.0).float()
    pos_loss = -torch.log(p) * (1 - p) ** 2 * pos
    neg_loss = -torch.log(1 - p) * p**2 * (1 - target) ** 4 * (1 - pos)
    return (pos_loss.sum() + neg_loss.sum()) / pos.sum().clamp(min=1.0)


def detector_loss(
    out: dict[str, torch.Tensor], t: dict[str, torch.Tensor], p: DetectorParams
) -> torch.Tensor:
    mask = t["mask"][:, None]
    n = mask.sum().clamp(min=1.0)
    size = (F.l1_loss(out["size"], t["size"], reduction="none") * mask).sum() / n
    offset = (F.l1_loss(out["offset"], t["offset"], reduction="none") * mask).sum() / n
    heat = focal_heatmap_loss(out["heatmap"], t["heatmap"])
    return heat + p.size_weight * size + p.offset_weight * offset


def shift_image(
    depth_m: np.ndarray, boxes_px: np.ndarray, dx: int, dy: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(depth, boxes, kept) of an image moved by (dx, dy) pixels: the edges are repeated
    into the uncovered side, each box moves along and is cut at the image border; a box
    keeping under half of its area is dropped (kept: (K,) bool)."""
    h, w = depth_m.shape
    m = max(abs(dx), abs(dy))
    padded = np.pad(depth_m, m, mode="edge")
    out = padded[m - dy : m - dy + h, m - dx : m - dx + w]
    x0y0 = boxes_px[:, :2] - boxes_px[:, 2:] / 2 + (dx, dy)
    x1y1 = x0y0 + boxes_px[:, 2:]
    c0, c1 = np.clip(x0y0, 0, (w, h)), np.clip(x1y1, 0, (w, h))
    kept = np.prod(c1 - c0, axis=1) >= 0.5 * np.prod(boxes_px[:, 2:], axis=1)
    moved = np.concatenate([(c0 + c1) / 2, c1 - c0], axis=1).astype(np.float32)
    return np.ascontiguousarray(out), moved[kept], kept


def training_batch(
    data: ArrangementSet,
    idx: np.ndarray,
    p: DetectorParams,
    rng: np.random.Generator,
    augment: DepthAugmentation | None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Depth (B, 1, H, W) and targets of scenes `idx`, augmented: shifted by up to
    p.shift_px, then through `augment` (p.augmentation: the noise or a sensor model); no
    flip (it would swap C^r and C^l)."""
    depths, classes, boxes = [], [], []
    for i in idx:
        depth, cls, box = data.depth_m[i], data.classes[i], data.boxes_px[i]
        if p.shift_px > 0:
            dx, dy = rng.integers(-p.shift_px, p.shift_px + 1, size=2)
            depth, box, kept = shift_image(depth, box, int(dx), int(dy))
            cls = cls[kept]
        if augment is not None:
            depth = augment.apply(depth, rng)
        depths.append(depth)
        classes.append(cls)
        boxes.append(box)
    grid = data.depth_m.shape[-1] // STRIDE
    targets = heatmap_targets(classes, boxes, p.net.n_classes, grid, p.gaussian_alpha)
    x = torch.from_numpy(np.stack(depths))[:, None]
    return x, {k: torch.from_numpy(v) for k, v in targets.items()}


# -- evaluation -------------------------------------------------------------------------------
def truth_of(data: ArrangementSet) -> list[Truth]:
    return [(b.astype(np.float64), c) for b, c in zip(data.boxes_px, data.classes)]


def detect_all(
    detector: ArrangementDetector, data: ArrangementSet, score_threshold: float, batch: int = 32
) -> list[Dets]:
    out: list[Dets] = []
    for lo in range(0, len(data), batch):
        out += detector.raw_batch(data.depth_m[lo : lo + batch], score_threshold)
    return out


def _finite(x: float) -> float | None:
    """NaN (no ground truth) as JSON null."""
    return None if np.isnan(x) else float(x)


def ap_summary(prs: list[ClassPR], map50: float, score_threshold: float) -> dict[str, Any]:
    """mAP and, per class, AP, truth count and precision / recall at `score_threshold`."""
    per_class = {}
    for name, pr in zip(ARRANGEMENT_CLASSES, prs):
        precision, recall = pr.at_score(score_threshold)
        per_class[name] = {
            "ap50": _finite(pr.ap()),
            "n_truth": pr.n_truth,
            "precision_at_threshold": precision,
            "recall_at_threshold": _finite(recall),
        }
    return {"map50": _finite(map50), "per_class": per_class}


# -- training ---------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class DetectorPaths:
    gen_dir: Path
    split_file: Path
    model_dir: Path
    """models/detector/: best.pt."""
    report_dir: Path
    """reports/detector/: log.csv, metrics.json, pr.csv, pr.png, figure.png."""
    timing_file: Path
    """Wall times (JSON); vary run to run, so kept out of dvc's outputs."""


def detector_seed(base_seed: int, dataset: str) -> int:
    return (base_seed * 1_000_003 + zlib.crc32(f"detector/{dataset}".encode())) % 2**31


def train_detector(
    p: DetectorParams, base_seed: int, paths: DetectorPaths, fovy_deg: float = 42.0
) -> tuple[ArrangementDetector, dict[str, Any]]:
    """Train on the train split, keep the best val-mAP epoch (val images as detector.sensing
    returns them); returns (its detector, the training summary). `fovy_deg`: sim.camera's."""
    train, val, size = _train_val_splits(p, paths)
    val_depth = sense_images(val.depth_m, p.sensing.preset, fovy_deg, base_seed)  # ideal: as is
    val = dataclasses.replace(val, depth_m=val_depth)
    seed = detector_seed(base_seed, p.dataset)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    augment = p.augmentation(fovy_deg)
    precision = resolve_precision(p.precision)
    bf16 = precision == "bf16"
    model = ArrangementNet(p.net)
    if p.channels_last:
        model = model.to(memory_format=torch.channels_last)
    opt, schedule = _optimizer(model, p, len(train))
    log = CsvLog(paths.report_dir / "log.csv", LOG_COLUMNS)
    meta = {
        "dataset": p.dataset,
        "image_size": size,
        "precision": precision,
        "classes": list(ARRANGEMENT_CLASSES),
        "seed": seed,
        "score_threshold": p.score_threshold,
        "nms_iou": p.nms_iou,
        "max_detections": p.max_detections,
        "params": as_dict(dataclasses.replace(p, net={})),
    }
    if p.sensing.preset == "ideal":  # default checkpoints stay byte for byte as before
        del meta["params"]["sensing"]
    best: dict[str, Any] = {"epoch": 0}
    best_score = -1.0
    stale, started, epoch_s = 0, time.perf_counter(), []
    for epoch in range(1, p.epochs + 1):
        t0 = time.perf_counter()
        total = _train_epoch(model, opt, schedule, train, p, rng, augment, bf16, epoch)
        row, val_map = _val_row(model, val, p, epoch, total / len(train))
        log.append(row)
        epoch_s.append(round(time.perf_counter() - t0, 1))
        print(f"detector epoch {epoch}: loss {row['train_loss']:.4f} val mAP@0.5 {val_map:.3f}")
        score = 0.0 if np.isnan(val_map) else val_map  # NaN: no val clusters (tiny runs)
        if score > best_score:
            best_score = score
            best = {"epoch": epoch} | {k: _finite(v) for k, v in row.items() if k[:4] == "val_"}
            save_detector(paths.model_dir / "best.pt", model, meta | {"epoch": epoch})
            stale = 0
        else:
            stale += 1
            if stale >= p.patience:
                break
    train_s = time.perf_counter() - started
    summary = {
        "epochs_run": epoch,
        "stopped_early": epoch < p.epochs,
        "best": best,
        "train_images": len(train),
        "val_images": len(val),
        "parameters": sum(t.numel() for t in model.parameters()),
        "precision": precision,
    }
    if p.noise and p.sensing.preset != "ideal":  # the sensor its images passed through
        summary["sensing"] = {"preset": p.sensing.preset, "spread": p.sensing.spread}
    write_json(paths.timing_file, {"stage": "detector", "train_s": train_s, "epoch_s": epoch_s})
    return ArrangementDetector.from_checkpoint(paths.model_dir / "best.pt"), summary


def _train_val_splits(
    p: DetectorParams, paths: DetectorPaths
) -> tuple[ArrangementSet, ArrangementSet, int]:
    """The train and val splits (neither empty, at the network's input size) and that size."""
    train = load_arrangement_split(paths.gen_dir, paths.split_file, "train")
    val = load_arrangement_split(paths.gen_dir, paths.split_file, "val")
    for name, part in (("train", train), ("val", val)):
        if len(part) == 0:
            raise ClutterbenchError(f"detector: dataset '{p.dataset}' has no {name} scenes")
    size = train.depth_m.shape[-1]
    if train.depth_m.shape[-2:] != (p.net.input_size, p.net.input_size):
        raise ClutterbenchError(
            f"detector.net.input_size is {p.net.input_size} but dataset '{p.dataset}' has "
            f"{train.depth_m.shape[-2]}x{size} images (sim.camera.image_size)"
        )
    return train, val, size


def _optimizer(
    model: ArrangementNet, p: DetectorParams, n_train: int
) -> tuple[torch.optim.AdamW, torch.optim.lr_scheduler.OneCycleLR]:
    """AdamW and its one-cycle schedule over every step of p.epochs."""
    opt = torch.optim.AdamW(model.parameters(), lr=p.lr, weight_decay=p.weight_decay)
    steps_per_epoch = -(-n_train // p.batch_size)
    schedule = torch.optim.lr_scheduler.OneCycleLR(
        opt,
        max_lr=p.lr,
        total_steps=p.epochs * steps_per_epoch,
        pct_start=0.1,
        div_factor=10.0,
        final_div_factor=10.0,
    )
    return opt, schedule


def _train_epoch(
    model: ArrangementNet,
    opt: torch.optim.AdamW,
    schedule: torch.optim.lr_scheduler.OneCycleLR,
    train: ArrangementSet,
    p: DetectorParams,
    rng: np.random.Generator,
    augment: DepthAugmentation | None,
    bf16: bool,
    epoch: int,
) -> float:
    """One pass over the train split in shuffled batches; returns the summed loss (each
    batch's mean loss times its size)."""
    model.train()
    order = rng.permutation(len(train))
    total = 0.0
    with progress_bar(f"detector epoch {epoch}", total=len(train)) as advance:
        for lo in range(0, len(order), p.batch_size):
            idx = np.sort(order[lo : lo + p.batch_size])
            x, targets = training_batch(train, idx, p, rng, augment)
            if p.channels_last:
                x = x.contiguous(memory_format=torch.channels_last)
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
                out = model(x)
            out = {k: v.float() for k, v in out.items()}
            loss = detector_loss(out, targets, p)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            schedule.step()
            total += float(loss.detach()) * len(idx)
            advance(len(idx))
    return total


def _val_row(
    model: ArrangementNet, val: ArrangementSet, p: DetectorParams, epoch: int, train_loss: float
) -> tuple[dict[str, Any], float]:
    """The epoch's log row (its val mAP@0.5 and per-class AP) and that mAP."""
    detector = ArrangementDetector(model.eval(), p.score_threshold, p.nms_iou, p.max_detections)
    val_map, prs = mean_ap(
        detect_all(detector, val, p.eval_score_threshold),
        truth_of(val),
        p.net.n_classes,
        p.match_iou,
    )
    row = {"epoch": epoch, "train_loss": train_loss, "val_map50": val_map}
    row |= {f"val_ap_{c}": pr.ap() for c, pr in zip(ARRANGEMENT_CLASSES, prs)}
    return row, val_map


def evaluate_detector(
    detector: ArrangementDetector, test: ArrangementSet, p: DetectorParams
) -> tuple[dict[str, Any], list[ClassPR], list[Dets]]:
    """(metrics, per-class PR, detections at the thesis threshold) on `test`."""
    dets = detect_all(detector, test, p.eval_score_threshold)
    truth = truth_of(test)
    map50, prs = mean_ap(dets, truth, p.net.n_classes, p.match_iou)
    metrics = ap_summary(prs, map50, p.score_threshold)
    # per scene family: the trials_ch5 streams are single families (stacked, shelved, ...)
    metrics["per_family"] = {}
    for family in sorted(set(test.family.tolist())):
        sel = np.nonzero(test.family == family)[0]
        fam_map, fam_prs = mean_ap(
            [dets[i] for i in sel], [truth[i] for i in sel], p.net.n_classes, p.match_iou
        )
        metrics["per_family"][family] = {
            "images": len(sel),
            "map50": _finite(fam_map),
            "ap50": {c: _finite(pr.ap()) for c, pr in zip(ARRANGEMENT_CLASSES, fam_prs)},
            "n_truth": {c: pr.n_truth for c, pr in zip(ARRANGEMENT_CLASSES, fam_prs)},
        }
    at_threshold = [
        (b[s >= p.score_threshold], s[s >= p.score_threshold], c[s >= p.score_threshold])
        for b, s, c in dets
    ]
    return metrics, prs, at_threshold
