"""Chapter 4 trials: pull one box toward the camera while a second arm holds another
(thesis 4.2.3, 4.3.3, Table 4.1).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
observe it, segment it (simulator instance masks, or depth alone), let the planner choose an
(extract, support) pair of segments, map the segments to the boxes the robot would grasp,
then execute the pull from the canonical start exactly as the ch. 4 labels were made
(`act_on_spec(..., "pull", extract, support)`) and judge it from physics:

- success (collapse-free, the thesis' trial notion; criteria.py): no box other than
  the pulled one left the shelf, and none but the support dropped or tipped beyond the
  `trials.collapse_free` thresholds;
- strict success: also no box but the support moved more than `moved_threshold_m`;

both judged after the support was released and the scene settled (trials/core/protocol.py), and
as while the support is still held (`success_held`: no other box left the shelf,
`strict_success_held`: nor moved). An invalid action (a segment of no box, or the support
the pulled box itself) is executed as chosen but never counted a success.

The risk planner sees only the depth image and the masks; the oracle reads the world.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.data.trial_scenes import policy_rng
from clutterbench.maniskill.config import ArmConfig
from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import shelf_roi
from clutterbench.perception.masks import Segmentation, match_segments, segment
from clutterbench.perception.seen import see_segments
from clutterbench.planning.ch4.risk import (
    candidate_pairs,
    random_pair,
)
from clutterbench.planning.ch4.risk_planner import plan_risk
from clutterbench.sim import benchmark
from clutterbench.sim.config import PhysicsConfig, SimConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch4.execution import arm_pull_outcome, plan_oracle, pull_outcome
from clutterbench.trials.ch4.jobs import Ch4Job
from clutterbench.trials.config import Ch4ConditionConfig, Ch4TrialParams, TrialsConfig
from clutterbench.trials.core.harness import (
    DECISION_TOPIC,
    EpisodeLog,
    EpisodeResult,
    load_predictor,
)
from clutterbench.trials.core.jobs import shelf_fields

RISKS_LOGGED = 8
"""The decision message lists the candidates of least risk, this many."""


# -- one episode ---------------------------------------------------------------------------
def observe_and_segment(
    world: BoxWorld, spec: SceneSpec, job: Ch4Job
) -> tuple[Observation, Segmentation, list[int | None], str | None]:
    """The picture (its depth through the condition's sensor, the simulator's instance image:
    the harness's), the planner's object masks, the box a pull of each mask takes (the
    harness's, never the planner's) and why the segmentation found nothing (None: it ran).

    Masks from depth: on exact depth perception/depth_segmentation.py, each segment the box
    covering most of it; under a sensor, region growing, each segment the box its grasp takes
    (perception/seen.py, as in chapter 6): the normals of depth_segmentation do not survive a
    sensor's noise."""
    cond: Ch4ConditionConfig = job.cond
    params: Ch4TrialParams = job.params
    obs = observe(world, job.camera, cond.sensing)
    roi = shelf_roi(spec.shelf)
    if cond.perception == "depth" and cond.sensing != "ideal":
        seen = see_segments(obs, roi, spec.n, params.min_pixels)
        ids = sorted(seen.grasps)
        masks = seen.obs.instance[None] == (np.array(ids, dtype=np.int64) + 1)[:, None, None]
        seg = Segmentation(ids=ids, masks=masks, source="depth")
        return obs, seg, [seen.box_of(i) for i in ids], seen.failure
    seg = segment(obs, cond.perception, min_pixels=params.min_pixels, roi=roi)
    return obs, seg, match_segments(seg, obs.instance), None


def target_segment(seg: Segmentation, instance: np.ndarray, box: int) -> int | None:
    """The segment the user points at for box `box`: the one covering most of its pixels."""
    overlap = [int(np.sum(m & (instance == box + 1))) for m in seg.masks]
    if not overlap or max(overlap) == 0:
        return None
    return int(np.argmax(overlap))


def run_ch4_episode(job: Ch4Job) -> EpisodeResult:
    """One ch. 4 trial on scene `job.index` of its stream."""
    cond: Ch4ConditionConfig = job.cond
    params: Ch4TrialParams = job.params
    physics: PhysicsConfig = job.physics
    start = job.start
    spec = start.spec()
    world = BoxWorld.from_spec(spec, physics, render=True)
    obs, seg, boxes, failure = observe_and_segment(world, spec, job)
    log = EpisodeLog(record_images=job.record_images)
    log.scene(0.0, spec.sizes_m, spec.shelf.boards(), obs.camera, obs.depth_m.shape)
    log.observation(0.0, obs.depth_m, obs.instance)
    log.poses(0.0, world.poses())
    target_box = target_k = None
    if cond.mode == "target":
        target_box = start.target(obs, params.min_target_pixels, spec)
        target_k = target_segment(seg, obs.instance, target_box)
    decision, chosen, risk, ties = _choose(job, spec, obs, seg, boxes, target_k)
    x_box = boxes[chosen[0]] if chosen[0] is not None else None
    s_box = boxes[chosen[1]] if chosen[1] is not None else None
    valid = x_box is not None and s_box is not None and x_box != s_box
    decision |= {"extract": chosen[0], "support": chosen[1], "boxes": [x_box, s_box]}
    finite = risk is not None and np.isfinite(risk)
    log.json(0.0, DECISION_TOPIC, decision | {"risk": round(risk, 4) if finite else None})
    out = _execute(job, spec, world, log, x_box, s_box)
    if cond.executor != "arm" or x_box is None:  # the arm's pull logged its own poses
        log.poses(world.steps_taken * physics.timestep_s, world.poses(), world.removed)
    out.pop("displacement_m", None)
    out.pop("displacement_held_m", None)
    valid = bool(valid and (target_box is None or x_box == target_box))
    out = count_if_valid(out, valid)
    record = _record(job, spec, seg, decision, target_box, x_box, s_box, risk, ties, valid)
    if cond.sensing != "ideal":  # exact-depth records keep their old fields
        record |= {"sensing": cond.sensing, "perception_failure": failure}
    record = record | {k: _plain(v) for k, v in out.items()}
    if cond.executor == "arm":  # kinematic records keep their old fields
        record["executor"] = "arm"
    return EpisodeResult(record, log)


def _choose(
    job: Ch4Job,
    spec: SceneSpec,
    obs: Observation,
    seg: Segmentation,
    boxes: list[int | None],
    target_k: int | None,
) -> tuple[dict[str, Any], tuple[int | None, int | None], Any, int | None]:
    """The planner's (extract, support) segment pair: the decision message so far, the pair,
    its risk and how many candidates tie at it (the risk planner's; None otherwise)."""
    cond: Ch4ConditionConfig = job.cond
    params: Ch4TrialParams = job.params
    physics: PhysicsConfig = job.physics
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
            predictor = load_predictor(job.model_path, job.camera.image_size)
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
            rng = policy_rng(job.seed, cond.stream, job.index, f"ch4_{cond.mode}_random")
            chosen = random_pair(pairs, rng)
        else:
            box_pairs = [(boxes[x], boxes[s]) for x, s in pairs]
            # valid actions only: an invalid one is never a success
            usable = [
                k
                for k, (x, s) in enumerate(box_pairs)
                if x is not None and s is not None and x != s
            ]
            rng = policy_rng(job.seed, cond.stream, job.index, f"ch4_{cond.mode}_oracle")
            if usable:
                k, tried, _ = plan_oracle(
                    spec,
                    physics,
                    [box_pairs[k] for k in usable],
                    params.moved_threshold_m,
                    job.collapse_free,
                    rng,
                )
                chosen = pairs[usable[k]]
                decision["simulated"] = tried
    return decision, chosen, risk, ties


def _execute(
    job: Ch4Job,
    spec: SceneSpec,
    world: BoxWorld,
    log: EpisodeLog,
    x_box: int | None,
    s_box: int | None,
) -> dict[str, Any]:
    """The chosen pull executed from the canonical start and judged (by the arm, or in
    `world`); nothing pulled when no box was chosen to extract."""
    params: Ch4TrialParams = job.params
    physics: PhysicsConfig = job.physics
    if x_box is not None and job.cond.executor == "arm":
        return arm_pull_outcome(
            spec,
            physics,
            x_box,
            s_box if s_box != x_box else None,
            params.moved_threshold_m,
            job.collapse_free,
            job,
            log,
        )
    if x_box is not None:
        return pull_outcome(
            spec,
            physics,
            x_box,
            s_box if s_box != x_box else None,
            params.moved_threshold_m,
            job.collapse_free,
            world=world,
        )
    # nothing graspable chosen (no pair, or a segment of no box): nothing was pulled
    return {
        "executed": False,
        "aborted_before_motion": True,
        "aborted_after_motion": False,
        "extracted": False,
        "target_out": False,
        "others_still": True,
        "collapse_free": True,
        "judged": False,
        "counted": True,
        "strict_counted": True,
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


def _record(
    job: Ch4Job,
    spec: SceneSpec,
    seg: Segmentation,
    decision: dict[str, Any],
    target_box: int | None,
    x_box: int | None,
    s_box: int | None,
    risk: Any,
    ties: int | None,
    valid: bool,
) -> dict[str, Any]:
    """The trial record's fields before the judged outcome."""
    cond: Ch4ConditionConfig = job.cond
    return {
        "condition": job.condition,
        "episode": job.index,
        "seed": job.seed,
        "stream": cond.stream,
        "family": spec.family,
        **benchmark.scene_fields(spec),
        "catalogue": job.stream_cfg.catalogue,
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
            "drop_m": job.collapse_free.drop_m,
            "tilt_deg": job.collapse_free.tilt_deg,
        },
        "moved_threshold_m": job.params.moved_threshold_m,
    }


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
    *,
    trials: TrialsConfig,
    sim: SimConfig,
    seed: int,
    arm: ArmConfig | None = None,
    **override: Any,
) -> list[Ch4Job]:
    """One job per episode, its fields from the configs (trials.ch4, trials.streams[cond.stream],
    trials' max_attempts, mcap_images and collapse_free, sim's physics and camera; `arm`: None
    for ArmConfig's defaults) but for the Ch4Job fields `override` names."""
    model_path = Path(f"models/{cond.model}/best.pt") if cond.model is not None else None
    fields = {"params": trials.ch4} | shelf_fields(cond.stream, trials, sim, seed, override)
    return [
        Ch4Job(
            condition=condition,
            cond=cond,
            index=i,
            model_path=model_path,
            arm=arm or ArmConfig(),
            **fields,
        )
        for i in range(cond.episodes)
    ]
