"""Inference: depth + masks -> collapse heatmaps, batched over candidates.

The support-graph step (thesis 6.2.2) calls `predict_collapse` once per scene with the masks
of every object, so all targets of a scene go through the network in one or a few batches;
the ch. 4 planner passes (extraction, support) mask pairs the same way.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from clutterbench.models.checkpoint import check_compatible, load_checkpoint


def forward_logits(
    model: nn.Module,
    depth_m: torch.Tensor,
    target: torch.Tensor,
    bf16: bool = True,
    channels_last: bool = True,
) -> torch.Tensor:
    """(B, 1, H, W) depth (m) and (B, n_masks, H, W) masks -> logits, in the
    measured-fastest CPU setup (channels-last memory, bf16 autocast; reports/bench/models.md)."""
    if channels_last:
        depth_m = depth_m.contiguous(memory_format=torch.channels_last)
        target = target.contiguous(memory_format=torch.channels_last)
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        return model(depth_m, target)


def forward_probs(
    model: nn.Module,
    depth_m: torch.Tensor,
    target: torch.Tensor,
    bf16: bool = True,
    channels_last: bool = True,
) -> torch.Tensor:
    """(B, 1, H, W) depth (m) and masks -> (B, 1, H, W) float32 collapse probabilities."""
    return collapse_probs(forward_logits(model, depth_m, target, bf16, channels_last))


def collapse_probs(logits: torch.Tensor) -> torch.Tensor:
    """(B, K, H, W) logits -> (B, 1, H, W) float32 collapse probability: the sigmoid of a
    single channel, or the softmax probability of the last class (C of thesis Fig. 4.4)."""
    logits = logits.float()
    if logits.shape[1] == 1:
        return torch.sigmoid(logits)
    return torch.softmax(logits, dim=1)[:, -1:]


class CollapsePredictor:
    """A trained collapse network ready for inference (eval mode, no grad)."""

    def __init__(
        self,
        model: nn.Module,
        batch_size: int = 16,
        bf16: bool = True,
        channels_last: bool = True,
    ):
        self.model = model.eval()
        if channels_last:
            self.model = self.model.to(memory_format=torch.channels_last)
        self.batch_size, self.bf16, self.channels_last = batch_size, bf16, channels_last

    @classmethod
    def from_checkpoint(
        cls, path: Path, image_size: int | None = None, **kwargs: object
    ) -> CollapsePredictor:
        """Rebuild the network from the checkpoint alone; refuse it for other image sizes."""
        ckpt = load_checkpoint(Path(path))
        if image_size is not None:
            check_compatible(ckpt, Path(path), image_size)
        return cls(ckpt.model(), **kwargs)  # type: ignore[arg-type]

    @property
    def input_size(self) -> int:
        return int(self.model.cfg.input_size)

    @torch.no_grad()
    def __call__(self, depth_m: np.ndarray, target_masks: np.ndarray) -> np.ndarray:
        return predict_collapse(self, depth_m, target_masks)


@torch.no_grad()
def predict_collapse(
    predictor: CollapsePredictor, depth_m: np.ndarray, target_masks: np.ndarray
) -> np.ndarray:
    """Heatmaps (K, H, W) float32 in [0, 1] for one depth image (H, W) float32 metres and
    K binary target masks (K, H, W) (or K mask sets (K, n_masks, H, W), e.g. extraction and
    support): the collapse probability of each candidate action."""
    assert depth_m.dtype == np.float32 and depth_m.ndim == 2, "depth must be float32 metres, HxW"
    masks = np.asarray(target_masks)
    if masks.ndim == 3:
        masks = masks[:, None]
    if masks.ndim != 4 or masks.shape[2:] != depth_m.shape:
        h, w = depth_m.shape
        raise ValueError(f"target_masks must be (K, {h}, {w}) or (K, n_masks, {h}, {w})")
    depth = torch.from_numpy(np.ascontiguousarray(depth_m))[None, None]
    out = np.empty((len(masks), *depth_m.shape), dtype=np.float32)
    for start in range(0, len(masks), predictor.batch_size):
        chunk = torch.from_numpy(masks[start : start + predictor.batch_size].astype(np.float32))
        probs = forward_probs(
            predictor.model,
            depth.expand(len(chunk), -1, -1, -1),
            chunk,
            predictor.bf16,
            predictor.channels_last,
        )
        out[start : start + len(chunk)] = probs[:, 0].numpy()
    return out
