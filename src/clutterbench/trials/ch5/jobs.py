"""Chapter 5's episode job (one replenishment trial), built by trials.ch5.episodes.ch5_jobs."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from clutterbench.trials.core.jobs import ShelfJob

if TYPE_CHECKING:
    from pathlib import Path

    from clutterbench.trials.config import Ch5ConditionConfig, Ch5TrialParams


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class Ch5Job(ShelfJob):
    """One ch. 5 replenishment trial: scene `index` of the condition's stream, one new box."""

    cond: Ch5ConditionConfig
    """The condition (its planner, stream, perception, sensing)."""
    params: Ch5TrialParams
    """The ch. 5 trials' parameters (trials.ch5)."""
    model_path: Path
    """The collapse network's checkpoint (read by the collapse planners)."""
    detector_path: Path
    """The arrangement detector's checkpoint (read by detector perception)."""
    prob_threshold: float
    """The collapse region's probability threshold."""
    scene_type: str
    """The stream's scene type (records' `scene_type`)."""
    oracle_detector: bool
    """Whether an oracle also simulates the actions seen through the detector."""
