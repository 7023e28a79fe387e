"""Collapse networks: a registry arch name -> (config dataclass, module), and checkpoints.

A network is registered with `register_arch(name, config_cls, module_cls)`; every module of
this package is imported with it, so a new network is one module here that calls
`register_arch` plus one `train.models` entry naming it in params.yaml (docs/extending.md).
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
from collections.abc import Mapping
from typing import Any

from torch import nn

from clutterbench.config import parse
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.fcn8s import FCN8s, FCN8sConfig

ARCHS: dict[str, tuple[type, type[nn.Module]]] = {}
"""arch name -> (config dataclass, module class); filled by `register_arch`."""


def register_arch(name: str, config_cls: type, module_cls: type[nn.Module]) -> None:
    """Make a network usable as `train.models.<model>.arch: <name>` and in checkpoints.

    `config_cls`: a frozen dataclass parsed from the params' `net` mapping (unknown keys,
    types and `bounded` ranges checked as everywhere else), with at least `input_size`,
    `n_masks` and `n_classes`. `module_cls(cfg)` builds the network; it keeps `cfg` as
    `self.cfg` (checkpoints save it) and maps (depth_m (B, 1, S, S) metres, masks
    (B, n_masks, S, S)) to logits (B, n_classes, S, S). A network whose depth encoder
    does not see the masks may set `encodes_scene_once = True` and accept a third argument
    scene_of (P,) int64 (depth (S, ...), masks (P, ...), mask p with depth scene_of[p]), so
    that training and inference encode each scene once for all its targets
    (models.collapse_map). Registering the same pair again is a no-op; another pair under a
    taken name is an error."""
    if not (isinstance(config_cls, type) and dataclasses.is_dataclass(config_cls)):
        raise TypeError(f"arch '{name}': config_cls must be a dataclass, got {config_cls!r}")
    if not (isinstance(module_cls, type) and issubclass(module_cls, nn.Module)):
        raise TypeError(f"arch '{name}': module_cls must be an nn.Module, got {module_cls!r}")
    if name in ARCHS and ARCHS[name] != (config_cls, module_cls):
        raise ValueError(f"arch '{name}' is already registered to {ARCHS[name][1].__name__}")
    ARCHS[name] = (config_cls, module_cls)


register_arch("collapse_map", CollapseMapConfig, CollapseMapNet)
register_arch("fcn8s", FCN8sConfig, FCN8s)


def parse_net_config(arch: str, raw: Mapping[str, Any], key: str) -> Any:
    """The arch's config dataclass from a params mapping (one-line errors naming `key`)."""
    from clutterbench.errors import ClutterbenchError

    if arch not in ARCHS:
        raise ClutterbenchError(f"{key}: unknown arch '{arch}' (known: {', '.join(ARCHS)})")
    return parse(ARCHS[arch][0], raw, key)


def build_model(arch: str, cfg: Any) -> nn.Module:
    return ARCHS[arch][1](cfg)


def _import_package_modules() -> None:
    """Import this package's other modules (sorted by name): each new network's module
    registers itself at import, so every stage sees it without a list to edit."""
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        importlib.import_module(f"{__name__}.{info.name}")


_import_package_modules()
