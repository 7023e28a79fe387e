"""The ch. 6 planners by name (`trials.conditions.<c>.planner`): the registry
(`register_planner`, docs/extending.md), the built-in factories (the thesis' previous
method, Algorithm 1 with predicted or truth maps, the oracles, physics from depth, random,
pull-the-target) and the user planner modules loaded by name."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from clutterbench.data.trial_scenes import policy_rng
from clutterbench.errors import ClutterbenchError
from clutterbench.observation import Observation
from clutterbench.planning.ch6.extraction import (
    CollapseGraphPlanner,
    Decision,
    RandomOrderPlanner,
    TargetFirstPlanner,
)
from clutterbench.planning.ch6.support import SupportParams
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6.oracle import SearchOracle
from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps
from clutterbench.trials.config import PLANNERS as BUILT_IN
from clutterbench.trials.config import PULL_MAP_HEADS, Ch6TrialParams
from clutterbench.trials.core.harness import load_predictor

if TYPE_CHECKING:
    from clutterbench.trials.ch6.jobs import Ch6Job


class SupportWhilePullPlanner:
    """The thesis' previous method as the single-step rows of Table 6.3 (their counts equal
    the various-size cells of Table 4.1): pull the target at once while the second arm holds
    the support of least risk r_c chosen by the chapter 4 network (eqs. 4.1, 4.2)."""

    def __init__(self, predictor: Any, params: Ch6TrialParams):
        self.predictor, self.params = predictor, params

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        from clutterbench.perception.masks import segment
        from clutterbench.planning.ch4.risk_planner import plan_risk

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


PLANNERS: dict[str, Callable[[Ch6Job, SceneSpec], Any]] = {}
"""ch. 6 planner name -> factory(job, spec): the registry the conditions' `planner` names."""


def chosen_support(thresholds: Path, rule: str) -> SupportParams:
    """The support rule's thresholds chosen on validation scenes by the support stage."""
    from clutterbench.io import read_json

    chosen = read_json(thresholds)
    try:
        return SupportParams(**chosen["chosen"][rule])
    except (KeyError, TypeError) as exc:
        # pull_<rule>, pull_collapse_<rule>: chosen only where the support model has that head
        hint = " with a support.model that has that pull head" if rule.startswith("pull_") else ""
        raise ClutterbenchError(
            f"{thresholds}: no usable thresholds for rule '{rule}' ({exc}); rerun the support "
            f"stage{hint}"
        ) from None


BOX_HEAD = Path("models/box_head/best.pt")
"""The box planners' per-box head (stage box_head)."""


def box_thresholds(thresholds: Path, meaning: str) -> tuple[float, float]:
    """(edge, outcome) thresholds of the box head on the head of pull_map_meaning `meaning`:
    an edge above the first, a pull rejected or aborted when some box's probability is above
    the second; both chosen on validation scenes by the support stage."""
    from clutterbench.io import read_json

    head = PULL_MAP_HEADS[meaning]
    try:
        chosen = read_json(thresholds)["box_head"][head]
        return float(chosen["edge"]), float(chosen["outcome"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ClutterbenchError(
            f"{thresholds}: no box-head thresholds for the {head} head ({exc}); rerun the support "
            "stage after box_head"
        ) from None


def box_fusion(
    thresholds: Path, meaning: str, contact: str = "head"
) -> tuple[float, float, tuple[float, ...], tuple[float, ...] | None]:
    """(edge, outcome, weights, contact weights) of the box head fused with physics from
    depth on the head of pull_map_meaning `meaning`: its support-edge and outcome thresholds,
    its logistic weights and, for `contact` learned (trials.ch6.box_contact), the learned
    contact's weights (None: the head's contact), chosen on validation scenes by the support
    stage, which writes them beside `thresholds` (box_fusion.json)."""
    from clutterbench.io import read_json

    head = PULL_MAP_HEADS[meaning]
    path = thresholds.with_name("box_fusion.json")
    try:
        chosen = read_json(path)["chosen"][head]
        weights = tuple(float(w) for w in chosen["weights"])
        learned = None
        if contact == "learned":
            learned = tuple(float(w) for w in chosen["contact_weights"])
        return float(chosen["edge"]), float(chosen["outcome"]), weights, learned
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ClutterbenchError(
            f"{path}: no box-head fusion for the {head} head with the {contact} contact "
            f"({exc}); rerun the support stage after box_head"
        ) from None


def register_planner(name: str):
    """Register a ch. 6 planner factory under `name` (usable as a condition's planner)."""

    def wrap(factory):
        PLANNERS[name] = factory
        return factory

    return wrap


@register_planner("pull_target")
def _pull_target(job: Ch6Job, spec: SceneSpec):
    return TargetFirstPlanner()


@register_planner("single_step")
def _single_step(job: Ch6Job, spec: SceneSpec):
    return SupportWhilePullPlanner(
        load_predictor(job.ch4_model_path, job.camera.image_size), job.params
    )


@register_planner("random")
def _random(job: Ch6Job, spec: SceneSpec):
    rng = policy_rng(job.seed, job.stream, job.index, job.planner)
    return RandomOrderPlanner(rng, job.params.min_pixels)


@register_planner("oracle")
def _oracle(job: Ch6Job, spec: SceneSpec):
    return SearchOracle(spec, job.physics, job.camera, job.params, False, job.collapse_free)


@register_planner("oracle_hold")
def _oracle_hold(job: Ch6Job, spec: SceneSpec):
    """May hold one box during any pull: the ceiling of every planner that holds, the
    bimanual pull planners' idle hold included."""
    return SearchOracle(
        spec,
        job.physics,
        job.camera,
        job.params,
        True,
        job.collapse_free,
        hold_any_pull=True,
    )


def _cpg_planner(job: Ch6Job, bimanual: bool, spec: SceneSpec | None = None, pull: bool = False):
    """Algorithm 1 with the collapse predictor, or (`spec` given) with physics-truth maps of
    that scene through the same interface (`pull`: maps of the trials' pull, else of
    deleting the box; the bimanual plan clears the held box's load first and an abort teaches
    the graph what it feared for, trials.ch6.abort_response): the same planner and
    rule. `pull` without `spec`: the collapse predictor's pull head, with the thresholds
    chosen for it (the job's `support`, trials.config.support_method)."""
    params: Ch6TrialParams = job.params
    if spec is None:
        head = PULL_MAP_HEADS[params.pull_map_meaning] if pull else "deletion"
        predictor = load_predictor(job.model_path, job.camera.image_size, head)
    else:
        action = (params.pull_increment_m, params.grasp_lift_m) if pull else None
        falls = job.collapse_free if pull and params.pull_map_meaning == "collapse" else None
        predictor = TruthCollapseMaps(
            spec, job.physics, params.moved_threshold_m, action, falls, params.release()
        )
    simulate_hold = spec is not None and pull and bimanual and params.truth_hold == "simulate"
    levers = pull_levers(params) if pull else {}
    if pull and spec is not None:
        levers["watch_m"] = None  # truth maps already know the pull in progress
    return CollapseGraphPlanner(
        predictor,
        job.support,
        job.cp_max,
        params.min_pixels,
        bimanual=bimanual,
        predict_held=predictor.held if simulate_hold else None,
        **levers,
    )


def pull_levers(params: Ch6TrialParams) -> dict[str, Any]:
    """The pull planners' choices beyond Algorithm 1 (trials.ch6; the thesis-faithful
    planners take CollapseGraphPlanner's defaults): clear the held box's load first, learn
    from aborts, watch the pull, the no-plan response, the idle hold, whose shares the score
    takes, and holding a feared box."""
    return {
        "clear_hold_load": True,
        "learn_from_aborts": params.abort_response == "learn",
        "watch_m": params.pull_watch_m,
        "when_no_plan": params.when_no_plan,
        "idle_hold_share": params.idle_hold_share,
        "idle_hold_prob": params.idle_hold_prob,
        "score_over": params.score_over,
        "hold_feared": params.hold_feared,
    }


@register_planner("multi_step")
def _multi_step(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=False)


@register_planner("bimanual")
def _bimanual(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=True)


@register_planner("multi_step_truth")
def _multi_step_truth(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=False, spec=spec)


@register_planner("bimanual_truth")
def _bimanual_truth(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=True, spec=spec)


@register_planner("multi_step_pull_truth")
def _multi_step_pull_truth(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=False, spec=spec, pull=True)


@register_planner("bimanual_pull_truth")
def _bimanual_pull_truth(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=True, spec=spec, pull=True)


@register_planner("multi_step_pull")
def _multi_step_pull(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=False, pull=True)


@register_planner("bimanual_pull")
def _bimanual_pull(job: Ch6Job, spec: SceneSpec):
    return _cpg_planner(job, bimanual=True, pull=True)


def _box_planner(job: Ch6Job, bimanual: bool, spec: SceneSpec, physics: bool = False):
    """Algorithm 1 on the box head's per-box predictions of the head of pull_map_meaning:
    its support graph (no pixel rule), each box's probability as its collapse score against
    cp_max (the head's own threshold, chosen on validation pairs); the pull planners' other
    choices. `physics`: each pull also simulated on the fitted boxes and fused per box with
    the network (collapse/box_predict.py FusedBoxMaps; the fusion's thresholds); bimanual,
    a pull made holding a box is simulated holding it where trials.ch6.box_hold says so."""
    from clutterbench.collapse.box_predict import BoxMaps, FusedBoxMaps

    params: Ch6TrialParams = job.params
    assert job.box_head_path is not None and job.box_edge_threshold is not None, job.planner
    head = PULL_MAP_HEADS[params.pull_map_meaning]
    args = (job.model_path, job.box_head_path, job.camera, head, job.box_edge_threshold)
    if physics:
        assert job.box_fusion is not None, job.planner
        simulate = fitted_pull(job, spec, head)
        learned = job.box_contact is not None  # trials.ch6.box_contact learned
        maps = FusedBoxMaps.from_paths(
            *args,
            simulate=simulate,
            weights=job.box_fusion,
            simulate_held=bimanual and params.box_hold == "simulate",
            contact=simulate.contacts if learned else None,
            contact_weights=job.box_contact,
        )
    else:
        maps = BoxMaps.from_paths(*args)
    return CollapseGraphPlanner(
        maps, job.support, job.cp_max, params.min_pixels, bimanual=bimanual, **pull_levers(params)
    )


def fitted_pull(job: Ch6Job, spec: SceneSpec, head: str):
    """SimulateFn of FusedBoxMaps: the trials' pull of one box in the scenes fitted to the
    observation (physics from depth's estimate, settled; trials.ch6.fit_hypotheses of them,
    perception/fitted_scenes.py), each box's outcome the share of those fits whose pull marks
    it by `head`; with a held box, the pull made holding it, the held box let go and judged
    as the trials judge a released box. Of the episode's spec it reads the shelf only; of
    its stream the catalogue. Its `contacts(obs, ids)` gives the same fits' contacts
    (FittedContactFn: trials.ch6.box_contact learned)."""
    from clutterbench.perception.fitted_scenes import (
        contact_share,
        fitted_scenes,
        make_estimator,
    )
    from clutterbench.sim.labelling import settled_contacts
    from clutterbench.sim.pull import SceneState

    params: Ch6TrialParams = job.params
    estimate = make_estimator(job.stream_cfg.catalogue, params.min_pixels)
    action = (params.pull_increment_m, params.grasp_lift_m)
    falls = job.collapse_free if head == "pull_collapse" else None
    cache: dict[int, list[tuple[list[int], Any]]] = {}  # the last observation's fits and maps
    touching: dict[int, list[list[tuple[int, int]]]] = {}  # and their settled contacts

    def fits_of(obs) -> list[tuple[list[int], Any]]:
        key = hash(obs.depth_m.tobytes())  # one estimate per observation
        if key not in cache:
            cache.clear()
            touching.clear()
            fits = []
            for scene in fitted_scenes(
                estimate,
                obs,
                spec.shelf,
                job.camera,
                job.physics,
                params.physics_depth_settle_s,
                params.fit_hypotheses,
                params.fit_noise_mm / 1000.0,
            ):
                maps = TruthCollapseMaps(
                    scene.spec,
                    job.physics,
                    params.moved_threshold_m,
                    action,
                    falls,
                    params.release(),
                )
                maps.at(SceneState.start(scene.spec), np.zeros(obs.depth_m.shape, np.uint8))
                fits.append(([int(b) for b in scene.spec.meta["ids"]], maps))
            cache[key] = fits
        return cache[key]

    def simulate(obs, ids: list[int], box: int, hold: int | None = None) -> np.ndarray | None:
        share, n = np.zeros(len(ids)), 0
        for fitted, maps in fits_of(obs):
            if box not in fitted or (hold is not None and hold not in fitted):
                continue
            if hold is None:
                marked = maps.moved_by_removing(fitted.index(box))
            else:
                marked = maps.moved_by_held_pull(fitted.index(box), fitted.index(hold))
            n += 1
            for j, other in enumerate(fitted):
                if other in ids and marked[j]:
                    share[ids.index(other)] += 1.0
        return share / n if n else None

    def contacts(obs, ids: list[int]) -> np.ndarray:
        """(K, K) the share of the fits in which boxes ids[x] and ids[y] touch once settled
        (the truth's rule; NaN where no fit holds both)."""
        fits = fits_of(obs)
        key = hash(obs.depth_m.tobytes())
        if key not in touching:
            touching[key] = [settled_contacts(maps.spec, job.physics) for _, maps in fits]
        where = [[ids.index(b) if b in ids else -1 for b in fitted] for fitted, _ in fits]
        return contact_share(len(ids), list(zip(where, touching[key], strict=True)))

    simulate.contacts = contacts  # type: ignore[attr-defined]
    return simulate


@register_planner("multi_step_box")
def _multi_step_box(job: Ch6Job, spec: SceneSpec):
    return _box_planner(job, bimanual=False, spec=spec)


@register_planner("bimanual_box")
def _bimanual_box(job: Ch6Job, spec: SceneSpec):
    return _box_planner(job, bimanual=True, spec=spec)


@register_planner("multi_step_box_physics")
def _multi_step_box_physics(job: Ch6Job, spec: SceneSpec):
    return _box_planner(job, bimanual=False, spec=spec, physics=True)


@register_planner("bimanual_box_physics")
def _bimanual_box_physics(job: Ch6Job, spec: SceneSpec):
    return _box_planner(job, bimanual=True, spec=spec, physics=True)


def _physics_from_depth(job: Ch6Job, spec: SceneSpec, holding: bool):
    """The physics-from-depth planner (planning/ch6/physics_depth.py): boxes fitted to each
    observation, searched in SAPIEN by the oracle's code on that estimate, with the action
    set of the oracle it mirrors (`holding`: oracle_hold's, a box may be held during any
    pull). Of the episode's spec it gets the shelf only (fixed, a robot knows it); of its
    stream the catalogue."""
    from clutterbench.perception.fitted_scenes import make_estimator
    from clutterbench.planning.ch6.physics_depth import PhysicsFromDepthPlanner
    from clutterbench.trials.ch6.physics_model import EstimatedWorldModel

    params: Ch6TrialParams = job.params
    model = EstimatedWorldModel(
        spec.shelf,
        job.camera,
        job.physics,
        params,
        holding,
        job.collapse_free,
        functools.partial(SearchOracle, hold_any_pull=True),
    )
    estimate = make_estimator(job.stream_cfg.catalogue, params.min_pixels)
    return PhysicsFromDepthPlanner(estimate, model, holding)


@register_planner("physics_from_depth")
def _pfd(job: Ch6Job, spec: SceneSpec):
    return _physics_from_depth(job, spec, holding=False)


@register_planner("physics_from_depth_hold")
def _pfd_hold(job: Ch6Job, spec: SceneSpec):
    return _physics_from_depth(job, spec, holding=True)


CP_PLANNERS = tuple(p for p in BUILT_IN if p.startswith(("multi_step", "bimanual")))
"""The planners of Algorithm 1 (a support rule, cp_max); `*_truth` read physics-truth maps
(`*_pull_truth`: of the trials' pull, the others of deletion); `*_pull` the collapse
predictor's pull head, the others its deletion head."""


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


def make_planner(job: Ch6Job, spec: SceneSpec):
    try:
        factory = PLANNERS[job.planner]
    except KeyError:
        raise ClutterbenchError(
            f"planner '{job.planner}': not registered (known: {', '.join(PLANNERS)})"
        ) from None
    return factory(job, spec)
