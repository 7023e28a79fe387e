"""Arrangement detector (thesis 5.2.1; YOLOv3 there): a compact one-stage, anchor-free
detector of object clusters in a depth image, in plain PyTorch (CenterNet-style).

Depth -> a small conv backbone (strides 2 ... 32) -> a top-down path back to stride 4 with
lateral 1x1 skips -> three heads on the stride-4 grid: a per-class centre heatmap (sigmoid),
the box size (log of pixels) and the sub-cell offset of the centre. A box is a heatmap peak:
centre (cell + offset) * stride, size exp(log size). Depth only, normalised as the collapse
networks do (models.common.normalise_depth), inside `forward`, so training and inference
cannot differ. Not a collapse network: it registers no arch and has its own checkpoint format.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from clutterbench.config import bounded
from clutterbench.models.common import (
    check_size_and_depth_range,
    conv_bn_relu,
    load_model_file,
    normalise_depth,
    save_model_file,
)

FORMAT = "clutterbench.detector/1"
STRIDE = 4
"""Output grid stride (pixels per heatmap cell)."""


@dataclasses.dataclass(frozen=True)
class DetectorConfig:
    input_size: int = bounded(128, ge=32)
    """Square input size in pixels (the dataset's sim.camera.image_size); a multiple of 32."""
    n_classes: int = bounded(4, ge=1)
    """Arrangement classes (perception.boxes.ARRANGEMENT_CLASSES)."""
    widths: tuple[int, int, int, int, int] = bounded((16, 32, 64, 96, 128), ge=1)
    """Backbone conv widths at strides 2, 4, 8, 16, 32 (two 3x3 convs each)."""
    neck_channels: int = bounded(48, ge=1)
    """Width of the top-down path and of the heads, on the stride-4 grid."""
    depth_range_m: tuple[float, float] = (0.3, 1.0)
    """Depth mapped to [-1, 1] over this range (as the collapse networks)."""

    def __post_init__(self) -> None:
        check_size_and_depth_range(self.input_size, self.depth_range_m)


class ArrangementNet(nn.Module):
    """(B, 1, S, S) depth in metres -> dict of (B, C, S/4, S/4) heatmap logits, (B, 2, ...)
    log box size in pixels (w, h) and (B, 2, ...) centre offset within the cell (x, y)."""

    def __init__(self, cfg: DetectorConfig):
        super().__init__()
        self.cfg = cfg
        stages, c = [], 1
        for w in cfg.widths:
            stages.append(nn.Sequential(conv_bn_relu(c, w, stride=2), conv_bn_relu(w, w)))
            c = w
        self.stages = nn.ModuleList(stages)
        n = cfg.neck_channels
        # lateral 1x1 convs of the stride 32, 16, 8, 4 maps; a 3x3 conv after each merge
        self.lateral = nn.ModuleList(nn.Conv2d(w, n, 1) for w in cfg.widths[:0:-1])
        self.smooth = nn.ModuleList(conv_bn_relu(n, n) for _ in cfg.widths[:0:-1])
        self.head = conv_bn_relu(n, n)
        self.heatmap = nn.Conv2d(n, cfg.n_classes, 1)
        self.size = nn.Conv2d(n, 2, 1)
        self.offset = nn.Conv2d(n, 2, 1)
        # CenterNet's prior: every cell starts at p = 0.1 of holding a centre
        nn.init.constant_(self.heatmap.bias, -2.19)

    def forward(self, depth_m: torch.Tensor) -> dict[str, torch.Tensor]:
        size = self.cfg.input_size
        if depth_m.ndim != 4 or depth_m.shape[1:] != (1, size, size):
            raise ValueError(f"depth_m must be (B, 1, {size}, {size}), got {tuple(depth_m.shape)}")
        x = normalise_depth(depth_m, *self.cfg.depth_range_m)
        feats = []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        y = None
        for lateral, smooth, f in zip(self.lateral, self.smooth, feats[:0:-1]):
            skip = lateral(f)
            y = skip if y is None else skip + F.interpolate(y, size=skip.shape[-2:], mode="nearest")
            y = smooth(y)
        y = self.head(y)
        return {"heatmap": self.heatmap(y), "size": self.size(y), "offset": self.offset(y)}


@torch.no_grad()
def decode(
    out: dict[str, torch.Tensor], score_threshold: float, max_detections: int = 50
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Network outputs -> per image (boxes (K, 4) (x, y, w, h) pixels, scores (K,), class
    indices (K,)) of the heatmap peaks (3x3 local maxima) scoring >= score_threshold, best
    first, at most `max_detections`; before non-maximum suppression."""
    heat = torch.sigmoid(out["heatmap"].float())
    peaks = heat * (F.max_pool2d(heat, 3, stride=1, padding=1) == heat)
    b, c, h, w = heat.shape
    scores, flat = peaks.reshape(b, -1).topk(min(max_detections, c * h * w), dim=1)
    result = []
    for i in range(b):
        keep = scores[i] >= score_threshold
        idx, s = flat[i][keep], scores[i][keep]
        cls, cell = idx // (h * w), idx % (h * w)
        gy, gx = cell // w, cell % w
        off = out["offset"][i].float().reshape(2, -1)[:, cell]
        wh = torch.exp(out["size"][i].float().reshape(2, -1)[:, cell].clamp(max=8.0))
        boxes = torch.stack([(gx + off[0]) * STRIDE, (gy + off[1]) * STRIDE, wh[0], wh[1]], dim=1)
        result.append(
            (
                boxes.numpy().astype(np.float64),
                s.numpy().astype(np.float64),
                cls.numpy().astype(np.int64),
            )
        )
    return result


def save_detector(path: Path, model: ArrangementNet, meta: dict[str, Any]) -> None:
    """Write atomically: format, config, training facts and weights."""
    save_model_file(path, FORMAT, model, meta)


def load_detector(path: Path) -> tuple[ArrangementNet, dict[str, Any]]:
    """(model in eval mode, meta) rebuilt from the checkpoint alone (one-line errors)."""
    return load_model_file(
        path,
        FORMAT,
        DetectorConfig,
        ArrangementNet,
        "detector checkpoint",
        "; run the detector stage first",
    )
