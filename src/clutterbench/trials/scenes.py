"""Trial scenes: drawn from seed streams of their own, settled, and their physics truth.

A trial scene is never a dataset scene: its placement stream is keyed by "trials/<stream>"
(data/generate keys datasets by their own names), and the target is drawn from a third
stream, so every condition on one stream sees the same scenes and the same targets.
"""

from __future__ import annotations

import zlib

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.observation import Observation
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.labelling import (
    catalogue_type_ids,
    draw_scene_setup,
    place_and_settle,
    removal_matrix,
    scene_rng,
    settled_contacts,
)
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import SceneStreamConfig


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
) -> SceneSpec:
    """Scene `index` of a trials stream, settled (the canonical start of its episode)."""
    shelf = shelf or Shelf()
    key = stream_key(stream)
    family, n = draw_scene_setup(seed, key, index, dict(cfg.families), cfg.n_objects)
    rejected: dict[str, int] = {}
    for attempt in range(max_attempts):
        rng = scene_rng(seed, key, index, attempt)
        world, _, reason = place_and_settle(family, cfg.catalogue, n, rng, physics, shelf)
        if reason is not None:
            rejected[reason] = rejected.get(reason, 0) + 1
            continue
        sizes = np.array(world.sizes_m)
        return SceneSpec(
            sizes_m=sizes,
            poses=world.poses(),
            shelf=shelf,
            camera=camera,
            family=family,
            meta={
                "stream": key,
                "index": index,
                "seed": seed,
                "attempt": attempt,
                "rejected": dict(sorted(rejected.items())),
            },
            type_ids=catalogue_type_ids(sizes, cfg.catalogue),
        )
    raise ClutterbenchError(
        f"trials stream {stream} scene {index}: rejected {max_attempts} times; "
        f"the {family} family cannot fit {n} boxes"
    )


def draw_target(seed: int, stream: str, index: int, obs: Observation, min_pixels: int) -> int:
    """The episode's target: uniform among the boxes with >= `min_pixels` visible pixels."""
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
