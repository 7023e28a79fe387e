"""VGG-16 encoder (Simonyan & Zisserman, configuration "D"), plain PyTorch.

Thesis 5.2.2 / 6.2.1: the scene encoder is VGG-16 up to its last convolutional block. Here
the channel counts scale with a width multiplier so that the default CPU profile can train
it; width 1.0 is the real VGG-16 and can load a local torchvision-format weights file.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch
from torch import nn

from clutterbench.config import bounded
from clutterbench.errors import ClutterbenchError
from clutterbench.models.common import load_torch_file

# Configuration "D": 13 conv layers in 5 blocks, each block ends in a 2x2 max-pool.
VGG16_BLOCKS: tuple[tuple[int, ...], ...] = (
    (64, 64),
    (128, 128),
    (256, 256, 256),
    (512, 512, 512),
    (512, 512, 512),
)
FROZEN_WITH_PRETRAINED = 10
"""Thesis 6.2.1: the first ten conv layers stay fixed when ImageNet weights are loaded."""


@dataclasses.dataclass(frozen=True)
class VGGConfig:
    width: float = bounded(0.25, gt=0.0, le=1.0)
    """Channel multiplier on every VGG-16 layer (1.0 = the real network)."""
    batch_norm: bool = True
    """BatchNorm after each conv: needed to train the deep encoder from scratch."""
    pretrained: str | None = None
    """Local torchvision-format VGG-16 state dict (.pth); freezes the first ten convs."""

    def __post_init__(self) -> None:
        if self.pretrained is not None and self.width != 1.0:
            raise ValueError("pretrained: VGG-16 weights need width 1.0")

    def channels(self, c: int) -> int:
        return max(4, round(c * self.width))

    @property
    def out_channels(self) -> int:
        return self.channels(VGG16_BLOCKS[-1][-1])

    def skip_channels(self) -> list[int]:
        """Channels after pool1..pool5 (strides 2, 4, 8, 16, 32)."""
        return [self.channels(block[-1]) for block in VGG16_BLOCKS]


class VGG16Encoder(nn.Module):
    """Returns the feature maps after each of the five pools (strides 2 ... 32)."""

    def __init__(self, cfg: VGGConfig, in_channels: int = 1):
        super().__init__()
        self.cfg = cfg
        self.blocks = nn.ModuleList()
        c_in = in_channels
        for block in VGG16_BLOCKS:
            layers: list[nn.Module] = []
            for c in block:
                c_out = cfg.channels(c)
                layers.append(nn.Conv2d(c_in, c_out, 3, padding=1, bias=not cfg.batch_norm))
                if cfg.batch_norm:
                    layers.append(nn.BatchNorm2d(c_out))
                layers.append(nn.ReLU(inplace=True))
                c_in = c_out
            layers.append(nn.MaxPool2d(2))
            self.blocks.append(nn.Sequential(*layers))
        if cfg.pretrained is not None:
            load_vgg16_weights(self, Path(cfg.pretrained))

    def convs(self) -> list[nn.Conv2d]:
        return [m for m in self.modules() if isinstance(m, nn.Conv2d)]

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = []
        for block in self.blocks:
            x = block(x)
            feats.append(x)
        return feats


def load_vgg16_weights(encoder: VGG16Encoder, path: Path) -> None:
    """Copy the 13 conv layers of a torchvision `vgg16` state dict into `encoder`.

    RGB first-layer filters are summed over colour for our one-channel depth input (a
    grey image x replicated to RGB gives the same response). The first ten convs are then
    frozen, as in thesis 6.2.1.
    """
    state = load_torch_file(path, "pretrained VGG-16 weights")
    # Conv kernels are the 4-D "features.N.weight" tensors (vgg16_bn also has 1-D BN ones).
    weights = sorted(
        (
            k
            for k in state
            if k.startswith("features.") and k.endswith(".weight") and state[k].ndim == 4
        ),
        key=lambda k: int(k.split(".")[1]),
    )
    convs = encoder.convs()
    if len(weights) != len(convs):
        raise ClutterbenchError(
            f"{path}: expected {len(convs)} VGG-16 conv layers, found {len(weights)}"
        )
    with torch.no_grad():
        for i, (key, conv) in enumerate(zip(weights, convs)):
            w = state[key]
            if i == 0 and w.shape[1] != conv.in_channels:
                w = w.sum(dim=1, keepdim=True).expand(-1, conv.in_channels, -1, -1)
            if w.shape != conv.weight.shape:
                raise ClutterbenchError(f"{path}: {key} has shape {tuple(w.shape)}")
            conv.weight.copy_(w)
            bias_key = key[: -len("weight")] + "bias"
            if conv.bias is not None and bias_key in state:
                conv.bias.copy_(state[bias_key])
    for conv in convs[:FROZEN_WITH_PRETRAINED]:
        conv.requires_grad_(False)
