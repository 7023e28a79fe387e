"""The groups of chapter 6's trial params (trials.ch6, config.Ch6TrialParams) that travel
together: how a pull is executed and judged, how far a search oracle searches, and the pull
planners' levers beyond Algorithm 1. Ch6TrialParams builds them (`.pull`, `.search`,
`.levers`); a function that reads one group takes that group, not the whole params.

Imports no SAPIEN and no torch (trials/config.py imports it).
"""

from __future__ import annotations

import dataclasses
from typing import Any


@dataclasses.dataclass(frozen=True)
class PullExecution:
    """How a trials pull is executed and judged: the executed steps, the search oracles'
    simulations and the noise replays alike (Ch6TrialParams.pull)."""

    increment_m: float
    """The pull toward the camera is cut into increments of this (trials.ch6.pull_increment_m)."""
    grasp_lift_m: float
    """The gripper raises the grasped box by this before pulling it (trials.ch6.grasp_lift_m)."""
    return_aborted: bool
    """An aborted pull puts its box back first (trials.ch6.abort_release back)."""
    lower_held: bool
    """The second arm sets its held box down before letting go (trials.ch6.held_release lower)."""
    moved_threshold_m: float
    """A box other than the pulled one moved past this (trials.ch6.moved_threshold_m)."""

    def release(self) -> dict[str, bool]:
        """execute_pull's options for releasing a pulled or held box (sim/pull.py)."""
        return {"return_aborted": self.return_aborted, "lower_held": self.lower_held}


@dataclasses.dataclass(frozen=True)
class SearchLimits:
    """How far a search oracle searches (trials/ch6/oracle.py; Ch6TrialParams.search): the
    physics-from-depth planners' search the same, with their own node budget."""

    node_budget: int
    """States expanded at most per search (trials.ch6.search_node_budget)."""
    same_m: float
    """Two states are one when every box stands within this (m) (trials.ch6.search_same_m)."""
    same_deg: float
    """... and within this of its orientation (degrees) (trials.ch6.search_same_deg)."""
    cut_m: float
    """A simulated pull stops, failed, once another box moved this (trials.ch6.search_cut_m)."""
    min_pixels: int
    """The search's candidates: boxes with this many visible pixels (trials.ch6.min_pixels)."""


@dataclasses.dataclass(frozen=True)
class PullLevers:
    """The pull planners' choices beyond Algorithm 1 (Ch6TrialParams.levers): the keyword
    arguments of planning.ch6.extraction.CollapseGraphPlanner of the same names (the
    thesis-faithful planners take its defaults)."""

    clear_hold_load: bool
    """Bimanual: remove what the box to be held carries before the held pull."""
    learn_from_aborts: bool
    """An abort teaches the graph what it feared for (trials.ch6.abort_response learn)."""
    watch_m: float | None
    """Watch the pull's depth images, stopping it past this (m) (trials.ch6.pull_watch_m)."""
    when_no_plan: str
    """What to do when the rule rejects every candidate (trials.ch6.when_no_plan)."""
    idle_hold_share: float | None
    """The idle second arm holds a neighbour above this share (trials.ch6.idle_hold_share)."""
    idle_hold_prob: float | None
    """The pixel threshold those shares are taken at (trials.ch6.idle_hold_prob)."""
    score_over: str
    """Whose shares the collapse score takes (trials.ch6.score_over)."""
    hold_feared: str
    """Which feared box an idle-arm pull may be retried holding (trials.ch6.hold_feared)."""

    def kwargs(self) -> dict[str, Any]:
        """The levers as CollapseGraphPlanner's keyword arguments."""
        return dataclasses.asdict(self)
