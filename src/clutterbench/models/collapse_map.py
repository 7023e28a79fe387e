"""Collapse map network / collapse predictor (thesis Fig. 5.4, Fig. 6.3) and the ch. 4
extraction / support network (thesis Fig. 4.2): one network, configured by its masks and
classes.

Depth -> VGG-16 encoder; each input mask -> its own 5 conv layers (16-32-32-32-64, BN +
ReLU, each halving the size); all meet at 1/32 of the input and a decoder of five conv
layers (each after a 2x upsampling, fed the VGG feature map of that size: the skip
connections) and one 1x1 conv gives per-pixel logits. With `output_stride` 2 (or 4) the
decoder stops one (two) upsampling(s) early and its logits are resized (bilinear) to the
input size: the per-target convs at the largest sizes, most of a target's cost, are gone
(reports/learning_curve/designs.md compares the designs at equal training time).

n_masks = 1, n_classes = 1: target mask -> collapse logit (sigmoid), thesis ch. 5 / 6.
n_masks = 2, n_classes = 4: extraction + support masks -> B / E / S / C logits (softmax),
thesis ch. 4 (classes in clutterbench.data.labels.PULL_CLASSES; collapse is the last one).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import torch
import torch.nn.functional as F
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
    output_stride: Literal[1, 2, 4] = 1
    """1: the decoder runs up to the input size (thesis Fig. 5.4 / 6.3); 2 or 4: it stops at
    1/2 or 1/4 of it (its last one or two decoder_channels unused) and the logits are
    upsampled (bilinear)."""

    def __post_init__(self) -> None:
        check_size_and_depth_range(self.input_size, self.depth_range_m)

    @property
    def decoder_blocks(self) -> int:
        """Decoder convs run: 5 up to the input size, one fewer per halving of the output."""
        return 5 - {1: 0, 2: 1, 4: 2}[self.output_stride]


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
        blocks = zip(cfg.decoder_channels, [*skips[3::-1], 0])
        for c_out, c_skip in list(blocks)[: cfg.decoder_blocks]:
            self.decoder.append(conv_bn_relu(c + c_skip, c_out))
            c = c_out
        self.head = nn.Conv2d(c, cfg.n_classes, 1)

    encodes_scene_once = True
    """The depth encoder does not see the masks: `encode` runs once per scene and `decode`
    once per target (clutterbench.collapse.predict.grouped_logits)."""

    def encode(self, depth_m: torch.Tensor) -> list[torch.Tensor]:
        """(S, 1, H, W) depth in metres -> the VGG feature maps of each scene (strides 2 ...
        32), shared by every target of that scene."""
        return self.depth_encoder(normalise_depth(depth_m, *self.cfg.depth_range_m))

    def decode(
        self,
        feats: list[torch.Tensor],
        masks: torch.Tensor,
        scene_of: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Scene features (from `encode`) and (P, n_masks, H, W) masks -> (P, n_classes, H, W)
        logits; target p belongs to scene scene_of[p] (None: target p to scene p).

        Grouped, each decoder conv is split by its input channels (a conv of concatenated
        maps is the sum of the convs of each map): the part that reads VGG maps runs once
        per scene and is added to each of its targets, only the part that reads the mask
        features runs per target. The same function as the concatenated decoder (within
        float rounding), with the same weights."""
        if scene_of is None:
            return self._decode_pairs(feats, masks)
        x = self.mask_encoder(masks)
        scene_parts = [feats[-1]]  # the VGG head is upsampled with the mask code
        for i, block in enumerate(self.decoder):
            conv, rest = block[0], block[1:]
            size = feats[3 - i].shape[-2:] if i < 4 else masks.shape[-2:]
            pair_in = [upsample_to(x, size)]
            scene_in = [upsample_to(t, size) for t in scene_parts]
            if i < 4:
                scene_in.append(feats[3 - i])
            if i == 0:  # channel order of the concatenated decoder: [VGG head, masks, skip]
                y = _split_conv(conv, [scene_in[0], pair_in[0], scene_in[1]], [1, 0, 1], scene_of)
            elif scene_in:  # [upsampled x, skip]
                y = _split_conv(conv, [pair_in[0], scene_in[0]], [0, 1], scene_of)
            else:  # the last layer, at full size, has no skip
                y = conv(pair_in[0])
            x, scene_parts = rest(y), []
        return self._full_size(self.head(x), masks)

    def _decode_pairs(self, feats: list[torch.Tensor], masks: torch.Tensor) -> torch.Tensor:
        """The concatenated decoder, one depth image per target (thesis Fig. 5.4, 6.3)."""
        x = torch.cat([feats[-1], self.mask_encoder(masks)], dim=1)
        for i, conv in enumerate(self.decoder):
            skip = feats[3 - i] if i < 4 else masks
            x = upsample_to(x, skip.shape[-2:])
            x = conv(torch.cat([x, skip], dim=1) if i < 4 else x)
        return self._full_size(self.head(x), masks)

    def _full_size(self, logits: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
        """Logits at the input size (upsampled where output_stride > 1)."""
        if logits.shape[-2:] == masks.shape[-2:]:
            return logits
        return upsample_to(logits, masks)

    def forward(
        self,
        depth_m: torch.Tensor,
        masks: torch.Tensor,
        scene_of: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(S, 1, H, W) depth in metres and (P, n_masks, H, W) masks -> (P, n_classes, H, W)
        logits. Without `scene_of`, S = P and mask p goes with depth p; with it, mask p goes
        with depth scene_of[p] and each depth image is encoded once."""
        check_input(depth_m, masks, self.cfg.input_size, self.cfg.n_masks, scene_of)
        return self.decode(self.encode(depth_m), masks, scene_of)


def _split_conv(
    conv: nn.Conv2d, parts: list[torch.Tensor], per_scene: list[int], scene_of: torch.Tensor
) -> torch.Tensor:
    """conv(cat(parts)) for targets, where the parts flagged `per_scene` hold one map per
    scene: each part meets its slice of the kernel; the scene parts' sum is gathered to the
    targets (scene_of) and added to the target parts' sum."""
    sums: list[torch.Tensor | None] = [None, None]
    c = 0
    for part, scene in zip(parts, per_scene):
        w = conv.weight[:, c : c + part.shape[1]]
        c += part.shape[1]
        y = F.conv2d(part, w, None, conv.stride, conv.padding)
        sums[scene] = y if sums[scene] is None else sums[scene] + y
    pairs, scenes = sums
    assert pairs is not None and scenes is not None and c == conv.in_channels
    if conv.bias is not None:  # once (BatchNorm folded into the conv for inference)
        pairs = pairs + conv.bias.reshape(1, -1, 1, 1)
    return pairs + scenes.index_select(0, scene_of)
