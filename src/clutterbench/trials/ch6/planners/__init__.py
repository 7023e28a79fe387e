"""The ch. 6 planners (`trials.conditions.<c>.planner`): each module here registers one or a
few built-in planners with their declaration (_registry.py: what a planner reads, whether it
holds, its label, its ceiling, its cost class), which the trials, the report, the
decomposition, the bench and the environments read. A new built-in planner is one module
here (found when the package is imported) and its conditions in params.yaml; a planner
outside the package is a module named in trials.planner_modules (docs/extending.md).
Importing the package imports neither SAPIEN nor torch: a factory imports what it builds."""

from __future__ import annotations

import importlib
import pkgutil

from clutterbench.trials.ch6.planners._common import (
    BOX_HEAD,
    box_fusion,
    box_thresholds,
    chosen_support,
    truth_maps_of,
)
from clutterbench.trials.ch6.planners._registry import (
    NETWORKS,
    PLANNERS,
    Planner,
    declared,
    load_planners,
    make_planner,
    planner_info,
    register_planner,
)

__all__ = [
    "BOX_HEAD",
    "NETWORKS",
    "PLANNERS",
    "Planner",
    "box_fusion",
    "box_thresholds",
    "BUILT_IN",
    "chosen_support",
    "declared",
    "load_planners",
    "make_planner",
    "planner_info",
    "register_planner",
    "truth_maps_of",
]

_BUILT_IN = sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
for _module in _BUILT_IN:
    importlib.import_module(f"{__name__}.{_module}")
BUILT_IN = tuple(PLANNERS)
"""The built-in planners' names, in registration order (module by module)."""
