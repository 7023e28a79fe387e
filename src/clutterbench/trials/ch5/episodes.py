"""Chapter 5 trials: replenish a shelf with one box of known size (thesis 5.3.2, Table 5.2).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
draw the new box, then repeat: observe -> arrangement clusters (the detector, or the
generator's ground truth) -> plan (planning/ch5/replenish.py) -> execute from a fresh world at the
present state through the action API (`carry_group` + `hold` a blocker aside, carry the
new box in through the shelf's front to the candidate, `release` every held box, settle) ->
judge from physics. A rearrangement (a cluster moved aside and let go) is judged, then the
planner looks again; the episode ends at its first failed step, when the box is placed, or
when the planner has no plan (gave up).

Success: the new box rests inside the working space within `place_tol_m` of its planned
place, and no box other than the manipulated ones (the clusters moved) moved beyond the
threshold or left the shelf; a moved box must stay on the shelf. Judged after every held box
was released and the scene settled. The trials are the one place that holds both the world
and a planner: which boxes a detection holds (what the robot grasps) is decided from the
instance image (ch5_execution.members), never by the planner.

A condition with a depth sensor (`sensing`, sim/sensor.py) gives its planner each picture
through that sensor (`sim.render.sensed` of the one exact rendering): the detector, the collapse
map network and the planner's depth points read the sensed depth, and the MCAP logs it. The
harness's side stays exact: the free places at the start, execution and judging (the true
instance image and physics) and the oracle (it simulates the world).

The chapter in four modules: this one (the episode, its record, the jobs), `ch5_perception`
(clusters and collapse maps), `ch5_execution` (executing and judging a plan) and `ch5_oracle`
(the action set and the oracle's search over it).
"""

from __future__ import annotations

import json
import re
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench import criteria
from clutterbench.data.trial_scenes import draw_trial_spec, policy_rng, stream_key
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.observation import Observation
from clutterbench.perception.boxes import Detection
from clutterbench.planning.ch5.replenish import (
    Candidate,
    Plan,
    ReplenishParams,
    ReplenishPlanner,
    WorkingSpace,
    candidates,
    place_clusters,
    rect_mask,
)
from clutterbench.sim import benchmark
from clutterbench.sim.catalog import box_extents_m
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe, sensed
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch5.execution import execute
from clutterbench.trials.ch5.jobs import Ch5Job
from clutterbench.trials.ch5.oracle import action_set, oracle_choice
from clutterbench.trials.ch5.perception import collapse_map_fn, perceive, true_clusters
from clutterbench.trials.config import Ch5ConditionConfig, Ch5TrialParams, TrialsConfig
from clutterbench.trials.core.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult
from clutterbench.trials.core.jobs import shelf_fields

ENDS = ("placed", "collapse", "misplaced", "gave_up", "max_steps")
"""Why an episode ended: the box was placed and nothing else moved (success); a step moved
another box beyond the threshold or off the shelf; the box did not come to rest at its place;
the planner had no plan; the plan cap."""


def space_of(spec: SceneSpec) -> WorkingSpace:
    s = spec.shelf
    return WorkingSpace(s.width_m, s.depth_m, s.height_m)


def new_box_size(seed: int, stream: str, index: int, catalogue: str) -> np.ndarray:
    """(3,) local extents (D, W, H) of the episode's box: one catalogue type, own stream."""
    rng = np.random.default_rng([seed, zlib.crc32(f"{stream_key(stream)}/new_box".encode()), index])
    types = box_extents_m(catalogue)
    return types[int(rng.integers(len(types)))].copy()


# -- the episode ---------------------------------------------------------------------------
def run_ch5_episode(job: Ch5Job) -> EpisodeResult:
    """One replenishment trial on scene `job.index` of its stream."""
    spec, size_m = draw_start(job)
    return replenish(spec, job, size_m)


def draw_start(job: Ch5Job) -> tuple[SceneSpec, np.ndarray]:
    """The episode's canonical start and new box (local extents): scene `job.index` of
    its stream, redrawn while a family of NO_FREE_PLACE offers a free candidate for it."""
    cond: Ch5ConditionConfig = job.cond
    physics: PhysicsConfig = job.physics
    camera: CameraConfig = job.camera
    params: Ch5TrialParams = job.params
    size_m = new_box_size(job.seed, cond.stream, job.index, params.new_boxes)

    def no_free_place(spec: SceneSpec) -> str | None:
        """Thesis Fig. 5.9: a shelved start has no free placement candidate for this box."""
        if spec.family in NO_FREE_PLACE and free_places(spec, job, size_m):
            return "free_place"
        return None

    spec = draw_trial_spec(
        cond.stream,
        job.stream_cfg,
        job.seed,
        job.index,
        physics,
        camera,
        job.max_attempts,
        keep_groups=True,
        accept=no_free_place,
        # what no_free_place reads: the new box and the candidates' geometry
        accept_key=json.dumps(
            {
                "no_free_place": list(NO_FREE_PLACE),
                "size_m": [float(v) for v in size_m],
                "finger_m": params.finger_m,
                "min_points": params.min_points,
            },
            sort_keys=True,
        ),
    )
    return spec, size_m


NO_FREE_PLACE = ("replenish_shelved",)
"""Families whose trial starts are redrawn while a placement candidate is free (thesis Fig.
5.9: the obstacle stands where the new box must go; the family builds them so, this makes
sure: docs/ch5-replenishment.md)."""


def free_places(
    spec: SceneSpec, job: Ch5Job, size_m: np.ndarray, obs: Observation | None = None
) -> list[str]:
    """The placement candidates free at the canonical start of `spec` for a box of `size_m`,
    as "cluster:side", seen through the generator's ground-truth clusters (what the scene
    offers, whatever a detector would make of it)."""
    state = SceneState.start(spec)
    if obs is None:
        obs = observe(world_at(spec, state, job.physics, render=True), job.camera)
    space = space_of(spec)
    dets = true_clusters(spec, state, job.physics, obs)
    clusters = place_clusters(obs, dets, space)
    cands = candidates(obs, clusters, np.asarray(size_m, float), planner_params(job), space)
    return [f"{c.cluster}:{c.side}" for c in cands if c.free]


def planner_params(job: Ch5Job) -> ReplenishParams:
    p: Ch5TrialParams = job.params
    return ReplenishParams(
        finger_m=p.finger_m,
        prob_threshold=job.prob_threshold,
        iou_threshold=p.iou_threshold,
        use_collapse=job.cond.planner in COLLAPSE_PLANNERS,
        min_points=p.min_points,
        blocker_goal=p.blocker_goal,
        upright_footprint=p.upright_footprint,
        contact=job.cond.planner == "contact",
    )


PLANNERS = ("replenish", "no_collapse", "contact")
"""The conditions planned by planning.replenish (the others: ch5_oracle's action set)."""
COLLAPSE_PLANNERS = ("replenish", "contact")
"""Those that predict collapse (a collapse map network)."""


def replenish(spec: SceneSpec, job: Ch5Job, size_m: np.ndarray | None = None):
    """Replenish the settled `spec` with the job's planner -> the episode's record and MCAP
    events (the CLI calls this with a hand-built spec and a given box)."""
    cond: Ch5ConditionConfig = job.cond
    params: Ch5TrialParams = job.params
    physics: PhysicsConfig = job.physics
    camera: CameraConfig = job.camera
    if size_m is None:
        size_m = new_box_size(job.seed, cond.stream, job.index, params.new_boxes)
    space = space_of(spec)
    rp = planner_params(job)
    planner = None
    if cond.planner in PLANNERS:
        cmap = collapse_map_fn(job) if cond.planner in COLLAPSE_PLANNERS else None
        planner = ReplenishPlanner(rp, space, cmap)
    state = SceneState.start(spec)
    world = world_at(spec, state, physics, render=True)
    obs = observe(world, camera)  # exact: the harness's (free places, execution, the oracle)
    seen = sensed(obs, cond.sensing)  # the planner's: through the condition's sensor
    free_at_start = free_places(spec, job, size_m, obs)
    log = EpisodeLog(record_images=job.record_images)
    log.scene(0.0, spec.sizes_m, spec.shelf.boards(), seen.camera, seen.depth_m.shape)
    steps: list[dict[str, Any]] = []
    end, t, dt = "max_steps", 0.0, physics.timestep_s
    queued: list[Plan] = []
    simulated = 0
    gave_up_why: list[str] = []
    while len(steps) < params.max_steps:
        log.observation(t, seen.depth_m, seen.instance)  # what the planner saw
        log.poses(t, state.poses)
        dets = perceive(job, spec, state, seen)
        log.json(t, "/perception/detections", _detections_json(dets))
        plan, queued, tried = _next_plan(
            job, spec, state, seen, obs, dets, size_m, planner, queued, len(steps), log, t
        )
        simulated += tried
        log.json(t, DECISION_TOPIC, plan_json(plan))
        if plan.branch == "none":
            end = "gave_up"
            why = {re.sub(r" by -?\d+$", "", w) for w in plan.info.get("why_not", []) if w}
            gave_up_why = sorted(why)
            break
        out = execute(world, obs, plan, size_m, params, state.removed, job.collapse_free)
        steps.append(out.record)
        t += world.steps_taken * dt
        log.poses(t, world.poses())
        if not out.record["collapse_free"]:  # the first collapse-free failure ends it
            end = "collapse"
            break
        if out.placed_box is not None:
            end = "placed" if out.record["at_place"] else "misplaced"
            break
        state = SceneState.of(world)
        world = world_at(spec, state, physics, render=True)  # the next step's canonical start
        obs = observe(world, camera)
        seen = sensed(obs, cond.sensing)
    log.json(t, "/trial/result", {"end": end})
    record = _episode_record(job, spec, size_m, steps, end, free_at_start, gave_up_why)
    if cond.planner in ("oracle", "oracle_no_contact"):
        record["simulated"] = simulated
    return EpisodeResult(_rounded(record), log)


def _next_plan(
    job: Ch5Job,
    spec: SceneSpec,
    state: SceneState,
    obs: Observation,
    exact: Observation,
    dets: list[Detection],
    size_m: np.ndarray,
    planner: ReplenishPlanner | None,
    queued: list[Plan],
    n_steps: int,
    log: EpisodeLog,
    t: float,
) -> tuple[Plan, list[Plan], int]:
    """The step's plan: the next of a queued sequence, else the planner's, a random one of the
    action set, or the oracle's -> (the plan, the sequence still queued, slides simulated).
    `obs`: the planner's picture (through the condition's sensor); `exact`: the renderer's,
    which the oracle reads (it simulates the world)."""
    cond: Ch5ConditionConfig = job.cond
    rp, space = planner_params(job), space_of(spec)
    tried = 0
    if queued:  # the oracle's simulated sequence goes on as simulated
        plan = queued.pop(0)
    elif planner is not None:
        plan = planner.plan(obs, dets, size_m)
        if plan.move is not None and planner.collapse_map is not None and rp.use_collapse:
            heat = planner.collapse_map(obs, _cluster_mask(obs, plan, space))
            log.heatmap(t, "/planner/collapse_map", heat)
    elif cond.planner == "random":  # uniform over the action set, then as drawn
        options = action_set(obs, dets, size_m, rp, space)
        rng = policy_rng(job.seed, cond.stream, job.index, f"ch5_random/{n_steps}")
        seq = options[int(rng.integers(len(options)))] if options else []
        plan, queued = (seq[0], seq[1:]) if seq else (Plan("none", None, None), [])
    else:
        views = [dets]
        if job.oracle_detector:  # the detector's actions too: no planner beats it
            views.append(perceive(job, spec, state, exact, "detector"))
        seq, tried = oracle_choice(spec, state, exact, views, size_m, rp, space, job)
        plan = seq[0]
        queued = seq[1:]
    return plan, queued, tried


def _episode_record(
    job: Ch5Job,
    spec: SceneSpec,
    size_m: np.ndarray,
    steps: list[dict[str, Any]],
    end: str,
    free_at_start: Any,
    gave_up_why: list[str],
) -> dict[str, Any]:
    """The episode's record (before rounding and the oracles' simulated count)."""
    cond: Ch5ConditionConfig = job.cond
    params: Ch5TrialParams = job.params
    branch = next(
        (s["branch"] for s in steps if s["placed"]), steps[-1]["branch"] if steps else "none"
    )
    record: dict[str, Any] = {
        "condition": job.condition,
        "episode": job.index,
        "seed": job.seed,
        "stream": cond.stream,
        "family": spec.family,
        **benchmark.scene_fields(spec),
        "scene_type": job.scene_type,
        "n_objects": spec.n,
        "planner": cond.planner,
        "perception": cond.perception,
        "new_box_m": [round(float(v), 4) for v in size_m],
        "steps": steps,
        "end": end,
        "branch": branch,
        "first_branch": steps[0]["branch"] if steps else "none",
        "success": end == "placed",
        # the strict episode is the prefix up to its first strict failure (criteria.py)
        "strict_success": end == "placed" and all(s["others_still"] for s in steps),
        "strict_steps": len(criteria.strict_prefix(steps)),
        "collapse_free_params": {
            "drop_m": job.collapse_free.drop_m,
            "tilt_deg": job.collapse_free.tilt_deg,
        },
        "moved_threshold_m": params.moved_threshold_m,
        "n_disturbed": int(sum(s["n_disturbed"] for s in steps)),
        "disturbance_m": round(float(sum(s["disturbance_m"] for s in steps)), 6),
        "rejected_starts": dict(spec.meta.get("rejected", {})),
        "free_at_start": free_at_start,
    }
    if end == "gave_up":  # why no candidate had a plan (planning/ch5/replenish.py why_not)
        record["gave_up_why"] = gave_up_why
    if cond.sensing != "ideal":  # exact-depth records keep their old fields
        record["sensing"] = cond.sensing
    return record


def _cluster_mask(obs: Observation, plan: Plan, space: WorkingSpace) -> np.ndarray:
    """The target mask the planner gave the network for the moved cluster (for the MCAP)."""
    from clutterbench.planning.ch5.replenish import box_points

    _, on_box = box_points(obs, space)
    return rect_mask(plan.move.box_px, obs.depth_m.shape) & on_box  # type: ignore[union-attr]


def _detections_json(dets: list[Detection]) -> dict[str, Any]:
    return {
        "detections": [
            {
                "cls": d.cls,
                "box_px": [round(float(v), 2) for v in d.box],
                "score": round(float(d.score), 4),
            }
            for d in dets
        ]
    }


def plan_json(plan: Plan) -> dict[str, Any]:
    out: dict[str, Any] = {"branch": plan.branch}
    if plan.candidate is not None:
        c: Candidate = plan.candidate
        out["candidate"] = {
            "cluster": c.cluster,
            "side": c.side,
            "rect_m": [round(float(v), 4) for v in c.rect_m],
            "occupants": list(c.occupants),
            "pose": [round(float(v), 4) for v in c.pose],
        }
    if plan.move is not None:
        m = plan.move
        out["move"] = {
            "cluster": m.cluster,
            "start_m": [round(float(v), 4) for v in m.start_m],
            "goal_m": [round(float(v), 4) for v in m.goal_m],
            "upright": m.upright,
        }
    return out | {k: v for k, v in plan.info.items() if k not in ("clusters",)}


def _rounded(d: Any) -> Any:
    if isinstance(d, float):
        return round(d, 6)
    if isinstance(d, dict):
        return {k: _rounded(v) for k, v in d.items()}
    if isinstance(d, list):
        return [_rounded(v) for v in d]
    if isinstance(d, np.generic):
        return _rounded(d.item())
    return d


def ch5_jobs(
    condition: str,
    cond: Ch5ConditionConfig,
    *,
    trials: TrialsConfig,
    sim: SimConfig,
    seed: int,
    prob_threshold: float,
    scene_type: str,
    oracle_detector: bool = False,
    params: Ch5TrialParams | None = None,
    **override: Any,
) -> list[Ch5Job]:
    """One job per episode, its fields from the configs (trials.streams[cond.stream], trials'
    max_attempts, mcap_images and collapse_free, sim's physics and camera) but for the Ch5Job
    fields `override` names; `params`: None for trials.ch5; `oracle_detector`: an oracle also
    simulates the actions seen through the detector (set when any condition perceives with
    it)."""
    params = trials.ch5 if params is None else params
    fields = shelf_fields(cond.stream, trials, sim, seed, override)
    return [
        Ch5Job(
            condition=condition,
            cond=cond,
            params=params,
            index=i,
            model_path=Path(f"models/{params.model}/best.pt"),
            detector_path=detector_path(cond),
            prob_threshold=prob_threshold,
            scene_type=scene_type,
            oracle_detector=oracle_detector,
            **fields,
        )
        for i in range(cond.episodes)
    ]


def detector_path(cond: Ch5ConditionConfig) -> Path:
    """The arrangement detector a condition reads: the thesis' (stage detector, trained on exact
    depth with the parametric noise), or, under a sensor, the one trained on that sensor's
    images (models/detector_<sensing>: stage detector_sensed, for trials.ch5_sensed's)."""
    name = "detector" if cond.sensing == "ideal" else f"detector_{cond.sensing}"
    return Path(f"models/{name}/best.pt")


def collapse_threshold(params: Ch5TrialParams) -> float:
    """The collapse region's probability threshold: params' own, else the one evaluate@
    <model>_ch5 chose on the ch. 5 validation split (never a test-scene choice)."""
    if params.prob_threshold is not None:
        return params.prob_threshold
    path = Path(f"reports/evaluate/{params.model}_ch5/metrics.json")
    try:
        return float(read_json(path)["val_chosen_threshold"])
    except (KeyError, TypeError, ValueError):
        raise ClutterbenchError(
            f"{path}: no val_chosen_threshold; rerun evaluate@{params.model}_ch5"
        ) from None


def check_models(conds: dict[str, Ch5ConditionConfig], params: Ch5TrialParams) -> None:
    if any(c.planner in COLLAPSE_PLANNERS for c in conds.values()):
        if not Path(f"models/{params.model}/best.pt").exists():
            raise ClutterbenchError(
                f"models/{params.model}/best.pt missing; run train@{params.model}"
            )
    for c in conds.values():
        if c.perception == "detector" and not (path := detector_path(c)).exists():
            stage = "detector" if c.sensing == "ideal" else "detector_sensed"
            raise ClutterbenchError(f"{path} missing; run the {stage} stage")
