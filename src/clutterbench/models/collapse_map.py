"""Collapse map network / collapse predictor (thesis Fig. 5.4, Fig. 6.3) and the ch. 4
extraction / support network (thesis Fig. 4.2): one network, configured by its masks and
classes.

Depth -> VGG-16 encoder; each input mask -> its own 5 conv layers (16-32-32-32-64, BN +
ReLU, each halving the size); all meet at 1/32 of the input and a decoder of five conv
layers (each after a 2x upsampling, fed the VGG feature map of that size: the skip
connections) and one 1x1 conv gives per-pixel logits.

n_masks = 1, n_classes = 1: target mask -> collapse logit (sigmoid), thesis ch. 5 / 6.
n_masks = 2, n_classes = 4: extraction + support masks -> B / E / S / C logits (softmax),
thesis ch. 4 (classes in clutterbench.data.labels.PULL_CLASSES; collapse is the last one).
"""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from clutterbench.config import bounded
from clutterbench.models.common import (
    check_input,
    check_size_and_depth_range,
    conv_bn_relu,
    normalise_depth,
    upsample_to,
)
from clutterbench.models.vgg import VGG16Encoder, VGGConfig


@dataclasses.dataclass(frozen=True)
class CollapseMapConfig:
    input_size: int = bounded(128, ge=32)
    """Square input (and output) size in pixels; must be a multiple of 32."""
    encoder: VGGConfig = VGGConfig()
    """Depth encoder."""
    mask_channels: tuple[int, int, int, int, int] = (16, 32, 32, 32, 64)
    """Conv widths of each mask's encoder (thesis 6.2.1)."""
    n_masks: int = bounded(1, ge=1)
    """Input masks, each with its own encoder: 1 (target, ch. 5 / 6) or 2 (extraction and
    support, thesis 4.2.2)."""
    n_classes: int = bounded(1, ge=1)
    """Output channels: 1 = a collapse logit (sigmoid), > 1 = class logits (softmax) whose
    last class is collapse (thesis Fig. 4.4: B, E, S, C)."""
    decoder_channels: tuple[int, int, int, int, int] = (128, 64, 32, 16, 16)
    """Decoder conv widths, from 1/16 up to full size."""
    depth_range_m: tuple[float, float] = (0.3, 1.0)
    """Depth mapped to [-1, 1] over this range (camera 0.5 m before a 0.28 m deep shelf)."""

    def __post_init__(self) -> None:
        check_size_and_depth_range(self.input_size, self.depth_range_m)


class CollapseMapNet(nn.Module):
    def __init__(self, cfg: CollapseMapConfig):
        super().__init__()
        self.cfg = cfg
        self.depth_encoder = VGG16Encoder(cfg.encoder, in_channels=1)
        # One encoder per mask as grouped convolutions: group k sees only mask k, and its
        # output channels are that mask's features (thesis Fig. 4.2: "two masks, each with
        # five convolution layer network", concatenated). With one mask, a plain encoder
        # with the same parameter names as before (old checkpoints load).
        m, c = cfg.n_masks, cfg.n_masks
        layers = []
        for c_out in cfg.mask_channels:
            layers.append(conv_bn_relu(c, m * c_out, stride=2, groups=m))
            c = m * c_out
        self.mask_encoder = nn.Sequential(*layers)
        skips = cfg.encoder.skip_channels()  # strides 2, 4, 8, 16, 32
        c = skips[-1] + m * cfg.mask_channels[-1]
        self.decoder = nn.ModuleList()
        # Upsample to strides 16, 8, 4, 2 (concatenating that VGG map), then to full size.
        for c_out, c_skip in zip(cfg.decoder_channels, [*skips[3::-1], 0]):
            self.decoder.append(conv_bn_relu(c + c_skip, c_out))
            c = c_out
        self.head = nn.Conv2d(c, cfg.n_classes, 1)

    def forward(self, depth_m: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        """(B, 1, H, W) depth in metres and (B, n_masks, H, W) masks -> (B, n_classes, H, W)
        logits."""
        check_input(depth_m, masks, self.cfg.input_size, self.cfg.n_masks)
        feats = self.depth_encoder(normalise_depth(depth_m, *self.cfg.depth_range_m))
        x = torch.cat([feats[-1], self.mask_encoder(masks)], dim=1)
        for i, conv in enumerate(self.decoder):
            skip = feats[3 - i] if i < 4 else depth_m
            x = upsample_to(x, skip)
            x = conv(torch.cat([x, skip], dim=1) if i < 4 else x)
        return self.head(x)
