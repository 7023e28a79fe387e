"""Chapter 6 trials: extract a chosen visible target from a pile (thesis 6.3.2, Table 6.3).

An episode: draw a scene from the condition's stream and settle it (the canonical start),
observe, choose the target, then repeat (Algorithm 1) observe -> plan -> pull in increments
(re-observing between them when the planner monitors the collapse score) -> release -> judge
the step from physics, under the episode protocol of trials/protocol.py (the episode ends
at its first failed step). This module is the one place that holds both the world and a
planner.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.maniskill.config import ArmConfig
from clutterbench.observation import Observation
from clutterbench.planning.extraction import (
    CollapseGraphPlanner,
    Decision,
    RandomOrderPlanner,
    TargetFirstPlanner,
    visible_objects,
)
from clutterbench.planning.support import SupportParams
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState, execute_pull, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch6TrialParams, SceneStreamConfig
from clutterbench.trials.criteria import CollapseFreeConfig
from clutterbench.trials.harness import DECISION_TOPIC, EpisodeLog, EpisodeResult, load_predictor
from clutterbench.trials.judge import disturbance
from clutterbench.trials.protocol import episode_end, judge_episode, judge_pull
from clutterbench.trials.scenes import draw_target, draw_trial_spec, policy_rng
from clutterbench.trials.truth_maps import TruthCollapseMaps

Action = tuple[int, "int | None"]
"""(box to pull, box the second arm holds or None)."""


class SearchOracle:
    """The ceiling: a depth-first search over sequences of pulls, each simulated from the
    present state with the trials' own step (`protocol.execute_pull` in a world built by
    `protocol.world_at`, released and judged as an executed step is), memoized over the set
    of removed boxes, for a sequence of clean steps that ends with the target out.

    Actions: every visible box (planners see no other) and the target; with `holding`, the
    target may also be pulled while any one visible box is held (the bimanual and ch. 4
    planners hold one box while pulling the target), the boxes its unheld pull disturbs
    tried first. Holding a box that the unheld pull leaves within the threshold can still
    save the others (it stops the few millimetres that let them slide), so no box is left
    out. As execution reproduces the simulation bit for bit, the plan found is followed; no
    planner succeeds on an episode where the search proved there is no such sequence,
    unless a node budget ran out (counted) or a planner's aborted pull left a state outside
    the search's actions.
    Lives here, not in planning/, because it reads the world."""

    def __init__(
        self,
        spec: SceneSpec,
        physics: PhysicsConfig,
        camera: CameraConfig,
        params: Ch6TrialParams,
        holding: bool,
        cf: CollapseFreeConfig,
    ):
        self.spec, self.physics, self.camera, self.params = spec, physics, camera, params
        self.holding, self.cf = holding, cf
        self.state: SceneState | None = None  # set by the harness before each decision
        self._plan: list[tuple[Action, SceneState]] = []
        self._expected: SceneState | None = None
        self.nodes = self.searches = self.exhausted = self.replanned = 0
        self.found: dict[str, bool] = {}  # criterion -> a clean sequence found (first search)

    # -- simulation -------------------------------------------------------------------------
    def simulate(
        self, state: SceneState, action: Action, cut_short: bool = True
    ) -> tuple[dict[str, Any], SceneState | None, np.ndarray | None]:
        """One step from `state` as the harness executes it -> (its judgement, the state it
        leaves, (N,) displacements). With `cut_short`, a pull during which another box (not
        held) has already moved more than `search_cut_m` is stopped there and judged a
        failure (no state, no displacements): that box does not come back within the moved
        threshold, and most simulated pulls in a pile fail, so this is most of the search's
        saving."""
        world = world_at(self.spec, state, self.physics)
        p = self.params
        box, hold = action
        watch = [k for k in range(self.spec.n) if k not in state.removed and k not in action]

        def go_on(done: int) -> bool:
            if done and watch and np.max(world.displacements()[watch]) > p.search_cut_m:
                raise _CutShort
            return True

        try:
            result = execute_pull(
                world, box, hold, p.pull_increment_m, p.grasp_lift_m, go_on if cut_short else None
            )
        except _CutShort:
            return {"success": False, "strict_success": False, "cut_short": True}, None, None
        step = judge_pull(result, box, hold, state.removed, p.moved_threshold_m, self.cf)
        return step, SceneState.of(world), result.displacement_m

    def candidates(self, state: SceneState, target: int) -> list[int]:
        """What a planner could pull in `state`: the visible boxes and the target."""
        obs = observe(world_at(self.spec, state, self.physics, render=True), self.camera)
        ids, _ = visible_objects(obs, self.params.min_pixels)
        return sorted(set(ids) | {target})

    def search(
        self, state: SceneState, target: int, key: str = "strict_success"
    ) -> tuple[list | None, int, bool]:
        """(plan: [(action, state after it)] or None, nodes expanded, budget exhausted): a
        sequence of steps each clean under the criterion `key` ("strict_success", pulls cut
        short once another box moved `search_cut_m`; or "success", collapse-free, pulls never
        cut short: a box that slid far may still be collapse-free)."""
        cut = key == "strict_success"
        visited: set[frozenset[int]] = {state.removed}
        nodes = 0
        budget = self.params.search_node_budget

        class _Budget(Exception):
            pass

        def visit(now: SceneState) -> list | None:
            nonlocal nodes
            if nodes >= budget:
                raise _Budget
            nodes += 1
            boxes = self.candidates(now, target)
            first, after, disp = self.simulate(now, (target, None), cut_short=False)
            if first[key]:
                return [((target, None), after)]
            # The boxes the target's pull disturbed: what stands in its way, and the holds
            # most likely to save it, so they are tried first.
            in_way = np.nan_to_num(disp, nan=0.0) > self.params.moved_threshold_m
            if self.holding:
                others = sorted((b for b in boxes if b != target), key=lambda b: (not in_way[b], b))
                for h in others:
                    step, after, _ = self.simulate(now, (target, h), cut_short=cut)
                    if step[key]:
                        return [((target, h), after)]
            children = []
            for x in boxes:
                if x != target:
                    step, after, _ = self.simulate(now, (x, None), cut_short=cut)
                    if step[key]:
                        children.append((x, after))
            children.sort(key=lambda c: (not in_way[c[0]], c[0]))
            for x, after in children:
                if after.removed in visited:
                    continue
                visited.add(after.removed)
                rest = visit(after)
                if rest is not None:
                    return [((x, None), after), *rest]
            return None

        try:
            return visit(state), nodes, False
        except _Budget:
            return None, nodes, True

    def plan_from(
        self, state: SceneState, target: int
    ) -> tuple[list | None, dict[str, bool], dict[str, Any]]:
        """(plan or None, found per criterion, search info): a ceiling under each criterion
        from one search tree: a strict sequence is also collapse-free, so it is searched
        first; only where none exists is the larger collapse-free tree searched."""
        found: dict[str, bool] = {}
        info: dict[str, Any] = {}
        plan = None
        for key in ("strict_success", "success"):
            plan, nodes, exhausted = self.search(state, target, key)
            self.searches += 1
            self.nodes += nodes
            self.exhausted += exhausted
            found[key] = plan is not None
            info |= {f"{key}_search_nodes": nodes, f"{key}_exhausted": exhausted}
            if plan is not None:
                found.setdefault("success", True)
                break
        return plan, found, info

    # -- the planner interface --------------------------------------------------------------
    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        state = self.state
        assert state is not None, "the harness sets the oracle's state before each decision"
        info: dict[str, Any] = {"policy": "oracle_hold" if self.holding else "oracle"}
        if self._plan and not _same_state(self._expected, state):
            self.replanned += 1  # the world left the simulated path: search again
            self._plan = []
        if not self._plan:
            plan, found, searched = self.plan_from(state, target)
            self.found = self.found or found
            info |= searched | {"found": found}
            self._plan = list(plan or [])
        if not self._plan:
            # No clean sequence exists (or the budget ran out): pull the target; it fails.
            return Decision(target, None, info | {"plan": None})
        (pull, hold), self._expected = self._plan.pop(0)
        info["plan"] = [[pull, hold], *[list(a) for a, _ in self._plan]]
        return Decision(pull, hold, info)


class _CutShort(Exception):
    """A simulated pull already disturbed another box beyond recovery."""


def _same_state(a: SceneState, b: SceneState) -> bool:
    return a.removed == b.removed and np.array_equal(a.poses, b.poses)


class SupportWhilePullPlanner:
    """The thesis' previous method as the single-step rows of Table 6.3 (their counts equal
    the various-size cells of Table 4.1): pull the target at once while the second arm holds
    the support of least risk r_c chosen by the chapter 4 network (eqs. 4.1, 4.2)."""

    def __init__(self, predictor: Any, params: Ch6TrialParams):
        self.predictor, self.params = predictor, params

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        from clutterbench.perception.masks import segment
        from clutterbench.planning.risk_planner import plan_risk

        seg = segment(obs, "instance", min_pixels=self.params.min_pixels)
        if target not in seg.ids or len(seg.ids) < 2:
            return Decision(target, None, {"policy": "single_step", "support": None})
        choice, pairs, risks, _ = plan_risk(
            self.predictor, obs, seg, seg.ids.index(target), self.params.ch4_pixel_threshold
        )
        hold = seg.ids[choice.support] if choice.support is not None else None
        finite = np.isfinite(choice.risk)
        state = {
            "policy": "single_step",
            "support": hold,
            "risk": round(float(choice.risk), 4) if finite else None,
        }
        return Decision(target, hold, state)


PLANNERS: dict[str, Callable[[dict[str, Any], SceneSpec], Any]] = {}
"""ch. 6 planner name -> factory(job, spec): the registry the conditions' `planner` names."""


def chosen_support(thresholds: Path, rule: str) -> SupportParams:
    """The support rule's thresholds chosen on validation scenes by the support stage."""
    from clutterbench.io import read_json

    chosen = read_json(thresholds)
    try:
        return SupportParams(**chosen["chosen"][rule])
    except (KeyError, TypeError) as exc:
        raise ClutterbenchError(
            f"{thresholds}: no usable thresholds for rule '{rule}' ({exc}); rerun the support stage"
        ) from None


def register_planner(name: str):
    """Register a ch. 6 planner factory under `name` (usable as a condition's planner)."""

    def wrap(factory):
        PLANNERS[name] = factory
        return factory

    return wrap


@register_planner("pull_target")
def _pull_target(job: dict[str, Any], spec: SceneSpec):
    return TargetFirstPlanner()


@register_planner("single_step")
def _single_step(job: dict[str, Any], spec: SceneSpec):
    return SupportWhilePullPlanner(
        load_predictor(job["ch4_model_path"], job["camera"].image_size), job["params"]
    )


@register_planner("random")
def _random(job: dict[str, Any], spec: SceneSpec):
    rng = policy_rng(job["seed"], job["stream"], job["index"], job["planner"])
    return RandomOrderPlanner(rng, job["params"].min_pixels)


@register_planner("oracle")
def _oracle(job: dict[str, Any], spec: SceneSpec):
    return SearchOracle(
        spec, job["physics"], job["camera"], job["params"], False, job["collapse_free"]
    )


@register_planner("oracle_hold")
def _oracle_hold(job: dict[str, Any], spec: SceneSpec):
    return SearchOracle(
        spec, job["physics"], job["camera"], job["params"], True, job["collapse_free"]
    )


def _cpg_planner(job: dict[str, Any], bimanual: bool, spec: SceneSpec | None = None):
    """Algorithm 1 with the collapse predictor, or (`spec` given) with physics-truth maps of
    that scene through the same interface: the same planner, rule and thresholds."""
    params: Ch6TrialParams = job["params"]
    if spec is None:
        predictor = load_predictor(job["model_path"], job["camera"].image_size)
    else:
        predictor = TruthCollapseMaps(spec, job["physics"], params.moved_threshold_m)
    return CollapseGraphPlanner(
        predictor, job["support"], job["cp_max"], params.min_pixels, bimanual=bimanual
    )


@register_planner("multi_step")
def _multi_step(job: dict[str, Any], spec: SceneSpec):
    return _cpg_planner(job, bimanual=False)


@register_planner("bimanual")
def _bimanual(job: dict[str, Any], spec: SceneSpec):
    return _cpg_planner(job, bimanual=True)


@register_planner("multi_step_truth")
def _multi_step_truth(job: dict[str, Any], spec: SceneSpec):
    return _cpg_planner(job, bimanual=False, spec=spec)


@register_planner("bimanual_truth")
def _bimanual_truth(job: dict[str, Any], spec: SceneSpec):
    return _cpg_planner(job, bimanual=True, spec=spec)


def _physics_from_depth(job: dict[str, Any], spec: SceneSpec, holding: bool):
    """The physics-from-depth planner (planning/physics_depth.py): boxes fitted to each
    observation, searched in SAPIEN by the oracle's code on that estimate. Of the episode's
    spec it gets the shelf only (fixed, a robot knows it); of its stream the catalogue."""
    from clutterbench.planning.physics_depth import PhysicsFromDepthPlanner
    from clutterbench.trials.physics_model import EstimatedWorldModel, make_estimator

    params: Ch6TrialParams = job["params"]
    model = EstimatedWorldModel(
        spec.shelf,
        job["camera"],
        job["physics"],
        params,
        holding,
        job["collapse_free"],
        SearchOracle,
    )
    estimate = make_estimator(job["stream_cfg"].catalogue, params.min_pixels)
    return PhysicsFromDepthPlanner(estimate, model, holding)


@register_planner("physics_from_depth")
def _pfd(job: dict[str, Any], spec: SceneSpec):
    return _physics_from_depth(job, spec, holding=False)


@register_planner("physics_from_depth_hold")
def _pfd_hold(job: dict[str, Any], spec: SceneSpec):
    return _physics_from_depth(job, spec, holding=True)


CP_PLANNERS = ("multi_step", "bimanual", "multi_step_truth", "bimanual_truth")
"""The planners of Algorithm 1 (a support rule, cp_max); `*_truth` read physics-truth maps."""


def reads_truth_maps(name: str) -> bool:
    return name.endswith("_truth") and name in CP_PLANNERS


def truth_maps_of(planner: Any) -> TruthCollapseMaps | None:
    """The physics-truth maps a planner reads instead of the collapse predictor, if any."""
    maps = getattr(planner, "predict", None)
    return maps if isinstance(maps, TruthCollapseMaps) else None


def load_planners(modules: Sequence[str], names: Sequence[str]) -> None:
    """Import the modules that register extra planners, then check that every planner a
    condition names is registered (one line naming the first that is not)."""
    import importlib

    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ClutterbenchError(
                f"trials.planner_modules: cannot import {module} ({exc})"
            ) from None
    for name in names:
        if name not in PLANNERS:
            raise ClutterbenchError(
                f"planner '{name}': not registered (known: {', '.join(PLANNERS)}; a module "
                "registering more goes in trials.planner_modules)"
            )


def make_planner(job: dict[str, Any], spec: SceneSpec):
    try:
        factory = PLANNERS[job["planner"]]
    except KeyError:
        raise ClutterbenchError(
            f"planner '{job['planner']}': not registered (known: {', '.join(PLANNERS)})"
        ) from None
    return factory(job, spec)


def execute_decision(
    world: BoxWorld,
    obs: Observation,
    decision: Decision,
    planner: Any,
    camera: CameraConfig,
    params: Ch6TrialParams,
    cp_max: float,
    gone: frozenset[int],
    log: EpisodeLog,
    cf: CollapseFreeConfig,
    t0: float = 0.0,
    arm: tuple[SceneSpec, SceneState, ArmConfig] | None = None,
) -> tuple[dict[str, Any], SceneState, float]:
    """Execute one decision from the step's canonical start (`world`, fresh) and judge it:
    pull in increments, checking the planner's collapse score before each (the first check
    reads the observation the planner decided on, so a box its own rule rejects is never
    picked and then aborted before motion), release, settle, judge. `arm`: (spec, state,
    Pandas) to execute it arm-level instead (trials/arm.py; `world` then only pictures).
    -> the step's record, the state it left, its duration (s)."""
    box, hold = decision.pull, decision.hold
    dt = world.cfg.timestep_s
    monitor = getattr(planner, "collapse_score", None)
    max_cp = 0.0

    truth = truth_maps_of(planner)

    def score(done: int, now: Observation | None, t: float) -> bool:
        nonlocal max_cp
        if monitor is None:
            return True
        if truth is not None and done:  # truth maps of the present, mid-pull state
            assert arm is None and now is not None, "truth maps run on the kinematic executor"
            truth.at(SceneState.of(world), now.instance, world.held())
        cp = float(monitor(obs if done == 0 else now, box, hold))
        max_cp = max(max_cp, cp)
        log.json(t, DECISION_TOPIC, {"box": box, "cp": round(cp, 4)})
        return cp <= cp_max

    arm_fields: dict[str, Any] = {}
    if arm is None:
        result = execute_pull(
            world,
            box,
            hold,
            params.pull_increment_m,
            params.grasp_lift_m,
            go_on=lambda done: score(
                done,
                observe(world, camera) if done and monitor else None,
                t0 + world.steps_taken * dt,
            ),
        )
        state, elapsed = SceneState.of(world), world.steps_taken * dt
    else:
        from clutterbench.trials.executors import arm_pull

        spec, start, arm_cfg = arm
        done_by_arm = arm_pull(
            spec,
            start,
            box,
            hold,
            params.pull_increment_m,
            params.grasp_lift_m,
            world.cfg,
            arm_cfg,
            log,
            t0,
            go_on=lambda done, now: score(done, now, t0),
            camera=camera,
        )
        result, arm_fields = done_by_arm.result, done_by_arm.fields
        state, elapsed = done_by_arm.state, done_by_arm.elapsed_s
    if arm is None:
        step = judge_pull(result, box, hold, gone, params.moved_threshold_m, cf)
    else:
        from clutterbench.trials.executors import judge_arm_step

        step = judge_arm_step(result, box, hold, gone, params.moved_threshold_m, cf)
    record = {
        "box": box,
        "hold": hold,
        "increments": result.increments,
        "max_cp": round(max_cp, 4),
    } | step
    return record | arm_fields, state, elapsed


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
    with the job's planner under the episode protocol (trials/protocol.py) -> the episode's
    record and MCAP events."""
    episode = Extraction(spec, job, target)
    planner = make_planner(job, spec)
    while not episode.done:
        episode.before_decision(planner)
        try:
            decision = planner.decide(episode.obs, episode.target, frozenset(episode.blocked))
        except ValueError:  # every action the planner would take is rejected by its own rule
            episode.give_up()
            break
        episode.step(decision, planner)
    return episode.result(planner)


class Extraction:
    """One ch. 6 extraction episode as a stepping object: the canonical start, then one
    `step(decision, planner)` per decision under the episode protocol (trials/protocol.py)
    until `done`; `result()` is the episode's record. The trials' loop (run_extraction) and
    the planning env (envs/plan.py) both drive it, so both run one protocol. `planner` is
    whatever made the decision: its `collapse_score` (if any) monitors the pull, as
    Algorithm 1 does; a planner that reads the world (oracle, truth maps) is handed the
    state in `before_decision`."""

    def __init__(self, spec: SceneSpec, job: dict[str, Any], target: int | None = None):
        self.spec, self.job = spec, job
        self.physics: PhysicsConfig = job["physics"]
        self.camera: CameraConfig = job["camera"]
        self.params: Ch6TrialParams = job["params"]
        self.state = SceneState.start(spec)
        self.world = world_at(spec, self.state, self.physics, render=True)
        self.log = EpisodeLog(record_images=job["record_images"])
        self.obs = observe(self.world, self.camera)
        self.log.scene(
            0.0, spec.sizes_m, spec.shelf.boards(), self.obs.camera, self.obs.depth_m.shape
        )
        if target is None:
            target = draw_target(
                job["seed"], job["stream"], job["index"], self.obs, self.params.min_target_pixels
            )
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
        job, params, spec = self.job, self.params, self.spec
        t = self.t
        self.log.json(
            t, DECISION_TOPIC, {"pull": decision.pull, "hold": decision.hold} | decision.state
        )
        arm = job.get("executor", "kinematic") == "arm"
        step, self.state, elapsed = execute_decision(
            self.world,
            self.obs,
            decision,
            planner,
            self.camera,
            params,
            job["cp_max"],
            self.state.removed,
            self.log,
            job["collapse_free"],
            t,
            arm=(spec, self.state, job["arm"]) if arm else None,
        )
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
            self.obs = observe(self.world, self.camera)
            if len(self.steps) >= params.max_steps:
                self.end = "max_steps"
        return step

    def result(self, planner: Any) -> EpisodeResult:
        """The episode's record (trials/records.py) and its MCAP events."""
        assert self.done, "the episode has not ended"
        job, params, spec, state, steps = self.job, self.params, self.spec, self.state, self.steps
        truth = truth_maps_of(planner)
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
            "condition": job["condition"],
            "episode": job["index"],
            "seed": job["seed"],
            "stream": job["stream"],
            "family": spec.family,
            "n_objects": spec.n,
            "target": self.target,
            "planner": job["planner"],
            "perception": "instance",
            "rule": job["rule"] if job["planner"] in CP_PLANNERS else None,
            "collapse_maps": None
            if job["planner"] not in CP_PLANNERS
            else ("physics truth" if truth is not None else "predicted"),
            "rejected_starts": dict(spec.meta.get("rejected", {})),
            "collapse_free_params": {
                "drop_m": job["collapse_free"].drop_m,
                "tilt_deg": job["collapse_free"].tilt_deg,
            },
            "moved_threshold_m": params.moved_threshold_m,
            "steps": [_rounded(s) for s in steps],
            "n_disturbed": overall.n_disturbed,
            "disturbance_m": overall.disturbance_m,
        } | judge_episode(steps, self.end, self.target)
        if job.get("executor", "kinematic") == "arm":  # kinematic records keep their old fields
            record["executor"] = "arm"
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
        if hasattr(planner, "first") and hasattr(planner, "steps"):  # physics from depth
            from clutterbench.trials.physics_model import estimate_record

            record |= estimate_record(planner, spec)
        return EpisodeResult(_rounded(record), log)


def _rounded(d: dict[str, Any]) -> dict[str, Any]:
    """Floats to 1e-6 (micrometres) so records read cleanly; the bits stay deterministic."""
    return {k: round(v, 6) if isinstance(v, float) else v for k, v in d.items()}


def condition_jobs(
    name: str,
    cond: Any,
    trials: Any,
    seed: int,
    physics: PhysicsConfig,
    camera: CameraConfig,
    thresholds: Path,
) -> tuple[list[dict[str, Any]], SupportParams, float]:
    """Condition `cond`'s episode jobs, with its support rule's thresholds (chosen on
    validation scenes by the support stage, `thresholds`) and its abort threshold cp_max;
    one-line errors when a network is missing."""
    for model in {trials.ch6.model, trials.ch6.ch4_model}:
        if not Path(f"models/{model}/best.pt").exists():
            raise ClutterbenchError(f"models/{model}/best.pt missing; run train@{model}")
    if cond.executor == "arm" and reads_truth_maps(cond.planner):
        raise ClutterbenchError(
            f"trials.conditions.{name}: planner {cond.planner} reads physics-truth maps, which "
            "run on the kinematic executor only (executor: kinematic)"
        )
    support = chosen_support(thresholds, cond.rule)
    cp_max = trials.ch6.cp_max if trials.ch6.cp_max is not None else support.score_threshold
    jobs = ch6_jobs(
        name,
        cond,
        trials,
        trials.streams[cond.stream],
        seed,
        physics,
        camera,
        support,
        cp_max,
        Path(f"models/{trials.ch6.model}/best.pt"),
    )
    return jobs, support, cp_max


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
    """Condition `condition`'s episode jobs (collapse-free thresholds: trials.collapse_free)."""
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
            "collapse_free": trials.collapse_free,
            "support": support,
            "cp_max": cp_max,
            "model_path": model_path,
            "ch4_model_path": Path(f"models/{trials.ch6.ch4_model}/best.pt"),
            "max_attempts": trials.max_attempts,
            "record_images": trials.mcap_images,
            "executor": cond.executor,
            "arm": trials.arm,
        }
        for i in range(cond.episodes)
    ]
