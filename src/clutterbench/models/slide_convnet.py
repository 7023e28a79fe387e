"""The chapter 3 slide-success ConvNet (thesis 3.3.1, Fig. 3.4): a depth crop, rotated so the
slide points up, -> P(the slide takes the piece off the board and moves nothing else).

Four convolutional layers (Conv. 1-4, ReLU, max pooling after the first three) and two fully
connected layers of 1024 units (Fully conn. 5-6, ReLU), then two logits: success and
failure; softmax at inference (eq. 3.2). The thesis takes 227 x 227 crops (paper scale); the
default scale takes smaller ones, the same layers with narrower convolutions. Heights above
the board are scaled by `height_scale_m` inside `forward`, so training and planning cannot
differ. Not a collapse network: it registers no arch and has its own checkpoint format.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch
from torch import nn

from clutterbench.config import bounded
from clutterbench.models.common import load_model_file, save_model_file

FORMAT = "clutterbench.slide_convnet/1"
SUCCESS = 0
"""Index of the success logit (p_y1, eq. 3.2); failure is 1."""


@dataclasses.dataclass(frozen=True)
class SlideConvNetConfig:
    input_size: int = bounded(64, ge=32)
    """Square crop size in pixels (thesis 227)."""
    widths: tuple[int, int, int, int] = bounded((32, 64, 96, 96), ge=1)
    """Output channels of Conv. 1-4 (thesis Fig. 3.4 sizes at paper scale: 96, 256, 384,
    256)."""
    fc_units: int = bounded(1024, ge=1)
    """Units of Fully conn. 5 and 6 (thesis 1024)."""
    dropout: float = bounded(0.5, ge=0.0, le=0.9)
    """Dropout before each fully connected layer while training."""
    height_scale_m: float = bounded(0.05, gt=0.0)
    """Heights (metres above the board) are divided by this: ~3 piece thicknesses -> 1."""


class SlideConvNet(nn.Module):
    def __init__(self, cfg: SlideConvNetConfig):
        super().__init__()
        self.cfg = cfg
        w1, w2, w3, w4 = cfg.widths
        self.features = nn.Sequential(
            nn.Conv2d(1, w1, 5, stride=2, padding=2),  # Conv. 1
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(w1, w2, 3, padding=1),  # Conv. 2
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(w2, w3, 3, padding=1),  # Conv. 3
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(w3, w4, 3, padding=1),  # Conv. 4
            nn.ReLU(inplace=True),
            nn.AdaptiveMaxPool2d(4),
        )
        self.classifier = nn.Sequential(
            nn.Flatten(),
            nn.Dropout(cfg.dropout),
            nn.Linear(w4 * 16, cfg.fc_units),  # Fully conn. 5
            nn.ReLU(inplace=True),
            nn.Dropout(cfg.dropout),
            nn.Linear(cfg.fc_units, cfg.fc_units),  # Fully conn. 6
            nn.ReLU(inplace=True),
            nn.Linear(cfg.fc_units, 2),
        )

    def forward(self, heights_m: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) heights above the board (metres) -> (B, 2) logits [success,
        failure]."""
        size = self.cfg.input_size
        if heights_m.ndim != 4 or heights_m.shape[1:] != (1, size, size):
            raise ValueError(f"crops must be (B, 1, {size}, {size}), got {tuple(heights_m.shape)}")
        return self.classifier(self.features(heights_m / self.cfg.height_scale_m))


@torch.no_grad()
def success_probability(model: SlideConvNet, crops_m: Any, batch: int = 256) -> torch.Tensor:
    """(K,) P(success) of (K, S, S) crops (eq. 3.2), in batches."""
    x = torch.as_tensor(crops_m, dtype=torch.float32)
    out = [
        torch.softmax(model(x[i : i + batch, None]), dim=1)[:, SUCCESS]
        for i in range(0, len(x), batch)
    ]
    return torch.cat(out) if out else torch.zeros(0)


def save_slide_convnet(path: Path, model: SlideConvNet, meta: dict[str, Any]) -> None:
    save_model_file(path, FORMAT, model, meta)


def load_slide_convnet(path: Path) -> tuple[SlideConvNet, dict[str, Any]]:
    """(model in eval mode, meta) from the checkpoint alone (one-line errors)."""
    return load_model_file(
        path,
        FORMAT,
        SlideConvNetConfig,
        SlideConvNet,
        "slide ConvNet checkpoint",
        "; run the train_slide stage first",
    )
