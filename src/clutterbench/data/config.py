"""Params of the generate stage (`generate` section). Imports no SAPIEN."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Literal

from clutterbench.config import bounded, cores_field
from clutterbench.sim.catalog import CATALOGUES
from clutterbench.sim.config import FAMILY_MAX_OBJECTS, FAMILY_NAMES


@dataclasses.dataclass(frozen=True)
class DatasetConfig:
    n_scenes: int = bounded(ge=1)
    """Number of accepted scenes."""
    families: Mapping[str, float] = dataclasses.field(default_factory=dict)
    """Scene family -> relative weight (thesis ch. 6: shelved : stacked : random = 1 : 1 : 3)."""
    catalogue: Literal["same", "various", "new"] = "various"
    """Box catalogue the sizes are drawn from."""
    n_objects: tuple[int, int] = bounded((5, 10), ge=1, le=30)
    """Inclusive range of the number of boxes per scene."""
    pulls: bool = False
    """Also simulate pulling each box out with each other box held (thesis ch. 4 pairs)."""
    pull_outcomes: bool = False
    """Also record what the trials' own pull of each box does (trials.ch6.pull_increment_m and
    grasp_lift_m, nothing held): every other box's displacement, drop, tilt and whether it
    left the shelf (arrays pullout_*, the pull head's labels: deletion labels miss what
    friction drags)."""
    moved_threshold_m: float = bounded(0.005, gt=0.0)
    """A box 'moved' when its centre moved more than this (thesis: 6.4 mm ch. 5, 5.0 mm
    ch. 6). Applied when labels are derived, so changing it regenerates nothing."""

    def __post_init__(self) -> None:
        if not self.families:
            raise ValueError("families: give at least one scene family")
        for name, w in self.families.items():
            if name not in FAMILY_NAMES:
                known = ", ".join(FAMILY_NAMES)
                raise ValueError(f"families.{name}: unknown family (known: {known})")
            if w <= 0:
                raise ValueError(f"families.{name}: weight must be > 0")
        if self.n_objects[0] > self.n_objects[1]:
            raise ValueError("n_objects: the range must be [low, high] with low <= high")
        for name in self.families:
            most = FAMILY_MAX_OBJECTS.get(name)
            if most is not None and self.n_objects[0] > most:
                # a larger draw is cut to `most` so that families can share one range, but a
                # range all above it would give the family none of the boxes asked for
                raise ValueError(
                    f"n_objects: family {name} arranges at most {most} boxes, "
                    f"the range asks for at least {self.n_objects[0]}"
                )
        assert self.catalogue in CATALOGUES


@dataclasses.dataclass(frozen=True)
class GenerateConfig:
    shard_size: int = bounded(50, ge=1)
    """Scenes per shard file (the unit of resuming and of parallel work)."""
    workers: int = cores_field(2)
    """Worker processes, each with its own renderer; auto: base.cores."""
    max_attempts: int = bounded(30, ge=1)
    """A scene is redrawn (counted as rejected) at most this often before the stage fails."""
    datasets: Mapping[str, DatasetConfig] = dataclasses.field(default_factory=dict)
    """Dataset name -> what to generate."""
