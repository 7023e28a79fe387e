"""The search oracles of Table 6.3 (`oracle`, `oracle_hold`): sequences of pulls (and holds)
simulated from the true state with the trials' own pull, under a node budget; a ceiling under
each criterion. The physics-from-depth planner runs the same search on an estimated scene
(`SearchOracle.plan_from`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.observation import Observation
from clutterbench.planning.ch6.extraction import (
    Decision,
    visible_objects,
)
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.pull import SceneState, execute_pull, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6_groups import PullExecution, SearchLimits
from clutterbench.trials.core.protocol import judge_pull

Action = tuple[int, "int | None"]
"""(box to pull, box the second arm holds or None)."""


class SearchOracle:
    """The ceiling: a depth-first search over sequences of pulls, each simulated from the
    present state with the trials' own step (`protocol.execute_pull` in a world built by
    `protocol.world_at`, released and judged as an executed step is), for a sequence of
    clean steps that ends with the target out. A state is what the next step depends on:
    the boxes out and where the rest stand, two states within `limits.same_m` and
    `limits.same_deg` of each other taken for one (`SeenStates`); every clean action from a
    state is searched, every clean hold of a pull included, so up to the node budget and
    that tolerance the search finds a clean sequence whenever one exists.

    Actions: every visible box (planners see no other) and the target; with `holding`, the
    target may also be pulled while any one visible box is held (the bimanual and ch. 4
    planners hold one box while pulling the target), the boxes its unheld pull disturbs
    tried first. Holding a box that the unheld pull leaves within the threshold can still
    save the others (it stops the few millimetres that let them slide), so no box is left
    out. With `hold_any_pull` as well, a box other than the target whose unheld pull is not
    clean may be pulled while any one visible box is held (the bimanual pull planners' idle
    arm holds during such pulls). As execution reproduces the simulation bit for bit, the
    plan found is followed; no planner succeeds on an episode where the search proved there
    is no such sequence, unless a node budget ran out (counted) or a planner's aborted pull
    left a state outside the search's actions.
    Lives here, not in planning/, because it reads the world."""

    def __init__(
        self,
        spec: SceneSpec,
        physics: PhysicsConfig,
        camera: CameraConfig,
        pull: PullExecution,
        limits: SearchLimits,
        holding: bool,
        cf: CollapseFreeConfig,
        hold_any_pull: bool = False,
    ):
        self.spec, self.physics, self.camera = spec, physics, camera
        self.pull, self.limits = pull, limits
        self.holding, self.cf = holding, cf
        self.hold_any_pull = holding and hold_any_pull
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
        held) has already moved more than `limits.cut_m` is stopped there and judged a
        failure (no state, no displacements): that box does not come back within the moved
        threshold, and most simulated pulls in a pile fail, so this is most of the search's
        saving."""
        world = world_at(self.spec, state, self.physics)
        p = self.pull
        box, hold = action
        watch = [k for k in range(self.spec.n) if k not in state.removed and k not in action]

        def go_on(done: int) -> bool:
            if done and watch and np.max(world.displacements()[watch]) > self.limits.cut_m:
                raise _CutShort
            return True

        try:
            result = execute_pull(
                world,
                box,
                hold,
                p.increment_m,
                p.grasp_lift_m,
                go_on if cut_short else None,
                **p.release(),
            )
        except _CutShort:
            return {"success": False, "strict_success": False, "cut_short": True}, None, None
        step = judge_pull(result, box, hold, state.removed, p.moved_threshold_m, self.cf)
        return step, SceneState.of(world), result.displacement_m

    def candidates(self, state: SceneState, target: int) -> list[int]:
        """What a planner could pull in `state`: the visible boxes and the target."""
        obs = observe(world_at(self.spec, state, self.physics, render=True), self.camera)
        ids, _ = visible_objects(obs, self.limits.min_pixels)
        return sorted(set(ids) | {target})

    def search(
        self, state: SceneState, target: int, key: str = "strict_success"
    ) -> tuple[list | None, int, bool]:
        """(plan: [(action, state after it)] or None, nodes expanded, budget exhausted): a
        sequence of steps each clean under the criterion `key` ("strict_success", pulls cut
        short once another box moved `limits.cut_m`; or "success", collapse-free, pulls never
        cut short: a box that slid far may still be collapse-free).

        Complete up to the node budget and the state tolerance: every clean action from a
        state is a child (every clean hold of a pull, not only the first), tried in order,
        and a state is skipped only when one seen before has the same boxes out and every
        other box within `limits.same_m` / `limits.same_deg` of where it stands here
        (`SeenStates`): two orders that take out the same boxes may leave the rest standing
        differently, and the next step depends on that."""
        cut = key == "strict_success"
        seen = SeenStates(self.limits.same_m, self.limits.same_deg)
        seen.add(state)
        nodes = 0
        budget = self.limits.node_budget

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
            in_way = np.nan_to_num(disp, nan=0.0) > self.pull.moved_threshold_m
            if self.holding:
                others = sorted((b for b in boxes if b != target), key=lambda b: (not in_way[b], b))
                for h in others:
                    step, after, _ = self.simulate(now, (target, h), cut_short=cut)
                    if step[key]:
                        return [((target, h), after)]
            for action in self._pulls_before(boxes, target, in_way):
                step, after, _ = self.simulate(now, action, cut_short=cut)
                if not step[key] or seen.contains(after):
                    continue
                seen.add(after)
                rest = visit(after)
                if rest is not None:
                    return [(action, after), *rest]
            return None

        try:
            return visit(state), nodes, False
        except _Budget:
            return None, nodes, True

    def _pulls_before(self, boxes: list[int], target: int, in_way: np.ndarray) -> list[Action]:
        """Every pull of a box other than the target a search may take before the target's,
        the boxes in the target's way first: unheld, then (with `hold_any_pull`) while each
        other visible box is held."""
        holds = boxes if self.hold_any_pull else []
        order = sorted((b for b in boxes if b != target), key=lambda b: (not in_way[b], b))
        return [(x, h) for x in order for h in [None, *(b for b in holds if b != x)]]

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


class _Budget(Exception):
    """A search expanded its node budget."""


class SeenStates:
    """The states a search has expanded, and whether a new one is one of them: the same boxes
    out, and every box still in within `same_m` of its position and `same_deg` of its
    orientation there."""

    def __init__(self, same_m: float, same_deg: float):
        self.same_m = same_m
        # Unit quaternions of rotations theta apart lie 2 sin(theta / 4) apart (q or -q):
        # a chord, not an angle from acos, so a pose stored in float32 matches itself.
        self.max_chord = 2.0 * np.sin(np.radians(same_deg) / 4.0)
        self._by_removed: dict[frozenset[int], list[np.ndarray]] = {}

    def add(self, state: SceneState) -> None:
        self._by_removed.setdefault(state.removed, []).append(self._standing(state))

    def contains(self, state: SceneState) -> bool:
        now = self._standing(state)
        return any(self._same(now, other) for other in self._by_removed.get(state.removed, []))

    @staticmethod
    def _standing(state: SceneState) -> np.ndarray:
        keep = [k for k in range(len(state.poses)) if k not in state.removed]
        return np.asarray(state.poses, dtype=np.float64)[keep]

    def _same(self, a: np.ndarray, b: np.ndarray) -> bool:
        if not len(a):
            return True
        if np.max(np.linalg.norm(a[:, :3] - b[:, :3], axis=1)) > self.same_m:
            return False
        qa, qb = a[:, 3:], b[:, 3:]
        chord = np.minimum(np.linalg.norm(qa - qb, axis=1), np.linalg.norm(qa + qb, axis=1))
        return bool(np.max(chord) <= self.max_chord)


class _CutShort(Exception):
    """A simulated pull already disturbed another box beyond recovery."""


def _same_state(a: SceneState, b: SceneState) -> bool:
    return a.removed == b.removed and np.array_equal(a.poses, b.poses)
