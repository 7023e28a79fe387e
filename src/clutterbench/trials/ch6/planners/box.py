"""Algorithm 1 on the box head's per-box predictions (`*_box`: no pixel rule,
collapse/box_predict.py), and on those predictions fused per box with each pull simulated on
boxes fitted to the observation (`*_box_physics`: learned plus physics), one arm and with the
bimanual hold."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from clutterbench.data.trial_params import PULL_MAP_HEADS
from clutterbench.trials.ch6.planners._registry import register_planner

if TYPE_CHECKING:
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.ch6.jobs import Ch6Job

BOX = {"networks": frozenset({"cp", "box_head"}), "cost": "network"}
FUSED = {"networks": frozenset({"cp", "box_head"}), "world": "fitted", "cost": "search"}
ONE_ARM = {"truth": "multi_step_pull_truth", "baseline": "physics_from_depth"}
HOLDING = {"holds": True, "truth": "bimanual_pull_truth", "baseline": "physics_from_depth_hold"}


def box_planner(job: Ch6Job, bimanual: bool, spec: SceneSpec, physics: bool = False):
    """Algorithm 1 on the box head's per-box predictions of the head of pull_map_meaning:
    its support graph (no pixel rule), each box's probability as its collapse score against
    cp_max (the head's own threshold, chosen on validation pairs); the pull planners' other
    choices. `physics`: each pull also simulated on the fitted boxes and fused per box with
    the network (collapse/box_predict.py FusedBoxMaps; the fusion's thresholds); bimanual,
    a pull made holding a box is simulated holding it where trials.ch6.box_hold says so."""
    from clutterbench.collapse.box_predict import BoxMaps, FusedBoxMaps
    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
    from clutterbench.trials.core.harness import load_box_networks

    params = job.params
    assert job.box_head_path is not None and job.box_edge_threshold is not None, job.planner
    head = PULL_MAP_HEADS[params.pull_map_meaning]
    networks = load_box_networks(job.model_path, job.box_head_path, job.camera.image_size)
    args = (*networks, job.camera, head, job.box_edge_threshold)
    if physics:
        assert job.box_fusion is not None, job.planner
        simulate = fitted_pull(job, spec, head)
        learned = job.box_contact is not None  # trials.ch6.box_contact learned
        maps = FusedBoxMaps(
            *args,
            simulate=simulate,
            weights=job.box_fusion,
            simulate_held=bimanual and params.box_hold == "simulate",
            contact=simulate.contacts if learned else None,
            contact_weights=job.box_contact,
        )
    else:
        maps = BoxMaps(*args)
    return CollapseGraphPlanner(
        maps,
        job.support,
        job.cp_max,
        params.min_pixels,
        bimanual=bimanual,
        **params.levers.kwargs(),
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
    from clutterbench.trials.ch6.truth_maps import TruthCollapseMaps

    params, how = job.params, job.params.pull
    estimate = make_estimator(job.stream_cfg.catalogue, params.min_pixels)
    action = (how.increment_m, how.grasp_lift_m)
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
                    scene.spec, job.physics, how.moved_threshold_m, action, falls, how.release()
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


@register_planner("multi_step_box", maps="box", **BOX, **ONE_ARM)
def _multi_step_box(job, spec):
    return box_planner(job, bimanual=False, spec=spec)


@register_planner("bimanual_box", maps="box", **BOX, **HOLDING)
def _bimanual_box(job, spec):
    return box_planner(job, bimanual=True, spec=spec)


@register_planner("multi_step_box_physics", maps="box_physics", **FUSED, **ONE_ARM)
def _multi_step_box_physics(job, spec):
    return box_planner(job, bimanual=False, spec=spec, physics=True)


@register_planner("bimanual_box_physics", maps="box_physics", **FUSED, **HOLDING)
def _bimanual_box_physics(job, spec):
    return box_planner(job, bimanual=True, spec=spec, physics=True)
