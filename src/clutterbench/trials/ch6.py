"""Chapter 6 trials: extract a chosen visible target from a pile (thesis 6.3.2, Table 6.3).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
observe, choose the target, then repeat (Algorithm 1) observe -> plan -> pull in increments
(re-observing between them when the planner monitors the collapse score) -> judge the step
from physics, until the target is out or `max_steps` attempts were made. This module is
the one place that holds both the world and a planner.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.observation import Observation
from clutterbench.planning.cpg import build_cpg, extraction_order, single_arm_plan
from clutterbench.planning.extraction import (
    CollapseGraphPlanner,
    Decision,
    RandomOrderPlanner,
    TargetFirstPlanner,
    visible_objects,
)
from clutterbench.planning.support import SupportEdge, SupportParams
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch6TrialParams, SceneStreamConfig
from clutterbench.trials.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult
from clutterbench.trials.judge import disturbance, judge_episode, judge_step
from clutterbench.trials.scenes import (
    draw_target,
    draw_trial_spec,
    policy_rng,
    pull_consequences,
    spec_of_world,
)

_PREDICTORS: dict[str, Any] = {}


def load_predictor(path: Path, image_size: int):
    """The collapse predictor, loaded once per worker process; returns predict(depth, masks)."""
    from clutterbench.collapse.predict import CollapsePredictor

    key = str(path)
    if key not in _PREDICTORS:
        _PREDICTORS[key] = CollapsePredictor.from_checkpoint(Path(path), image_size=image_size)
    return _PREDICTORS[key]


class OraclePlanner:
    """The ceiling: Algorithm 1 on the true consequences of the action the trials execute.
    For every visible box X, pulling X out is simulated from the present state's canonical
    start; X -> Y when that moves Y beyond the threshold (support, but also a box in front
    that X would push, or one it drags). Its state also lists the visible boxes whose pull
    moves no other box ("safe"): where there is none, no single-arm planner can succeed.
    Lives here, not in planning/, because it reads the world."""

    def __init__(
        self, world: BoxWorld, spec: SceneSpec, physics: PhysicsConfig, params: Ch6TrialParams
    ):
        self.world, self.spec, self.physics, self.params = world, spec, physics, params

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        now, index = spec_of_world(self.world, self.spec)
        ids, _ = visible_objects(obs, self.params.min_pixels)
        visible = [index.index(k) for k in ids if k in index]
        disp = pull_consequences(now, self.physics, visible, self.params.grasp_lift_m)
        edges = [
            SupportEdge(index[a], index[b], float(disp[a][b]))
            for a in visible
            for b in visible
            if a != b and disp[a][b] > self.params.moved_threshold_m
        ]
        graph = build_cpg(edges, target)
        plan = single_arm_plan(graph, target, blocked)
        # The pulls that move no other box at all (hidden ones included): none means every
        # single-arm action from this state disturbs the pile, whatever the planner.
        thr = self.params.moved_threshold_m
        safe = [index[a] for a in visible if not (np.nan_to_num(disp[a]) > thr).any()]
        state = {
            "edges": [[e.supporter, e.supported, round(e.score, 4)] for e in edges],
            "order": extraction_order(graph, target),
            "blocked": sorted(blocked),
            "safe": sorted(safe),
        }
        return Decision(plan.pull, None, state)


def make_planner(job: dict[str, Any], world: BoxWorld, spec: SceneSpec):
    params: Ch6TrialParams = job["params"]
    planner = job["planner"]
    if planner == "single_step":
        return TargetFirstPlanner()
    if planner == "random":
        rng = policy_rng(job["seed"], job["stream"], job["index"], planner)
        return RandomOrderPlanner(rng, params.min_pixels)
    if planner == "oracle":
        return OraclePlanner(world, spec, job["physics"], params)
    predictor = load_predictor(job["model_path"], job["camera"].image_size)
    return CollapseGraphPlanner(
        predictor,
        job["support"],
        job["cp_max"],
        params.min_pixels,
        bimanual=planner == "bimanual",
    )


def pull_out(
    world: BoxWorld,
    decision: Decision,
    planner: Any,
    camera: CameraConfig,
    params: Ch6TrialParams,
    cp_max: float,
    log: EpisodeLog,
) -> dict[str, Any]:
    """Pull `decision.pull` toward the camera in increments (holding `decision.hold`),
    checking the collapse score before each increment when the planner has one; lift it out
    once it has left the shelf, or release it where it is when the score exceeds cp_max."""
    box, hold = decision.pull, decision.hold
    dt = world.cfg.timestep_s
    gone = set(world.removed)
    before = world.positions()
    if hold is not None:
        world.hold([hold])
    monitor = getattr(planner, "collapse_score", None)
    travel = world.pull_travel_m(box)
    pulled, increments, max_cp, aborted = 0.0, 0, 0.0, False
    while pulled < travel - 1e-9:
        if monitor is not None:
            obs = observe(world, camera)
            cp = float(monitor(obs, box, hold))
            max_cp = max(max_cp, cp)
            log.json(world.steps_taken * dt, DECISION_TOPIC, {"box": box, "cp": round(cp, 4)})
            if cp > cp_max:
                aborted = True
                break
        step = min(params.pull_increment_m, travel - pulled)
        world.pull_step(box, step, params.grasp_lift_m)
        pulled += step
        increments += 1
    if aborted:
        world.release([box] + ([hold] if hold is not None else []))
        world.settle_action()
    else:
        world.lift_out(box)
    moved = disturbance(
        before, world.positions(), {box, hold} - {None}, gone, params.moved_threshold_m
    )
    out = {"box": box, "hold": hold, "increments": increments, "max_cp": round(max_cp, 4)}
    return out | judge_step(extracted=not aborted, aborted=aborted, moved=moved)


def run_ch6_episode(job: dict[str, Any]) -> EpisodeResult:
    """One ch. 6 extraction episode on scene `job["index"]` of its stream."""
    spec = draw_trial_spec(
        job["stream"],
        job["stream_cfg"],
        job["seed"],
        job["index"],
        job["physics"],
        job["camera"],
        job["max_attempts"],
    )
    return run_extraction(spec, job)


def run_extraction(
    spec: SceneSpec, job: dict[str, Any], target: int | None = None
) -> EpisodeResult:
    """Extract `target` (None: drawn from the stream's target stream) from the settled `spec`
    with the job's planner -> the episode's record and MCAP events."""
    physics: PhysicsConfig = job["physics"]
    camera: CameraConfig = job["camera"]
    params: Ch6TrialParams = job["params"]
    world = BoxWorld.from_spec(spec, physics, render=True)
    log = EpisodeLog(record_images=job["record_images"])
    dt = physics.timestep_s
    obs = observe(world, camera)
    if target is None:
        target = draw_target(
            job["seed"], job["stream"], job["index"], obs, params.min_target_pixels
        )
    planner = make_planner(job, world, spec)
    start = world.positions()
    steps: list[dict[str, Any]] = []
    blocked: set[int] = set()
    touched: set[int] = set()
    end = "max_steps"
    while len(steps) < params.max_steps:
        t = world.steps_taken * dt
        log.observation(t, obs.depth_m, obs.instance)
        log.poses(t, world.poses())
        try:
            decision = planner.decide(obs, target, frozenset(blocked))
        except ValueError:  # every extractable object was blocked
            end = "stuck"
            break
        log.json(t, DECISION_TOPIC, {"pull": decision.pull, "hold": decision.hold} | decision.state)
        step = pull_out(world, decision, planner, camera, params, job["cp_max"], log)
        if "safe" in decision.state:  # the oracle saw how many visible boxes were safe to pull
            step["safe_pulls"] = len(decision.state["safe"])
        steps.append(step)
        touched.add(decision.pull)
        if step["aborted"]:
            blocked.add(decision.pull)
        else:
            blocked.clear()
        if target in world.removed:
            end = "target_out"
            break
        obs = observe(world, camera)
    t = world.steps_taken * dt
    log.poses(t, world.poses())
    held = {s["hold"] for s in steps if s["hold"] is not None}
    overall = disturbance(
        start, world.positions(), touched | held, set(world.removed), params.moved_threshold_m
    )
    record = {
        "condition": job["condition"],
        "episode": job["index"],
        "seed": job["seed"],
        "stream": job["stream"],
        "family": spec.family,
        "n_objects": spec.n,
        "target": target,
        "planner": job["planner"],
        "perception": "instance",
        "rule": job["rule"] if job["planner"] in ("multi_step", "bimanual") else None,
        "steps": [_rounded(s) for s in steps],
        "end": end,
    } | _rounded(judge_episode(target in world.removed, steps, overall))
    return EpisodeResult(record, log)


def _rounded(d: dict[str, Any]) -> dict[str, Any]:
    """Floats to 1e-6 (micrometres) so records read cleanly; the bits stay deterministic."""
    return {k: round(v, 6) if isinstance(v, float) else v for k, v in d.items()}


def ch6_jobs(
    condition: str,
    cond: Any,
    trials: Any,
    stream_cfg: SceneStreamConfig,
    seed: int,
    physics: PhysicsConfig,
    camera: CameraConfig,
    support: SupportParams | None,
    cp_max: float,
    model_path: Path,
) -> list[dict[str, Any]]:
    return [
        {
            "condition": condition,
            "planner": cond.planner,
            "rule": cond.rule,
            "stream": cond.stream,
            "stream_cfg": stream_cfg,
            "index": i,
            "seed": seed,
            "physics": physics,
            "camera": camera,
            "params": trials.ch6,
            "support": support,
            "cp_max": cp_max,
            "model_path": model_path,
            "max_attempts": trials.max_attempts,
            "record_images": trials.mcap_images,
        }
        for i in range(cond.episodes)
    ]
