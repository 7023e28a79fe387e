"""Physics-truth collapse maps behind the collapse predictor's interface: the perception
ceiling of the CP planners (Table 6.3's `*_truth` rows).

`TruthCollapseMaps(depth_m, masks) -> (K, H, W)` answers what the collapse predictor is asked,
from physics instead of a network: the map of removing box x is the visible pixels of the
boxes that move beyond the label threshold when x is lifted out of the *present* state and the
rest settles, simulated in a fresh world built at that state (the canonical start, as the
dataset labels are), with the boxes the second arm holds at that moment still held. The trial
harness tells it the present state before the planner's decision and before every monitor
check during a pull (`at`); the planner itself is unchanged, so a truth row differs from its
CP row only in the maps. Lives in trials/, not planning/, because it reads the world.

With `pull=(increment_m, lift_m)` the maps are of the trial's own action instead
(`*_pull_truth`): the map of box x is the boxes that move beyond the label threshold or leave
the shelf when x is pulled out of the present state by the trials' executor
(sim.pull.execute_pull, the same increments and lift, the held box held and released, the
scene settled), so it agrees bit for bit with executing that whole pull. Friction drags
what rests on or leans against the pulled box, which deleting it never shows. During a pull
the maps keep the decision's answers: the pull in progress is the very pull simulated, so
the rest of it is already known (the monitor of a truth-pull planner never fires on its own
choice).

`held(depth_m, mask, held_mask)` answers for a pull made holding a box (trials.ch6.truth_hold
simulate, planning/ch6/extraction.py PredictHeldFn): the boxes that pulling x while holding h
collapses, h let go and settled at the end and judged as the trials judge a released box
(only leaving the shelf counts for it), so a held pull's map agrees with its executed step.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from clutterbench.criteria import CollapseFreeConfig, box_motion, collapsed, moved
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import PullResult, SceneState, execute_pull, world_at
from clutterbench.sim.spec import SceneSpec


class TruthCollapseMaps:
    """A PredictFn (planning/ch6/extraction.py) answered by simulation at the present state."""

    def __init__(
        self,
        spec: SceneSpec,
        physics: PhysicsConfig,
        moved_threshold_m: float,
        pull: tuple[float, float] | None = None,
        collapse: CollapseFreeConfig | None = None,
        release: Mapping[str, bool] | None = None,
    ):
        self.spec, self.physics, self.threshold = spec, physics, moved_threshold_m
        self.pull = pull
        """(increment_m, lift_m) of the trials' pull: maps of pulling; None: of deleting."""
        self.release = dict(release or {})
        """execute_pull's release options (trials.ch6's pull.release()): as the trials execute."""
        self.collapse = collapse
        """With `pull`: mark only the boxes the pull collapses by this collapse-free
        criterion (criteria.py), not every box it moves (None)."""
        self._state: SceneState | None = None
        self._instance: np.ndarray | None = None
        self._held: tuple[int, ...] = ()
        self._cache: dict[int, np.ndarray] = {}
        self._held_cache: dict[tuple[int, int], np.ndarray] = {}
        self.simulations = 0
        """Removals simulated so far (each a fresh world settled once)."""

    def at(self, state: SceneState, instance: np.ndarray, held: Iterable[int] = ()) -> None:
        """The present state, the instance image the masks are cut from (box k is k + 1) and
        the boxes held there; the next calls answer for it."""
        mid_pull = self.pull is not None and bool(tuple(held))
        self._state, self._instance = state, np.asarray(instance)
        if not mid_pull:  # a pull in progress is the one simulated: keep its answers
            self._held = tuple(sorted(int(k) for k in held))
            self._cache, self._held_cache = {}, {}

    def moved_by_removing(self, box: int) -> np.ndarray:
        """(N,) bool: the boxes (not `box`, not held, not already out) that move beyond the
        label threshold when `box` is lifted out of the present state (with `pull`: pulled
        out by the trials' executor; leaving the shelf counts as moving)."""
        if box not in self._cache:
            state = self._state
            assert state is not None, "the harness sets the present state first (at)"
            held = [k for k in self._held if k != box]
            if self.pull is None:
                world = BoxWorld.from_state(self.spec, state.poses, state.removed, self.physics)
                if held:
                    world.hold(held)
                disp = np.nan_to_num(world.lift_out(box).displacement_m, nan=0.0)
                marked = disp > self.threshold
            else:
                result = pull_outcome(
                    self.spec, state, self.physics, box, held, self.pull, self.release
                )
                marked = self._marked(result)
            self.simulations += 1
            marked[[box, *held, *sorted(state.removed)]] = False
            self._cache[box] = marked
        return self._cache[box]

    def _marked(self, result: PullResult, hold: int | None = None) -> np.ndarray:
        """(N,) bool: the boxes a simulated pull moves beyond the threshold or off the shelf
        (`collapse`: that it collapses by that criterion). A released `hold` is judged as
        the trials judge it: only leaving the shelf counts (it may settle lower)."""
        if hold is None and self.collapse is None:
            disp = np.nan_to_num(result.displacement_m, nan=0.0)
            return (disp > self.threshold) | ~result.on_shelf
        held = [] if hold is None else [hold]
        others = [k for k in range(self.spec.n) if k not in held]
        motion = box_motion(result.poses_start, result.poses_end, result.on_shelf, others, held)
        if self.collapse is None:
            return np.array([moved(e, self.threshold) or e["left_shelf"] for e in motion])
        return np.array([collapsed(e, self.collapse) for e in motion])

    def moved_by_held_pull(self, box: int, hold: int) -> np.ndarray:
        """(N,) bool: as moved_by_removing with `pull`, for pulling `box` while `hold` is
        held (then let go and settled, as the trials' executor does): the held box marked as
        the trials judge a released box (_marked)."""
        assert self.pull is not None, "a held pull's map is a map of the pull"
        key = (box, hold)
        if key not in self._held_cache:
            state = self._state
            assert state is not None, "the harness sets the present state first (at)"
            result = pull_outcome(
                self.spec, state, self.physics, box, [hold], self.pull, self.release
            )
            marked = self._marked(result, hold)
            self.simulations += 1
            marked[[box, *sorted(state.removed)]] = False
            self._held_cache[key] = marked
        return self._held_cache[key]

    def held(self, depth_m: np.ndarray, mask: np.ndarray, held_mask: np.ndarray) -> np.ndarray:
        """(H, W) float32 (planning/ch6/extraction.py PredictHeldFn): 1 on the visible pixels of
        every box that pulling the box under `mask` while holding the one under `held_mask`
        moves (moved_by_held_pull)."""
        assert self._instance is not None, "the harness sets the present state first (at)"
        marked = self.moved_by_held_pull(self.box_of(mask), self.box_of(held_mask))
        return np.isin(self._instance, np.flatnonzero(marked) + 1).astype(np.float32)

    def box_of(self, mask: np.ndarray) -> int:
        """The box whose visible pixels `mask` (H, W) marks, in the present instance image."""
        assert self._instance is not None, "the harness sets the present state first (at)"
        ids = self._instance[np.asarray(mask, bool)]
        ids = ids[ids > 0]
        if ids.size == 0:
            raise ValueError("a mask that covers no box of the present instance image")
        return int(np.bincount(ids).argmax()) - 1

    def __call__(self, depth_m: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(K, H, W) float32: 1 on the visible pixels of every box that the removal of the
        box under mask k moves beyond the threshold, 0 elsewhere."""
        assert self._instance is not None, "the harness sets the present state first (at)"
        out = np.zeros((len(masks), *self._instance.shape), dtype=np.float32)
        for k, mask in enumerate(masks):
            moved = np.flatnonzero(self.moved_by_removing(self.box_of(mask)))
            out[k] = np.isin(self._instance, moved + 1)
        return out


def pull_outcome(
    spec: SceneSpec,
    state: SceneState,
    physics: PhysicsConfig,
    box: int,
    held: Iterable[int],
    pull: tuple[float, float],
    release: Mapping[str, bool] | None = None,
) -> PullResult:
    """The trials' whole pull of `box` from `state` (a fresh world there, the first of
    `held` held): what an executed step that the monitor lets run does, bit for bit."""
    hold = next(iter(held), None)
    increment_m, lift_m = pull
    return execute_pull(
        world_at(spec, state, physics), box, hold, increment_m, lift_m, **(release or {})
    )
