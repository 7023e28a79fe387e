"""FCN-8s-style baseline (Long et al.; thesis Table 5.1, first row).

Same inputs as the collapse map network, depth and masks stacked as channels into one
VGG-16; fc6/fc7 as convolutions; class scores from pool5, pool4 and pool3 fused by 2x, 2x,
8x upsampling.
"""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from clutterbench.config import bounded
from clutterbench.models.common import (
    check_input,
    check_size_and_depth_range,
    normalise_depth,
    upsample_to,
)
from clutterbench.models.vgg import VGG16Encoder, VGGConfig


@dataclasses.dataclass(frozen=True)
class FCN8sConfig:
    input_size: int = bounded(128, ge=32)
    """Square input (and output) size in pixels; must be a multiple of 32."""
    encoder: VGGConfig = VGGConfig()
    """Backbone over the stacked (depth, masks) input."""
    fc_channels: int = bounded(1024, ge=1)
    """Width of fc6 / fc7 (4096 in FCN-8s)."""
    fc_kernel: int = bounded(3, ge=1)
    """fc6 kernel size (7 in FCN-8s, where pool5 is 7x7; our pool5 is input_size / 32)."""
    dropout: float = bounded(0.5, ge=0.0, le=1.0)
    """Dropout after fc6 and fc7, as in FCN."""
    depth_range_m: tuple[float, float] = (0.3, 1.0)
    """Depth mapped to [-1, 1] over this range."""
    n_masks: int = bounded(1, ge=1)
    """Input masks, stacked after depth (as CollapseMapConfig.n_masks)."""
    n_classes: int = bounded(1, ge=1)
    """Output channels (as CollapseMapConfig.n_classes)."""

    def __post_init__(self) -> None:
        check_size_and_depth_range(self.input_size, self.depth_range_m)
        if self.fc_kernel % 2 == 0:
            raise ValueError("fc_kernel: must be odd")


class FCN8s(nn.Module):
    def __init__(self, cfg: FCN8sConfig):
        super().__init__()
        self.cfg = cfg
        self.backbone = VGG16Encoder(cfg.encoder, in_channels=1 + cfg.n_masks)
        skips = cfg.encoder.skip_channels()
        k = cfg.fc_kernel
        self.fc = nn.Sequential(
            nn.Conv2d(skips[4], cfg.fc_channels, k, padding=k // 2),
            nn.ReLU(inplace=True),
            nn.Dropout2d(cfg.dropout),
            nn.Conv2d(cfg.fc_channels, cfg.fc_channels, 1),
            nn.ReLU(inplace=True),
            nn.Dropout2d(cfg.dropout),
            nn.Conv2d(cfg.fc_channels, cfg.n_classes, 1),
        )
        self.score_pool4 = nn.Conv2d(skips[3], cfg.n_classes, 1)
        self.score_pool3 = nn.Conv2d(skips[2], cfg.n_classes, 1)

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        """(B, 1, H, W) depth in metres and (B, n_masks, H, W) masks -> (B, n_classes, H, W)
        logits."""
        check_input(depth_m, masks, self.cfg.input_size, self.cfg.n_masks)
        x = torch.cat([normalise_depth(depth_m, *self.cfg.depth_range_m), masks], dim=1)
        feats = self.backbone(x)
        score = self.fc(feats[4])
        score = upsample_to(score, feats[3]) + self.score_pool4(feats[3])
        score = upsample_to(score, feats[2]) + self.score_pool3(feats[2])
        return upsample_to(score, depth_m)
