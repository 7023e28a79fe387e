"""Chapter 5 trials: replenish a shelf with one box of known size (thesis 5.3.2, Table 5.2).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
draw the new box, then repeat: observe -> arrangement clusters (the detector, or the
generator's ground truth) -> plan (planning/replenish.py) -> execute from a fresh world at the
present state through the action API (`carry_group` + `hold` a blocker aside, carry the
new box in through the shelf's front to the candidate, `release` every held box, settle) ->
judge from physics. A
rearrangement (a cluster moved aside and let go) is judged, then the planner looks again; the
episode ends at its first failed step, when the box is placed, or when the planner has no
plan (gave up).

Success: the new box rests inside the working space within `place_tol_m` of its planned
place, and no box other than the manipulated ones (the clusters moved) moved beyond the
threshold or left the shelf; a moved box must stay on the shelf. Judged after every held box
was released and the scene settled. This module is the one place that holds both the world
and a planner: which boxes a detection holds (what the robot grasps) is decided here from
the instance image, never by the planner.
"""

from __future__ import annotations

import dataclasses
import re
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.observation import Observation
from clutterbench.perception.boxes import Detection, detections_from_clusters
from clutterbench.planning.replenish import (
    DROP_M,
    Candidate,
    Move,
    Plan,
    ReplenishParams,
    ReplenishPlanner,
    WorkingSpace,
    candidates,
    in_working_space,
    move_goal,
    new_box_extent_m,
    place_clusters,
    rearrange_goal,
    rect_mask,
)
from clutterbench.sim.catalog import box_extents_m
from clutterbench.sim.clusters import box_tilt, scene_clusters
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.geometry import aabb_overlap_xy, box_aabb_half_extents
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials import criteria
from clutterbench.trials.config import Ch5ConditionConfig, Ch5TrialParams, SceneStreamConfig
from clutterbench.trials.criteria import CollapseFreeConfig
from clutterbench.trials.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult
from clutterbench.trials.scenes import draw_trial_spec, policy_rng, stream_key

ENDS = ("placed", "collapse", "misplaced", "gave_up", "max_steps")
"""Why an episode ended: the box was placed and nothing else moved (success); a step moved
another box beyond the threshold or off the shelf; the box did not come to rest at its place;
the planner had no plan; the plan cap."""
FRONT_CLEARANCE_M = 0.005
"""The new box starts its way in this far in front of the shelf's open front."""
MEMBER_FRACTION = 0.5
"""A box belongs to a detection (is grasped with it) when at least this fraction of its
visible pixels lie inside the detection's image box."""

_MODELS: dict[str, Any] = {}


def _cached(key: str, make):
    if key not in _MODELS:
        _MODELS[key] = make()
    return _MODELS[key]


def space_of(spec: SceneSpec) -> WorkingSpace:
    s = spec.shelf
    return WorkingSpace(s.width_m, s.depth_m, s.height_m)


def new_box_size(seed: int, stream: str, index: int, catalogue: str) -> np.ndarray:
    """(3,) local extents (D, W, H) of the episode's box: one catalogue type, own stream."""
    rng = np.random.default_rng([seed, zlib.crc32(f"{stream_key(stream)}/new_box".encode()), index])
    types = box_extents_m(catalogue)
    return types[int(rng.integers(len(types)))].copy()


# -- perception ----------------------------------------------------------------------------
def true_clusters(spec: SceneSpec, state: SceneState, physics: PhysicsConfig, obs: Observation):
    """The generator's ground-truth clusters of the present state (sim/clusters.py) as
    detections of score 1."""
    poses = state.poses[: spec.n]
    world = BoxWorld.from_state(spec, poses, state.removed, physics)
    world.step(1)
    contacts = world.contact_pairs()
    groups = spec.meta.get("groups", [])
    _, classes, boxes = scene_clusters(spec.sizes_m, poses, groups, contacts, obs.instance)
    return detections_from_clusters(classes, boxes)


def perceive(
    job: dict[str, Any],
    spec: SceneSpec,
    state: SceneState,
    obs: Observation,
    perception: str | None = None,
):
    if (perception or job["cond"].perception) == "clusters":
        return true_clusters(spec, state, job["physics"], obs)
    from clutterbench.collapse.detector import ArrangementDetector

    detector = _cached(
        str(job["detector_path"]),
        lambda: ArrangementDetector.from_checkpoint(Path(job["detector_path"])),
    )
    return detector.detect(obs.depth_m)


def collapse_map_fn(job: dict[str, Any]):
    """(obs, target mask) -> collapse probabilities, through the ch. 5 network."""
    from clutterbench.collapse.predict import CollapsePredictor

    path = str(job["model_path"])
    predictor = _cached(
        path,
        lambda: CollapsePredictor.from_checkpoint(Path(path), image_size=job["camera"].image_size),
    )

    def collapse_map(obs: Observation, mask: np.ndarray) -> np.ndarray:
        return predictor(obs.depth_m, mask[None].astype(np.uint8))[0]

    return collapse_map


# -- execution -----------------------------------------------------------------------------
def members(obs: Observation, det_box_px: np.ndarray) -> list[int]:
    """The boxes a detection holds: those with >= MEMBER_FRACTION of their visible pixels
    inside its image box (what a gripper closing on the detection would take)."""
    inside = rect_mask(det_box_px, obs.instance.shape)
    total = np.bincount(obs.instance.ravel(), minlength=256)
    within = np.bincount(obs.instance[inside].ravel(), minlength=256)
    ids = np.nonzero((total[1:] > 0) & (within[1:] >= MEMBER_FRACTION * total[1:]))[0]
    return [int(k) for k in ids]


def upright_angle_rad(world: BoxWorld, boxes: list[int]) -> float:
    """The turn about x (`BoxWorld.carry_group`'s, right-handed: a positive turn tips a top
    toward -y) that sets a leaning cluster upright: the mean lean of its standing boxes
    (`box_tilt`'s, positive with the top toward +y), a gripper closing on the cluster aligns
    it."""
    poses = world.poses()
    leans = [box_tilt(np.asarray(world.sizes_m[i]), poses[i, 3:]) for i in boxes]
    standing = [a for flat, a in leans if not flat]
    return float(np.deg2rad(np.mean(standing))) if standing else 0.0


def floor_lift_m(world: BoxWorld, boxes: list[int], move: np.ndarray, turn: float) -> float:
    """How far to raise a carried cluster so that, turned upright, no box dips into the floor."""
    if turn == 0.0:
        return 0.0
    lo, _ = world.aabbs()
    return float(max(0.0, 0.002 - (lo[boxes, 2].min() + move[2])) + 0.01)


def set_down(world: BoxWorld, boxes: list[int]) -> None:
    """Lower held boxes straight down until DROP_M above what lies under them (the floor or
    a box), as a gripper sets its load down before it opens: a blocker lifted clear of B^top
    comes to rest on the new box instead of being dropped onto it (thesis Fig. 5.9 c)."""
    lo, hi = world.aabbs()
    glo, ghi = lo[boxes].min(axis=0), hi[boxes].max(axis=0)
    tops = [
        hi[i, 2]
        for i in range(world.n)
        if i not in boxes
        and i not in world.removed
        and hi[i, 2] <= glo[2] + 0.002
        and aabb_overlap_xy(glo, ghi, lo[i], hi[i])
    ]
    drop = glo[2] - max(tops, default=0.0) - DROP_M
    if drop > 0.001:
        world.carry_group(boxes, np.array([0.0, 0.0, -drop]))


def insert_from_front(world: BoxWorld, size_m: np.ndarray, pose: np.ndarray) -> int:
    """Carry the new box in through the shelf's open front (x = 0) along +x, at its place's
    height and attitude, held (kinematic: what stands in its way is pushed, and judged), let
    it go at its place and settle (the blocker, if any, still held). A box made to appear at
    its place would push what it overlaps aside by depenetration, through no motion a robot
    could make. Returns the new box's index."""
    pose = np.asarray(pose, dtype=np.float64)
    half_x = float(box_aabb_half_extents(np.asarray(size_m, float), pose[3:])[0])
    start = pose.copy()
    start[0] = min(float(pose[0]), -half_x - FRONT_CLEARANCE_M)
    placed = world.add_box(size_m, start)
    world.hold([placed])
    world.carry_group([placed], np.array([float(pose[0] - start[0]), 0.0, 0.0]))
    world.release([placed])
    world.settle_action()
    return placed


@dataclasses.dataclass
class StepOutcome:
    record: dict[str, Any]
    placed_box: int | None


def execute(
    world: BoxWorld,
    obs: Observation,
    plan: Plan,
    size_m: np.ndarray,
    params: Ch5TrialParams,
    gone: frozenset[int],
    cf: CollapseFreeConfig,
) -> StepOutcome:
    """Execute a plan from the step's canonical start (`world`, fresh): carry the moved
    cluster (held for a placement, set down and let go for a rearrangement), insert the new
    box at the candidate, set every held box down, release it, settle, judge."""
    assert world.steps_taken == 0, "a step starts from a freshly built world"
    start = world.poses().copy()
    n_before = world.n
    moved: list[int] = []
    if plan.move is not None:
        moved = members(obs, plan.move.box_px)
        if moved:
            shift = plan.move.translation_m
            # a gripper closing on standing boxes aligns them: a leaning cluster (C^r / C^l,
            # thesis 5.2.3) and a lone leaning box (classed C^v) alike
            turn = upright_angle_rad(world, moved)
            shift = shift + np.array([0.0, 0.0, floor_lift_m(world, moved, shift, turn)])
            world.carry_group(moved, shift, turn)
            if plan.branch == "rearrange":
                set_down(world, moved)
                world.release(moved)
                world.settle_action()
    placed = None
    if plan.candidate is not None:
        placed = insert_from_front(world, size_m, plan.candidate.pose)
    if world.held():
        set_down(world, world.held())
    world.release(world.held())
    world.settle_action()
    return StepOutcome(
        judge_step(world, start, n_before, moved, placed, plan, params, gone, cf), placed
    )


def judge_step(
    world: BoxWorld,
    start_poses: np.ndarray,
    n_before: int,
    moved: list[int],
    placed: int | None,
    plan: Plan,
    params: Ch5TrialParams,
    gone: frozenset[int],
    cf: CollapseFreeConfig,
) -> dict[str, Any]:
    """A step's named outcome from physics under both criteria (trials/criteria.py), after
    every held box was released and settled: every box but the moved ones is judged, the
    moved ones (carried, then let go) only on staying on the shelf; the new box must rest at
    its place."""
    poses = world.poses()
    now = poses[:, :3]
    on_shelf = world.shelf.contains(now)
    others = [k for k in range(n_before) if k not in moved and k not in gone]
    motion = criteria.box_motion(
        start_poses, poses[:n_before], on_shelf, others, [k for k in moved if k not in gone]
    )
    disp = np.linalg.norm(now[:n_before] - start_poses[:, :3], axis=1)
    at_place = None
    if placed is not None:
        goal = plan.candidate.pose[:3]  # type: ignore[union-attr]
        off = now[placed, 1:] - goal[1:]
        # across (y) within the tolerance; up (z): resting, so not above the drop height and
        # not sunk below its place by more than the tolerance
        at_place = bool(
            on_shelf[placed]
            and abs(off[0]) <= params.place_tol_m
            and abs(off[1]) <= params.place_tol_m
        )
    others_still = criteria.still(motion, params.moved_threshold_m, cf)
    free = criteria.collapse_free(motion, cf)
    placed_ok = at_place if placed is not None else True
    return {
        "branch": plan.branch,
        "moved_boxes": moved,
        "placed": placed is not None,
        "at_place": at_place,
        # a replenishment step always acts (nothing aborts): executed and judged
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": False,
        "extracted": False,
        "others_still": others_still,
        "collapse_free": free,
        "judged": True,
        "strict_judged": True,
        "success": bool(free and placed_ok),
        "strict_success": bool(others_still and placed_ok),
        "n_disturbed": criteria.n_disturbed(motion, params.moved_threshold_m, cf),
        "n_collapsed": criteria.n_collapsed(motion, cf),
        "disturbance_m": float(np.sum(disp[others])) if others else 0.0,
        "box_motion": motion,
    }


# -- the floor and the ceiling -------------------------------------------------------------
def action_set(
    obs: Observation,
    dets: list[Detection],
    size_m: np.ndarray,
    params: ReplenishParams,
    space: WorkingSpace,
) -> list[list[Plan]]:
    """Every action the planner could take from this observation, as step sequences: a
    placement at every candidate; a blocker carried aside per eq. (5.6) and held while placing;
    an obstacle of the blocker moved per eq. (5.9) first, then the same."""
    clusters = place_clusters(obs, dets, space)
    cands = candidates(obs, clusters, size_m, params, space)
    simple = [[Plan("simple", c, None)] for c in cands]
    held, first = [], []
    g = params.finger_m
    for c in cands:
        if not c.occupants or c.occupants[0] < 0 or c.occupants[0] == c.cluster:
            continue
        s = clusters[c.occupants[0]]
        w_new, h_new = new_box_extent_m(size_m, c.side)
        goal = move_goal(s.rect_m, c.side, w_new, h_new, g)
        if not in_working_space(np.array([*goal, *s.rect_m[2:]]), space):
            continue
        move_s = Move(s.index, s.box_px, s.rect_m[:2].copy(), goal, s.cls in ("C^r", "C^l"))
        held.append([Plan("bimanual", c, move_s)])
        for k in clusters:
            if k.index in (s.index, c.cluster):
                continue
            goal_k = rearrange_goal(k.rect_m, s.rect_m, g, goal)
            if not in_working_space(np.array([*goal_k, *k.rect_m[2:]]), space):
                continue
            move_k = Move(k.index, k.box_px, k.rect_m[:2].copy(), goal_k, k.cls in ("C^r", "C^l"))
            first.append([Plan("rearrange", None, move_k), Plan("bimanual", c, move_s)])
    return simple + held + first


# -- the episode ---------------------------------------------------------------------------
def run_ch5_episode(job: dict[str, Any]) -> EpisodeResult:
    """One replenishment trial on scene `job["index"]` of its stream."""
    cond: Ch5ConditionConfig = job["cond"]
    physics: PhysicsConfig = job["physics"]
    camera: CameraConfig = job["camera"]
    spec = draw_trial_spec(
        cond.stream,
        job["stream_cfg"],
        job["seed"],
        job["index"],
        physics,
        camera,
        job["max_attempts"],
        keep_groups=True,
    )
    return replenish(spec, job)


def planner_params(job: dict[str, Any]) -> ReplenishParams:
    p: Ch5TrialParams = job["params"]
    return ReplenishParams(
        finger_m=p.finger_m,
        prob_threshold=job["prob_threshold"],
        iou_threshold=p.iou_threshold,
        use_collapse=job["cond"].planner == "replenish",
        min_points=p.min_points,
    )


def replenish(spec: SceneSpec, job: dict[str, Any], size_m: np.ndarray | None = None):
    """Replenish the settled `spec` with the job's planner -> the episode's record and MCAP
    events (the CLI calls this with a hand-built spec and a given box)."""
    cond: Ch5ConditionConfig = job["cond"]
    params: Ch5TrialParams = job["params"]
    physics: PhysicsConfig = job["physics"]
    camera: CameraConfig = job["camera"]
    if size_m is None:
        size_m = new_box_size(job["seed"], cond.stream, job["index"], params.new_boxes)
    space = space_of(spec)
    rp = planner_params(job)
    planner = None
    if cond.planner in ("replenish", "no_collapse"):
        cmap = collapse_map_fn(job) if cond.planner == "replenish" else None
        planner = ReplenishPlanner(rp, space, cmap)
    state = SceneState.start(spec)
    world = world_at(spec, state, physics, render=True)
    obs = observe(world, camera)
    log = EpisodeLog(record_images=job["record_images"])
    log.scene(0.0, spec.sizes_m, spec.shelf.boards(), obs.camera, obs.depth_m.shape)
    steps: list[dict[str, Any]] = []
    end, t, dt = "max_steps", 0.0, physics.timestep_s
    queued: list[Plan] = []
    simulated = 0
    gave_up_why: list[str] = []
    while len(steps) < params.max_steps:
        log.observation(t, obs.depth_m, obs.instance)
        log.poses(t, state.poses)
        dets = perceive(job, spec, state, obs)
        log.json(t, "/perception/detections", _detections_json(dets))
        if queued:  # the oracle's simulated sequence goes on as simulated
            plan = queued.pop(0)
        elif planner is not None:
            plan = planner.plan(obs, dets, size_m)
            if plan.move is not None and planner.collapse_map is not None and rp.use_collapse:
                heat = planner.collapse_map(obs, _cluster_mask(obs, plan, space))
                log.heatmap(t, "/planner/collapse_map", heat)
        elif cond.planner == "random":
            options = action_set(obs, dets, size_m, rp, space)
            simple = [p[0] for p in options if p[0].branch == "simple"]
            rng = policy_rng(job["seed"], cond.stream, job["index"], "ch5_random")
            plan = simple[int(rng.integers(len(simple)))] if simple else Plan("none", None, None)
        else:
            views = [dets]
            if job.get("oracle_detector"):  # the detector's actions too: no planner beats it
                views.append(perceive(job, spec, state, obs, "detector"))
            seq, tried = oracle_choice(spec, state, obs, views, size_m, rp, space, job)
            simulated += tried
            plan = seq[0]
            queued = seq[1:]
        log.json(t, DECISION_TOPIC, plan_json(plan))
        if plan.branch == "none":
            end = "gave_up"
            why = {re.sub(r" by -?\d+$", "", w) for w in plan.info.get("why_not", []) if w}
            gave_up_why = sorted(why)
            break
        out = execute(world, obs, plan, size_m, params, state.removed, job["collapse_free"])
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
    log.json(t, "/trial/result", {"end": end})
    branch = next(
        (s["branch"] for s in steps if s["placed"]), steps[-1]["branch"] if steps else "none"
    )
    record = {
        "condition": job["condition"],
        "episode": job["index"],
        "seed": job["seed"],
        "stream": cond.stream,
        "family": spec.family,
        "scene_type": job["scene_type"],
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
            "drop_m": job["collapse_free"].drop_m,
            "tilt_deg": job["collapse_free"].tilt_deg,
        },
        "moved_threshold_m": params.moved_threshold_m,
        "n_disturbed": int(sum(s["n_disturbed"] for s in steps)),
        "disturbance_m": round(float(sum(s["disturbance_m"] for s in steps)), 6),
        "rejected_starts": dict(spec.meta.get("rejected", {})),
    }
    if end == "gave_up":  # why no candidate had a plan (planning/replenish.py why_not)
        record["gave_up_why"] = gave_up_why
    if cond.planner == "oracle":
        record["simulated"] = simulated
    return EpisodeResult(_rounded(record), log)


def oracle_choice(
    spec: SceneSpec,
    state: SceneState,
    obs: Observation,
    views: list[list[Detection]],
    size_m: np.ndarray,
    rp: ReplenishParams,
    space: WorkingSpace,
    job: dict[str, Any],
) -> tuple[list[Plan], int]:
    """The first action sequence (in action_set's order, for each set of detections in
    `views` in turn) that succeeds under the strict criterion when simulated from the present
    state exactly as it would be executed, else the first that is collapse-free (a ceiling
    under each criterion: a strict success is collapse-free); none: the first one (it
    fails), or no plan."""
    options = [seq for dets in views for seq in action_set(obs, dets, size_m, rp, space)]
    params: Ch5TrialParams = job["params"]
    physics: PhysicsConfig = job["physics"]
    tried = 0
    free: list[Plan] | None = None
    for seq in options[: params.oracle_budget]:
        tried += 1
        now, view = state, obs
        ok = {"strict_success": True, "success": True}
        for k, plan in enumerate(seq):
            world = world_at(spec, now, physics, render=k > 0)
            if k > 0:  # what execution will see before its next step
                view = observe(world, job["camera"])
            out = execute(world, view, plan, size_m, params, now.removed, job["collapse_free"])
            lost = out.placed_box is None and plan.candidate is not None
            ok = {key: ok[key] and out.record[key] and not lost for key in ok}
            if not ok["success"]:
                break
            now = SceneState.of(world)
        if ok["strict_success"]:
            return seq, tried
        if ok["success"] and free is None:
            free = seq
    if free is not None:
        return free, tried
    if options:
        return options[0], tried
    return [Plan("none", None, None)], tried


def _cluster_mask(obs: Observation, plan: Plan, space: WorkingSpace) -> np.ndarray:
    """The target mask the planner gave the network for the moved cluster (for the MCAP)."""
    from clutterbench.planning.replenish import box_points

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
    params: Ch5TrialParams,
    stream_cfg: SceneStreamConfig,
    seed: int,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    record_images: bool,
    prob_threshold: float,
    scene_type: str,
    oracle_detector: bool = False,
    collapse_free: CollapseFreeConfig | None = None,
) -> list[dict[str, Any]]:
    """One job per episode; `oracle_detector`: an oracle also simulates the actions seen
    through the detector (set when any condition perceives with it); `collapse_free`:
    trials.collapse_free (None: its defaults)."""
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
            "model_path": Path(f"models/{params.model}/best.pt"),
            "detector_path": Path("models/detector/best.pt"),
            "prob_threshold": prob_threshold,
            "max_attempts": max_attempts,
            "record_images": record_images,
            "scene_type": scene_type,
            "oracle_detector": oracle_detector,
            "collapse_free": collapse_free or CollapseFreeConfig(),
        }
        for i in range(cond.episodes)
    ]


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
    if any(c.planner == "replenish" for c in conds.values()):
        if not Path(f"models/{params.model}/best.pt").exists():
            raise ClutterbenchError(
                f"models/{params.model}/best.pt missing; run train@{params.model}"
            )
    if any(c.perception == "detector" for c in conds.values()):
        if not Path("models/detector/best.pt").exists():
            raise ClutterbenchError("models/detector/best.pt missing; run the detector stage")
