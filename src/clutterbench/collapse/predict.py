"""Inference: depth + masks -> collapse heatmaps, batched over candidates.

The support-graph step (thesis 6.2.2) calls `predict_collapse` once per scene with the masks
of every object, so the scene's depth image is encoded once and its targets go through the
mask encoder and decoder in one or a few batches; the ch. 4 planner passes (extraction,
support) mask pairs the same way (`scene_logits`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from clutterbench.models.checkpoint import check_compatible, head_channel, load_checkpoint
from clutterbench.models.common import fold_batchnorm
from clutterbench.precision import inference_precision, resolve_precision


def forward_logits(
    model: nn.Module,
    depth_m: torch.Tensor,
    target: torch.Tensor,
    bf16: bool = True,
    channels_last: bool = True,
    scene_of: torch.Tensor | None = None,
) -> torch.Tensor:
    """(S, 1, H, W) depth (m) and (P, n_masks, H, W) masks -> (P, K, H, W) logits, in the
    measured-fastest CPU setup (channels-last memory; bf16 autocast where the CPU runs it
    natively: clutterbench.precision, reports/bench/models.md).

    Without `scene_of` mask p goes with depth p (S = P). With it, mask p goes with depth
    scene_of[p]: a network that `encodes_scene_once` encodes each depth image once for all
    its targets, any other network sees each pair's depth image as before."""
    if scene_of is not None and not getattr(model, "encodes_scene_once", False):
        depth_m, scene_of = depth_m.index_select(0, scene_of), None
    if channels_last:
        depth_m = depth_m.contiguous(memory_format=torch.channels_last)
        target = target.contiguous(memory_format=torch.channels_last)
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
        if scene_of is None:
            return model(depth_m, target)
        return model(depth_m, target, scene_of)


def forward_probs(
    model: nn.Module,
    depth_m: torch.Tensor,
    target: torch.Tensor,
    bf16: bool = True,
    channels_last: bool = True,
    scene_of: torch.Tensor | None = None,
    channel: int | None = None,
) -> torch.Tensor:
    """Depth (m) and masks as `forward_logits` -> (P, 1, H, W) float32 collapse
    probabilities (of output channel `channel` of a multi-head network: `collapse_probs`)."""
    logits = forward_logits(model, depth_m, target, bf16, channels_last, scene_of)
    return collapse_probs(logits, channel)


def collapse_probs(logits: torch.Tensor, channel: int | None = None) -> torch.Tensor:
    """(B, K, H, W) logits -> (B, 1, H, W) float32 collapse probability: the sigmoid of a
    single channel, or the softmax probability of the last class (C of thesis Fig. 4.4);
    with `channel`, the sigmoid of that channel (one head of a network with one sigmoid
    channel per label kind, train.models.<m>.labels)."""
    logits = logits.float()
    if channel is not None:
        return torch.sigmoid(logits[:, channel : channel + 1])
    if logits.shape[1] == 1:
        return torch.sigmoid(logits)
    return torch.softmax(logits, dim=1)[:, -1:]


class CollapsePredictor:
    """A trained collapse network ready for inference (eval mode, no grad).

    `precision` auto / fp32 / bf16 (clutterbench.precision); None takes the process's
    inference precision (params' inference.precision as set by the stage, else auto).
    `channel`: the output channel of the head it answers for, on a network with several
    (`from_checkpoint(head=...)`); None: the network's one collapse output."""

    def __init__(
        self,
        model: nn.Module,
        batch_size: int = 16,
        precision: str | None = None,
        channels_last: bool = True,
        encode_once: bool = True,
        fold_bn: bool = True,
        channel: int | None = None,
        head: str = "deletion",
    ):
        self.model = fold_batchnorm(model) if fold_bn else model.eval()
        if channels_last:
            self.model = self.model.to(memory_format=torch.channels_last)
        self.precision = (
            inference_precision() if precision is None else resolve_precision(precision)
        )
        """The precision used: fp32 or bf16."""
        self.bf16 = self.precision == "bf16"
        self.batch_size, self.channels_last = batch_size, channels_last
        self.encode_once = encode_once
        self.channel, self.head = channel, head
        """The head's output channel (None: the one collapse output) and its label kind."""
        self.seconds = 0.0
        """Wall time spent in `scene_logits` so far (the collapse prediction's share)."""

    @classmethod
    def from_checkpoint(
        cls, path: Path, image_size: int | None = None, head: str = "deletion", **kwargs: object
    ) -> CollapsePredictor:
        """Rebuild the network from the checkpoint alone, answering for its head `head`
        (deletion or pull: models.checkpoint.checkpoint_heads); refuse it for other image
        sizes, and where it has no such head."""
        ckpt = load_checkpoint(Path(path))
        if image_size is not None:
            check_compatible(ckpt, Path(path), image_size)
        channel = head_channel(ckpt, Path(path), head)
        return cls(ckpt.model(), channel=channel, head=head, **kwargs)  # type: ignore[arg-type]

    @property
    def input_size(self) -> int:
        return int(self.model.cfg.input_size)

    @torch.no_grad()
    def __call__(self, depth_m: np.ndarray, target_masks: np.ndarray) -> np.ndarray:
        return predict_collapse(self, depth_m, target_masks)


@torch.no_grad()
def scene_logits(
    predictor: CollapsePredictor, depth_m: np.ndarray, masks: np.ndarray
) -> torch.Tensor:
    """One depth image (H, W) float32 metres and K candidate mask sets (K, n_masks, H, W) ->
    (K, n_classes, H, W) logits, in batches of the predictor's batch size. A network that
    `encodes_scene_once` encodes the depth image once for all K candidates and runs only its
    mask encoders and decoder per candidate."""
    assert depth_m.dtype == np.float32 and depth_m.ndim == 2, "depth must be float32 metres, HxW"
    if masks.ndim != 4 or masks.shape[2:] != depth_m.shape:
        h, w = depth_m.shape
        raise ValueError(f"target_masks must be (K, {h}, {w}) or (K, n_masks, {h}, {w})")
    started = time.perf_counter()
    model, bf16, channels_last = predictor.model, predictor.bf16, predictor.channels_last
    memory = torch.channels_last if channels_last else torch.contiguous_format
    depth = torch.from_numpy(np.ascontiguousarray(depth_m))[None, None]
    feats = None
    # One candidate: nothing to share, and the concatenated decoder is the faster one.
    if predictor.encode_once and len(masks) > 1 and getattr(model, "encodes_scene_once", False):
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            feats = model.encode(depth.contiguous(memory_format=memory))
    out = []
    for start in range(0, len(masks), predictor.batch_size):
        chunk = torch.from_numpy(masks[start : start + predictor.batch_size].astype(np.float32))
        if feats is None:  # one depth image per candidate
            d = depth.expand(len(chunk), -1, -1, -1)
            out.append(forward_logits(model, d, chunk, bf16, channels_last))
            continue
        scene_of = torch.zeros(len(chunk), dtype=torch.int64)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out.append(model.decode(feats, chunk.contiguous(memory_format=memory), scene_of))
    channels = int(getattr(getattr(model, "cfg", None), "n_classes", 1))
    logits = torch.cat(out) if out else torch.zeros((0, channels, *depth_m.shape))
    predictor.seconds += time.perf_counter() - started
    return logits


def predict_collapse(
    predictor: CollapsePredictor, depth_m: np.ndarray, target_masks: np.ndarray
) -> np.ndarray:
    """Heatmaps (K, H, W) float32 in [0, 1] for one depth image (H, W) float32 metres and
    K binary target masks (K, H, W) (or K mask sets (K, n_masks, H, W), e.g. extraction and
    support): the collapse probability of each candidate action (by the predictor's head)."""
    masks = np.asarray(target_masks)
    if masks.ndim == 3:
        masks = masks[:, None]
    logits = scene_logits(predictor, depth_m, masks)
    return collapse_probs(logits, predictor.channel)[:, 0].numpy()
