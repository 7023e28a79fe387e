"""Generate one labelled scene: place, settle, render, then simulate every action.

The removal matrix D[x, y] is the displacement (m) of box y when box x is removed (SPEC.md);
one simulation per target x from the same settled state. With pulls, P[x, s, y] is the
displacement of y when x is pulled out toward the camera while box s is held (s == N: no
support), as thesis ch. 4 labels its (extract, support) pairs.
"""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.sim.catalog import box_extents_m
from clutterbench.sim.families import get_family
from clutterbench.sim.physics import BoxWorld, PhysicsConfig
from clutterbench.sim.render import CameraConfig, render_depth_instance
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec

REJECT_REASONS = ("moving", "fell", "no_room")


@dataclasses.dataclass
class LabelledScene:
    spec: SceneSpec
    depth_m: np.ndarray
    instance: np.ndarray
    removal_m: np.ndarray
    """(N, N) D[x, y]; NaN on the diagonal."""
    pull_m: np.ndarray | None
    """(N, N + 1, N) P[x, s, y] or None; NaN where x == y or s == x or s == y."""
    rejected: dict[str, int]
    steps: int
    pictures: int
    sapien_s: float
    """Wall time spent inside SAPIEN step/render calls, rejected attempts included."""


def scene_rng(seed: int, dataset: str, index: int, attempt: int) -> np.random.Generator:
    """Each scene's own stream: (base seed, dataset, scene index, attempt) -> generator."""
    return np.random.default_rng([seed, zlib.crc32(dataset.encode()), index, attempt])


def build_world(spec: SceneSpec, physics: PhysicsConfig, render: bool) -> BoxWorld:
    world = BoxWorld(spec.shelf, physics, render=render)
    for size, pose in zip(spec.sizes_m, spec.poses):
        world.add_box(size, pose)
    return world


def place_and_settle(
    family: str,
    catalogue: str,
    n_objects: int,
    rng: np.random.Generator,
    physics: PhysicsConfig,
    shelf: Shelf,
    render: bool,
) -> tuple[BoxWorld, list[dict], str | None]:
    """Arrange a scene and let it come to rest; returns (world, clusters, reject reason)."""
    types = box_extents_m(catalogue)
    sizes = types[rng.integers(0, len(types), size=n_objects)]
    world = BoxWorld(shelf, physics, render=render)
    placement = get_family(family).place(world, sizes, rng)
    if world.n < n_objects:
        return world, placement.clusters, "no_room"
    if not world.settle().at_rest:
        return world, placement.clusters, "moving"
    if not np.all(shelf.contains(world.positions())):
        return world, placement.clusters, "fell"
    return world, placement.clusters, None


def removal_matrix(world: BoxWorld) -> np.ndarray:
    state = world.save()
    out = np.full((world.n, world.n), np.nan)
    for x in range(world.n):
        world.restore(state)
        out[x] = world.remove(x)
    world.restore(state)
    return out


def pull_tensor(world: BoxWorld) -> np.ndarray:
    n = world.n
    state = world.save()
    out = np.full((n, n + 1, n), np.nan)
    for x in range(n):
        for s in [n, *[j for j in range(n) if j != x]]:
            world.restore(state)
            disp = world.pull(x, None if s == n else s)
            if s != n:
                disp[s] = np.nan
            out[x, s] = disp
    world.restore(state)
    return out


def generate_labelled_scene(
    *,
    seed: int,
    dataset: str,
    index: int,
    family_weights: dict,
    catalogue: str,
    n_objects: tuple[int, int],
    pulls: bool,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf | None = None,
) -> LabelledScene:
    """Scene `index` of `dataset`, regenerable alone from (seed, dataset, index)."""
    shelf = shelf or Shelf()
    rejected = dict.fromkeys(REJECT_REASONS, 0)
    names = sorted(family_weights)
    weights = np.array([family_weights[k] for k in names], dtype=np.float64)
    steps, sapien_s = 0, 0.0
    for attempt in range(max_attempts):
        rng = scene_rng(seed, dataset, index, attempt)
        family = names[int(rng.choice(len(names), p=weights / weights.sum()))]
        n = int(rng.integers(n_objects[0], n_objects[1] + 1))
        world, clusters, reason = place_and_settle(
            family, catalogue, n, rng, physics, shelf, render=True
        )
        if reason is not None:
            rejected[reason] += 1
            steps += world.steps_taken
            sapien_s += world.sapien_s
            continue
        depth_m, instance = render_depth_instance(world, camera)
        spec = SceneSpec(
            sizes_m=np.array(world.sizes_m),
            poses=world.poses(),
            shelf=shelf,
            camera=camera,
            family=family,
            meta={
                "dataset": dataset,
                "index": index,
                "seed": seed,
                "attempt": attempt,
                "clusters": clusters,
            },
        )
        removal = removal_matrix(world)
        pull = pull_tensor(world) if pulls else None
        steps += world.steps_taken
        sapien_s += world.sapien_s
        return LabelledScene(spec, depth_m, instance, removal, pull, rejected, steps, 1, sapien_s)
    raise ClutterbenchError(
        f"{dataset} scene {index}: rejected {max_attempts} times ({rejected}); "
        "the family cannot fit these boxes"
    )
