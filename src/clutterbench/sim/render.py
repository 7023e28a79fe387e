"""Depth + instance rendering of a BoxWorld with one SAPIEN renderer kept alive per process.

One renderer per process and one depth camera per world (sim/renderer.py): every picture
after a process's first costs milliseconds (docs/platform.md).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import sapien

from clutterbench.observation import CameraModel, Observation
from clutterbench.sim.config import CameraConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.renderer import add_depth_camera


def _camera(world: BoxWorld, cam: CameraConfig):
    """The world's one camera, created on its first picture (a camera per picture costs a
    pipeline rebuild each time)."""
    if world.camera is None:
        world.camera = add_depth_camera(
            world.scene, "depth", cam.image_size, np.deg2rad(cam.fovy_deg), cam.near_m, cam.far_m
        )
        world.camera.entity.set_pose(sapien.Pose(cam.position_m(world.shelf.height_m)))
    return world.camera


def render_depth_instance(world: BoxWorld, cam: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Render (depth_m float32 HxW, instance uint8 HxW: 0 background, k+1 = box k)."""
    assert world.render, "BoxWorld must be built with render=True"
    camera = _camera(world, cam)
    t0 = time.perf_counter()
    world.scene.update_render()
    camera.take_picture()
    position = camera.get_picture("Position")  # OpenGL camera frame: depth = -z
    seg = camera.get_picture("Segmentation")[..., 1]  # per-scene entity id
    world.sapien_s += time.perf_counter() - t0
    depth_m = (-position[..., 2]).astype(np.float32)
    depth_m[position[..., 3] >= 1.0] = 0.0  # w >= 1: nothing hit before the far plane
    lut = np.zeros(int(seg.max()) + 1, dtype=np.uint8)
    for k, entity in enumerate(world.entities):
        if entity.per_scene_id < lut.size and k not in world.removed:
            lut[entity.per_scene_id] = k + 1
    return depth_m, lut[seg]


def camera_model(world: BoxWorld, cam: CameraConfig) -> CameraModel:
    """Intrinsics and OpenCV-frame pose of the world's camera, as SAPIEN renders with them."""
    camera = _camera(world, cam)
    T_cam_from_world = np.eye(4)
    T_cam_from_world[:3, :] = camera.get_extrinsic_matrix()  # world -> OpenCV camera
    return CameraModel(
        K=np.asarray(camera.get_intrinsic_matrix(), dtype=np.float64),
        T_world_from_cam=np.linalg.inv(T_cam_from_world),
    )


def observe(world: BoxWorld, cam: CameraConfig, sensing: str = "ideal") -> Observation:
    """What the robot sees now: depth (through the `sensing` preset's sensor model,
    sim/sensor.py, seeded by the picture itself so a rerun sees the same; ideal: the exact
    depth), instance ids and the camera model."""
    depth_m, instance = render_depth_instance(world, cam)
    exact = Observation(depth_m=depth_m, instance=instance, camera=camera_model(world, cam))
    return sensed(exact, sensing)


def sensed(obs: Observation, sensing: str) -> Observation:
    """The exact observation `obs` as the `sensing` preset's sensor returns it: its depth
    through the sensor model (sim/sensor.py), seeded by the exact picture itself so the same
    picture always gets the same noise; its instance image and camera as they are. Ideal:
    `obs` itself, unchanged."""
    if sensing == "ideal":
        return obs
    from clutterbench.sim.sensor import observation_rng, preset, sense

    depth_m = sense(obs.depth_m, obs.camera, preset(sensing), observation_rng(0, obs.depth_m))
    return dataclasses.replace(obs, depth_m=depth_m)
