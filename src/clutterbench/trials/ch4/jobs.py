"""Chapter 4's episode job (one trial), built by trials.ch4.episodes.ch4_jobs."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from clutterbench.trials.core.jobs import ShelfJob

if TYPE_CHECKING:
    from pathlib import Path

    from clutterbench.data.trial_scenes import StreamStart
    from clutterbench.maniskill.config import ArmConfig
    from clutterbench.trials.config import Ch4ConditionConfig, Ch4TrialParams


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class Ch4Job(ShelfJob):
    """One ch. 4 trial: scene `index` of the condition's stream, one pull."""

    cond: Ch4ConditionConfig
    """The condition (its planner, stream, mode, model, executor)."""
    params: Ch4TrialParams
    """The ch. 4 trials' parameters (trials.ch4)."""
    model_path: Path | None
    """The risk network's checkpoint (None: the condition's planner reads none)."""
    arm: ArmConfig
    """The Pandas' configuration (trials.arm), read by the arm executor."""

    @property
    def start(self) -> StreamStart:
        """Its start: scene `index` of the condition's stream and its target's draw."""
        return self.start_on(self.cond.stream)
