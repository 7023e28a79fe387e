"""Generate one labelled scene: place, settle, render, then simulate every action.

The removal matrix D[x, y] is the displacement (m) of box y when box x is removed
(docs/simulation.md).
With pulls, P[x, s, y] is the displacement of y when x is pulled out toward the camera while
box s is held (s == N: no support), as thesis ch. 4 labels its (extract, support) pairs.

Every label starts from the canonical state: a fresh world built from the settled spec
(`BoxWorld.from_spec`), so each is a function of the spec alone, whatever was simulated
before it, and `act_on_spec` (the CLI's replay) reproduces it bit for bit.
"""

from __future__ import annotations

import dataclasses
import numbers
import zlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import numpy as np

from clutterbench.errors import ClutterbenchError
from clutterbench.sim import benchmark
from clutterbench.sim.catalog import box_extents_m
from clutterbench.sim.clusters import scene_clusters
from clutterbench.sim.config import REJECT_REASONS, CameraConfig, PhysicsConfig
from clutterbench.sim.families import get_family
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import render_depth_instance
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec, deepest_overlap


@dataclasses.dataclass
class LabelledScene:
    spec: SceneSpec
    depth_m: np.ndarray
    instance: np.ndarray
    removal_m: np.ndarray
    """(N, N) D[x, y]; NaN on the diagonal."""
    pull_m: np.ndarray | None
    """(N, N + 1, N) P[x, s, y] or None; NaN where x == y or s == x or s == y."""
    cluster_of: np.ndarray
    """(N,) arrangement cluster of each box (thesis 5.2.1)."""
    cluster_class: np.ndarray
    """(C,) class of each cluster, an index into sim.clusters.CLASSES."""
    cluster_bbox_px: np.ndarray
    """(C, 4) (x, y, w, h) image box of each cluster (thesis eq. 5.1)."""
    contacts: list[tuple[int, int]]
    """Pairs of boxes touching in the settled scene (PhysX contacts)."""
    rejected: dict[str, int]
    steps: int
    pictures: int
    sapien_s: float
    """Wall time spent inside SAPIEN step/render calls, rejected attempts included."""
    pull_outcome: PullOutcomes | None = None
    """What the trials' own pull of each box does, or None."""


@dataclasses.dataclass(frozen=True)
class PullOutcomes:
    """The trials' whole pull of each box x from the canonical start (sim.pull.execute_pull,
    nothing held, the trials' increments and lift; the scene settled after): per (x, y), box
    y's centre displacement, drop and tilt change and whether it ended off the shelf. Row x
    of every array is what a truth map of pulling x reads; NaN / False at y == x."""

    displacement_m: np.ndarray
    """(N, N) float64."""
    drop_m: np.ndarray
    """(N, N) float64: start height - end height."""
    tilt_deg: np.ndarray
    """(N, N) float64: change of the world's up direction in the box's frame."""
    left_shelf: np.ndarray
    """(N, N) bool."""


def scene_rng(seed: int, dataset: str, index: int, attempt: int) -> np.random.Generator:
    """Each attempt's placement stream: (base seed, dataset, scene index, attempt)."""
    return np.random.default_rng([seed, zlib.crc32(dataset.encode()), index, attempt])


MAX_OBJECTS = 30
"""The most boxes a scene may hold (the params' n_objects bound; the environments pad their
observations to this many)."""


def check_n_objects(n_objects: Any, key: str = "n_objects") -> tuple[int, int]:
    """(low, high) of a box count or an inclusive range [low, high] of them, with
    1 <= low <= high <= MAX_OBJECTS; anything else is refused in one line naming `key` (a
    scene of no box has no target, and its first reduction over the boxes would fail deep in
    numpy instead)."""
    pair = [n_objects] * 2 if isinstance(n_objects, numbers.Integral) else n_objects
    try:
        lo, hi = pair
        ok = all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in (lo, hi))
    except (TypeError, ValueError):  # not a pair: a string, a dict, three numbers
        ok = False
    if not ok or isinstance(n_objects, bool) or not 1 <= lo <= hi <= MAX_OBJECTS:
        raise ClutterbenchError(
            f"{key}={n_objects!r}: a number of boxes or a range [low, high] of them, integers "
            f"with 1 <= low <= high <= {MAX_OBJECTS}"
        )
    return int(lo), int(hi)


def draw_scene_setup(
    seed: int,
    dataset: str,
    index: int,
    family_weights: Mapping[str, float],
    n_objects: Sequence[int],
) -> tuple[str, int]:
    """(family, number of boxes) of scene `index`, drawn once from its own stream: a rejected
    attempt redraws only the placement, so hard families are not under-represented. The
    number is capped at the family's `max_objects`."""
    check_n_objects(n_objects)  # (draws nothing: the stream is the same for a valid range)
    rng = np.random.default_rng([seed, zlib.crc32(f"{dataset}/setup".encode()), index])
    names = sorted(family_weights)
    weights = np.array([family_weights[k] for k in names], dtype=np.float64)
    family = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    n = int(rng.integers(n_objects[0], n_objects[1] + 1))
    cap = get_family(family).max_objects
    return family, n if cap is None else min(n, cap)


def build_world(spec: SceneSpec, physics: PhysicsConfig, render: bool) -> BoxWorld:
    return BoxWorld.from_spec(spec, physics, render=render)


def place_and_settle(
    family: str,
    catalogue: str,
    n_objects: int,
    rng: np.random.Generator,
    physics: PhysicsConfig,
    shelf: Shelf,
) -> tuple[BoxWorld, list[list[int]], str | None]:
    """Arrange a scene and let it come to rest (physics only); returns (world, the groups the
    family arranged, reject reason)."""
    types = box_extents_m(catalogue)
    sizes = types[rng.integers(0, len(types), size=n_objects)]
    world = BoxWorld(shelf, physics, render=False)
    placement = get_family(family).place(world, sizes, rng)
    groups = [list(g) for g in placement.groups]
    if world.n < n_objects:
        return world, groups, "no_room"
    if not world.settle().at_rest:
        return world, groups, "moving"
    if not np.all(shelf.contains(world.positions())):
        return world, groups, "fell"
    if deepest_overlap(np.array(world.sizes_m), world.poses()) is not None:
        return world, groups, "overlap"
    # The canonical start must be at rest too: rebuilt from the settled poses (what every
    # action starts from), no box may creep when left alone.
    fresh = BoxWorld(shelf, physics)
    for size, pose in zip(world.sizes_m, world.poses()):
        fresh.add_box(size, pose)
    if np.nanmax(fresh.idle_creep_m()) > physics.rest_check_m:
        return world, groups, "creeping"
    return world, groups, None


def start_creep(spec: SceneSpec, physics: PhysicsConfig) -> tuple[int, float] | None:
    """(box, metres) of the box that moves most in sim.physics.rest_check_s with no action,
    from the spec's canonical start, when it moves more than sim.physics.rest_check_m (the
    generator's "creeping" test); None when the start is at rest. A floating box falls: it
    is named here, before any action would report its fall as a consequence."""
    creep = np.nan_to_num(BoxWorld.from_spec(spec, physics).idle_creep_m(), nan=0.0)
    box = int(np.argmax(creep)) if creep.size else 0
    if creep.size == 0 or creep[box] <= physics.rest_check_m:
        return None
    return box, float(creep[box])


def creep_warning(spec: SceneSpec, physics: PhysicsConfig, name: str) -> str | None:
    """The one-line warning for a spec whose start is not at rest, or None."""
    found = start_creep(spec, physics)
    if found is None:
        return None
    box, dist = found
    return (
        f"warning: {name}: box {box} moves {1000 * dist:.1f} mm in {physics.rest_check_s:g} s "
        "with no action (not at rest; every action on this spec will include that motion)"
    )


def draw_settled_spec(
    *,
    seed: int,
    key: str,
    index: int,
    families: Mapping[str, float],
    n_objects: Sequence[int],
    catalogue: str,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf,
    meta: Mapping[str, object] | None = None,
    keep_groups: bool = False,
    accept: Callable[[SceneSpec], str | None] | None = None,
    accept_key: str | None = None,
) -> SceneSpec:
    """Scene `index` of the seed stream `key`, placed and settled (no labels): the canonical
    start of a trial, or a single scene for the CLI; its meta records the attempt and the
    rejections before it, and with `keep_groups` the groups the family arranged (meta
    "groups", the seeds of the ground-truth arrangement clusters, sim/clusters.py).
    `accept`: the caller's own test of a settled start (None: accepted, else the reason it
    is rejected and the next attempt drawn), e.g. chapter 5's "no free place at the start";
    `accept_key`: what `accept` depends on (a start drawn with an accept but no key is never
    read from the benchmark scenes). A start in the benchmark scenes (sim/benchmark.py) is
    read from them, bit for bit the start drawn where they were made."""
    fields = _start_fields(
        seed,
        ("key", key),
        index,
        families,
        n_objects,
        catalogue,
        physics,
        camera,
        max_attempts,
        shelf,
    ) | {
        "meta": dict(meta or {}),
        "keep_groups": keep_groups,
        "accept": accept_key if accept is not None else None,
    }
    stored_key, stored = benchmark.lookup("settled", fields)
    if stored is not None and (accept is None or accept_key is not None):
        return SceneSpec.from_dict(stored["spec"], where=f"{benchmark.DIR} {key} scene {index}")
    spec = _draw_settled_spec(
        seed,
        key,
        index,
        families,
        n_objects,
        catalogue,
        physics,
        camera,
        max_attempts,
        shelf,
        meta,
        keep_groups,
        accept,
    )
    if accept is None or accept_key is not None:
        value = {"spec": spec.to_dict(), "scene_hash": benchmark.scene_hash(spec)}
        benchmark.remember(stored_key, "settled", key, index, value)
    return spec


def _start_fields(
    seed: int,
    stream: tuple[str, str],
    index: int,
    families: Mapping[str, float],
    n_objects: Sequence[int],
    catalogue: str,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf,
) -> dict[str, object]:
    """What a settled start depends on (its key in the benchmark scenes); `stream`: the seed
    stream's field name and value."""
    return {
        "seed": seed,
        stream[0]: stream[1],
        "index": index,
        "families": {f: float(w) for f, w in sorted(families.items())},
        "n_objects": [int(v) for v in n_objects],
        "catalogue": catalogue,
        "physics": physics,
        "camera": camera,
        "max_attempts": max_attempts,
        "shelf": shelf,
    }


def _draw_settled_spec(
    seed: int,
    key: str,
    index: int,
    families: Mapping[str, float],
    n_objects: Sequence[int],
    catalogue: str,
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf,
    meta: Mapping[str, object] | None,
    keep_groups: bool,
    accept: Callable[[SceneSpec], str | None] | None,
) -> SceneSpec:
    family, n = draw_scene_setup(seed, key, index, families, n_objects)
    rejected: dict[str, int] = {}
    for attempt in range(max_attempts):
        rng = scene_rng(seed, key, index, attempt)
        world, groups, reason = place_and_settle(family, catalogue, n, rng, physics, shelf)
        if reason is not None:
            rejected[reason] = rejected.get(reason, 0) + 1
            continue
        sizes = np.array(world.sizes_m)
        kept = {"groups": [[int(i) for i in g] for g in groups]} if keep_groups else {}
        spec = SceneSpec(
            sizes_m=sizes,
            poses=world.poses(),
            shelf=shelf,
            camera=camera,
            family=family,
            meta={
                "stream": key,
                "index": index,
                "seed": seed,
                **dict(meta or {}),
                "attempt": attempt,
                "rejected": dict(sorted(rejected.items())),
                **kept,
            },
            type_ids=catalogue_type_ids(sizes, catalogue),
        )
        reason = accept(spec) if accept is not None else None
        if reason is not None:
            rejected[reason] = rejected.get(reason, 0) + 1
            continue
        return spec
    raise ClutterbenchError(
        f"{key} scene {index}: rejected {max_attempts} times ({rejected}); "
        f"the {family} family cannot fit {n} boxes"
    )


def catalogue_type_ids(sizes_m: np.ndarray, catalogue: str) -> np.ndarray:
    """(N,) index of each box's size in the catalogue (-1 if it is none of them)."""
    types = box_extents_m(catalogue)
    match = np.all(sizes_m[:, None, :] == types[None], axis=-1)
    return np.where(match.any(axis=1), match.argmax(axis=1), -1)


Action = Literal["remove", "pull"]


def act_on_spec(
    spec: SceneSpec,
    physics: PhysicsConfig,
    action: Action,
    target: int,
    support: int | None = None,
    world: BoxWorld | None = None,
    lift_m: float = 0.0,
) -> np.ndarray:
    """Displacement (m) of every box when `target` is removed or pulled out (with `support`
    held; a pull raised by `lift_m` first), simulated from the canonical start. The one code
    path of labels and replays."""
    world = world or BoxWorld.from_spec(spec, physics)
    assert world.steps_taken == 0, "actions start from a freshly built world"
    if action == "pull":
        return world.pull(target, support, lift_m)
    return world.remove(target, support)


class _Tally:
    """Physics steps and SAPIEN time over every world a scene used (for the benchmark)."""

    def __init__(self) -> None:
        self.steps, self.sapien_s = 0, 0.0

    def add(self, world: BoxWorld) -> BoxWorld:
        self.steps += world.steps_taken
        self.sapien_s += world.sapien_s
        return world


def removal_matrix(
    spec: SceneSpec, physics: PhysicsConfig, tally: _Tally | None = None
) -> np.ndarray:
    out = np.full((spec.n, spec.n), np.nan)
    for x in range(spec.n):
        world = BoxWorld.from_spec(spec, physics)
        out[x] = act_on_spec(spec, physics, "remove", x, world=world)
        if tally is not None:
            tally.add(world)
    return out


def pull_tensor(spec: SceneSpec, physics: PhysicsConfig, tally: _Tally | None = None) -> np.ndarray:
    n = spec.n
    out = np.full((n, n + 1, n), np.nan)
    for x in range(n):
        for s in [n, *[j for j in range(n) if j != x]]:
            world = BoxWorld.from_spec(spec, physics)
            disp = act_on_spec(spec, physics, "pull", x, None if s == n else s, world=world)
            if tally is not None:
                tally.add(world)
            if s != n:
                disp[s] = np.nan
            out[x, s] = disp
    return out


def pull_outcomes(
    spec: SceneSpec,
    physics: PhysicsConfig,
    pull: tuple[float, float],
    tally: _Tally | None = None,
) -> PullOutcomes:
    """Pull every box out of the canonical start with the trials' executor (`pull`:
    increment_m, lift_m) -> PullOutcomes. The one code path of these labels, the truth maps
    of the pull (trials/ch6/truth_maps.py) and executed steps."""
    from clutterbench.sim.geometry import tilt_change_deg
    from clutterbench.sim.pull import SceneState, execute_pull, world_at

    n = spec.n
    disp, drop, tilt = (np.full((n, n), np.nan) for _ in range(3))
    left = np.zeros((n, n), dtype=bool)
    start = SceneState.start(spec)
    for x in range(n):
        world = world_at(spec, start, physics)
        result = execute_pull(world, x, None, *pull)
        if tally is not None:
            tally.add(world)
        for y in range(n):
            if y == x:
                continue
            a, b = result.poses_start[y], result.poses_end[y]
            disp[x, y] = float(np.linalg.norm(b[:3] - a[:3]))
            drop[x, y] = float(a[2] - b[2])
            tilt[x, y] = tilt_change_deg(a[3:], b[3:])
            left[x, y] = not bool(result.on_shelf[y])
    return PullOutcomes(disp, drop, tilt, left)


def settled_contacts(
    spec: SceneSpec, physics: PhysicsConfig, tally: _Tally | None = None
) -> list[tuple[int, int]]:
    """Pairs of boxes touching in the settled scene: the canonical start, one step."""
    world = BoxWorld.from_spec(spec, physics)
    world.step(1)
    if tally is not None:
        tally.add(world)
    return world.contact_pairs()


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
    pull_outcome: tuple[float, float] | None = None,
) -> LabelledScene:
    """Scene `index` of `dataset`, regenerable alone from (seed, dataset, index); with
    `pull_outcome` (the trials' increment_m, lift_m), what the trials' pull of each box does."""
    tally = _Tally()
    spec, groups, rejected = dataset_start(
        seed,
        dataset,
        index,
        family_weights,
        catalogue,
        n_objects,
        physics,
        camera,
        max_attempts,
        shelf or Shelf(),
        tally,
    )
    scene = _label_start(spec, groups, rejected, pulls, physics, camera, tally)
    if pull_outcome is None:
        return scene
    outcomes = pull_outcomes(spec, physics, pull_outcome, tally)
    return dataclasses.replace(
        scene, pull_outcome=outcomes, steps=tally.steps, sapien_s=tally.sapien_s
    )


def dataset_start(
    seed: int,
    dataset: str,
    index: int,
    family_weights: Mapping[str, float],
    catalogue: str,
    n_objects: Sequence[int],
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf,
    tally: _Tally | None = None,
) -> tuple[SceneSpec, list, dict[str, int]]:
    """A dataset scene's settled start, its family's groups and the rejections before it; a
    start in the benchmark scenes (sim/benchmark.py: Table 6.2's test scenes) is read from
    them."""
    fields = _start_fields(
        seed,
        ("dataset", dataset),
        index,
        family_weights,
        n_objects,
        catalogue,
        physics,
        camera,
        max_attempts,
        shelf,
    )
    key, stored = benchmark.lookup("dataset", fields)
    if stored is not None:
        spec = SceneSpec.from_dict(stored["spec"], where=f"{benchmark.DIR} {dataset} scene {index}")
        rejected = dict.fromkeys(REJECT_REASONS, 0) | stored["rejected"]
        return spec, [list(g) for g in stored["groups"]], rejected
    spec, groups, rejected = _dataset_start(
        seed,
        dataset,
        index,
        dict(family_weights),
        catalogue,
        tuple(n_objects),
        physics,
        camera,
        max_attempts,
        shelf,
        tally or _Tally(),
    )
    value = {
        "spec": spec.to_dict(),
        "scene_hash": benchmark.scene_hash(spec),
        "groups": [[int(i) for i in g] for g in groups],
        "rejected": rejected,
    }
    benchmark.remember(key, "dataset", dataset, index, value)
    return spec, groups, rejected


def _dataset_start(
    seed: int,
    dataset: str,
    index: int,
    family_weights: dict,
    catalogue: str,
    n_objects: tuple[int, int],
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    shelf: Shelf,
    tally: _Tally,
) -> tuple[SceneSpec, list, dict[str, int]]:
    """A dataset scene's settled start, its family's groups and the rejections before it."""
    rejected = dict.fromkeys(REJECT_REASONS, 0)
    family, n = draw_scene_setup(seed, dataset, index, family_weights, n_objects)
    for attempt in range(max_attempts):
        rng = scene_rng(seed, dataset, index, attempt)
        world, groups, reason = place_and_settle(family, catalogue, n, rng, physics, shelf)
        tally.add(world)
        if reason is not None:
            rejected[reason] += 1
            continue
        sizes = np.array(world.sizes_m)
        spec = SceneSpec(
            sizes_m=sizes,
            poses=world.poses(),
            shelf=shelf,
            camera=camera,
            family=family,
            meta={"dataset": dataset, "index": index, "seed": seed, "attempt": attempt},
            type_ids=catalogue_type_ids(sizes, catalogue),
        )
        return spec, groups, rejected
    raise ClutterbenchError(
        f"{dataset} scene {index}: rejected {max_attempts} times ({rejected}); "
        f"the {family} family cannot fit {n} boxes"
    )


def label_spec(
    spec: SceneSpec, physics: PhysicsConfig, camera: CameraConfig, pull: tuple[float, float]
) -> LabelledScene:
    """A given settled start (a benchmark scene's) rendered and labelled as a dataset scene
    with pull outcomes (the trials' (increment_m, lift_m)): what deleting and what pulling
    each box does."""
    tally = _Tally()
    scene = _label_start(spec, [], {}, False, physics, camera, tally)
    outcomes = pull_outcomes(spec, physics, pull, tally)
    return dataclasses.replace(scene, pull_outcome=outcomes, steps=tally.steps)


def _label_start(
    spec: SceneSpec,
    groups: list,
    rejected: dict[str, int],
    pulls: bool,
    physics: PhysicsConfig,
    camera: CameraConfig,
    tally: _Tally,
) -> LabelledScene:
    """Render and label a settled dataset start."""
    view = BoxWorld.from_spec(spec, physics, render=True)
    depth_m, instance = render_depth_instance(view, camera)
    tally.add(view)
    contacts = settled_contacts(spec, physics, tally)
    cluster_of, classes, boxes = scene_clusters(
        spec.sizes_m, spec.poses, groups, contacts, instance
    )
    removal = removal_matrix(spec, physics, tally)
    pull = pull_tensor(spec, physics, tally) if pulls else None
    return LabelledScene(
        spec,
        depth_m,
        instance,
        removal,
        pull,
        cluster_of,
        classes,
        boxes,
        contacts,
        rejected,
        tally.steps,
        1,
        tally.sapien_s,
    )
