"""Chapter 6 trials: extract a chosen visible target from a pile (thesis 6.3.2, Table 6.3).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
observe, choose the target, then repeat (Algorithm 1) observe -> plan -> pull in increments
(re-observing between them when the planner monitors the collapse score) -> release -> judge
the step from physics, under the episode protocol of trials/core/protocol.py (the episode ends
at its first failed step). This module is the one place that holds both the world and a
planner.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.observation import Observation
from clutterbench.planning.ch6.extraction import Decision
from clutterbench.planning.ch6.support import SupportParams
from clutterbench.sim import benchmark
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.pull import SceneState, execute_pull, world_at
from clutterbench.sim.spec import SceneSpec
from clutterbench.support.config import box_head_files
from clutterbench.trials.ch6.jobs import Ch6Job
from clutterbench.trials.ch6.oracle import SearchOracle
from clutterbench.trials.ch6.planners import (  # noqa: F401  (register_planner, PLANNERS: the documented entry points)
    BOX_HEAD,
    PLANNERS,
    box_fusion,
    box_thresholds,
    chosen_support,
    load_planners,
    make_planner,
    planner_info,
    register_planner,
    truth_maps_of,
)
from clutterbench.trials.ch6.planners import declared as planner_declared
from clutterbench.trials.ch6.seeing import Eyes
from clutterbench.trials.ch6_groups import PullExecution
from clutterbench.trials.config import Ch6TrialParams, ConditionConfig, TrialsConfig
from clutterbench.trials.core.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult
from clutterbench.trials.core.jobs import shelf_fields
from clutterbench.trials.core.judge import disturbance
from clutterbench.trials.core.protocol import episode_end, judge_episode, judge_pull, step_notes


def _judge(
    result: Any,
    box: int,
    hold: int | None,
    gone: frozenset[int],
    pull: PullExecution,
    cf: CollapseFreeConfig,
    *,
    by_arm: bool,
) -> dict[str, Any]:
    """The executed pull judged: by the kinematic judge, or the arm's."""
    if not by_arm:
        return judge_pull(result, box, hold, gone, pull.moved_threshold_m, cf)
    from clutterbench.trials.core.executors import judge_arm_step

    return judge_arm_step(result, box, hold, gone, pull.moved_threshold_m, cf)


def job_spec(job: Ch6Job) -> SceneSpec:
    """The settled scene `job.index` of the job's stream."""
    return job.start.spec()


def run_ch6_episode(job: Ch6Job) -> EpisodeResult:
    """One ch. 6 extraction episode on scene `job.index` of its stream."""
    return run_extraction(job_spec(job), job)


def run_extraction(spec: SceneSpec, job: Ch6Job, target: int | None = None) -> EpisodeResult:
    """Extract `target` (None: drawn from the stream's target stream) from the settled `spec`
    with the job's planner under the episode protocol (trials/core/protocol.py) -> the episode's
    record and MCAP events."""
    episode = Extraction(spec, job, target)
    planner = make_planner(job, spec)
    while not episode.done:
        episode.before_decision(planner)
        try:
            target = episode.eyes.pointed(episode.target)
            decision = planner.decide(episode.obs, target, frozenset(episode.blocked))
        except ValueError:  # every action the planner would take is rejected by its own rule
            episode.give_up()
            break
        episode.step(decision, planner)
    return episode.result(planner)


class Extraction:
    """One ch. 6 extraction episode as a stepping object: the canonical start, then one
    `step(decision, planner)` per decision under the episode protocol (trials/core/protocol.py)
    until `done`; `result()` is the episode's record. The trials' loop (run_extraction) and
    the planning env (envs/plan.py) both drive it, so both run one protocol. `planner` is
    whatever made the decision: its `collapse_score` (if any) monitors the pull, as
    Algorithm 1 does; a planner that reads the world (oracle, truth maps) is handed the
    state in `before_decision`."""

    def __init__(self, spec: SceneSpec, job: Ch6Job, target: int | None = None):
        self.spec, self.job = spec, job
        self.physics: PhysicsConfig = job.physics
        self.camera: CameraConfig = job.camera
        self.params: Ch6TrialParams = job.params
        self.state = SceneState.start(spec)
        self.world = world_at(spec, self.state, self.physics, render=True)
        self.log = EpisodeLog(record_images=job.record_images)
        self.eyes = Eyes(job, spec)
        self.obs = self.eyes.look(self.world)
        self.log.scene(
            0.0, spec.sizes_m, spec.shelf.boards(), self.obs.camera, self.obs.depth_m.shape
        )
        if target is None:  # drawn from the simulator's masks: the same under every perception
            target = job.start.target(self.eyes.truth, self.params.min_target_pixels, spec)
        self.target = target
        self.steps: list[dict[str, Any]] = []
        self.blocked: set[int] = set()
        """Boxes whose last pull aborted (planners skip them until a step succeeds)."""
        self.end: str | None = None
        """Why the episode ended (protocol.EPISODE_ENDS), None while it goes on."""
        self.t = 0.0

    @property
    def done(self) -> bool:
        return self.end is not None

    def before_decision(self, planner: Any) -> None:
        """Log the observation the next decision reads; give world-reading planners the
        state (the oracle's search, physics-truth maps)."""
        self.log.observation(self.t, self.obs.depth_m, self.obs.instance)
        self.log.poses(self.t, self.state.poses, self.state.removed)
        if isinstance(planner, SearchOracle):
            planner.state = self.state
        truth = truth_maps_of(planner)
        if truth is not None:
            truth.at(self.state, self.obs.instance)

    def give_up(self) -> None:
        """The planner has no action left: the episode ends."""
        self.end = "gave_up"

    def step(self, decision: Decision, planner: Any) -> dict[str, Any]:
        """Execute `decision` from the step's canonical start, judge it, and decide whether
        the episode goes on (then the next step's canonical start is built) -> the step."""
        assert not self.done, "the episode has ended"
        params, spec = self.params, self.spec
        t = self.t
        self.log.json(
            t, DECISION_TOPIC, {"pull": decision.pull, "hold": decision.hold} | decision.state
        )
        grasped = self.eyes.grasped(decision.pull), self.eyes.grasped(decision.hold)
        if grasped[0] is None or (decision.hold is not None and grasped[1] is None):
            return self._missed_grasp(decision)
        void_hold = grasped[1] is not None and grasped[1] == grasped[0]
        if void_hold:  # two segments of one box: the second arm finds it taken and stays idle
            grasped = (grasped[0], None)
        step, self.state, elapsed = self.execute_decision(decision, planner, grasped)
        if void_hold:
            step["grasp"] = "hold on the pulled box"
        self.steps.append(step)
        self.t = t + elapsed
        if step["aborted_before_motion"] or step["aborted_after_motion"]:
            self.blocked.add(decision.pull)
        else:
            self.blocked.clear()
        target = self.target
        target_out = target in self.state.removed
        on_shelf = bool(spec.shelf.contains(self.state.poses[target : target + 1])[0])
        self.end = episode_end(step, target_out, target_out or on_shelf)
        if self.end is None:
            # the next step's canonical start
            self.world = world_at(spec, self.state, self.physics, render=True)
            self.obs = self.eyes.look(self.world)
            if len(self.steps) >= params.max_steps:
                self.end = "max_steps"
        return step

    def _missed_grasp(self, decision: Decision) -> dict[str, Any]:
        """A decision whose grasp takes no box (a segment on no box): a failed step that moved
        nothing; the episode ends there."""
        step = judge_pull(None, -1, None, self.state.removed, 0.0, self.job.collapse_free)
        step |= {"aborted_before_motion": False, "judged": True, "counted": True}
        step |= {"strict_counted": True, "success": False, "strict_success": False}
        step |= {"success_held": False, "grasp": "no box"}
        seen = {"seen_pull": decision.pull, "seen_hold": decision.hold}
        step = {"box": None, "hold": None, "increments": 0, "max_cp": 0.0} | step | seen
        self.steps.append(step)
        self.end = "missed_grasp"
        return step

    def execute_decision(
        self, decision: Decision, planner: Any, grasped: tuple[int, int | None] | None = None
    ) -> tuple[dict[str, Any], SceneState, float]:
        """Execute one decision from the step's canonical start (`self.world`, fresh) and
        judge it: pull in increments, checking the planner's collapse score before each (the
        first check reads the observation the planner decided on, so a box its own rule
        rejects is never picked and then aborted before motion), release, settle, judge.
        With the job's executor `arm`, executed arm-level by Pandas from the step's start
        (trials/arm/episodes.py; `self.world` then only pictures).
        `grasped`: the boxes the grasps of the decision's pull and hold take (None: the
        decision's ids, the simulator's masks).
        -> the step's record, the state it left, its duration (s)."""
        job, world, obs, pull = self.job, self.world, self.obs, self.params.pull
        seen_box, seen_hold = decision.pull, decision.hold  # what the planner's monitor reads
        box, hold = grasped or (seen_box, seen_hold)
        by_arm, t0, gone = job.executor == "arm", self.t, self.state.removed
        dt = world.cfg.timestep_s
        monitor = getattr(planner, "collapse_score", None)
        max_cp = 0.0

        truth = truth_maps_of(planner)
        # the job's abort threshold, or a least-risk pull's own
        limit = job.cp_max if decision.cp_max is None else decision.cp_max

        def score(done: int, now: Observation | None, t: float) -> bool:
            nonlocal max_cp
            if monitor is None:
                return True
            if truth is not None and done:  # truth maps of the present, mid-pull state
                assert not by_arm and now is not None, "truth maps run on the kinematic executor"
                truth.at(SceneState.of(world), now.instance, world.held())
            cp = float(monitor(obs if done == 0 else now, seen_box, seen_hold))
            max_cp = max(max_cp, cp)
            self.log.json(t, DECISION_TOPIC, {"box": seen_box, "cp": round(cp, 4)})
            return cp <= limit

        arm_fields: dict[str, Any] = {}
        if not by_arm:
            result = execute_pull(
                world,
                box,
                hold,
                pull.increment_m,
                pull.grasp_lift_m,
                go_on=lambda done: score(
                    done,
                    self.eyes.look(world) if done and monitor else None,
                    t0 + world.steps_taken * dt,
                ),
                **pull.release(),
            )
            state, elapsed = SceneState.of(world), world.steps_taken * dt
        else:
            result, arm_fields, state, elapsed = self._execute_by_arm(decision, score)
        step = _judge(result, box, hold, gone, pull, job.collapse_free, by_arm=by_arm)
        record = {
            "box": box,
            "hold": hold,
            "increments": result.increments,
            "max_cp": round(max_cp, 4),
        } | step
        if (seen_box, seen_hold) != (box, hold):  # the planner's names of what it grasped
            record |= {"seen_pull": seen_box, "seen_hold": seen_hold}
        return record | step_notes(decision.state) | arm_fields, state, elapsed

    def _execute_by_arm(
        self, decision: Decision, score: Callable[[int, Observation | None, float], bool]
    ) -> tuple[Any, dict[str, Any], SceneState, float]:
        """execute_decision's pull executed arm-level (trials/core/executors.py) from the
        step's start, checked by `score` -> the pull's result, the arm's record fields, the
        state it left, its duration."""
        from clutterbench.trials.core.executors import arm_pull

        pull, t0 = self.params.pull, self.t
        done_by_arm = arm_pull(
            self.spec,
            self.state,
            decision.pull,
            decision.hold,
            pull.increment_m,
            pull.grasp_lift_m,
            self.world.cfg,
            self.job.arm,
            self.log,
            t0,
            go_on=lambda done, now: score(done, now, t0),
            camera=self.camera,
            sensing=self.job.sensing,
        )
        result, arm_fields = done_by_arm.result, done_by_arm.fields
        state, elapsed = done_by_arm.state, done_by_arm.elapsed_s
        return result, arm_fields, state, elapsed

    def result(self, planner: Any) -> EpisodeResult:
        """The episode's record (trials/core/records.py) and its MCAP events."""
        assert self.done, "the episode has not ended"
        job, params, spec, state, steps = self.job, self.params, self.spec, self.state, self.steps
        truth = truth_maps_of(planner)
        declared = planner_declared(job.planner)  # an agent's episodes: no registered planner
        log = self.log
        log.poses(self.t, state.poses, state.removed)
        touched = {s["box"] for s in steps}
        overall = disturbance(
            np.asarray(spec.poses)[:, :3],
            state.poses[:, :3],
            touched,
            set(state.removed) - touched,
            params.moved_threshold_m,
        )
        record = {
            "condition": job.condition,
            "episode": job.index,
            "seed": job.seed,
            "stream": job.stream,
            "family": spec.family,
            **benchmark.scene_fields(spec),
            "n_objects": spec.n,
            "target": self.target,
            "planner": job.planner,
            "perception": job.perception,
            "rule": job.rule if declared.algorithm1 else None,
            "support_method": declared.support_method(job.rule, job.params.pull_map_meaning)
            if declared.algorithm1
            else None,
            "collapse_maps": declared.maps_text(job.params.pull_map_meaning),
            "rejected_starts": dict(spec.meta.get("rejected", {})),
            "collapse_free_params": {
                "drop_m": job.collapse_free.drop_m,
                "tilt_deg": job.collapse_free.tilt_deg,
            },
            "moved_threshold_m": params.moved_threshold_m,
            "steps": [_rounded(s) for s in steps],
            "n_disturbed": overall.n_disturbed,
            "disturbance_m": overall.disturbance_m,
        } | judge_episode(steps, self.end, self.target)
        if job.executor == "arm":  # kinematic records keep their old fields
            record["executor"] = "arm"
        if job.sensing != "ideal":  # ... and so do ideal ones
            record["sensing"] = job.sensing
        record |= self.eyes.record_fields()
        if truth is not None:
            record["truth_simulations"] = truth.simulations
        if isinstance(planner, SearchOracle):
            record |= {
                "search_nodes": planner.nodes,
                "search_exhausted": planner.exhausted,
                "search_replanned": planner.replanned,
                # what the first search proved possible under each criterion (the ceilings)
                "search_found_strict": bool(planner.found.get("strict_success", False)),
                "search_found": bool(planner.found.get("success", False)),
            }
        simulated = getattr(getattr(planner, "predict", None), "simulated", None)
        if declared.reads_box_head and simulated is not None:
            record["box_pulls_simulated"] = int(simulated)  # the fused planners' physics calls
        if hasattr(planner, "first") and hasattr(planner, "steps"):  # physics from depth
            from clutterbench.trials.ch6.physics_model import estimate_record

            record |= estimate_record(planner, spec)
        return EpisodeResult(_rounded(record), log)


def _rounded(d: dict[str, Any]) -> dict[str, Any]:
    """Floats to 1e-6 (micrometres) so records read cleanly; the bits stay deterministic."""
    return {k: round(v, 6) if isinstance(v, float) else v for k, v in d.items()}


def planner_support(
    thresholds: Path, planner: str, rule: str, ch6: Any, sensing: str = "ideal"
) -> tuple[SupportParams, float]:
    """A CP planner's support thresholds and its abort threshold cp_max: the support stage's
    choice on validation scenes (their depth as `sensing` returns it) for its method
    (Planner.support_method), the pull-head
    planners' overridden by trials.ch6.pull_prob_threshold / pull_score_threshold where set
    (chosen on dev streams); cp_max: trials.ch6.cp_max, else the score threshold."""
    declared = planner_info(planner)
    method = declared.support_method(rule, ch6.pull_map_meaning)
    support = chosen_support(thresholds, method, sensing)
    if declared.maps == "pull":
        over = {
            "prob_threshold": ch6.pull_prob_threshold,
            "score_threshold": ch6.pull_score_threshold,
        }
        support = dataclasses.replace(support, **{k: v for k, v in over.items() if v is not None})
    return support, ch6.cp_max if ch6.cp_max is not None else support.score_threshold


def box_fields(
    thresholds: Path, planner: str, ch6: Any, sensing: str = "ideal"
) -> tuple[dict[str, Any], float | None]:
    """A box planner's job fields (its head's checkpoint, edge threshold and, learned plus
    physics, its fusion's weights) and its cp_max (the outcome threshold), all chosen on
    validation scenes (their depth as `sensing` returns it) by the support stage, cp_max
    overridden by trials.ch6.box_cp_max where
    set (chosen on dev streams); ({}, None) for any other planner. One line when the box
    head is missing."""
    declared = planner_info(planner)
    if not declared.reads_box_head:
        return {}, None
    head = box_head_files(sensing)[0]  # a sensed row's: trained on its sensor's depth
    if not head.exists():
        stage = "box_head" if sensing == "ideal" else "box_head_sensed"
        raise ClutterbenchError(f"{head} missing (planner {planner} reads it); run {stage}")
    if declared.maps == "box_physics":
        edge, outcome, weights, contact = box_fusion(
            thresholds, ch6.pull_map_meaning, ch6.box_contact, sensing
        )
        fields = {"box_head_path": head, "box_edge_threshold": edge, "box_fusion": weights}
        fields |= {"box_contact": contact}
    else:
        edge, outcome = box_thresholds(thresholds, ch6.pull_map_meaning, sensing)
        fields = {"box_head_path": head, "box_edge_threshold": edge}
    return fields, outcome if ch6.box_cp_max is None else ch6.box_cp_max


def condition_jobs(
    name: str,
    cond: ConditionConfig,
    *,
    trials: TrialsConfig,
    sim: SimConfig,
    seed: int,
    thresholds: Path,
) -> tuple[list[Ch6Job], SupportParams, float]:
    """Condition `cond`'s episode jobs, with its support rule's thresholds (chosen on
    validation scenes as its sensor returns them by the support stage, `thresholds`) and its
    abort threshold cp_max;
    one-line errors when a network is missing."""
    declared = planner_info(cond.planner)
    networks = {"cp": trials.ch6.model, "ch4": trials.ch6.ch4_model}
    for model in sorted({networks[n] for n in declared.networks if n in networks}):
        if not Path(f"models/{model}/best.pt").exists():
            raise ClutterbenchError(
                f"models/{model}/best.pt missing (planner {cond.planner} reads it); run "
                f"train@{model}"
            )
    if cond.executor == "arm" and declared.reads_truth_maps:
        raise ClutterbenchError(
            f"trials.conditions.{name}: planner {cond.planner} reads physics-truth maps, which "
            "run on the kinematic executor only (executor: kinematic)"
        )
    if cond.perception == "depth" and (declared.world == "truth" or cond.executor == "arm"):
        raise ClutterbenchError(
            f"trials.conditions.{name}: perception depth is for planners that read what a "
            f"robot sees ({cond.planner} reads the world: {declared.world}) on the kinematic "
            f"executor ({cond.executor})"
        )
    support, cp_max = planner_support(thresholds, cond.planner, cond.rule, trials.ch6, cond.sensing)
    box, box_cp_max = box_fields(thresholds, cond.planner, trials.ch6, cond.sensing)
    cp_max = box_cp_max if box_cp_max is not None else cp_max
    jobs = ch6_jobs(
        name,
        cond,
        trials=trials,
        sim=sim,
        seed=seed,
        support=support,
        cp_max=cp_max,
        model_path=Path(f"models/{trials.ch6.model}/best.pt"),
        **box,
    )
    return jobs, support, cp_max


def ch6_jobs(
    condition: str,
    cond: ConditionConfig,
    *,
    trials: TrialsConfig,
    sim: SimConfig,
    seed: int,
    support: SupportParams | None,
    cp_max: float,
    model_path: Path | None,
    **override: Any,
) -> list[Ch6Job]:
    """Condition `condition`'s episode jobs, their fields from the configs (trials.ch6,
    trials.streams[cond.stream], trials' max_attempts, mcap_images, collapse_free and arm,
    sim's physics and camera) but for the Ch6Job fields `override` names."""
    fields = shelf_fields(cond.stream, trials, sim, seed, override)
    return [
        Ch6Job(
            condition=condition,
            planner=cond.planner,
            rule=cond.rule,
            stream=cond.stream,
            index=i,
            params=trials.ch6,
            support=support,
            cp_max=cp_max,
            model_path=model_path,
            ch4_model_path=Path(f"models/{trials.ch6.ch4_model}/best.pt"),
            executor=cond.executor,
            arm=trials.arm,
            sensing=cond.sensing,
            perception=cond.perception,
            **fields,
        )
        for i in range(cond.episodes)
    ]
