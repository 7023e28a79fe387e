"""A plain fully convolutional network: the worked example of docs/extending.md.

Depth (normalised like the other networks) and the masks, stacked as channels, go through
`layers` 3x3 conv + BN + ReLU layers at full resolution and a 1x1 conv to the logits.
"""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from clutterbench.config import bounded
from clutterbench.models import register_arch
from clutterbench.models.common import check_input, check_size_and_depth_range, normalise_depth


@dataclasses.dataclass(frozen=True)
class PlainCNNConfig:
    input_size: int = bounded(128, ge=32)
    """Square input (and output) size in pixels; a multiple of 32, as the data checks."""
    n_masks: int = bounded(1, ge=1)
    """Input masks: 1 (target, ch. 5 / 6) or 2 (extraction and support, ch. 4)."""
    n_classes: int = bounded(1, ge=1)
    """Output channels: 1 = collapse logit, 4 = B / E / S / C logits (ch. 4)."""
    width: int = bounded(32, ge=1)
    """Channels of every hidden layer."""
    layers: int = bounded(4, ge=1)
    """Hidden 3x3 conv layers."""
    depth_range_m: tuple[float, float] = (0.3, 1.0)
    """Depth mapped to [-1, 1] over this range."""

    def __post_init__(self) -> None:
        check_size_and_depth_range(self.input_size, self.depth_range_m)


class PlainCNN(nn.Module):
    def __init__(self, cfg: PlainCNNConfig):
        super().__init__()
        self.cfg = cfg  # checkpoints save it; the predictor reads cfg.input_size
        layers: list[nn.Module] = []
        c = 1 + cfg.n_masks
        for _ in range(cfg.layers):
            layers += [
                nn.Conv2d(c, cfg.width, 3, padding=1, bias=False),
                nn.BatchNorm2d(cfg.width),
                nn.ReLU(inplace=True),
            ]
            c = cfg.width
        layers.append(nn.Conv2d(c, cfg.n_classes, 1))
        self.body = nn.Sequential(*layers)

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) depth in metres, (B, n_masks, S, S) masks -> (B, n_classes, S, S)."""
        check_input(depth_m, masks, self.cfg.input_size, self.cfg.n_masks)
        x = normalise_depth(depth_m, *self.cfg.depth_range_m)
        return self.body(torch.cat([x, masks.to(x.dtype)], dim=1))


register_arch("plain_cnn", PlainCNNConfig, PlainCNN)
