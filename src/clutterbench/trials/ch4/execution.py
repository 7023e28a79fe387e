"""How a ch. 4 action is executed and judged (thesis 4.2.3, 4.3.3): pull the extracted box out
with the support held, from the canonical start (the code path of the ch. 4 labels) or by the
Pandas, release the support, settle, judge from the boxes' motion under both criteria; and
the oracle, which executes every candidate pair this way and keeps the best."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from clutterbench import criteria
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.labelling import act_on_spec
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.core.harness import EpisodeLog

if TYPE_CHECKING:
    from clutterbench.trials.ch4.jobs import Ch4Job


# -- execution and the judge -----------------------------------------------------------------
def pull_outcome(
    spec: SceneSpec,
    physics: PhysicsConfig,
    extract: int,
    support: int | None,
    threshold_m: float,
    cf: CollapseFreeConfig,
    world: BoxWorld | None = None,
) -> dict[str, Any]:
    """Pull `extract` out toward the camera with `support` held, from the canonical start (the
    code path of the ch. 4 labels), then release the support, let the scene settle and judge
    from the boxes' motion (trials/core/protocol.py: release, then judge). The judgement while the
    support is still held is kept beside it (`*_held`)."""
    world = world or BoxWorld.from_spec(spec, physics)
    poses_start = world.poses()
    disp_held = act_on_spec(spec, physics, "pull", extract, support, world=world)
    on_shelf_held = spec.shelf.contains(world.positions())
    if support is not None:
        world.release([support])
        world.settle_action()
    disp = world.displacements()
    on_shelf = spec.shelf.contains(world.positions())
    out = extract in world.removed
    return judge_ch4_pull(
        spec.n,
        extract,
        support,
        threshold_m,
        cf,
        disp_held,
        on_shelf_held,
        disp,
        on_shelf,
        out,
        poses_start,
        world.poses(),
    )


def arm_pull_outcome(
    spec: SceneSpec,
    physics: PhysicsConfig,
    extract: int,
    support: int | None,
    threshold_m: float,
    cf: CollapseFreeConfig,
    job: Ch4Job,
    log: EpisodeLog,
) -> dict[str, Any]:
    """pull_outcome with the Pandas (executor: arm): one straight pull, no lift (as the
    kinematic pull), the support held by the second arm; judged the same way."""
    from clutterbench.trials.core.executors import arm_pull

    done = arm_pull(
        spec,
        SceneState.start(spec),
        extract,
        support,
        float("inf"),
        0.0,
        physics,
        job.arm,
        log,
        0.0,
    )
    r = done.result
    log.poses(done.elapsed_s, done.state.poses, done.state.removed)
    out = judge_ch4_pull(
        spec.n,
        extract,
        support,
        threshold_m,
        cf,
        r.displacement_held_m,
        done.on_shelf_held,
        r.displacement_m,
        r.on_shelf,
        r.extracted,
        r.poses_start,
        r.poses_end,
    )
    # An arm that never took hold pulled nothing; if it knocked a box on its way, the step
    # was still executed (and judged: a failure), aborted after that motion.
    reached = done.fields["arm_outcome"] == "ok"
    executed = reached or not out["others_still"]
    flags = {
        "executed": executed,
        "aborted_before_motion": not executed,
        "aborted_after_motion": executed and not reached,
    }
    return out | flags | _counted_flags(out | flags) | done.fields


def judge_ch4_pull(
    n: int,
    extract: int,
    support: int | None,
    threshold_m: float,
    cf: CollapseFreeConfig,
    disp_held: np.ndarray,
    on_shelf_held: np.ndarray,
    disp: np.ndarray,
    on_shelf: np.ndarray,
    out: bool,
    poses_start: np.ndarray,
    poses_end: np.ndarray,
) -> dict[str, Any]:
    """A ch. 4 pull's judgement under both criteria (criteria.py) from the boxes'
    motion and shelf membership after the support's release, and while it was held (thesis
    4.3.3)."""
    # Every box but the pulled one is judged; the released support only on leaving the
    # shelf (it may settle lower once released).
    others = [k for k in range(n) if k != extract]
    still = [k for k in others if k != support]
    motion = criteria.box_motion(
        poses_start, poses_end, on_shelf, still, [support] if support is not None else []
    )
    left_held = sum(not on_shelf_held[k] for k in still)
    moved_held = sum(disp_held[k] > threshold_m for k in still)
    step = {
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": False,
        "extracted": out,
        "target_out": out,
        "others_still": criteria.still(motion, threshold_m, cf),
        "collapse_free": criteria.collapse_free(motion, cf),
        "n_left_shelf": sum(bool(e["left_shelf"]) for e in motion),
        "n_disturbed": criteria.n_disturbed(motion, threshold_m, cf),
        "n_collapsed": criteria.n_collapsed(motion, cf),
        "disturbance_m": float(np.sum(disp[others])) if others else 0.0,
        "box_motion": motion,
        "success_held": out and not left_held,
        "strict_success_held": out and not left_held and not moved_held,
        "displacement_m": disp,
        "displacement_held_m": disp_held,
    }
    return step | _counted_flags(step)


def _counted_flags(step: dict[str, Any]) -> dict[str, Any]:
    """`judged` (executed, judged from physics), `counted` / `strict_counted` and the success
    under each criterion of one executed (or not) pull: a trial always counts (an abort is a
    failure of its one attempt)."""
    ok = step["executed"] and step["extracted"]
    return {
        "judged": bool(step["executed"]),
        "counted": True,
        "strict_counted": True,
        "success": bool(ok and step["collapse_free"]),
        "strict_success": bool(ok and step["others_still"]),
    }


def _better(a: dict[str, Any], b: dict[str, Any] | None) -> bool:
    if b is None:
        return True
    key = ("strict_success", "success")
    return (tuple(a[k] for k in key), -a["n_disturbed"], -a["disturbance_m"]) > (
        tuple(b[k] for k in key),
        -b["n_disturbed"],
        -b["disturbance_m"],
    )


def plan_oracle(
    spec: SceneSpec,
    physics: PhysicsConfig,
    pairs: list[tuple[int, int | None]],
    threshold_m: float,
    cf: CollapseFreeConfig,
    rng: np.random.Generator,
) -> tuple[int, int, int]:
    """The ceiling: simulate the candidate box pairs from the canonical start in a random
    order and keep the best (strict success, then collapse-free success, then the least
    disturbance): a ceiling under each criterion, since a strict success is collapse-free
    and so cannot be beaten on either; the search stops at the first one.
    -> (index of the chosen pair, pairs simulated, index of the first strict success or -1)."""
    best, best_k, tried = None, 0, 0
    for k in rng.permutation(len(pairs)):
        x, s = pairs[int(k)]
        out = pull_outcome(spec, physics, x, s, threshold_m, cf)
        tried += 1
        if _better(out, best):
            best, best_k = out, int(k)
        if out["strict_success"]:
            return best_k, tried, best_k
    return best_k, tried, -1
