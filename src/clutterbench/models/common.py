"""What the collapse networks share: depth normalisation and the upsampling decoder block."""

from __future__ import annotations

import copy
import io
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from clutterbench.config import as_dict, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path


def normalise_depth(depth_m: torch.Tensor, near_m: float, far_m: float) -> torch.Tensor:
    """Metres -> [-1, 1] over [near, far]; missing returns (0 m) map to -1 like the near
    plane (thesis 5.2.2: "grayscale and normalized in advance")."""
    x = (depth_m.clamp(near_m, far_m) - near_m) / (far_m - near_m)
    return torch.where(depth_m > 0, 2.0 * x - 1.0, torch.full_like(x, -1.0))


def conv_bn_relu(c_in: int, c_out: int, stride: int = 1, groups: int = 1) -> nn.Sequential:
    """3x3 conv + BN + ReLU; `groups` > 1 runs that many independent branches side by side
    (channels split in equal groups)."""
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False, groups=groups),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


def check_input(
    depth_m: torch.Tensor,
    masks: torch.Tensor,
    input_size: int,
    n_masks: int = 1,
    scene_of: torch.Tensor | None = None,
) -> None:
    """Depth (S, 1, H, W) and masks (P, n_masks, H, W); P = S without `scene_of`, else
    scene_of is (P,) int64 indices into the S depth images."""
    if depth_m.ndim != 4 or depth_m.shape[1] != 1:
        raise ValueError(f"depth_m must be (B, 1, H, W), got {tuple(depth_m.shape)}")
    s, _, h, w = depth_m.shape
    p = s if scene_of is None else len(scene_of)
    if masks.shape != (p, n_masks, h, w):
        per = "" if scene_of is None else f", B = len(scene_of) = {p}"
        raise ValueError(
            f"masks {tuple(masks.shape)} must be (B, {n_masks}, H, W) like depth "
            f"{tuple(depth_m.shape)}{per}"
        )
    if scene_of is not None and (
        scene_of.ndim != 1
        or scene_of.dtype != torch.int64
        or (len(scene_of) and not 0 <= int(scene_of.min()) <= int(scene_of.max()) < s)
    ):
        raise ValueError(f"scene_of must be (P,) int64 indices into the {s} depth images")
    if depth_m.shape[-2:] != (input_size, input_size):
        raise ValueError(
            f"model takes {input_size}x{input_size} images, got "
            f"{depth_m.shape[-2]}x{depth_m.shape[-1]}"
        )


def upsample_to(x: torch.Tensor, like: torch.Tensor | torch.Size) -> torch.Tensor:
    """`x` resized (bilinear) to the size of the map `like` (or to the size `like`)."""
    size = like if isinstance(like, torch.Size) else like.shape[-2:]
    return F.interpolate(x, size=size, mode="bilinear", align_corners=False)


def load_torch_file(path: Path, what: str, missing_hint: str = "") -> Any:
    """torch.load (tensors only) with one-line errors for a missing or unreadable file."""
    if not path.exists():
        raise ClutterbenchError(f"{what} not found: {path}{missing_hint}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or foreign file raises many types, multi-line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ClutterbenchError(f"{what} {path} is unreadable: {first}") from None


def check_size_and_depth_range(input_size: int, depth_range_m: tuple[float, float]) -> None:
    """Shared config checks of the networks (raise ValueError -> one-line params error)."""
    if input_size % 32:
        raise ValueError(f"input_size: {input_size} is not a multiple of 32")
    if not 0 < depth_range_m[0] < depth_range_m[1]:
        raise ValueError("depth_range_m: need 0 < near < far")


@torch.no_grad()
def fold_batchnorm(model: nn.Module) -> nn.Module:
    """An inference copy of `model` (eval mode) in which every BatchNorm that directly
    follows a convolution in a Sequential is folded into that convolution's weights and
    bias (W' = W g / s, b' = (b - mean) g / s + beta, s = sqrt(var + eps)) and replaced by
    Identity: the same function with one pass over memory less per layer."""
    model = copy.deepcopy(model).eval()
    for seq in [m for m in model.modules() if isinstance(m, nn.Sequential)]:
        layers = list(seq)
        for i, (conv, bn) in enumerate(zip(layers, layers[1:])):
            if not (isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d)):
                continue
            if bn.running_mean is None or conv.out_channels != bn.num_features:
                continue
            scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
            bias = conv.bias if conv.bias is not None else torch.zeros_like(bn.running_mean)
            conv.weight.mul_(scale.reshape(-1, 1, 1, 1))
            conv.bias = nn.Parameter((bias - bn.running_mean) * scale + bn.bias)
            seq[i + 1] = nn.Identity()
    return model


def save_model_file(path: Path, fmt: str, model: nn.Module, meta: dict[str, Any]) -> None:
    """Write a network that is not a collapse network atomically: format, its config
    (`model.cfg`), training facts and weights; the bytes depend only on them."""
    write_model_payload(path, {"format": fmt}, model, meta)


def write_model_payload(
    path: Path, head: dict[str, Any], model: nn.Module, meta: dict[str, Any]
) -> None:
    """torch.save of `head` + the model's config (`model.cfg`), `meta` and weights, written
    atomically: the bytes depend only on them (every checkpoint format writes this way)."""
    payload = {
        **head,
        "net": as_dict(model.cfg),
        "meta": meta,
        "state_dict": {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()},
    }
    buf = io.BytesIO()
    torch.save(payload, buf)
    with atomic_path(Path(path)) as tmp:
        tmp.write_bytes(buf.getvalue())


def load_model_file(
    path: Path, fmt: str, config_cls: type, module_cls: type[nn.Module], what: str, hint: str
) -> tuple[nn.Module, dict[str, Any]]:
    """(model in eval mode, meta) rebuilt from a `save_model_file` file alone; one-line
    errors for a missing, unreadable or foreign file, or weights that do not fit the stored
    config. `what` names the file in errors ("detector checkpoint"), `hint` how to make it."""
    path = Path(path)
    payload = load_torch_file(path, what, hint)
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise ClutterbenchError(f"checkpoint {path} is not a clutterbench {what}")
    cfg = parse(config_cls, payload["net"], f"checkpoint {path}: net")
    model = module_cls(cfg)
    try:
        model.load_state_dict(payload["state_dict"])
    except RuntimeError:
        raise ClutterbenchError(
            f"checkpoint {path}: its weights do not fit its config; retrain it"
        ) from None
    return model.eval(), dict(payload.get("meta", {}))
