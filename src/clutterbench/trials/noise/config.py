"""Params of the task-noise replays (the `noise` section of params.yaml, stage `noise`).

Imports no SAPIEN and no torch, so that the report stage can read them."""

from __future__ import annotations

import dataclasses

from clutterbench.config import bounded, cores_field


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """How each ch. 6 condition's episodes are replayed under perturbed physics."""

    draws: int = bounded(4, ge=1)
    """Perturbed worlds each episode is replayed in (seeded by stream, episode and draw: every
    condition on a stream meets the same worlds)."""
    episodes: int = bounded(200, ge=1)
    """At most this many episodes of each condition (the first ones) are replayed."""
    friction_rel: float = bounded(0.1, ge=0.0, le=0.9)
    """Static and dynamic friction each scaled by one factor drawn from 1 +- this (uniform)."""
    mass_rel: float = bounded(0.2, ge=0.0, le=0.9)
    """Each box's mass scaled by its own factor drawn from 1 +- this."""
    pull_speed_rel: float = bounded(0.25, ge=0.0, le=0.9)
    """The pull's speed scaled by a factor drawn from 1 +- this."""
    jitter_m: float = bounded(0.0005, ge=0.0, le=0.001)
    """Every box of a step's start is moved by up to this along the shelf's depth and width
    and raised by up to this (never lowered: no box starts inside the board); at most the
    scene validator's creep tolerance (sim.physics.rest_check_m, 1 mm), so a start the
    validator could not tell apart from the table's."""
    robust_draws: int = bounded(3, ge=1)
    """Perturbed worlds the robust oracles simulate each candidate step in (drawn apart from
    the replay draws): a step is clean only when it is clean in the table's world and in each."""
    robust: dict[str, str] = bounded(
        {"oracle_robust": "oracle", "oracle_hold_robust": "oracle_hold"}
    )
    """Robust oracle condition -> the search-oracle condition it mirrors (same stream and
    episodes; its planner searches over perturbed worlds). Run by this stage, replayed too."""
    conditions: tuple[str, ...] = ()
    """The ch. 6 conditions replayed (empty: every condition of trials.conditions)."""
    workers: int = cores_field(2)
    """Worker processes; auto: base.cores."""
