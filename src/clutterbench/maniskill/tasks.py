"""ManiSkill 3 tasks built from any SceneSpec: the shelf, its boxes at their settled poses and
the project's depth camera, with one Panda (`ClutterShelfExtract-v1`) or two
(`ClutterShelfBimanual-v1`), each with a rod tool (ManiSkill's `panda_stick`, its rod
lengthened: rod_robot), standing in front of the shelf, on the CPU backend.

    import gymnasium as gym
    import clutterbench.envs  # registers the tasks, the pipeline's streams plugged in
    env = gym.make("ClutterShelfExtract-v1")          # scenes of the stream ch6_3_10
    obs, info = env.reset(seed=17)                     # = the pipeline's episode 17 (scene, target)
    env = gym.make("ClutterShelfExtract-v1", spec=spec, target=2, obs_mode="state",
                   reward_mode="none", render_backend="none")   # one scene of your own

With no `spec`, `reset(seed=i)` draws episode i of a named stream (the default scene source,
which `import clutterbench.envs` plugs in: trials/sources.py, the pipeline's scene i of that
stream, its canonical settled start as its chapter's trials draw it, and its target;
`scene_source=` plugs in another; `import clutterbench.maniskill.tasks` alone registers the
tasks for specs and sources of your own); the stream is
`stream=` (a key of trials.streams, default ch6_3_10) or `family=` / `n_objects=` /
`catalogue=`, as make kwargs or reset options (`scale=`: the params' scale profile). Box
observations are then padded to MAX_BOXES (a padded slot is out of the scene), so the
observation space stays fixed across scenes, as state dicts (box_0..box_29 always:
get_state_dict). Obs modes: SUPPORTED_OBS_MODES (the sensor modes, and render_mode
"rgb_array" / "sensors", render on the CPU backend). An action holding NaN is refused
(ValueError). Every id's observation, action, info and episode end: docs/environments.md.

`evaluate()` judges the scene as the project's judge does (trials/core/protocol.py), with the
same function: `target_out` (the target is out of the shelf, in front of its opening),
`others_still` (no box but the target and the held one moved beyond the threshold or left
the shelf, measured from the episode's start), `released` (no tool holds a box),
`success` (all three) and `fail` (another box moved: ManiSkill ends the episode on either).
The sparse reward is `success`. The dense reward (reward_mode="dense")
is the target's progress out of the shelf (0 at the start, 1 once its back face is past the
opening) minus the other boxes' displacement (each box still in the scene: its displacement
from the start over the moved threshold, capped at 1, averaged over those boxes; a box off
the shelf counts 1), plus 1 on success: at most 2 ("normalized_dense": the same over 2).

Physics is the project's (sim.physics): the same timestep, friction, restitution and
density, and PhysX's solver and contact settings left at SAPIEN's defaults, which every
BoxWorld of the process uses (a ManiSkill env sets them process-wide).
"""

from __future__ import annotations

import hashlib
import importlib
import os
import reprlib
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig as MsCameraConfig
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.types import DefaultMaterialsConfig, SceneConfig, SimConfig
from sapien import physx

from clutterbench.errors import ActionError, ClutterbenchError
from clutterbench.maniskill.config import ArmConfig
from clutterbench.maniskill.motion import base_quat, make_planner, solve_ik, tool_quat
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.geometry import box_aabb_half_extents
from clutterbench.sim.labelling import check_n_objects
from clutterbench.sim.physics import ROOM_FLOOR_BELOW_SHELF_M
from clutterbench.sim.pull import moved_others
from clutterbench.sim.spec import SceneSpec

PARK_POSE = sapien.Pose([0.0, 0.0, -50.0])
"""Where a box taken out of the scene is kept (kinematic, touching nothing), as BoxWorld."""
ELBOW_OUT_QPOS = np.array([-1.23, 0.88, 0.63, -2.82, 1.91, 0.96, 0.75])
"""Where inverse kinematics for the first arm's ready pose starts: a joint state whose links
all stay outward of its tool (on the arm's own side), so that the mirrored second arm never
meets it, and from which straight paths reach the whole shelf (found by a search over 61 IK
solutions of the default ready pose: straight paths to 45 of 45 test faces spread over the
shelf, no link origin inward of the tool)."""
MIRROR_SIGNS = np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
MIRROR_OFFSETS = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -np.pi / 2])
"""A Panda's joint state mirrored in its base's x-z plane: q -> q * signs + offsets (the
hand is mounted at -45 degrees about the last joint; the mirror image of the tool is the
tool turned half a turn about its rod, which the rod does not feel: tool_quat)."""
MAX_BOXES = 30
"""Box observations of a stream-drawn env are padded to this many boxes (SceneStreamConfig
allows at most 30)."""
STATE_OBS_MODES = ("state", "state_dict", "none")
"""Obs modes that render nothing (no render backend needed)."""
TEXTURE_OBS_MODES = (
    "rgb",
    "depth",
    "segmentation",
    "rgbd",
    "rgb+depth",
    "rgb+segmentation",
    "depth+segmentation",
    "rgb+depth+segmentation",
)
"""ManiSkill's texture obs modes of the shelf camera (`rgbd` = rgb+depth)."""
SENSOR_OBS_MODES = ("sensor_data", *TEXTURE_OBS_MODES, "pointcloud")
"""Obs modes that render (they need a render backend: the CPU one by default)."""
RENDER_SIZE = 512
"""The human render camera's picture (render_mode="rgb_array"), as ManiSkill's tasks; smaller
with `human_render_camera_configs=dict(width=..., height=...)`."""
ROD_START_M = 0.05
"""ManiSkill's `panda_stick` rod starts this far in front of the hand's origin (8 mm radius)."""


def rod_robot(rod_length_m: float) -> str:
    """The uid of ManiSkill's `panda_stick` with a rod `rod_length_m` long (its tip the TCP),
    registered on first use: the same Panda, URDF and SRDF with the rod and the TCP moved,
    written to this machine's temporary directory (beside a link to ManiSkill's meshes). A
    rod long enough keeps the wrist out of the shelf when the face is deep in it."""
    from mani_skill.agents.registration import REGISTERED_AGENTS, register_agent
    from mani_skill.agents.robots.panda.panda_stick import PandaStick

    mm = int(round(rod_length_m * 1000))
    uid = f"panda_rod_{mm}mm"
    if uid in REGISTERED_AGENTS:
        return uid
    src = Path(PandaStick.urdf_path)
    rod = rod_length_m
    urdf = src.read_text()
    swaps = [
        (
            '<origin xyz="0 0 0.1" rpy="0 0 0"/>',
            f'<origin xyz="0 0 {ROD_START_M + rod / 2:.4f}" rpy="0 0 0"/>',
            2,
        ),
        (
            '<cylinder radius="0.008" length="0.1"/>',
            f'<cylinder radius="0.008" length="{rod:.4f}"/>',
            2,
        ),
        (
            '<origin rpy="0 0 0" xyz="0 0 0.15"/>',
            f'<origin rpy="0 0 0" xyz="0 0 {ROD_START_M + rod:.4f}"/>',
            1,
        ),
    ]
    for old, new, count in swaps:
        if urdf.count(old) != count:
            raise ClutterbenchError(
                f"{src}: not the panda_stick URDF this code knows ({old!r} found "
                f"{urdf.count(old)} times, expected {count}); check the mani-skill pin"
            )
        urdf = urdf.replace(old, new)
    # one directory per ManiSkill installation (its meshes are linked, not copied)
    where = hashlib.sha1(str(src.parent.resolve()).encode()).hexdigest()[:12]
    out = Path(tempfile.gettempdir()) / "clutterbench_robots" / where
    out.mkdir(parents=True, exist_ok=True)
    meshes = out / "franka_description"  # mesh paths stay relative (mplib wants them so)
    if not meshes.exists():
        tmp = out / f".franka_description.{os.getpid()}.tmp"
        tmp.symlink_to(src.parent / "franka_description", target_is_directory=True)
        os.replace(tmp, meshes)
    path = out / f"{uid}.urdf"
    for target, text in (
        (path, urdf),
        (path.with_suffix(".srdf"), src.with_suffix(".srdf").read_text()),
    ):
        if not target.exists() or target.read_text() != text:
            tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
            tmp.write_text(text)
            os.replace(tmp, target)
    cls = type(f"PandaRod{mm}mm", (PandaStick,), {"uid": uid, "urdf_path": str(path)})
    register_agent()(cls)
    return uid


def _sapien_physx_defaults() -> SceneConfig:
    """PhysX settings as every BoxWorld of this process finds them (SAPIEN's defaults)."""
    shape, body, scene = physx.get_shape_config(), physx.get_body_config(), physx.get_scene_config()
    return SceneConfig(
        gravity=np.asarray(scene.gravity, dtype=np.float64),
        bounce_threshold=scene.bounce_threshold,
        sleep_threshold=body.sleep_threshold,
        contact_offset=shape.contact_offset,
        rest_offset=shape.rest_offset,
        solver_position_iterations=body.solver_position_iterations,
        solver_velocity_iterations=body.solver_velocity_iterations,
        enable_pcm=scene.enable_pcm,
        enable_tgs=scene.enable_tgs,
        enable_ccd=scene.enable_ccd,
        enable_enhanced_determinism=scene.enable_enhanced_determinism,
        enable_friction_every_iteration=scene.enable_friction_every_iteration,
    )


SCENE_OPTIONS = ("spec", "target", "hold", "poses", "removed")
"""Reset options that set the scene (its boxes, target and held box): a reset naming any of
them rebuilds the scene."""


class SpecTypeError(ClutterbenchError, TypeError):
    """A `spec` that is not a SceneSpec: one line naming it (a TypeError too, as Python's own
    refusals of a wrong type are)."""


def check_spec(spec: Any, key: str = "spec") -> SceneSpec:
    """`spec` if it is a SceneSpec; anything else (a dict, a path) is refused in one line
    naming `key`, instead of failing later on a missing attribute."""
    if not isinstance(spec, SceneSpec):
        raise SpecTypeError(
            f"{key}={reprlib.repr(spec)} (a {type(spec).__name__}): expected a "
            "clutterbench.sim.spec.SceneSpec (SceneSpec.load(path) reads a spec file)"
        )
    return spec


def refuse_fork_after_render(env_name: str) -> None:
    """Refuse, in the parent and in one line, to be made as the env gymnasium's
    AsyncVectorEnv builds before it forks its workers, when this process has a renderer and
    the workers would render: SAPIEN's renderer does not survive a fork, so each forked
    worker would refuse (sim/renderer.py) and gymnasium would print every worker's trace, or
    lose a worker that refused while it was being made and report only a broken pipe."""
    from clutterbench.sim import renderer

    if renderer._RENDERER is None or renderer._RENDERER_PID != os.getpid():
        return  # nothing rendered here: a forked worker makes its own renderer
    if _start_method_of_vector_env() != "fork":
        return
    raise ClutterbenchError(
        f"{env_name}: this process holds SAPIEN's renderer (it has rendered, or a camera made "
        "it), which does not survive the fork that would start the vector env's workers: "
        'start them with spawn or forkserver (gym.make_vec: vector_kwargs={"context": '
        '"forkserver"}; docs/environments.md)'
    )


def _start_method_of_vector_env() -> str | None:
    """How the gymnasium AsyncVectorEnv making this env starts its workers (None: no
    AsyncVectorEnv is making it). Read off its __init__'s frame: gymnasium makes one env in
    the parent for the spaces before it starts the workers, and says nothing to that env."""
    import multiprocessing

    from gymnasium.vector import AsyncVectorEnv

    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "__init__" and isinstance(
            frame.f_locals.get("self"), AsyncVectorEnv
        ):
            context = frame.f_locals.get("context")
            if context is None:  # multiprocessing's default, without fixing it as a side effect
                default = multiprocessing.get_start_method(allow_none=True)
                return default or multiprocessing.get_all_start_methods()[0]
            return context
        frame = frame.f_back
    return None


_default_scene_source: Callable[..., Any] | None = None
"""What draws a spec-less env's scenes unless `scene_source=` (a callable or its
"module:function" name) names another: a factory `(stream, family, n_objects, catalogue,
scale) -> source`, the source giving `.episode(i) -> (spec, target)`, `.spec(i)`, `.physics`
and `.trials` (its `arm` and `ch6.moved_threshold_m`). The layer that owns the streams plugs
it in (`set_default_scene_source`; `import clutterbench.envs` plugs in the pipeline's named
streams), so that the arm level names nothing above it."""


def set_default_scene_source(factory: Callable[..., Any]) -> None:
    """Make `factory` the scene source of every spec-less env made after (`_default_scene_source`;
    a process's forked workers inherit it)."""
    global _default_scene_source
    _default_scene_source = factory


def resolve_scene_source(source: str | Callable[..., Any] | None) -> Callable[..., Any]:
    """A scene-source factory from itself, its "module:function" name, or (None) the default
    one plugged in; with none plugged in, one line saying where one comes from."""
    if source is None:
        if _default_scene_source is None:
            raise ClutterbenchError(
                "ClutterShelf env: no spec and no scene source: pass spec= or scene_source=, "
                "or import clutterbench.envs (which plugs in the pipeline's streams)"
            )
        return _default_scene_source
    if callable(source):
        return source
    module, _, name = str(source).partition(":")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ClutterbenchError(
            f"scene_source {source!r}: no such module:function ({exc})"
        ) from None


class ClutterShelfEnv(BaseEnv):
    """The shelf scene of a SceneSpec with Pandas in front of it (see the module's doc).

    kwargs: `spec` (SceneSpec; None: scenes drawn from a stream, see the module's doc),
    `target` (the box to take out), `hold` (the box a second arm holds, or None), `poses`
    ((N, 7) start poses, default the spec's) and `removed` (boxes already out), `physics`
    (PhysicsConfig), `arm` (ArmConfig), `moved_threshold_m`; with no spec also `stream`,
    `family`, `n_objects`, `catalogue`, `scale`. `reset(options=...)` takes the same keys to
    start another scene or step in the same env (naming any of SCENE_OPTIONS rebuilds the
    scene)."""

    SUPPORTED_OBS_MODES = ("state", *STATE_OBS_MODES[1:], *SENSOR_OBS_MODES)
    N_ARMS = 1

    def __init__(
        self,
        *args: Any,
        spec: SceneSpec | None = None,
        target: int = 0,
        hold: int | None = None,
        poses: np.ndarray | None = None,
        removed: tuple[int, ...] = (),
        physics: PhysicsConfig | None = None,
        arm: ArmConfig | None = None,
        moved_threshold_m: float | None = None,
        stream: str | None = None,
        family: Any = None,
        n_objects: Any = None,
        catalogue: str | None = None,
        scale: str | None = None,
        scene_source: str | Callable[..., Any] | None = None,
        **kwargs: Any,
    ):
        self.stream_source = None
        self._source_factory = scene_source
        self._streams_live = False  # BaseEnv.__init__ resets once with its own seed
        self._next_episode = 0
        self._simulated = False  # stepped since the scene was built: reset rebuilds it
        if spec is None:
            if n_objects is not None:
                check_n_objects(n_objects)
            stream_source = resolve_scene_source(scene_source)
            self.stream_source = stream_source(stream, family, n_objects, catalogue, scale)
            # Episode 0's settled start only: its target is drawn from a rendered view, and
            # a process that renders cannot fork (gym.make_vec makes one env in the parent
            # before forking its workers); reset draws the episode, target and all.
            spec, target = self.stream_source.spec(0), 0
            self.episode_index = None
            physics = physics or self.stream_source.physics
            arm = arm or self.stream_source.trials.arm
            if moved_threshold_m is None:
                moved_threshold_m = self.stream_source.trials.ch6.moved_threshold_m
        elif any(v is not None for v in (stream, family, n_objects, catalogue, scale)):
            raise ClutterbenchError(
                "ClutterShelf env: stream/family/n_objects/catalogue/scale draw the scene; "
                "not with spec="
            )
        moved_threshold_m = 0.005 if moved_threshold_m is None else moved_threshold_m
        physics, arm = physics or PhysicsConfig(), arm or ArmConfig()
        self.physics, self.arm_cfg = physics, arm
        self.moved_threshold_m = moved_threshold_m
        self._set_scene(spec, target, hold, poses, removed)
        substeps = 1.0 / (physics.timestep_s * arm.control_freq_hz)
        if abs(substeps - round(substeps)) > 1e-6:
            raise ClutterbenchError(
                f"arm.control_freq_hz {arm.control_freq_hz}: must divide the physics rate "
                f"1 / sim.physics.timestep_s = {1 / physics.timestep_s:g} Hz"
            )
        self.attached: dict[int, tuple[int, sapien.Pose]] = {}
        """arm index -> (box, box pose in the tool frame): boxes a tool holds."""
        uids = self._robot_uids(arm, kwargs)
        kwargs.setdefault("sim_backend", "physx_cpu")
        renders = (
            kwargs.get("obs_mode", "state") not in STATE_OBS_MODES
            or kwargs.get("render_mode") is not None
        )
        kwargs.setdefault("render_backend", "cpu" if renders else "none")
        kwargs.setdefault("obs_mode", "state")
        kwargs.setdefault("control_mode", "pd_joint_pos")
        super().__init__(*args, robot_uids=uids, **kwargs)
        self._streams_live = True
        # A worker renders if its env has a render backend, or draws its episodes' targets
        # from rendered views (a stream-drawn env's reset).
        if kwargs["render_backend"] != "none" or self.stream_source is not None:
            refuse_fork_after_render(type(self).__name__.removesuffix("Env"))

    def _robot_uids(self, arm: ArmConfig, kwargs: dict[str, Any]) -> Any:
        """The task's robot uid(s) (one per arm); a `robot_uids` of kwargs other than these,
        or a `num_envs` other than 1, is refused in one line."""
        robot = rod_robot(arm.rod_length_m)
        uids = robot if self.N_ARMS == 1 else (robot,) * self.N_ARMS
        self.SUPPORTED_ROBOTS = [uids]
        asked = kwargs.pop("robot_uids", None)
        if asked is not None and asked not in (uids, (robot,) * self.N_ARMS, [robot] * self.N_ARMS):
            raise ClutterbenchError(
                f"robot_uids={asked!r}: this task's robots are fixed ({uids!r}: ManiSkill's "
                f"panda_stick with the rod of arm.rod_length_m); leave robot_uids out"
            )
        if kwargs.get("num_envs", 1) != 1:
            raise ClutterbenchError(
                f"num_envs={kwargs['num_envs']}: the CPU backend runs one env per process; use "
                'gym.make_vec(id, num_envs=N, vectorization_mode="async") (docs/environments.md)'
            )
        return uids

    def _reconfigure(self, options: dict | None = None) -> None:
        # ManiSkill sets the camera shader directory process-wide for its sensors; every
        # other camera of the process (sim/renderer.py's depth cameras) sets its own.
        shader_dir = sapien.render.get_camera_shader_dir()
        try:
            super()._reconfigure(options if options is not None else {})
        finally:
            sapien.render.set_camera_shader_dir(shader_dir)
        self._simulated = False

    def _after_simulation_step(self) -> None:
        self._simulated = True  # every physics step of the scene passes here

    def _setup_scene(self) -> None:
        # One renderer per process: SAPIEN renders on one device only, and ManiSkill's "cpu"
        # device is not the one the project's renderer (sim/renderer.py, SAPIEN's default:
        # lavapipe's Vulkan device) opened, so the env renders on that one too.
        if self._render_device is not None and self._render_device.is_cpu():
            self._render_device = _process_render_device()
        super()._setup_scene()

    @property
    def obs_boxes(self) -> int:
        """How many boxes the box observations hold (stream-drawn: MAX_BOXES, padded)."""
        return self.scene_spec.n if self.stream_source is None else MAX_BOXES

    def reset(self, seed: Any = None, options: dict | None = None):
        """ManiSkill's reset; with no spec, `seed` (an int >= 0) is the episode index of the
        stream (None: the next one) and the options may name another stream. The scene is
        rebuilt whenever it has been simulated since it was built, or the options name its
        boxes (SCENE_OPTIONS)."""
        options = dict(options or {})
        if "spec" in options:
            check_spec(options["spec"], "reset options spec")
        if self.stream_source is not None and self._streams_live and "spec" not in options:
            keys = ("stream", "family", "n_objects", "catalogue", "scale")
            if options.get("n_objects") is not None:
                check_n_objects(options["n_objects"], "reset options n_objects")
            if any(k in options for k in keys):
                stream_source = resolve_scene_source(self._source_factory)
                self.stream_source = stream_source(*(options.pop(k, None) for k in keys))
            if seed is None:
                index = self._next_episode
            elif isinstance(seed, int | np.integer) and seed >= 0:
                index = int(seed)
            else:
                raise ClutterbenchError(f"reset(seed={seed!r}): an episode index, an int >= 0")
            spec, target = self.stream_source.episode(index)
            self.episode_index, self._next_episode = index, index + 1
            if spec is not self.scene_spec or target != self.target:
                options |= {"spec": spec, "target": target, "reconfigure": True}
        # PhysX repeats a simulation bit for bit only in a scene built afresh: a scene that
        # has been stepped keeps its contact pairs' internal state, so the same start and
        # actions in it split the impulses of a new contact otherwise (a tool meeting two
        # shelf boards at once took the bimanual task's arm 1 elsewhere within 30 steps). A
        # rebuild costs 0.2-0.5 s (2 CPU cores); a reset with no step since reuses the scene.
        if self._simulated or any(k in options for k in SCENE_OPTIONS):
            options["reconfigure"] = True
        obs, info = super().reset(seed=seed, options=options)
        if self.stream_source is not None and self._streams_live:
            from clutterbench.sim import benchmark

            info |= benchmark.scene_fields(self.scene_spec)
        return obs, info

    def step(self, action: Any):
        if _has_nan(action):
            raise ActionError(
                "ClutterShelf env: the action holds NaN (a policy produced NaN; refused)"
            )
        return super().step(action)

    def _set_scene(self, spec, target, hold, poses, removed) -> None:
        check_spec(spec)
        if not 0 <= target < spec.n or (hold is not None and not 0 <= hold < spec.n):
            raise ClutterbenchError(
                f"target {target} / hold {hold}: the spec has boxes 0..{spec.n - 1}"
            )
        self.scene_spec, self.target, self.hold = spec, int(target), hold
        self.start_poses = np.asarray(spec.poses if poses is None else poses, dtype=np.float64)
        self.start_removed = frozenset(int(k) for k in removed)

    # -- ManiSkill hooks -------------------------------------------------------------------
    @property
    def _default_sim_config(self) -> SimConfig:
        m = physx.get_default_material()
        return SimConfig(
            sim_freq=int(round(1.0 / self.physics.timestep_s)),
            control_freq=self.arm_cfg.control_freq_hz,
            scene_config=_sapien_physx_defaults(),
            default_materials_config=DefaultMaterialsConfig(
                m.static_friction, m.dynamic_friction, m.restitution
            ),
        )

    @property
    def _default_sensor_configs(self):
        cam = self.scene_spec.camera
        return [
            MsCameraConfig(
                "shelf_camera",
                sapien.Pose(cam.position_m(self.scene_spec.shelf.height_m)),
                cam.image_size,
                cam.image_size,
                np.deg2rad(cam.fovy_deg),
                cam.near_m,
                cam.far_m,
            )
        ]

    @property
    def _default_human_render_camera_configs(self):
        """render_mode="rgb_array": the shelf and the arms, seen from above the right arm."""
        from mani_skill.utils import sapien_utils

        shelf = self.scene_spec.shelf
        x, y, _ = self.arm_cfg.base_m
        centre = [(shelf.depth_m + x) / 2, 0.0, shelf.height_m / 2]
        eye = [centre[0] + 0.2, -abs(y) - 1.1, shelf.height_m + 0.8]
        pose = sapien_utils.look_at(eye=eye, target=centre)
        return MsCameraConfig("render_camera", pose, RENDER_SIZE, RENDER_SIZE, 1.0, 0.01, 10.0)

    def arm_bases(self) -> list[np.ndarray]:
        """Each arm's base pose [x, y, z, qw, qx, qy, qz] (arm.*_base_m, arm.base_pitch_deg)."""
        q = base_quat(self.arm_cfg.base_pitch_deg)
        x, y, z = self.arm_cfg.base_m
        return [np.hstack([[x, y, z], q]), np.hstack([[x, -y, z], q])][: self.N_ARMS]

    def _load_agent(self, options: dict) -> None:
        super()._load_agent(options, [sapien.Pose(b[:3], b[3:]) for b in self.arm_bases()])

    def _load_scene(self, options: dict) -> None:
        for key in SCENE_OPTIONS:
            if key in options:
                self._set_scene(
                    options.get("spec", self.scene_spec),
                    options.get("target", self.target),
                    options.get("hold", self.hold),
                    options.get("poses"),
                    options.get("removed", ()),
                )
                break
        spec, phys = self.scene_spec, self.physics
        material = physx.PhysxMaterial(
            phys.static_friction, phys.dynamic_friction, phys.restitution
        )
        floor = self.scene.create_actor_builder()
        floor.add_box_collision(half_size=[3.0, 3.0, 0.01], material=material)
        floor.initial_pose = sapien.Pose([0.0, 0.0, -ROOM_FLOOR_BELOW_SHELF_M - 0.01])
        floor.build_static(name="room_floor")
        for name, half, centre in spec.shelf.boards():
            b = self.scene.create_actor_builder()
            b.add_box_collision(half_size=half, material=material)
            b.add_box_visual(half_size=half)
            b.initial_pose = sapien.Pose(centre)
            b.build_static(name=f"shelf_{name}")
        self.boxes = []
        for k in range(spec.n):
            b = self.scene.create_actor_builder()
            half = np.asarray(spec.sizes_m[k], dtype=np.float64) / 2
            b.add_box_collision(
                half_size=half, material=material, density=spec.density(k, phys.density_kg_m3)
            )
            b.add_box_visual(half_size=half)
            b.initial_pose = self._pose(k)
            self.boxes.append(b.build(name=f"box_{k}"))
        self.bodies = [
            box._objs[0].find_component_by_type(physx.PhysxRigidDynamicComponent)
            for box in self.boxes
        ]

    def _pose(self, k: int) -> sapien.Pose:
        if k in self.start_removed:
            return PARK_POSE
        p = self.start_poses[k]
        return sapien.Pose(p[:3], p[3:])

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict) -> None:
        self.attached = {}
        for k, body in enumerate(self.bodies):
            body.set_kinematic(k in self.start_removed)
            body.entity.set_pose(self._pose(k))
            if k in self.start_removed:
                body.set_kinematic_target(PARK_POSE)
            else:
                body.set_linear_velocity(np.zeros(3))
                body.set_angular_velocity(np.zeros(3))
        self.removed = set(self.start_removed)
        self.reference = self.start_poses[:, :3].copy()
        self.target_back0_m = self._back_face_m(self.target)
        # The arms' bases too: PhysX moves a fixed base by float rounding as it simulates, so
        # a reset that reuses the scene would otherwise start off a rebuilt scene's bits.
        for agent, qpos, base in zip(self.agents, self.ready_qpos(), self.arm_bases(), strict=True):
            agent.robot.set_pose(sapien.Pose(base[:3], base[3:]))
            agent.reset(qpos)

    @property
    def agents(self) -> list:
        return list(self.agent.agents) if self.N_ARMS > 1 else [self.agent]

    def ready_poses(self) -> list[np.ndarray]:
        """Each arm's tool pose between steps (arm.ready_tool_m, in line with its base)."""
        x, z = self.arm_cfg.ready_tool_m
        return [np.hstack([[x, b[1], z], tool_quat(i)]) for i, b in enumerate(self.arm_bases())]

    def ready_qpos(self) -> list[np.ndarray]:
        """Each arm's joint positions at its ready pose (solved once per env): the first
        arm's by inverse kinematics, the second's its mirror image (the Panda's joint limits
        are not mirror-symmetric, so a separate solution could start on a worse branch)."""
        if getattr(self, "_ready", None) is None or len(self._ready) != self.N_ARMS:
            base, pose = self.arm_bases()[0], self.ready_poses()[0]
            q = solve_ik(make_planner(self.agents[0], base, 1.0), pose, ELBOW_OUT_QPOS)
            if q is None:
                raise ClutterbenchError(
                    f"arm.ready_tool_m {pose[:3].tolist()}: out of reach of the arm at "
                    f"{base[:3].tolist()}"
                )
            q = np.asarray(q[:7], dtype=np.float64)
            self._ready = [q, q * MIRROR_SIGNS + MIRROR_OFFSETS][: self.N_ARMS]
        return self._ready

    def _before_simulation_step(self) -> None:
        # The suction-like grasp: a held box follows its tool rigidly, every physics step.
        for i, (k, rel) in self.attached.items():
            tcp = self.agents[i].tcp._objs[0].entity_pose
            self.bodies[k].set_kinematic_target(tcp * rel)

    # -- grasp ------------------------------------------------------------------------------
    def tcp_pose(self, arm: int) -> sapien.Pose:
        return self.agents[arm].tcp._objs[0].entity_pose

    def attach(self, arm: int, box: int) -> None:
        """Arm `arm`'s tool takes hold of `box` where both are now (kinematic from now)."""
        body = self.bodies[box]
        body.set_kinematic(True)
        body.set_kinematic_target(body.entity.pose)
        self.attached[arm] = (box, self.tcp_pose(arm).inv() * body.entity.pose)

    def detach(self, arm: int) -> int | None:
        """Arm `arm` lets its box go (dynamic again, at rest: an opening grasp throws
        nothing) -> the box, or None when it held none."""
        if arm not in self.attached:
            return None
        box, _ = self.attached.pop(arm)
        if box not in self.removed:
            body = self.bodies[box]
            body.set_kinematic(False)
            body.set_linear_velocity(np.zeros(3))
            body.set_angular_velocity(np.zeros(3))
            for other in self.bodies:
                if not other.kinematic:
                    other.wake_up()
        return box

    def park(self, box: int) -> None:
        """Take `box` out of the scene (kinematic, far below the floor), as BoxWorld.park."""
        for arm, (k, _) in list(self.attached.items()):
            if k == box:
                self.attached.pop(arm)
        body = self.bodies[box]
        body.set_kinematic(True)
        body.set_kinematic_target(PARK_POSE)
        body.entity.set_pose(PARK_POSE)
        self.removed.add(box)

    # -- the scene's state and its judgement --------------------------------------------------
    def box_poses(self) -> np.ndarray:
        """(N, 7) poses [x, y, z, qw, qx, qy, qz] (a box out of the scene: its parking pose,
        as BoxWorld.poses)."""
        out = np.empty((self.scene_spec.n, 7))
        for k, body in enumerate(self.bodies):
            pose = body.entity.pose
            out[k, :3], out[k, 3:] = pose.p, pose.q
        return out

    @property
    def state_boxes(self) -> int:
        """How many box entries a state dict holds (`box_0`..): MAX_BOXES, or more for a
        bigger scene; so a flat state (get_state) has one size across episodes."""
        return max(MAX_BOXES, self.scene_spec.n)

    def get_state_dict(self) -> dict:
        """ManiSkill's state dict (each box's pose and velocities, each arm's joints, the
        controllers') with `box_0`..`box_{state_boxes - 1}` always: a box the scene does not
        have is all zeros (NO_BOX_STATE); a box out of the scene sits at PARK_POSE."""
        state = super().get_state_dict()
        actors = state.get("actors", {})
        boxes = {f"box_{k}": actors.get(f"box_{k}", NO_BOX_STATE) for k in range(self.state_boxes)}
        others = {k: v for k, v in actors.items() if not _is_box_key(k)}
        return {"actors": boxes | others} | {k: v for k, v in state.items() if k != "actors"}

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None) -> None:
        """Set a state of this scene (get_state_dict's; a state of a scene with another
        number of boxes is refused, one line: reset to its episode first). A box at the
        parking pose is taken out of the scene (park); a box out that the state puts back is
        dynamic again. Grasps (attach) are not part of the state."""
        actors = dict(state.get("actors", {}))
        n = self.scene_spec.n
        boxes = {int(k[4:]): actors.pop(k) for k in list(actors) if _is_box_key(k)}
        present = sorted(k for k, v in boxes.items() if bool(torch.as_tensor(v).any()))
        if present != list(range(n)):
            raise ClutterbenchError(
                f"set_state: a state of a scene with boxes {_ranges(present)}; this episode's "
                f"scene has boxes 0..{n - 1} (reset to the state's episode first)"
            )
        parked = []
        for k in range(n):
            v = torch.as_tensor(boxes[k]).reshape(-1, 13)
            if float(v[0, 2]) < PARK_POSE.p[2] / 2:
                parked.append(k)
                continue
            actors[f"box_{k}"] = v
            if k in self.removed:  # back in the scene
                self.bodies[k].set_kinematic(False)
                self.removed.discard(k)
        super().set_state_dict(dict(state) | {"actors": actors}, env_idx)
        for k in parked:
            if k not in self.removed:
                self.park(k)

    def front_face_m(self, box: int) -> np.ndarray:
        """The centre of `box`'s face toward the camera (its AABB's front, at its centre)."""
        pose = self.box_poses()[box]
        half = box_aabb_half_extents(self.scene_spec.sizes_m[box], pose[3:])
        return np.array([pose[0] - half[0], pose[1], pose[2]])

    def displacements(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) each box's displacement from the episode's start (NaN: out of the scene)
        and (N,) whether its centre is inside the shelf (False when out)."""
        poses = self.box_poses()
        disp = np.linalg.norm(poses[:, :3] - self.reference, axis=1)
        disp[sorted(self.removed)] = np.nan
        on_shelf = self.scene_spec.shelf.contains(poses[:, :3])
        on_shelf[sorted(self.removed)] = False
        return disp, on_shelf

    def evaluate(self) -> dict[str, torch.Tensor]:
        disp, on_shelf = self.displacements()
        k = self.target
        manipulated = {k} | ({self.hold} if self.hold is not None else set())
        n, _ = moved_others(disp, on_shelf, manipulated, self.start_removed, self.moved_threshold_m)
        if self.hold is not None and self.hold not in self.removed and not on_shelf[self.hold]:
            n += 1  # the held box fell off the shelf
        out = k in self.removed or self._back_face_m(k) < 0.0
        released = not self.attached
        flags = {
            "target_out": out,
            "others_still": n == 0,
            "released": released,
            "success": out and n == 0 and released,
            "fail": n > 0,  # another box moved: the step can no longer succeed
        }
        return {name: torch.tensor([v]) for name, v in flags.items()}

    def _back_face_m(self, box: int) -> float:
        """x of `box`'s face farthest into the shelf (its AABB's back; < 0: out of the shelf)."""
        pose = self.box_poses()[box]
        return float(pose[0] + box_aabb_half_extents(self.scene_spec.sizes_m[box], pose[3:])[0])

    def compute_sparse_reward(self, obs: Any, action: Any, info: dict) -> torch.Tensor:
        return info["success"].float()

    def compute_dense_reward(self, obs: Any, action: Any, info: dict) -> torch.Tensor:
        """Target progress out of the shelf minus the others' displacement (module doc)."""
        k = self.target
        if k in self.removed or self.target_back0_m <= 0.0:
            progress = 1.0
        else:
            progress = float(np.clip(1.0 - self._back_face_m(k) / self.target_back0_m, 0.0, 1.0))
        disp, on_shelf = self.displacements()
        others = [
            j for j in range(self.scene_spec.n) if j not in (k, self.hold) and j not in self.removed
        ]
        share = 0.0
        if others:
            moved = np.minimum(np.nan_to_num(disp[others], nan=0.0) / self.moved_threshold_m, 1.0)
            share = float(np.mean(np.where(on_shelf[others], moved, 1.0)))
        reward = progress - share + float(info["success"].item())
        return torch.tensor([reward], dtype=torch.float32)

    def compute_normalized_dense_reward(self, obs: Any, action: Any, info: dict) -> torch.Tensor:
        return self.compute_dense_reward(obs, action, info) / 2.0

    def _get_obs_extra(self, info: dict) -> dict[str, torch.Tensor]:
        n, m = self.scene_spec.n, self.obs_boxes
        poses = np.zeros((m, 7))
        poses[:n] = self.box_poses()
        out = [k >= n or k in self.removed for k in range(m)]
        return {
            "box_poses": torch.as_tensor(poses, dtype=torch.float32).reshape(1, -1),
            "box_out": torch.as_tensor([out]),
            "target": torch.tensor([self.target]),
        }


NO_BOX_STATE = torch.zeros(1, 13)
"""A state dict's entry for a box the scene does not have."""


def _is_box_key(name: str) -> bool:
    return name.startswith("box_") and name[4:].isdigit()


def _ranges(boxes: list[int]) -> str:
    return f"0..{boxes[-1]}" if boxes == list(range(len(boxes))) and boxes else str(boxes)


_RENDER_DEVICE: list[sapien.Device] = []


def _process_render_device() -> sapien.Device:
    """The device of the process-wide renderer (SAPIEN's default render device)."""
    from clutterbench.sim.renderer import ensure_renderer

    ensure_renderer()  # (refuses a process forked after rendering)
    if not _RENDER_DEVICE:
        _RENDER_DEVICE.append(sapien.render.RenderSystem().device)
    return _RENDER_DEVICE[0]


def _has_nan(action: Any) -> bool:
    if action is None:
        return False
    if isinstance(action, dict):
        return any(_has_nan(v) for v in action.values())
    if isinstance(action, torch.Tensor):
        return bool(torch.isnan(action).any())
    a = np.asarray(action)
    return a.dtype.kind in "fc" and bool(np.isnan(a).any())


@register_env("ClutterShelfExtract-v1", max_episode_steps=2000)
class ClutterShelfExtractEnv(ClutterShelfEnv):
    """Take a target box out of a shelf scene with one Panda (thesis ch. 4-6 pulls)."""

    N_ARMS = 1


@register_env("ClutterShelfBimanual-v1", max_episode_steps=2000)
class ClutterShelfBimanualEnv(ClutterShelfEnv):
    """The same with two Pandas: the first pulls, the second holds a box in place (thesis
    ch. 6 bimanual steps, ch. 4 extract-while-support)."""

    N_ARMS = 2


def make_task(env_id: str, **kwargs: Any) -> BaseEnv:
    """gymnasium's entry point of this module's ids: ManiSkill's make, from this module, so
    that a worker process that unpickles it (gym.make_vec with spawn or forkserver) imports
    this module and so registers the tasks with ManiSkill first."""
    from mani_skill.utils.registration import make

    return make(env_id, **kwargs)


def _entry_points_from_here() -> None:
    import functools

    import gymnasium as gym

    for env_id in ("ClutterShelfExtract-v1", "ClutterShelfBimanual-v1"):
        gym.registry[env_id].entry_point = functools.partial(make_task, env_id=env_id)


_entry_points_from_here()
