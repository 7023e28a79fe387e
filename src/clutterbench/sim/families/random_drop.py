"""`random` (thesis Fig. 6.4c): boxes dropped at random poses and heights onto the others."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.families.base import Placement, SceneFamily, drop_on_top, random_xy
from clutterbench.sim.geometry import random_quat
from clutterbench.sim.physics import BoxWorld


class RandomDrop(SceneFamily):
    name = "random"
    max_lift_m = 0.06
    """Extra random drop height above the surface below."""
    candidates = 4
    """Random drop spots tried per box; the lowest is used."""
    x_frac = (0.45, 1.0)
    """Drop spots span this fraction of the shelf depth (front boxes would tip out)."""
    drop_every_s = 0.15
    """Simulated time between drops, so later boxes land on a moving, then resting, pile."""

    def place(self, world: BoxWorld, sizes_m: np.ndarray, rng: np.random.Generator) -> Placement:
        steps = max(1, int(round(self.drop_every_s / world.cfg.timestep_s)))
        for size in sizes_m:
            quat = random_quat(rng)
            # A few candidate spots, the lowest wins: piles spread instead of towering.
            xy = random_xy(world, rng, self.candidates, self.x_frac)
            idx = drop_on_top(world, size, quat, xy, lift_m=rng.uniform(0, self.max_lift_m))
            if idx is None:  # no room above: let the pile settle once, then try again
                world.settle(0.5)
                drop_on_top(world, size, quat, xy)
            world.step(steps)
        return Placement([])
