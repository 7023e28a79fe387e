"""A perturbed world: one seeded draw of friction, box masses, pull speed and start-pose jitter
(noise.* params), applied to a scene spec, the physics and each step's start state."""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.noise.config import NoiseConfig

REPLAY, SEARCH = 0, 1
"""The two families of draws: the replays' and the robust oracles' (never the same worlds)."""


@dataclasses.dataclass(frozen=True)
class Draw:
    """One perturbed world; factors of 1 and jitter 0 give the table's world bit for bit."""

    friction: float
    """Factor on static and dynamic friction."""
    pull_speed: float
    """Factor on the pull's speed."""
    mass: np.ndarray
    """(N,) factor on each box's density (so its mass)."""
    jitter_m: float
    """Largest move of a box at a step's start (m)."""
    seed: tuple[int, ...]
    """Seeds each step's jitter (with the step's index)."""

    @classmethod
    def none(cls, n: int) -> Draw:
        """The table's own world."""
        return cls(1.0, 1.0, np.ones(n), 0.0, (0,))

    def physics(self, base: PhysicsConfig) -> PhysicsConfig:
        return dataclasses.replace(
            base,
            static_friction=base.static_friction * self.friction,
            dynamic_friction=base.dynamic_friction * self.friction,
            pull_speed_m_s=base.pull_speed_m_s * self.pull_speed,
        )

    def spec(self, spec: SceneSpec, base: PhysicsConfig) -> SceneSpec:
        density = np.array([spec.density(k, base.density_kg_m3) for k in range(spec.n)])
        return dataclasses.replace(spec, densities_kg_m3=density * self.mass)

    def start(self, state: SceneState, step: int) -> SceneState:
        """A step's start state with every box still in the scene jittered."""
        if self.jitter_m == 0.0:
            return state
        rng = np.random.default_rng([*self.seed, step])
        n = len(state.poses)
        move = np.zeros((n, 3))
        move[:, :2] = rng.uniform(-self.jitter_m, self.jitter_m, (n, 2))
        move[:, 2] = rng.uniform(0.0, self.jitter_m, n)
        move[sorted(state.removed)] = 0.0
        poses = state.poses.copy()
        poses[:, :3] += move
        return SceneState(poses, state.removed)


def draw(cfg: NoiseConfig, seed: int, stream: str, index: int, k: int, n: int, kind: int) -> Draw:
    """Draw `k` of episode `index` of `stream` (n boxes): the same for every condition on the
    stream (common random numbers: the conditions are compared on the same worlds)."""
    key = (seed, zlib.crc32(stream.encode()), index, kind, k)
    rng = np.random.default_rng(key)
    return Draw(
        friction=float(rng.uniform(1 - cfg.friction_rel, 1 + cfg.friction_rel)),
        pull_speed=float(rng.uniform(1 - cfg.pull_speed_rel, 1 + cfg.pull_speed_rel)),
        mass=rng.uniform(1 - cfg.mass_rel, 1 + cfg.mass_rel, n),
        jitter_m=cfg.jitter_m,
        seed=key,
    )
