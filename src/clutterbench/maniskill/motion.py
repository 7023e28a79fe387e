"""Motion planning for the Pandas: one mplib planner per arm (as ManiSkill's motion-planning
solutions build it), straight-line (screw) paths, the tool's pose for a box's front face.

Every path here is deterministic: screw motions follow the Jacobian from the current joint
state, and inverse kinematics starts from the current joint state only (mplib's random
restarts are not used), so the same step plans the same path in every process.
"""

from __future__ import annotations

import numpy as np
from transforms3d.quaternions import axangle2quat, qmult

from clutterbench.sim.shelf import Shelf

TOOL_INTO_SHELF_Q = qmult(axangle2quat([0.0, 1.0, 0.0], -np.pi / 2), [0.0, 1.0, 0.0, 0.0])
"""The tool's orientation [w, x, y, z] when it points into the shelf (+x): the Panda's
pointing-down hand pitched up by 90 degrees (its z onto the world's x, its x up)."""
MOVE_GROUP = "panda_hand_tcp"


TOOL_ROLLS_DEG = (225.0, 180.0, 270.0, 135.0, 90.0, 315.0, 45.0, 0.0)
"""Turns of the first arm's tool about its rod from TOOL_INTO_SHELF_Q, in the order an
approach tries them (the rod does not feel the turn, the wrist does: it sits off the rod's
axis). 225: the wrist outward of the rod and low, away from the other arm, from which
straight paths reached every face of a test grid over the shelf (36 of 36; 25-34 for the
others but one); a face low and deep puts that wrist into the shelf's floor, so the next
turns (wrist up, then sideways) are tried in turn."""


SIDE_BY_SIDE_ROLLS_DEG = (270.0, 90.0, 225.0, 315.0, 135.0, 45.0, 180.0, 0.0)
"""The same turns when the other arm works beside this one: the hand's wide side (its y,
where fingers would open) upright first, so that the two hands fit side by side."""


def tool_quat(arm: int, roll_deg: float = TOOL_ROLLS_DEG[0]) -> np.ndarray:
    """Arm `arm`'s tool orientation pointing into the shelf, turned `roll_deg` about the rod.
    The second arm's joint state is the mirror image of the first's, which puts its tool at
    the mirrored turn plus half a turn (the hand is mounted at -45 degrees about the last
    joint)."""
    roll = np.deg2rad(roll_deg) if arm == 0 else np.pi - np.deg2rad(roll_deg)
    return qmult(TOOL_INTO_SHELF_Q, axangle2quat([0.0, 0.0, 1.0], roll))


def base_quat(pitch_deg: float) -> np.ndarray:
    """A base's orientation [w, x, y, z]: facing the shelf (+x), leaning back by `pitch_deg`."""
    return axangle2quat([0.0, 1.0, 0.0], -np.deg2rad(pitch_deg))


def make_planner(agent, base_pose: np.ndarray, speed_scale: float):
    """An mplib planner for `agent` (a ManiSkill Panda) with its base at `base_pose`
    [x, y, z, qw, qx, qy, qz]."""
    import mplib

    planner = mplib.Planner(
        urdf=agent.urdf_path,
        srdf=agent.urdf_path.replace(".urdf", ".srdf"),
        user_link_names=[link.get_name() for link in agent.robot.get_links()],
        user_joint_names=[j.get_name() for j in agent.robot.get_active_joints()],
        move_group=MOVE_GROUP,
    )
    planner.set_base_pose(np.asarray(base_pose, dtype=np.float64))
    planner.joint_vel_limits = np.asarray(planner.joint_vel_limits) * speed_scale
    planner.joint_acc_limits = np.asarray(planner.joint_acc_limits) * speed_scale
    return planner


def shelf_points(shelf: Shelf, spacing_m: float = 0.01) -> np.ndarray:
    """(K, 3) points on the surfaces of the shelf's boards: mplib's collision world."""
    pts = []
    for _, half, centre in shelf.boards():
        axes = [
            np.arange(-h, h + 1e-9, spacing_m) if h > spacing_m else np.array([-h, h]) for h in half
        ]
        for k in range(3):  # the two faces normal to axis k
            others = [a for j, a in enumerate(axes) if j != k]
            u, v = np.meshgrid(*others, indexing="ij")
            for sign in (-1.0, 1.0):
                face = np.zeros((u.size, 3))
                face[:, k] = sign * half[k]
                face[:, [j for j in range(3) if j != k]] = np.stack([u.ravel(), v.ravel()], 1)
                pts.append(face + centre)
    return np.concatenate(pts)


ARM_POINT_SPACING_M = 0.008
"""Spacing of the points standing for the other arm in a planner's collision world (below
the rod's 16 mm diameter, so no path slips between them)."""
NEAR_LINKS = (
    "panda_link3",
    "panda_link4",
    "panda_link5",
    "panda_link6",
    "panda_link7",
    "panda_hand",
)
"""The links of the other arm a path can meet (the ones near its base cannot)."""


def link_points(link_component, spacing_m: float = ARM_POINT_SPACING_M) -> np.ndarray:
    """(K, 3) points on the surfaces of a SAPIEN link's collision shapes (convex meshes and
    cylinders), in the link's frame; deterministic (a fixed seed)."""
    rng = np.random.default_rng(0)
    out = []
    for shape in link_component.get_collision_shapes():
        local = shape.get_local_pose().to_transformation_matrix()
        if hasattr(shape, "get_triangles"):
            v = np.asarray(shape.get_vertices(), dtype=np.float64) * np.asarray(shape.get_scale())
            tri = v[np.asarray(shape.get_triangles())]
            area = 0.5 * np.linalg.norm(
                np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1
            )
            n = np.maximum(1, np.ceil(area / spacing_m**2).astype(int))
            which = np.repeat(np.arange(len(tri)), n)
            a, b = rng.random((2, len(which)))
            flip = a + b > 1.0
            a[flip], b[flip] = 1.0 - a[flip], 1.0 - b[flip]
            t = tri[which]
            pts = t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])
        elif hasattr(shape, "get_half_length"):  # a cylinder along its x axis
            r, h = shape.get_radius(), shape.get_half_length()
            xs = np.arange(-h, h + 1e-9, spacing_m)
            angles = np.arange(0.0, 2 * np.pi, spacing_m / max(r, 1e-3))
            x, ang = np.meshgrid(xs, angles, indexing="ij")
            pts = np.stack([x.ravel(), r * np.cos(ang.ravel()), r * np.sin(ang.ravel())], 1)
        else:
            continue
        out.append(pts @ local[:3, :3].T + local[:3, 3])
    return np.concatenate(out) if out else np.zeros((0, 3))


def face_pose(
    front_face_m: np.ndarray,
    offset_m: float,
    arm: int = 0,
    roll_deg: float = TOOL_ROLLS_DEG[0],
    yaw_deg: float = 0.0,
) -> np.ndarray:
    """Arm `arm`'s tool pose `offset_m` back along the rod from a box's front-face point,
    pointing into it: turned `roll_deg` about the rod, the rod turned `yaw_deg` about the
    vertical from straight into the shelf (positive: its tip toward +y)."""
    yaw = np.deg2rad(yaw_deg)
    along = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    p = np.asarray(front_face_m, dtype=np.float64) - offset_m * along
    q = qmult(axangle2quat([0.0, 0.0, 1.0], yaw), tool_quat(arm, roll_deg))
    return np.hstack([p, q])


SIDE_BY_SIDE_YAWS_DEG = (0.0, 20.0, 35.0)
"""With two arms side by side, the rods are also tried turned outward by these angles about
the vertical (each hand farther toward its own arm's side): wide hands that do not fit side
by side in front of two neighbouring faces fit when their rods converge."""


IK_STARTS = 12
"""Joint states inverse kinematics starts from: the current one, then this many more drawn
from a fixed seed (mplib's own restarts are unseeded)."""


def solve_ik(
    planner, pose: np.ndarray, qpos: np.ndarray, most_room: bool = False
) -> np.ndarray | None:
    """Joint positions putting the tool at `pose` (world frame), searched from `qpos` and
    then from IK_STARTS fixed joint states (deterministic), or None when the pose is out of
    reach (or every solution collides with the robot itself). `most_room`: of all the
    solutions found, the one farthest from its joint limits (a pose paths start from);
    otherwise the first."""
    goal = planner.transform_goal_to_wrt_base(pose)
    lo, hi = np.asarray(planner.joint_limits, dtype=np.float64).T
    rng = np.random.default_rng(0)
    starts = [np.asarray(qpos, dtype=np.float64)]
    starts += [np.hstack([rng.uniform(lo, hi), qpos[len(lo) :]]) for _ in range(IK_STARTS)]
    best, room = None, -np.inf
    for start in starts:
        status, results = planner.IK(goal, start, n_init_qpos=1)
        if status == "Success" and results:
            if not most_room:
                return results[0]
            q = results[0][: len(lo)]
            margin = float(np.min(np.minimum(q - lo, hi - q) / (hi - lo)))
            if margin > room:
                best, room = results[0], margin
    return best


def plan_joint_line(planner, goal_q: np.ndarray, qpos: np.ndarray, dt_s: float, check_shelf: bool):
    """A straight line in joint space from `qpos` to `goal_q` (the arm's joints), timed
    within the velocity and acceleration limits -> (status, (T, 7) joint positions or None);
    status "planning_failed" when a point of it hits the shelf or the robot itself."""
    q0, q1 = np.asarray(qpos[:7], dtype=np.float64), np.asarray(goal_q[:7], dtype=np.float64)
    n = max(2, int(np.ceil(np.abs(q1 - q0).max() / 0.05)) + 1)
    path = q0 + np.linspace(0.0, 1.0, n)[:, None] * (q1 - q0)
    planner.planning_world.set_use_point_cloud(check_shelf)
    planner.planning_world.set_use_attach(False)
    for q in path:
        planner.planning_world.set_qpos_all(q)
        if planner.planning_world.collide():
            return "planning_failed", None
    if np.abs(q1 - q0).max() < 1e-6:
        return "ok", path[-1:]
    return _timed(planner, path, dt_s)


def _timed(planner, path: np.ndarray, dt_s: float):
    """The path timed within the joint velocity and acceleration limits (TOPP-RA), sampled
    at the control rate -> ("ok", (T, 7)), or ("planning_failed", None) when it cannot be."""
    try:
        _, pos, _, _, _ = planner.TOPP(path, dt_s)
    except RuntimeError:  # mplib: "Fail to parameterize path"
        return "planning_failed", None
    return "ok", np.asarray(pos)


LINE_STEP_M = 0.01
"""Straight tool paths are followed through waypoints this far apart."""
MAX_JOINT_JUMP_RAD = 0.35
"""Two consecutive waypoints of a straight path whose joint states differ more than this
are a branch switch of the inverse kinematics, not a path."""


def plan_line(planner, pose: np.ndarray, qpos: np.ndarray, dt_s: float, check_shelf: bool):
    """A straight tool path to `pose` from the joint state `qpos`: waypoints every
    LINE_STEP_M, each solved by inverse kinematics from the one before (a continuous,
    deterministic path), timed within the joint limits -> (status, (T, 7) joint positions at
    the control rate or None). status: "ok", "unreachable" (no joint state puts the tool at
    the goal), "planning_failed" (the line leaves the joint limits, jumps branches, or hits
    the shelf or the robot itself)."""
    planner.planning_world.set_use_point_cloud(check_shelf)
    planner.planning_world.set_use_attach(False)
    q = np.asarray(qpos, dtype=np.float64)
    planner.pinocchio_model.compute_forward_kinematics(q)
    start = np.asarray(planner.pinocchio_model.get_link_pose(planner.link_name_2_idx[MOVE_GROUP]))
    goal_base = planner.transform_goal_to_wrt_base(pose)
    n = max(1, int(np.ceil(np.linalg.norm(goal_base[:3] - start[:3]) / LINE_STEP_M)))
    q0, q1 = start[3:], np.asarray(goal_base[3:], dtype=np.float64)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    path = [q[:7].copy()]
    for k in range(1, n + 1):
        t = k / n
        quat = (1 - t) * q0 + t * q1
        waypoint = np.hstack([(1 - t) * start[:3] + t * goal_base[:3], quat / np.linalg.norm(quat)])
        status, results = planner.IK(waypoint, q, n_init_qpos=1)
        if (
            status != "Success"
            or not results
            or np.abs(results[0][:7] - q[:7]).max() > MAX_JOINT_JUMP_RAD
        ):
            if k == n or solve_ik(planner, pose, q) is None:
                return "unreachable", None
            return "planning_failed", None
        q = np.asarray(results[0], dtype=np.float64)
        path.append(q[:7].copy())
    if len(path) < 2 or np.abs(path[-1] - path[0]).max() < 1e-6:
        return "ok", np.asarray(path[-1:])
    return _timed(planner, np.asarray(path), dt_s)
