"""Checkpoints that describe themselves: arch, net config, data contract and weights.

Evaluation rebuilds the network from the checkpoint alone and refuses one whose data
contract (image size, dataset labels) does not match what it is asked to evaluate.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch
from torch import nn

from clutterbench.errors import ClutterbenchError
from clutterbench.models import build_model, parse_net_config
from clutterbench.models.common import load_torch_file, write_model_payload

FORMAT = "clutterbench.collapse/1"


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    arch: str
    net: Any
    """The arch's config dataclass."""
    state_dict: dict[str, torch.Tensor]
    meta: dict[str, Any]
    """Training facts: dataset, moved threshold, epoch, val loss, ..."""

    def model(self) -> nn.Module:
        model = build_model(self.arch, self.net)
        model.load_state_dict(self.state_dict)
        return model.eval()


def save_checkpoint(path: Path, arch: str, model: nn.Module, meta: dict[str, Any]) -> None:
    """Write atomically; the bytes depend only on the weights and the config."""
    write_model_payload(path, {"format": FORMAT, "arch": arch}, model, meta)


def load_checkpoint(path: Path) -> Checkpoint:
    path = Path(path)
    payload = load_torch_file(path, "checkpoint", "; run its train stage first")
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ClutterbenchError(f"checkpoint {path} is not a clutterbench collapse checkpoint")
    net = parse_net_config(payload["arch"], payload["net"], f"checkpoint {path}: net")
    return Checkpoint(payload["arch"], net, payload["state_dict"], payload["meta"])


DEFAULT_HEADS = ("deletion",)
"""The heads of a checkpoint that records none: every network trained before heads."""


def checkpoint_heads(ckpt: Checkpoint) -> tuple[str, ...]:
    """What each sigmoid output channel of the network predicts (train.models.<m>.labels),
    in channel order; a checkpoint without a record is a deletion network."""
    return tuple(ckpt.meta.get("heads", DEFAULT_HEADS))


def head_channel(ckpt: Checkpoint, path: Path, head: str) -> int | None:
    """The output channel of head `head` (None: the network's one collapse output, read as
    ever: a sigmoid, or the last class of a softmax); one line when it has no such head."""
    heads = checkpoint_heads(ckpt)
    if head not in heads:
        raise ClutterbenchError(
            f"checkpoint {path} has no '{head}' head (it has {', '.join(heads)}); train it "
            f"with train.models.<model>.labels naming {head}"
        )
    return heads.index(head) if len(heads) > 1 else None


def check_compatible(ckpt: Checkpoint, path: Path, image_size: int) -> None:
    """One clear error when a checkpoint cannot run on these images."""
    if ckpt.net.input_size != image_size:
        raise ClutterbenchError(
            f"checkpoint {path} takes {ckpt.net.input_size}x{ckpt.net.input_size} images but the "
            f"data are {image_size}x{image_size}; retrain it at this scale"
        )
