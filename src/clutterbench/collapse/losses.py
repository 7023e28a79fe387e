"""Per-pixel losses on collapse logits (one channel) and class logits (thesis ch. 4)."""

from __future__ import annotations

import dataclasses

import torch
import torch.nn.functional as F

from clutterbench.config import bounded


@dataclasses.dataclass(frozen=True)
class FocalConfig:
    alpha_pos: float = bounded(0.25, ge=0.0, le=1.0)
    """alpha_1: weight of collapse pixels (thesis 6.2.1)."""
    alpha_neg: float = bounded(0.75, ge=0.0, le=1.0)
    """alpha_0: weight of background / non-collapse pixels."""
    gamma: float = bounded(2.0, ge=0.0)
    """Focusing exponent."""


def focal_loss(logits: torch.Tensor, target: torch.Tensor, cfg: FocalConfig) -> torch.Tensor:
    """Mean over pixels of L(y) = -alpha_y (1 - y)^gamma log(y), thesis eq. (6.1), where y is
    the predicted probability of the true label (RetinaNet's p_t)."""
    logits, target = logits.float(), target.float()
    log_pt = -F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    alpha = torch.where(target > 0.5, cfg.alpha_pos, cfg.alpha_neg)
    return (-alpha * (1.0 - log_pt.exp()).pow(cfg.gamma) * log_pt).mean()


def bce_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy, mean over pixels (the ch. 5 collapse map network)."""
    return F.binary_cross_entropy_with_logits(logits.float(), target.float())


def ce_loss(logits: torch.Tensor, classes: torch.Tensor) -> torch.Tensor:
    """Softmax cross-entropy, mean over pixels: (B, K, H, W) logits, (B, H, W) class labels
    (the ch. 4 network's B / E / S / C map; the thesis names no loss, CE is the FCN's)."""
    return F.cross_entropy(logits.float(), classes.long())
