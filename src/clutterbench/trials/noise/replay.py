"""An episode's recorded actions replayed in a perturbed world (draws.py), under the trials'
own step (sim.pull.execute_pull from a freshly built world), judgement and episode protocol
(trials/core/protocol.py): the same pulls and holds, each stopped after as many increments
as it ran in the record. Open loop: the planner is not asked again, so a replay says whether
what the planner did still works when the world differs a little."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.pull import SceneState, execute_pull, world_at
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6_groups import PullExecution
from clutterbench.trials.core.protocol import episode_end, judge_episode, judge_pull
from clutterbench.trials.noise.draws import Draw


@dataclasses.dataclass(frozen=True)
class Replayed:
    """A replayed episode's outcome under both criteria."""

    success: bool
    strict_success: bool
    end: str
    steps: int


def replay_episode(
    record: Mapping[str, Any],
    spec: SceneSpec,
    draw: Draw,
    physics: PhysicsConfig,
    pull: PullExecution,
    cf: CollapseFreeConfig,
) -> Replayed:
    """`record`'s steps (box, hold, increments) replayed from `spec`'s start in the world of
    `draw`. The episode ends as the protocol ends it (first collapse, target out or fallen);
    actions that run out first end it as the record's own end if that was the step cap, else
    as `gave_up` (a failure)."""
    spec_d, physics_d = draw.spec(spec, physics), draw.physics(physics)
    target = int(record["target"])
    state = SceneState.start(spec)
    steps: list[dict[str, Any]] = []
    end = None
    for i, rec in enumerate(record["steps"]):
        world = world_at(spec_d, draw.start(state, i), physics_d)
        step = replay_step(world, rec, state.removed, pull, cf)
        steps.append(step)
        state = SceneState.of(world)
        out = target in state.removed
        on_shelf = bool(spec.shelf.contains(state.poses[target : target + 1, :3])[0])
        end = episode_end(step, out, out or on_shelf)
        if end is not None:
            break
    if end is None:
        end = "max_steps" if record.get("end") == "max_steps" else "gave_up"
    judged = judge_episode(steps, end, target)
    return Replayed(bool(judged["success"]), bool(judged["strict_success"]), end, len(steps))


def replay_step(
    world: Any,
    rec: Mapping[str, Any],
    gone: frozenset[int],
    pull: PullExecution,
    cf: CollapseFreeConfig,
) -> dict[str, Any]:
    """One recorded step in `world` (freshly built): its pull stopped after the recorded
    increments where the record's pull was aborted -> the step judged as the trials judge it."""
    box, hold = int(rec["box"]), rec["hold"]
    hold = None if hold is None else int(hold)
    aborted = bool(rec["aborted_before_motion"] or rec["aborted_after_motion"])
    k = int(rec["increments"])
    result = execute_pull(
        world,
        box,
        hold,
        pull.increment_m,
        pull.grasp_lift_m,
        (lambda done: done < k) if aborted else None,
        **pull.release(),
    )
    step = judge_pull(result, box, hold, gone, pull.moved_threshold_m, cf)
    return {"box": box, "hold": hold} | step


def survival(nominal: Sequence[bool], draws: Sequence[Sequence[bool]]) -> dict[str, Any]:
    """One condition under one criterion: `nominal[i]` the table's outcome of episode i,
    `draws[i][d]` its replay in draw d -> the rate in each draw, their mean and spread, the
    share of the table's successes that succeed in a draw (pooled over draws), and the
    episodes that succeed in every draw."""
    n = len(nominal)
    n_draws = len(draws[0]) if draws else 0
    per_draw = [sum(bool(e[d]) for e in draws) for d in range(n_draws)]
    rates = [k / n for k in per_draw] if n else []
    kept = sum(bool(x) for i, s in enumerate(nominal) if s for x in draws[i])
    wins = sum(bool(s) for s in nominal)
    mean = sum(rates) / len(rates) if rates else float("nan")
    spread = (
        (sum((r - mean) ** 2 for r in rates) / (len(rates) - 1)) ** 0.5 if len(rates) > 1 else 0.0
    )
    return {
        "n": n,
        "draws": n_draws,
        "nominal_k": wins,
        "draw_k": per_draw,
        "mean_rate": mean,
        "sd_rate": spread,
        "survive": kept / (wins * n_draws) if wins and n_draws else float("nan"),
        "all_draws_k": sum(all(e) and len(e) > 0 for e in draws),
    }
