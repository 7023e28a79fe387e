"""Depth + instance rendering of a BoxWorld with one SAPIEN renderer kept alive per process.

The first picture a process renders compiles shaders (~3 s on lavapipe); keeping the
renderer alive makes every later scene cost milliseconds (shared/PLATFORM.md).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import sapien

from clutterbench.config import bounded
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.physics import BoxWorld

_RENDERER: sapien.render.SapienRenderer | None = None


def ensure_renderer() -> sapien.render.SapienRenderer:
    """The process-wide renderer (created on first use, never torn down)."""
    global _RENDERER
    if _RENDERER is None:
        try:
            _RENDERER = sapien.render.SapienRenderer()
        except RuntimeError as exc:
            raise ClutterbenchError(
                f"SAPIEN found no Vulkan device ({exc}); install Mesa from bookworm-backports "
                "(scripts/setup_system.sh)"
            ) from None
    return _RENDERER


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    image_size: int = bounded(128, ge=16, le=1024)
    """Square image side in pixels (256 at paper scale, as in the thesis)."""
    fovy_deg: float = bounded(42.0, gt=1.0, le=150.0)
    """Vertical field of view; 42 deg frames the 330 mm opening from 0.5 m."""
    distance_m: float = bounded(0.5, gt=0.05)
    """Distance of the camera in front of the shelf opening, on the shelf's centre line."""
    near_m: float = bounded(0.05, gt=0.0)
    """Near clipping plane."""
    far_m: float = bounded(2.0, gt=0.0)
    """Far clipping plane; pixels that see nothing get depth 0."""

    def position_m(self, shelf_height_m: float) -> np.ndarray:
        # Camera at the shelf opening's centre, looking +x (into the shelf): SAPIEN cameras
        # look along their local +x with +z up, so gravity is down in the image.
        return np.array([-self.distance_m, 0.0, shelf_height_m / 2])


def render_depth_instance(world: BoxWorld, cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Render (depth_m float32 HxW, instance uint8 HxW: 0 background, k+1 = box k)."""
    assert world.render, "BoxWorld must be built with render=True"
    ensure_renderer()
    camera = world.scene.add_camera(
        "depth", cam.image_size, cam.image_size, np.deg2rad(cam.fovy_deg), cam.near_m, cam.far_m
    )
    camera.entity.set_pose(sapien.Pose(cam.position_m(world.shelf.height_m)))
    t0 = time.perf_counter()
    world.scene.update_render()
    camera.take_picture()
    position = camera.get_picture("Position")  # OpenGL camera frame: depth = -z
    seg = camera.get_picture("Segmentation")[..., 1]  # per-scene entity id
    world.sapien_s += time.perf_counter() - t0
    world.scene.remove_camera(camera)
    depth_m = (-position[..., 2]).astype(np.float32)
    depth_m[position[..., 3] >= 1.0] = 0.0  # w >= 1: nothing hit before the far plane
    lut = np.zeros(int(seg.max()) + 1, dtype=np.uint8)
    for k, entity in enumerate(world.entities):
        if entity.per_scene_id < lut.size:
            lut[entity.per_scene_id] = k + 1
    return depth_m, lut[seg]
