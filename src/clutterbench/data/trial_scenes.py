"""Trial scenes: drawn from seed streams of their own, settled, and their physics truth.

A trial scene is never a dataset scene: its placement stream is keyed by "trials/<stream>"
(data/generate keys datasets by their own names), and the target is drawn from a third
stream, so every condition on one stream sees the same scenes and the same targets.

Here, below the trials, because the support stage (the test set's benchmark starts, its own
test stream) draws the same scenes and targets as the trials and stands below them.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.data.trial_params import SceneStreamConfig
from clutterbench.observation import Observation
from clutterbench.sim import benchmark
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.labelling import draw_settled_spec, removal_matrix, settled_contacts
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec


def stream_key(stream: str) -> str:
    return f"trials/{stream}"


def draw_trial_spec(
    stream: str,
    cfg: SceneStreamConfig,
    seed: int,
    index: int,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf | None = None,
    keep_groups: bool = False,
    accept: Callable[[SceneSpec], str | None] | None = None,
    accept_key: str | None = None,
) -> SceneSpec:
    """Scene `index` of a trials stream, settled (the canonical start of its episode); with
    `keep_groups` its meta holds the family's groups (ground-truth clusters); `accept`: a
    further test of the start, `accept_key` what it depends on
    (sim.labelling.draw_settled_spec). Read from the benchmark scenes when they hold it."""
    return draw_settled_spec(
        seed=seed,
        key=stream_key(stream),
        index=index,
        families=dict(cfg.families),
        n_objects=cfg.n_objects,
        catalogue=cfg.catalogue,
        physics=physics,
        camera=camera,
        max_attempts=max_attempts,
        shelf=shelf or Shelf(),
        keep_groups=keep_groups,
        accept=accept,
        accept_key=accept_key,
    )


def draw_target(
    seed: int,
    stream: str,
    index: int,
    obs: Observation,
    min_pixels: int,
    spec: SceneSpec | None = None,
) -> int:
    """The episode's target: uniform among the boxes with >= `min_pixels` visible pixels in
    the start's observation; with the start's `spec`, read from the benchmark scenes when
    they hold it (the observation is a render, and renders differ across CPUs too)."""
    if spec is None:
        return _draw_target(seed, stream, index, obs, min_pixels)
    key, stored = benchmark.lookup("target", target_fields(seed, stream, index, min_pixels, spec))
    if stored is not None:
        return int(stored["target"])
    target = _draw_target(seed, stream, index, obs, min_pixels)
    benchmark.remember(key, "target", stream_key(stream), index, {"target": target})
    return target


@dataclasses.dataclass(frozen=True)
class StreamStart:
    """One episode's start on a trials stream: what its settled scene (draw_trial_spec) and
    its target (draw_target) are drawn from."""

    stream: str
    """The stream's name (its seed streams are keyed by it)."""
    cfg: SceneStreamConfig
    """The stream's scene distribution (trials.streams[stream])."""
    seed: int
    """The base seed its scene and target streams are drawn from."""
    index: int
    """The episode's scene within the stream."""
    physics: PhysicsConfig
    """The physics the scene settles under."""
    camera: CameraConfig
    """The camera of the start's observation."""
    max_attempts: int
    """How many draws the scene may take to settle before the stream gives up."""

    def spec(self, **options: Any) -> SceneSpec:
        """The settled scene (draw_trial_spec; `options`: its shelf, keep_groups, accept,
        accept_key)."""
        return draw_trial_spec(
            self.stream,
            self.cfg,
            self.seed,
            self.index,
            self.physics,
            self.camera,
            self.max_attempts,
            **options,
        )

    def target(self, obs: Observation, min_pixels: int, spec: SceneSpec | None = None) -> int:
        """The episode's target, drawn from the start's observation `obs` (draw_target)."""
        return draw_target(self.seed, self.stream, self.index, obs, min_pixels, spec)


def target_fields(
    seed: int, stream: str, index: int, min_pixels: int, spec: SceneSpec
) -> dict[str, object]:
    """What an episode's target depends on (its key in the benchmark scenes)."""
    return {
        "seed": seed,
        "stream": stream,
        "index": index,
        "min_pixels": min_pixels,
        "scene": benchmark.scene_hash(spec),
    }


def _draw_target(seed: int, stream: str, index: int, obs: Observation, min_pixels: int) -> int:
    rng = np.random.default_rng([seed, zlib.crc32(f"{stream_key(stream)}/target".encode()), index])
    counts = np.bincount(obs.instance.ravel(), minlength=256)[1:]
    candidates = np.nonzero(counts >= min_pixels)[0]
    if candidates.size == 0:
        candidates = np.array([int(np.argmax(counts))])
    return int(candidates[rng.integers(candidates.size)])


def policy_rng(seed: int, stream: str, index: int, planner: str) -> np.random.Generator:
    """The random policy's own stream per episode."""
    return np.random.default_rng(
        [seed, zlib.crc32(f"{stream_key(stream)}/{planner}".encode()), index]
    )


def truth_moved_contact(
    spec: SceneSpec, physics: PhysicsConfig, threshold_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Physics truth of a settled spec: moved[x, y] (box y moved beyond the threshold when x
    was removed, from the canonical start) and contact[x, y] (they touch), both (N, N)."""
    removal = removal_matrix(spec, physics)
    moved = np.nan_to_num(removal, nan=0.0) > threshold_m
    np.fill_diagonal(moved, False)
    contact = np.zeros((spec.n, spec.n), dtype=bool)
    for a, b in settled_contacts(spec, physics):
        contact[a, b] = contact[b, a] = True
    return moved, contact
