"""What the collapse networks share: depth normalisation and the upsampling decoder block."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def normalise_depth(depth_m: torch.Tensor, near_m: float, far_m: float) -> torch.Tensor:
    """Metres -> [-1, 1] over [near, far]; missing returns (0 m) map to -1 like the near
    plane (thesis 5.2.2: "grayscale and normalized in advance")."""
    x = (depth_m.clamp(near_m, far_m) - near_m) / (far_m - near_m)
    return torch.where(depth_m > 0, 2.0 * x - 1.0, torch.full_like(x, -1.0))


def conv_bn_relu(c_in: int, c_out: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


def check_input(depth_m: torch.Tensor, target: torch.Tensor, input_size: int) -> None:
    if depth_m.ndim != 4 or depth_m.shape[1] != 1:
        raise ValueError(f"depth_m must be (B, 1, H, W), got {tuple(depth_m.shape)}")
    if target.shape != depth_m.shape:
        raise ValueError(f"target {tuple(target.shape)} must match depth {tuple(depth_m.shape)}")
    if depth_m.shape[-2:] != (input_size, input_size):
        raise ValueError(
            f"model takes {input_size}x{input_size} images, got "
            f"{depth_m.shape[-2]}x{depth_m.shape[-1]}"
        )


def upsample_to(x: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, size=like.shape[-2:], mode="bilinear", align_corners=False)
