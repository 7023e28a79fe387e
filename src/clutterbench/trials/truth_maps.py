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
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec


class TruthCollapseMaps:
    """A PredictFn (planning/extraction.py) answered by simulation at the present state."""

    def __init__(self, spec: SceneSpec, physics: PhysicsConfig, moved_threshold_m: float):
        self.spec, self.physics, self.threshold = spec, physics, moved_threshold_m
        self._state: SceneState | None = None
        self._instance: np.ndarray | None = None
        self._held: tuple[int, ...] = ()
        self._cache: dict[int, np.ndarray] = {}
        self.simulations = 0
        """Removals simulated so far (each a fresh world settled once)."""

    def at(self, state: SceneState, instance: np.ndarray, held: Iterable[int] = ()) -> None:
        """The present state, the instance image the masks are cut from (box k is k + 1) and
        the boxes held there; the next calls answer for it."""
        self._state, self._instance = state, np.asarray(instance)
        self._held = tuple(sorted(int(k) for k in held))
        self._cache = {}

    def moved_by_removing(self, box: int) -> np.ndarray:
        """(N,) bool: the boxes (not `box`, not held, not already out) that move beyond the
        label threshold when `box` is lifted out of the present state."""
        if box not in self._cache:
            state = self._state
            assert state is not None, "the harness sets the present state first (at)"
            world = BoxWorld.from_state(self.spec, state.poses, state.removed, self.physics)
            held = [k for k in self._held if k != box]
            if held:
                world.hold(held)
            disp = np.nan_to_num(world.lift_out(box).displacement_m, nan=0.0)
            self.simulations += 1
            moved = disp > self.threshold
            moved[[box, *held, *sorted(state.removed)]] = False
            self._cache[box] = moved
        return self._cache[box]

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
