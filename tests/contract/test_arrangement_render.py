"""C^r and C^l are not swapped anywhere between the simulator's tilt and the rendered image
(thesis 5.2.1: the detector must tell them apart, so nothing may flip left and right): books
whose tops lean toward the image's right are C^r, their cluster box lies where the camera
projects them, and the mirrored scene is C^l in the mirrored image."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.perception.boxes import ARRANGEMENT_CLASSES, detections_from_clusters
from clutterbench.sim.clusters import CLASSES, scene_clusters
from clutterbench.sim.families.shelved import STANDING
from clutterbench.sim.geometry import quat_from_axis_angle, quat_mul, quat_to_matrix
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.shelf import Shelf
from clutterbench.sim.spec import SceneSpec

BOOK = np.array([0.10, 0.12, 0.03])  # local (D, W, H): standing, W vertical, H along y
LEAN_DEG = 25.0
CORNERS = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], float)


def leaning_books(side: int) -> SceneSpec:
    """Two books tilted LEAN_DEG about the shelf's x axis, standing on the floor apart, on the
    image's right (side -1: tops toward -y, the camera's right) or the mirror image (+1)."""
    # Rotating +a about x takes a standing box's top toward -y (sim/clusters.py).
    quat = quat_mul(quat_from_axis_angle([1, 0, 0], np.deg2rad(-side * LEAN_DEG)), STANDING)
    lowest = (0.5 * BOOK * CORNERS @ quat_to_matrix(quat).T)[:, 2].min()
    poses = [np.array([0.14, side * y, 0.001 - lowest, *quat]) for y in (0.03, 0.11)]
    return SceneSpec(sizes_m=np.array([BOOK, BOOK]), poses=np.array(poses))


def projected_box_px(spec: SceneSpec, obs) -> np.ndarray:
    """(x0, y0, x1, y1) image extent of every box corner, through the camera model."""
    corners = [
        pose[:3] + (0.5 * size * CORNERS) @ quat_to_matrix(pose[3:]).T
        for size, pose in zip(spec.sizes_m, spec.poses)
    ]
    u, v, _ = obs.camera.world_to_pixel(np.concatenate(corners))
    return np.array([u.min(), v.min(), u.max(), v.max()])


@pytest.fixture(scope="module")
def views(physics, camera):
    out = {}
    for side in (-1, 1):
        spec = leaning_books(side)
        obs = observe(BoxWorld.from_spec(spec, physics, render=True), camera)
        out[side] = (spec, obs)
    return out


@pytest.mark.parametrize(("side", "expected"), [(-1, "C^r"), (1, "C^l")])
def test_lean_class_and_cluster_box_in_the_image(views, camera, side, expected):
    spec, obs = views[side]
    _, classes, boxes = scene_clusters(spec.sizes_m, spec.poses, [[0, 1]], [], obs.instance)
    assert [CLASSES[c] for c in classes] == [expected]
    [det] = detections_from_clusters(classes, boxes)
    assert det.cls == expected and ARRANGEMENT_CLASSES.index(det.cls) == classes[0]
    x, y, w, h = det.box
    half = camera.image_size / 2
    assert (x > half) if expected == "C^r" else (x < half)  # on its side of the image
    x0, y0, x1, y1 = projected_box_px(spec, obs)
    assert [x - w / 2, y - h / 2, x + w / 2, y + h / 2] == pytest.approx([x0, y0, x1, y1], abs=1.0)
    # each book's top (upper rows of its pixels) lies toward the class's side of its bottom
    for k in (1, 2):
        rows, cols = np.nonzero(obs.instance == k)
        top = cols[rows <= np.percentile(rows, 20)].mean()
        bottom = cols[rows >= np.percentile(rows, 80)].mean()
        assert (top > bottom + 2) if expected == "C^r" else (top < bottom - 2)


def test_mirrored_scene_renders_mirrored(views):
    right, left = views[-1][1], views[1][1]
    a, b = right.instance > 0, np.fliplr(left.instance > 0)
    assert (a & b).sum() / (a | b).sum() > 0.95


@pytest.mark.parametrize(("side", "expected"), [(-1, "C^r"), (1, "C^l")])
def test_a_lone_book_leaning_on_a_wall_is_c_r_or_c_l(physics, camera, side, expected):
    """Thesis Fig. 5.9: a single object leaning against the side wall is C^r / C^l by its
    lean, not C^v (the class of a single upright object, thesis 5.2.1), after settling."""
    from clutterbench.sim.families.replenish import lean_against

    world = BoxWorld(Shelf(), physics)
    wall = side * (world.shelf.width_m / 2)
    lean_against(world, BOOK, wall, side, 22.0, 0.14)
    assert world.settle().at_rest
    spec = SceneSpec(sizes_m=np.array([BOOK]), poses=world.poses())
    obs = observe(BoxWorld.from_spec(spec, physics, render=True), camera)
    _, classes, _ = scene_clusters(spec.sizes_m, spec.poses, [[0]], [], obs.instance)
    assert [CLASSES[c] for c in classes] == [expected]
