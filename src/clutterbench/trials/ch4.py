"""Chapter 4 trials: pull one box toward the camera while a second arm holds another
(thesis 4.2.3, 4.3.3, Table 4.1).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
observe it, segment it (simulator instance masks, or depth alone), let the planner choose an
(extract, support) pair of segments, map the segments to the boxes the robot would grasp,
then execute the pull from the canonical start exactly as the ch. 4 labels were made
(`act_on_spec(..., "pull", extract, support)`) and judge it from physics:

- success (collapse-free, the thesis' trial notion; trials/criteria.py): no box other than
  the pulled one left the shelf, and none but the support dropped or tipped beyond the
  `trials.collapse_free` thresholds;
- strict success: also no box but the support moved more than `moved_threshold_m`;

both judged after the support was released and the scene settled (trials/protocol.py), and
as while the support is still held (`success_held`: no other box left the shelf,
`strict_success_held`: nor moved). An invalid action (a segment of no box, or the support
the pulled box itself) is executed as chosen but never counted a success.

The risk planner sees only the depth image and the masks; the oracle reads the world.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.maniskill.config import ArmConfig
from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import shelf_roi
from clutterbench.perception.masks import Segmentation, match_segments, segment
from clutterbench.planning.risk import (
    candidate_pairs,
    random_pair,
)
from clutterbench.planning.risk_planner import plan_risk
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.labelling import act_on_spec
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials import criteria
from clutterbench.trials.config import Ch4ConditionConfig, Ch4TrialParams, SceneStreamConfig
from clutterbench.trials.criteria import CollapseFreeConfig
from clutterbench.trials.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult, load_predictor
from clutterbench.trials.scenes import draw_target, draw_trial_spec, policy_rng

RISKS_LOGGED = 8
"""The decision message lists the candidates of least risk, this many."""


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
    from the boxes' motion (trials/protocol.py: release, then judge). The judgement while the
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
    job: dict[str, Any],
    log: EpisodeLog,
) -> dict[str, Any]:
    """pull_outcome with the Pandas (executor: arm): one straight pull, no lift (as the
    kinematic pull), the support held by the second arm; judged the same way."""
    from clutterbench.trials.executors import arm_pull

    done = arm_pull(
        spec,
        SceneState.start(spec),
        extract,
        support,
        float("inf"),
        0.0,
        physics,
        job["arm"],
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
    return out | flags | _judged_flags(out | flags) | done.fields


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
    """A ch. 4 pull's judgement under both criteria (trials/criteria.py) from the boxes'
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
    return step | _judged_flags(step)


def _judged_flags(step: dict[str, Any]) -> dict[str, Any]:
    """`judged` / `strict_judged` and the success under each criterion of one executed (or
    not) pull: a trial is always judged (an abort is a failure of its one attempt)."""
    ok = step["executed"] and step["extracted"]
    return {
        "judged": True,
        "strict_judged": True,
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


# -- one episode ---------------------------------------------------------------------------
def observe_and_segment(
    world: BoxWorld, spec: SceneSpec, job: dict[str, Any]
) -> tuple[Observation, Segmentation]:
    cond: Ch4ConditionConfig = job["cond"]
    params: Ch4TrialParams = job["params"]
    obs = observe(world, job["camera"])
    seg = segment(obs, cond.perception, min_pixels=params.min_pixels, roi=shelf_roi(spec.shelf))
    return obs, seg


def target_segment(seg: Segmentation, instance: np.ndarray, box: int) -> int | None:
    """The segment the user points at for box `box`: the one covering most of its pixels."""
    overlap = [int(np.sum(m & (instance == box + 1))) for m in seg.masks]
    if not overlap or max(overlap) == 0:
        return None
    return int(np.argmax(overlap))


def run_ch4_episode(job: dict[str, Any]) -> EpisodeResult:
    """One ch. 4 trial on scene `job["index"]` of its stream."""
    cond: Ch4ConditionConfig = job["cond"]
    params: Ch4TrialParams = job["params"]
    physics: PhysicsConfig = job["physics"]
    spec = draw_trial_spec(
        cond.stream,
        job["stream_cfg"],
        job["seed"],
        job["index"],
        physics,
        job["camera"],
        job["max_attempts"],
    )
    world = BoxWorld.from_spec(spec, physics, render=True)
    obs, seg = observe_and_segment(world, spec, job)
    log = EpisodeLog(record_images=job["record_images"])
    log.scene(0.0, spec.sizes_m, spec.shelf.boards(), obs.camera, obs.depth_m.shape)
    log.observation(0.0, obs.depth_m, obs.instance)
    log.poses(0.0, world.poses())
    boxes = match_segments(seg, obs.instance)  # the harness's, never the planner's
    target_box = target_k = None
    if cond.mode == "target":
        target_box = draw_target(
            job["seed"], cond.stream, job["index"], obs, params.min_target_pixels
        )
        target_k = target_segment(seg, obs.instance, target_box)
    decision: dict[str, Any] = {"candidates": 0}
    chosen: tuple[int | None, int | None] = (None, None)  # segment indices
    risk, ties = None, None
    if len(seg.ids) >= 2 and (cond.mode == "pair" or target_k is not None):
        pairs = (
            candidate_pairs(list(range(len(seg.ids))))
            if target_k is None
            else [(target_k, s) for s in range(len(seg.ids)) if s != target_k]
        )
        decision["candidates"] = len(pairs)
        if cond.planner == "risk":
            predictor = load_predictor(job["model_path"], job["camera"].image_size)
            choice, pairs, risks, _ = plan_risk(
                predictor, obs, seg, target_k, params.pixel_threshold
            )
            chosen, risk = (choice.extract, choice.support), choice.risk
            # How many candidates share the least risk: above 1, the tie-break decided.
            ties = int(np.sum(risks == choice.risk))
            top = np.argsort(risks, kind="stable")[:RISKS_LOGGED]
            decision["least_risk"] = [
                [*pairs[k], round(float(risks[k]), 4) if np.isfinite(risks[k]) else None]
                for k in top
            ]
        elif cond.planner == "random":
            rng = policy_rng(job["seed"], cond.stream, job["index"], f"ch4_{cond.mode}_random")
            chosen = random_pair(pairs, rng)
        else:
            box_pairs = [(boxes[x], boxes[s]) for x, s in pairs]
            # valid actions only: an invalid one is never a success
            usable = [
                k
                for k, (x, s) in enumerate(box_pairs)
                if x is not None and s is not None and x != s
            ]
            rng = policy_rng(job["seed"], cond.stream, job["index"], f"ch4_{cond.mode}_oracle")
            if usable:
                k, tried, _ = plan_oracle(
                    spec,
                    physics,
                    [box_pairs[k] for k in usable],
                    params.moved_threshold_m,
                    job["collapse_free"],
                    rng,
                )
                chosen = pairs[usable[k]]
                decision["simulated"] = tried
    x_box = boxes[chosen[0]] if chosen[0] is not None else None
    s_box = boxes[chosen[1]] if chosen[1] is not None else None
    valid = x_box is not None and s_box is not None and x_box != s_box
    decision |= {"extract": chosen[0], "support": chosen[1], "boxes": [x_box, s_box]}
    finite = risk is not None and np.isfinite(risk)
    log.json(0.0, DECISION_TOPIC, decision | {"risk": round(risk, 4) if finite else None})
    if x_box is not None and cond.executor == "arm":
        out = arm_pull_outcome(
            spec,
            physics,
            x_box,
            s_box if s_box != x_box else None,
            params.moved_threshold_m,
            job["collapse_free"],
            job,
            log,
        )
    elif x_box is not None:
        out = pull_outcome(
            spec,
            physics,
            x_box,
            s_box if s_box != x_box else None,
            params.moved_threshold_m,
            job["collapse_free"],
            world=world,
        )
    else:  # nothing graspable chosen (no pair, or a segment of no box): nothing was pulled
        out = {
            "executed": False,
            "aborted_before_motion": True,
            "aborted_after_motion": False,
            "extracted": False,
            "target_out": False,
            "others_still": True,
            "collapse_free": True,
            "judged": True,
            "strict_judged": True,
            "n_left_shelf": 0,
            "n_disturbed": 0,
            "n_collapsed": 0,
            "disturbance_m": 0.0,
            "box_motion": [],
            "success": False,
            "strict_success": False,
            "success_held": False,
            "strict_success_held": False,
        }
    if cond.executor != "arm" or x_box is None:  # the arm's pull logged its own poses
        log.poses(world.steps_taken * physics.timestep_s, world.poses(), world.removed)
    out.pop("displacement_m", None)
    out.pop("displacement_held_m", None)
    valid = bool(valid and (target_box is None or x_box == target_box))
    out = count_if_valid(out, valid)
    record = {
        "condition": job["condition"],
        "episode": job["index"],
        "seed": job["seed"],
        "stream": cond.stream,
        "family": spec.family,
        "catalogue": job["stream_cfg"].catalogue,
        "n_objects": spec.n,
        "planner": cond.planner,
        "mode": cond.mode,
        "model": cond.model,
        "perception": cond.perception,
        "n_segments": len(seg.ids),
        "n_candidates": decision["candidates"],
        "target": target_box,
        "extract": x_box,
        "support": s_box,
        # r_c is +inf where the network claims no region at all: no evidence, written null
        "risk": None if risk is None or not np.isfinite(risk) else round(risk, 6),
        "risk_ties": ties,
        "valid": valid,
        "collapse_free_params": {
            "drop_m": job["collapse_free"].drop_m,
            "tilt_deg": job["collapse_free"].tilt_deg,
        },
        "moved_threshold_m": params.moved_threshold_m,
    } | {k: _plain(v) for k, v in out.items()}
    if cond.executor == "arm":  # kinematic records keep their old fields
        record["executor"] = "arm"
    return EpisodeResult(record, log)


OUTCOMES = ("target_out", "success", "strict_success", "success_held", "strict_success_held")
"""A ch. 4 trial's outcome flags, all false for an invalid action."""


def count_if_valid(out: dict[str, Any], valid: bool) -> dict[str, Any]:
    """The judged pull `out` with every outcome flag false unless the action was valid (both
    segments grasp boxes, two different ones, and with a given target the pulled box is it):
    an invalid action is executed as chosen, but never counted a success."""
    return out | {k: bool(out[k] and valid) for k in OUTCOMES}


def _plain(v: Any) -> Any:
    """JSON-plain values; floats to 1e-6 so records read cleanly (bits stay deterministic)."""
    if isinstance(v, bool | np.bool_):
        return bool(v)
    if isinstance(v, float | np.floating):
        return round(float(v), 6)
    return v


def ch4_jobs(
    condition: str,
    cond: Ch4ConditionConfig,
    params: Ch4TrialParams,
    stream_cfg: SceneStreamConfig,
    seed: int,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    record_images: bool,
    arm: ArmConfig | None = None,
    collapse_free: CollapseFreeConfig | None = None,
) -> list[dict[str, Any]]:
    """One job per episode (`collapse_free`: trials.collapse_free; None: its defaults)."""
    model_path = Path(f"models/{cond.model}/best.pt") if cond.model is not None else None
    return [
        {
            "condition": condition,
            "cond": cond,
            "params": params,
            "stream_cfg": stream_cfg,
            "index": i,
            "seed": seed,
            "physics": physics,
            "camera": camera,
            "model_path": model_path,
            "max_attempts": max_attempts,
            "record_images": record_images,
            "arm": arm or ArmConfig(),
            "collapse_free": collapse_free or CollapseFreeConfig(),
        }
        for i in range(cond.episodes)
    ]
