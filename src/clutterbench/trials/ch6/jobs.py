"""Chapter 6's episode job (one extraction), built by trials.ch6.episodes.ch6_jobs."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from clutterbench.trials.core.jobs import ShelfJob

if TYPE_CHECKING:
    from pathlib import Path

    from clutterbench.data.trial_scenes import StreamStart
    from clutterbench.maniskill.config import ArmConfig
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.trials.config import Ch6TrialParams


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class Ch6Job(ShelfJob):
    """One ch. 6 extraction episode: scene `index` of stream `stream`, one planner."""

    planner: str
    """The planner's name in the registry (trials/ch6/planners/)."""
    rule: str | None
    """The condition's support rule (CP planners' support method)."""
    stream: str
    """The scene stream's name."""
    params: Ch6TrialParams
    """The ch. 6 trials' parameters (trials.ch6)."""
    support: SupportParams | None
    """A CP planner's support thresholds (None: the planner reads none)."""
    cp_max: float
    """The collapse score above which a monitored pull aborts."""
    model_path: Path | None
    """The collapse network's checkpoint (None: none)."""
    ch4_model_path: Path | None
    """The ch. 4 risk network's checkpoint, for the single-step planner (None: none)."""
    executor: str
    """Who executes the pulls: 'kinematic' or 'arm' (the Pandas)."""
    arm: ArmConfig
    """The Pandas' configuration (trials.arm), read by the arm executor."""
    sensing: str = "ideal"
    """The depth sensor model its pictures pass through (sim/sensor.py PRESETS)."""
    perception: str = "instance"
    """Its planner's object masks: the simulator's instance image, or segments of the sensed
    depth (depth; trials/ch6/seeing.py)."""
    box_head_path: Path | None = None
    """The box head's checkpoint, for the box planners (None: none)."""
    box_edge_threshold: float | None = None
    """The box planners' support edge where its probability exceeds this (the support
    stage's choice on validation scenes; None: not a box planner)."""
    box_fusion: tuple[float, ...] | None = None
    """The learned-plus-physics box planners' fusion weights (head logit, simulated and
    marked, simulated and not, bias; the support stage's fit on validation scenes; None:
    another planner)."""
    box_contact: tuple[float, ...] | None = None
    """Their learned contact's weights (trials.ch6.box_contact learned: head contact logit,
    fitted and touching, fitted and not, bias; the support stage's fit on validation
    scenes); None: the edges take the box head's contact."""

    @property
    def start(self) -> StreamStart:
        """Its start: scene `index` of stream `stream` and its target's draw."""
        return self.start_on(self.stream)
