"""Collapse networks: a registry arch name -> (config dataclass, module), and checkpoints."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torch import nn

from clutterbench.config import parse
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.fcn8s import FCN8s, FCN8sConfig

ARCHS: dict[str, tuple[type, type[nn.Module]]] = {
    "collapse_map": (CollapseMapConfig, CollapseMapNet),
    "fcn8s": (FCN8sConfig, FCN8s),
}


def parse_net_config(arch: str, raw: Mapping[str, Any], key: str) -> Any:
    """The arch's config dataclass from a params mapping (one-line errors naming `key`)."""
    from clutterbench.errors import ClutterbenchError

    if arch not in ARCHS:
        raise ClutterbenchError(f"{key}: unknown arch '{arch}' (known: {', '.join(ARCHS)})")
    return parse(ARCHS[arch][0], raw, key)


def build_model(arch: str, cfg: Any) -> nn.Module:
    return ARCHS[arch][1](cfg)
