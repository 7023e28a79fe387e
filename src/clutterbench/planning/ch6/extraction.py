"""Multi-step extraction planners of chapter 6: what to pull next, what to hold, when to stop.

A planner sees one `Observation` (depth, instance masks, camera) and nothing else; the
collapse predictor is passed in as a function (depth, masks) -> heatmaps, so this module
imports neither SAPIEN nor torch. The trial harness executes the `Decision` and calls
`collapse_score` between pull increments (Algorithm 1, lines 7-18).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.observation import Observation
from clutterbench.planning.ch6.cpg import (
    BimanualPlan,
    bimanual_plan,
    build_cpg,
    extraction_order,
    single_arm_plan,
)
from clutterbench.planning.ch6.support import (
    SupportEdge,
    SupportParams,
    infer_support,
    support_contact,
    surface_gaps,
)

PredictFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(depth_m (H, W) float32, masks (K, H, W)) -> (K, H, W) float32 collapse heatmaps."""

PredictHeldFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(depth_m (H, W), mask of the pulled box (H, W), mask of the held box (H, W)) -> (H, W)
float32: the collapse map of pulling that box while the other arm holds the other, the held
box included (it is let go after the pull)."""


@dataclasses.dataclass(frozen=True)
class Decision:
    pull: int
    """Box to pull out toward the camera."""
    hold: int | None
    """Box the second arm holds during the pull (bimanual), or None."""
    state: dict[str, Any]
    """What the planner saw and decided (JSON; logged to the MCAP)."""
    cp_max: float | None = None
    """This pull's abort threshold of the collapse score; None: the planner's own (a
    least-risk pull taken when no plan is left carries its own score: NO_PLAN_RESPONSES)."""


NO_PLAN_RESPONSES = ("give_up", "least_risk", "least_risk_unmonitored", "clear")
"""What a CPG planner does when every candidate is rejected by its own rule:
give_up (the episode ends, Algorithm 1); least_risk pulls the rejected candidate of the
lowest collapse score, aborting only when the score grows beyond that one;
least_risk_unmonitored pulls it without abort checks; clear first pulls a box the rule
passes (score <= cp_max) from around the rejected ones (a neighbour of a rejected candidate
or of a box its score feared for), so the next decision meets a smaller pile, and does
least_risk when no such box is left."""

SCORE_OVER = ("contact", "visible")
"""Whose shares a collapse score takes: contact, the objects in pseudo-direct
contact with the pulled box (eq. 6.2); visible, every visible object (what the pull drags
along to a box it does not touch, through one between)."""

HOLD_FEARED = ("never", "any", "free", "search")
"""Which box a bimanual planner may hold to save a candidate pulled with its second arm idle
whose collapse score exceeds cp_max: never (the candidate is rejected, thesis);
any, the box that score fears for; free, that box only where it carries nothing in the graph
(what a held box carries falls when it is let go); search, that box and then every other
visible one in id order, the first whose held pull passes (with maps that know a held pull,
predict_held, or a per-box predictor's held_row; without them, holding a box only removes its
own share, so it is `any`)."""


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
        learn_from_aborts: bool = False,
        watch_m: float | None = None,
        when_no_plan: str = "give_up",
        idle_hold_share: float | None = None,
        idle_hold_prob: float | None = None,
        score_over: str = "contact",
        hold_feared: str = "never",
        predict_held: PredictHeldFn | None = None,
    ):
        self.predict, self.params, self.cp_max = predict, params, cp_max
        self.min_pixels, self.bimanual = min_pixels, bimanual
        self.clear_hold_load = clear_hold_load
        """Bimanual: remove what the box to be held carries before the held pull (cpg)."""
        self.learn_from_aborts = learn_from_aborts
        """Not the thesis: a collapse score over cp_max names the box it fears for
        (the contact box of the largest share); that box is then treated as carried by the
        box being pulled (an edge of the CPG for the rest of the episode), so the plan
        removes it first or, bimanual, holds it, instead of skipping the pulled box until
        the graph has nothing left (Algorithm 1 blocks the box and re-plans)."""
        self.watch_m = watch_m
        """Not the thesis: also watch the pull. Before each increment, a box other
        than the pulled and the held one whose pixels, seen in both the decision's
        observation and the present one, moved in depth by more than this (median, m) stops
        the pull as a collapse score over cp_max does (score: 1 + that depth change, above
        any share), naming that box. None: the prediction alone (Algorithm 1)."""
        if when_no_plan not in NO_PLAN_RESPONSES:
            raise ValueError(f"when_no_plan: {when_no_plan!r} is none of {NO_PLAN_RESPONSES}")
        self.when_no_plan = when_no_plan
        """Not the thesis: what to do when the rule rejects every candidate
        (NO_PLAN_RESPONSES)."""
        self.idle_hold_share = idle_hold_share
        """Not the thesis, bimanual: a pull the plan makes with the second arm idle
        holds the pulled box's contact neighbour of the largest predicted share above this
        (one that carries nothing in the graph; the held box may settle when let go, what it
        carries may not). None: the arm stays idle (Fig. 6.7)."""
        self.idle_hold_prob = idle_hold_prob
        """The pixel probability threshold of the collapse area those shares are taken of
        (None: the rule's, params.prob_threshold)."""
        if score_over not in SCORE_OVER:
            raise ValueError(f"score_over: {score_over!r} is none of {SCORE_OVER}")
        self.score_over = score_over
        """Not the thesis: whose shares the collapse score takes (SCORE_OVER)."""
        if hold_feared not in HOLD_FEARED:
            raise ValueError(f"hold_feared: {hold_feared!r} is none of {HOLD_FEARED}")
        self.hold_feared = hold_feared
        """Not the thesis, bimanual: a candidate pulled with the second arm idle
        whose score exceeds cp_max is tried again holding the box that score fears for
        (HOLD_FEARED says which boxes may be held)."""
        self.predict_held = predict_held
        """Not the thesis: the map of a pull made holding a box, where the maps
        know it (the truth maps of the executed pull); the score of a held pull then reads
        it and judges the held box too. None: the unheld pull's map without the held box
        (Fig. 6.7 (d): a network sees no hold)."""
        self._decided_on: Observation | None = None
        """The observation of the last decision: where the watched pull started."""
        self.learned: dict[tuple[int, int], float] = {}
        """(supporter, supported) -> collapse score: the edges the aborts taught."""
        self._threat: tuple[int, int, float] | None = None
        """(box, the box its score feared for, score) of the last check over cp_max."""
        self._maps: tuple[Observation, list[int], np.ndarray] | None = None
        """The last observation's heatmaps of every visible object (from support_edges):
        the decision's collapse scores and the pull's first abort check read the same
        observation and reuse them."""

    def support_edges(self, obs: Observation) -> list[SupportEdge]:
        """Support relations inferred from one observation (thesis 6.2.2)."""
        ids, masks = visible_objects(obs, self.min_pixels)
        if len(ids) < 2:
            return []
        box_edges = getattr(self.predict, "box_edges", None)
        if box_edges is not None:  # a per-box predictor gives the graph itself (no pixel rule)
            return [SupportEdge(*e) for e in box_edges(obs, ids, masks)]
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
        motion. When every candidate is blocked, raises ValueError (the planner gives up) or,
        by `when_no_plan`, pulls the rejected candidate of the lowest score (its Decision
        carries the abort threshold of that pull)."""
        edges = self.support_edges(obs)
        now = set(blocked)
        threat, self._threat = self._threat, None
        if self.learn_from_aborts and threat is not None and threat[0] in now:
            # the last pull aborted; what its score feared for explains it: the box is free
            # again, now carrying that one (removed first, or held by the other arm)
            if self._learn(threat):
                now.discard(threat[0])
        visible = set(visible_objects(obs, self.min_pixels)[0])
        graph = build_cpg([*edges, *self._learned_edges(visible)], target)
        if self.bimanual:
            plan_fn = functools.partial(bimanual_plan, clear_hold_load=self.clear_hold_load)
        else:
            plan_fn = single_arm_plan
        rejected: list[tuple[float, Any]] = []  # (collapse score, plan), in order
        feared: set[int] = set()  # the boxes the rejected candidates' scores feared for
        limit = None
        no_plan = None
        state_notes: dict[str, int] = {}
        while True:
            try:
                plan = plan_fn(graph, target, frozenset(now))
            except ValueError:
                if self.when_no_plan == "give_up" or not rejected:
                    raise
                cp, plan, limit, no_plan = self._no_plan(obs, target, now, rejected, feared)
                break
            cp = self.collapse_score(obs, plan.pull, plan.hold)
            if cp > self.cp_max and self.bimanual and plan.hold is None:
                held = self._hold_feared(obs, plan, graph)
                if held is not None:
                    cp, plan = held
                    state_notes["feared_hold"] = plan.hold
            if cp <= self.cp_max:
                break
            rejected.append((cp, plan))
            threat, self._threat = self._threat, None
            if threat is not None:
                feared.add(threat[1])
            if self.learn_from_aborts and threat is not None and self._learn(threat):
                graph = build_cpg([*edges, *self._learned_edges(visible)], target)
            else:  # nothing new to learn: skip the box (Algorithm 1)
                now.add(plan.pull)
        state = {
            "edges": _edges_json(edges),
            "order": extraction_order(graph, target),
            "blocked": sorted(blocked),
            "rejected": [
                [p.pull, -1 if p.hold is None else p.hold, round(c, 4)] for c, p in rejected
            ],
            "cp": round(cp, 4),
            "steps_to_target": plan.steps_to_target,
        }
        if self.learn_from_aborts:
            state["learned"] = [[a, b, round(v, 4)] for (a, b), v in sorted(self.learned.items())]
        if no_plan is not None:
            state["no_plan"] = no_plan
        state |= state_notes
        hold = self._with_idle_hold(obs, plan, graph, limit, state)
        self._decided_on = obs
        return Decision(plan.pull, hold, state, limit)

    def _no_plan(
        self,
        obs: Observation,
        target: int,
        now: set[int],
        rejected: list[tuple[float, BimanualPlan]],
        feared: set[int],
    ) -> tuple[float, BimanualPlan, float | None, str]:
        """(score, plan, abort threshold, no_plan note) of the pull made when every
        candidate is blocked (when_no_plan other than give_up, at least one rejected): a
        cleared neighbour (clear) where there is one, else the rejected candidate of the
        lowest score."""
        clear = None
        if self.when_no_plan == "clear":
            around = {p.pull for _, p in rejected} | feared
            clear = self._clear_around(obs, around, {target, *now})
        if clear is not None:
            cp, plan = clear
            return cp, plan, None, "clear"
        cp, plan = min(rejected, key=lambda c: c[0])  # ties: the first rejected
        limit = math.inf if self.when_no_plan == "least_risk_unmonitored" else cp
        no_plan = "least_risk" if self.when_no_plan == "clear" else self.when_no_plan
        return cp, plan, limit, no_plan

    def _with_idle_hold(
        self,
        obs: Observation,
        plan: BimanualPlan,
        graph: Any,
        limit: float | None,
        state: dict[str, Any],
    ) -> int | None:
        """The box held while `plan` pulls: its own hold, or (bimanual, idle_hold_share) the
        idle arm's where the held pull's score passes; a hold so made is noted in `state`."""
        hold = plan.hold
        if self.bimanual and hold is None and self.idle_hold_share is not None:
            idle = self._idle_hold(obs, plan.pull, graph)
            if idle is not None:
                held_cp = self.collapse_score(obs, plan.pull, idle)
                self._threat = None
                # without a held pull's own map, leaving the held box out never raises the
                # score; with one (predict_held), a hold whose pull fails is not made
                if held_cp <= (self.cp_max if limit is None else limit):
                    hold = idle
                    state["idle_hold"] = hold
                    state["cp"] = round(held_cp, 4)
        return hold

    def _clear_around(
        self, obs: Observation, around: set[int], skip: set[int]
    ) -> tuple[float, BimanualPlan] | None:
        """(score, plan) of the box the rule passes (collapse score <= cp_max) among the
        contact neighbours of `around` (not in `skip`, not in `around`): the lowest score,
        ties the smallest id; None where there is none (when_no_plan clear)."""
        ids, masks = visible_objects(obs, self.min_pixels)
        contact = support_contact(masks, self.params, self._gaps(obs, masks))
        index = {box: k for k, box in enumerate(ids)}
        near = sorted(
            ids[j]
            for k in (index[b] for b in around if b in index)
            for j in np.flatnonzero(contact[k])
            if ids[j] not in skip and ids[j] not in around
        )
        best = None
        for box in dict.fromkeys(near):
            cp = self.collapse_score(obs, box)
            self._threat = None
            if cp <= self.cp_max and (best is None or cp < best[0]):
                best = (cp, BimanualPlan(hold=None, pull=box, steps_to_target=len(ids) - 1))
        return best

    def _hold_feared(
        self, obs: Observation, plan: BimanualPlan, graph: Any
    ) -> tuple[float, BimanualPlan] | None:
        """(score, plan) of `plan`'s pull holding the box its score over cp_max fears for
        (search: else the first other visible box, in id order, whose hold passes), where
        hold_feared allows that box and the score with it held passes; else None, and the
        threat of the unheld pull stands (what an abort-learning planner learns)."""
        threat = self._threat
        if self.hold_feared == "never" or threat is None:
            return None
        holds = [threat[1]]
        if self.hold_feared == "search":
            ids = visible_objects(obs, self.min_pixels)[0]
            holds += [j for j in ids if j not in (threat[1], plan.pull)]
        for hold in holds:
            if self.hold_feared == "free" and hold in graph and graph.out_degree(hold) > 0:
                continue
            cp = self.collapse_score(obs, plan.pull, hold)
            if cp <= self.cp_max:
                return cp, dataclasses.replace(plan, hold=hold)
        self._threat = threat
        return None

    def _idle_hold(self, obs: Observation, box: int, graph: Any) -> int | None:
        """The box the idle arm holds while `box` is pulled (idle_hold_share), or None."""
        carries = {n for n in graph if graph.out_degree(n) > 0}
        shares = {
            j: v
            for j, v in self._shares(obs, box, None, self.idle_hold_prob).items()
            if v > self.idle_hold_share and j not in carries
        }
        return min(shares, key=lambda j: (-shares[j], j)) if shares else None

    def _learn(self, threat: tuple[int, int, float]) -> bool:
        """Record that `threat`'s box carries the box its score feared for -> whether that
        edge is new (an edge learned twice is skipped as Algorithm 1 does, so a decision
        always ends)."""
        box, other, score = threat
        if (box, other) in self.learned:
            return False
        self.learned[(box, other)] = score
        return True

    def _learned_edges(self, visible: set[int]) -> list[SupportEdge]:
        """The learned edges between boxes still seen (a box gone takes its edges along)."""
        return [
            SupportEdge(a, b, score)
            for (a, b), score in sorted(self.learned.items())
            if a in visible and b in visible
        ]

    def collapse_score(self, obs: Observation, box: int, hold: int | None = None) -> float:
        """Thesis eq. (6.2) during a pull: R_C predicted for removing `box` now, against the
        area of each object in pseudo-direct contact with it; the largest share. The object
        the other arm holds (`hold`) cannot collapse and is left out (Fig. 6.7 (d))."""
        scores = self._shares(obs, box, hold, contact=self.score_over == "contact")
        start = self._decided_on
        if self.watch_m is not None and start is not None and start is not obs:
            moved = {
                j: 1.0 + change
                for j, change in depth_changes(start, obs, self.min_pixels).items()
                if j not in (box, hold) and change > self.watch_m
            }
            scores |= {j: max(scores.get(j, 0.0), v) for j, v in moved.items()}
        cp = max(scores.values(), default=0.0)
        if cp > self.cp_max:  # the box it fears for (ties: the smallest id)
            feared = min(scores, key=lambda j: (-scores[j], j))
            self._threat = (box, feared, cp)
        return cp

    def _shares(
        self,
        obs: Observation,
        box: int,
        hold: int | None,
        prob: float | None = None,
        contact: bool = True,
    ) -> dict[int, float]:
        """Eq. (6.2)'s shares: box id -> the part of it in R_C predicted for removing `box`,
        for each object in pseudo-direct contact with it (`contact`; else each visible one)
        but `hold` (R_C: heatmap > `prob`, None: the rule's threshold). With predict_held,
        a held pull's own map, the held box judged as the others."""
        ids, masks = visible_objects(obs, self.min_pixels)
        if box not in ids or len(ids) < 2:
            return {}
        k = ids.index(box)
        box_row = getattr(self.predict, "box_row", None)
        if box_row is not None:  # a per-box predictor: each box's probability is its share
            near = self._near(obs, masks, k, contact)
            p = self._held_box_row(obs, ids, masks, k, hold)
            if p is None:
                p = box_row(obs, ids, masks, k)
            else:  # the held pull itself: the held box judged as the others
                near = near.copy()
                near[ids.index(hold)] = True
                hold = None
            return {
                ids[j]: float(p[j])
                for j in range(len(ids))
                if j != k and near[j] and ids[j] != hold
            }
        if hold is not None and self.predict_held is not None and hold in ids:
            held = masks[ids.index(hold)].astype(np.uint8)
            heat = self.predict_held(obs.depth_m, masks[k].astype(np.uint8), held)
            hold = None
        elif self.reuse_maps and self._maps and self._maps[0] is obs and self._maps[1] == ids:
            heat = self._maps[2][k]
        else:
            heat = self.predict(obs.depth_m, masks[k : k + 1].astype(np.uint8))[0]
        area_c = heat > (self.params.prob_threshold if prob is None else prob)
        near = self._near(obs, masks, k, contact)
        return {
            ids[j]: float(np.logical_and(area_c, masks[j]).sum() / masks[j].sum())
            for j in range(len(ids))
            if j != k and near[j] and ids[j] != hold
        }

    def _held_box_row(
        self, obs: Observation, ids: list[int], masks: np.ndarray, k: int, hold: int | None
    ) -> np.ndarray | None:
        """(K,) a per-box predictor's row for pulling ids[k] while `hold` is held, the held
        box judged too, where it answers for a held pull (`held_row`); else None."""
        held_row = getattr(self.predict, "held_row", None)
        if hold is None or held_row is None or hold not in ids:
            return None
        return held_row(obs, ids, masks, k, ids.index(hold))

    def _near(self, obs: Observation, masks: np.ndarray, k: int, contact: bool) -> np.ndarray:
        """(K,) bool: the objects a share is taken of for object k (its pseudo-direct
        contacts, or with `contact` False every visible one)."""
        if contact:
            return support_contact(masks, self.params, self._gaps(obs, masks))[k]
        return np.ones(len(masks), bool)


def depth_changes(start: Observation, now: Observation, min_pixels: int) -> dict[int, float]:
    """Box id -> the median |depth change| (m) over its pixels visible in both observations
    (at least `min_pixels` of them): how far it moved along the view, from the images alone.
    A box hidden behind another now (the pulled box coming closer) keeps only its pixels
    still seen, so occlusion alone is no motion."""
    out = {}
    for k in start.visible_boxes(min_pixels):
        both = (start.instance == k + 1) & (now.instance == k + 1)
        if both.sum() >= min_pixels:
            out[k] = float(np.median(np.abs(now.depth_m[both] - start.depth_m[both])))
    return out


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
