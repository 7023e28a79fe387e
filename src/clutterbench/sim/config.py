"""Simulation params (`sim` section): physics and camera. Imports no SAPIEN, so that stages
that only read configs (train, evaluate, report) do not load the simulator."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from clutterbench.config import bounded

if TYPE_CHECKING:
    from clutterbench.observation import CameraModel

FAMILY_NAMES = (
    "shelved",
    "stacked",
    "random",
    "organized",
    "disorganized",
    "pile",
    "leaning",
    "replenish_stacked",
    "replenish_shelved",
    "replenish_random",
)
"""Names of the scene families in sim/families (checked equal to its registry by a test)."""
FAMILY_MAX_OBJECTS = {"replenish_stacked": 7, "replenish_random": 8}
"""The most boxes a family can arrange (the families not named: any number); the families'
own `max_objects` (sim/families) read it from here, so params are checked without SAPIEN."""
REJECT_REASONS = ("moving", "fell", "no_room", "overlap", "creeping")
"""Why a placement attempt is redrawn: still moving after sim.physics.settle_max_s, a box
off the shelf, no room for every box, boxes jammed into each other (> 1 mm, e.g. a stack
pressed against the top board), which no spec may hold (sim/spec.py), or a canonical start
that is not at rest: rebuilt from its spec and left alone for sim.physics.rest_check_s, a
box moved more than sim.physics.rest_check_m (it would creep during every action)."""


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    timestep_s: float = bounded(1 / 240, gt=0.0, le=0.02)
    """Physics step (s). 240 Hz keeps 20 mm boxes from tunnelling."""
    density_kg_m3: float = bounded(300.0, gt=0.0)
    """Box density. The thesis' 1.0 kg/m^3 gives 2 g boxes the solver handles badly;
    300 kg/m^3 (a filled carton) gives 60-800 g boxes."""
    static_friction: float = bounded(0.9, ge=0.0)
    """Static friction of boxes and shelf (thesis 4.2.1)."""
    dynamic_friction: float = bounded(0.8, ge=0.0)
    """Dynamic friction (thesis 4.2.1)."""
    restitution: float = bounded(0.1, ge=0.0, le=1.0)
    """Coefficient of restitution (thesis 4.2.1)."""
    settle_max_s: float = bounded(4.0, gt=0.0)
    """Longest a scene may take to come to rest after generation; longer -> rejected."""
    action_settle_max_s: float = bounded(3.0, gt=0.0)
    """Longest to simulate after an action before displacements are measured."""
    check_every_steps: int = bounded(8, ge=1)
    """Rest is checked every this many steps."""
    rest_linear_m_s: float = bounded(0.004, gt=0.0)
    """A box is at rest when its centre moved slower than this (m/s) over a check window,
    from its poses (PhysX's reported velocity of a resting box can be ~20 mm/s) ..."""
    rest_angular_rad_s: float = bounded(0.04, gt=0.0)
    """... and it turned slower than this (rad/s); two windows in a row."""
    pull_speed_m_s: float = bounded(0.2, gt=0.0)
    """Speed of a horizontal pull toward the camera (thesis ch. 4 extraction)."""
    rest_check_s: float = bounded(1.0, gt=0.0)
    """A new scene's canonical start (rebuilt from its spec) is left alone this long ..."""
    rest_check_m: float = bounded(0.001, gt=0.0)
    """... and rejected as "creeping" when a box moved more than this (m): a start that is
    not at rest would move boxes in every action with no cause (a user's spec: a warning)."""


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

    def model(self, shelf_height_m: float) -> CameraModel:
        """The OpenCV camera model of this camera at position_m, as sim/render.py's camera_model
        reads it from the renderer (a contract test holds them equal), for images that come
        without one (a dataset's): square pixels of f = (H / 2) / tan(fovy / 2), the principal
        point at the image centre, looking +x with image right -y and image down -z."""
        from clutterbench.observation import CameraModel

        f = (self.image_size / 2) / np.tan(np.deg2rad(self.fovy_deg) / 2)
        c = self.image_size / 2
        T = np.eye(4)
        T[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]  # columns: x, y, z
        T[:3, 3] = self.position_m(shelf_height_m)
        K = np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])
        return CameraModel(K=K, T_world_from_cam=T)


@dataclasses.dataclass(frozen=True)
class SimConfig:
    physics: PhysicsConfig = PhysicsConfig()
    """PhysX settings shared by data generation and the simulated trials."""
    camera: CameraConfig = CameraConfig()
    """The depth camera in front of the shelf."""
