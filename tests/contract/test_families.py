"""Every scene family: shapes, dtypes, physical sanity and determinism of one seeded scene."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim.config import FAMILY_NAMES
from clutterbench.sim.families import FAMILIES
from clutterbench.sim.labelling import build_world, generate_labelled_scene
from clutterbench.sim.spec import SceneSpec

CATALOGUE = {"pile": "same"}
N_OBJECTS = {"pile": (6, 6), "organized": (5, 9), "disorganized": (5, 9)}


def make(family: str, physics, camera, index: int = 0, pulls: bool = False):
    return generate_labelled_scene(
        seed=0,
        dataset="contract",
        index=index,
        family_weights={family: 1.0},
        catalogue=CATALOGUE.get(family, "various"),
        n_objects=N_OBJECTS.get(family, (5, 8)),
        pulls=pulls,
        physics=physics,
        camera=camera,
        max_attempts=30,
    )


@pytest.fixture(scope="module", params=sorted(FAMILIES))
def family_scene(request, physics, camera):
    return request.param, make(request.param, physics, camera)


def test_shapes_and_dtypes(family_scene, camera):
    family, sc = family_scene
    n, size = sc.spec.n, camera.image_size
    lo, hi = N_OBJECTS.get(family, (5, 8))
    assert lo <= n <= hi and sc.spec.family == family
    assert sc.depth_m.shape == (size, size) and sc.depth_m.dtype == np.float32
    assert sc.instance.shape == (size, size) and sc.instance.dtype == np.uint8
    assert sc.removal_m.shape == (n, n)
    assert np.all(np.isnan(np.diag(sc.removal_m)))
    off = sc.removal_m[~np.eye(n, dtype=bool)]
    assert np.all(np.isfinite(off)) and np.all(off >= 0)
    assert set(np.unique(sc.instance)) <= set(range(n + 1))
    assert 0.3 < sc.depth_m[sc.instance > 0].min() and sc.depth_m.max() < 1.0  # metres
    assert sc.spec.sizes_m.shape == (n, 3) and sc.spec.poses.shape == (n, 7)


def test_one_seeded_scene_is_deterministic(family_scene, physics, camera):
    family, sc = family_scene
    again = make(family, physics, camera)
    assert again.spec.to_json() == sc.spec.to_json()
    assert np.array_equal(again.depth_m, sc.depth_m)
    assert np.array_equal(again.instance, sc.instance)
    assert np.array_equal(again.removal_m, sc.removal_m, equal_nan=True)


def test_settled_scene_with_no_action_moves_nothing(family_scene, physics):
    """Physics sanity: a settled scene left alone for 2 s keeps every box in place."""
    _, sc = family_scene
    world = build_world(sc.spec, physics, render=False)
    before = world.positions()
    world.step(int(2.0 / physics.timestep_s))
    drift = np.linalg.norm(world.positions() - before, axis=1)
    assert drift.max() < 0.5e-3, f"boxes drifted {drift.max() * 1e3:.2f} mm with no action"


def test_settled_spec_passes_validation_and_pulls_have_their_shape(family_scene):
    """Every generated spec loads (no box outside the shelf, none jammed into another)."""
    _, sc = family_scene
    again = SceneSpec.from_json(sc.spec.to_json())
    assert np.array_equal(again.poses, sc.spec.poses)
    assert np.array_equal(again.sizes_m, sc.spec.sizes_m)


def test_family_names_match_the_registry():
    """Configs validate family names without importing SAPIEN: the list must stay in step."""
    assert set(FAMILY_NAMES) == set(FAMILIES)
