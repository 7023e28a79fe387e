"""Multi-step extraction planners of chapter 6: what to pull next, what to hold, when to stop.

A planner sees one `Observation` (depth, instance masks, camera) and nothing else; the
collapse predictor is passed in as a function (depth, masks) -> heatmaps, so this module
imports neither SAPIEN nor torch. The trial harness executes the `Decision` and calls
`collapse_score` between pull increments (Algorithm 1, lines 7-18).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.observation import Observation
from clutterbench.planning.cpg import bimanual_plan, build_cpg, extraction_order, single_arm_plan
from clutterbench.planning.support import (
    SupportEdge,
    SupportParams,
    infer_support,
    support_contact,
    surface_gaps,
)

PredictFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(depth_m (H, W) float32, masks (K, H, W)) -> (K, H, W) float32 collapse heatmaps."""


@dataclasses.dataclass(frozen=True)
class Decision:
    pull: int
    """Box to pull out toward the camera."""
    hold: int | None
    """Box the second arm holds during the pull (bimanual), or None."""
    state: dict[str, Any]
    """What the planner saw and decided (JSON; logged to the MCAP)."""


def visible_objects(obs: Observation, min_pixels: int) -> tuple[list[int], np.ndarray]:
    """Box ids with >= `min_pixels` visible pixels and their (K, H, W) bool masks."""
    ids = obs.visible_boxes(min_pixels)
    masks = (
        np.stack([obs.instance == k + 1 for k in ids])
        if ids
        else np.zeros((0, *obs.instance.shape), bool)
    )
    return ids, masks


def _edges_json(edges: list[SupportEdge]) -> list[list[float]]:
    return [[e.supporter, e.supported, round(float(e.score), 4)] for e in edges]


class CollapseGraphPlanner:
    """Algorithm 1 on the collapse prediction graph (CPG) from the CP's heatmaps; with
    `bimanual`, the Fig. 6.7 option of holding the target's single supported object."""

    reuse_maps = True
    """Read a collapse score from the heatmaps support_edges computed on the same
    observation (False: predict it again, as before; kept for `make bench`)."""

    def __init__(
        self,
        predict: PredictFn,
        params: SupportParams,
        cp_max: float,
        min_pixels: int,
        bimanual: bool = False,
        clear_hold_load: bool = False,
    ):
        self.predict, self.params, self.cp_max = predict, params, cp_max
        self.min_pixels, self.bimanual = min_pixels, bimanual
        self.clear_hold_load = clear_hold_load
        """Bimanual: remove what the box to be held carries before the held pull (cpg)."""
        self._maps: tuple[Observation, list[int], np.ndarray] | None = None
        """The last observation's heatmaps of every visible object (from support_edges):
        the decision's collapse scores and the pull's first abort check read the same
        observation and reuse them."""

    def support_edges(self, obs: Observation) -> list[SupportEdge]:
        """Support relations inferred from one observation (thesis 6.2.2)."""
        ids, masks = visible_objects(obs, self.min_pixels)
        if len(ids) < 2:
            return []
        heatmaps = self.predict(obs.depth_m, masks.astype(np.uint8))
        self._maps = (obs, ids, heatmaps)
        return infer_support(heatmaps, masks, ids, self.params, self._gaps(obs, masks))

    def _gaps(self, obs: Observation, masks: np.ndarray) -> np.ndarray | None:
        """The objects' surface gaps when the rule tests them (from the depth alone)."""
        if self.params.max_gap_m is None:
            return None
        return surface_gaps(obs.camera.depth_to_points(obs.depth_m), masks)

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        """Algorithm 1's next pull, under one decision rule: a candidate whose collapse score
        (eq. 6.2, the abort test of the pull) already exceeds cp_max on this observation is
        blocked here and the plan redrawn, so the pull executed never aborts before any
        motion. Raises ValueError when every candidate is blocked (the planner gives up)."""
        edges = self.support_edges(obs)
        graph = build_cpg(edges, target)
        if self.bimanual:
            plan_fn = functools.partial(bimanual_plan, clear_hold_load=self.clear_hold_load)
        else:
            plan_fn = single_arm_plan
        rejected: list[list[float]] = []
        now = set(blocked)
        while True:
            plan = plan_fn(graph, target, frozenset(now))
            cp = self.collapse_score(obs, plan.pull, plan.hold)
            if cp <= self.cp_max:
                break
            rejected.append([plan.pull, -1 if plan.hold is None else plan.hold, round(cp, 4)])
            now.add(plan.pull)
        state = {
            "edges": _edges_json(edges),
            "order": extraction_order(graph, target),
            "blocked": sorted(blocked),
            "rejected": rejected,
            "cp": round(cp, 4),
            "steps_to_target": plan.steps_to_target,
        }
        return Decision(plan.pull, plan.hold, state)

    def collapse_score(self, obs: Observation, box: int, hold: int | None = None) -> float:
        """Thesis eq. (6.2) during a pull: R_C predicted for removing `box` now, against the
        area of each object in pseudo-direct contact with it; the largest share. The object
        the other arm holds (`hold`) cannot collapse and is left out (Fig. 6.7 (d))."""
        ids, masks = visible_objects(obs, self.min_pixels)
        if box not in ids or len(ids) < 2:
            return 0.0
        k = ids.index(box)
        if self.reuse_maps and self._maps and self._maps[0] is obs and self._maps[1] == ids:
            heat = self._maps[2][k]
        else:
            heat = self.predict(obs.depth_m, masks[k : k + 1].astype(np.uint8))[0]
        area_c = heat > self.params.prob_threshold
        contact = support_contact(masks, self.params, self._gaps(obs, masks))[k]
        scores = [
            float(np.logical_and(area_c, masks[j]).sum() / masks[j].sum())
            for j in range(len(ids))
            if j != k and contact[j] and ids[j] != hold
        ]
        return max(scores, default=0.0)


class TargetFirstPlanner:
    """Single-step extraction: pull the target at once (thesis Table 6.3, [90])."""

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        return Decision(target, None, {"policy": "single_step"})


class RandomOrderPlanner:
    """The floor: pull a uniformly random visible box each step until the target is out."""

    def __init__(self, rng: np.random.Generator, min_pixels: int):
        self.rng, self.min_pixels = rng, min_pixels

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        ids = [k for k in obs.visible_boxes(self.min_pixels) if k not in blocked] or [target]
        if target not in ids:
            ids.append(target)
        pick = int(ids[self.rng.integers(len(ids))])
        return Decision(pick, None, {"policy": "random", "choices": sorted(ids)})
