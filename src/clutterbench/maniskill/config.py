"""The arm-level executor's setup (params `trials.arm`): the Panda bases, the tool and the motion
limits. Plain data, so the trials' params parse without loading ManiSkill or SAPIEN."""

from __future__ import annotations

import dataclasses

from clutterbench.config import bounded


@dataclasses.dataclass(frozen=True)
class ArmConfig:
    control_freq_hz: int = bounded(20, ge=1)
    """Joint-position commands per second (each control step runs 1 / (timestep_s *
    control_freq_hz) physics steps: sim.physics.timestep_s must divide it)."""
    rod_length_m: float = bounded(0.3, gt=0.0, le=1.0)
    """The tool: a rod this long (8 mm radius) in front of the hand, its tip the TCP (ManiSkill's
    `panda_stick` has 0.1 m). Long enough that the wrist stays out of the shelf for a face
    deep in it (the shelf is 0.28 m deep; a 0.1 m rod put the wrist into its floor or walls
    for most faces beyond 0.1 m)."""
    base_m: tuple[float, float, float] = (-0.82, -0.3, 0.25)
    """Where the first Panda's base stands (shelf frame: x into the shelf, y to the camera's
    left, z up; the shelf opening is x = 0, its floor z = 0), facing the shelf (+x); a
    second Panda stands mirrored (y negated). With two, the one on the pulled box's side
    pulls and the other holds."""
    base_pitch_deg: float = bounded(-45.0, ge=-90.0, le=90.0)
    """Both bases lean back by this much (about their y axis): a Panda points its tool
    forward-and-down most easily, so leaning back makes that direction level with the
    shelf's depth (an upright Panda pointing level needs joint 6 at its limit)."""
    ready_tool_m: tuple[float, float] = (-0.12, 0.15)
    """Where an arm's tool waits between steps, pointing into the shelf: (x, z), in line
    with its base (y). Every motion is a straight tool path: ready -> in front of the face
    -> the face, and back."""
    entry_clearance_m: float = bounded(0.05, gt=0.0)
    """The approach enters the shelf in a straight line from this far in front of the
    opening (or of the face, if the box hangs out)."""
    contact_gap_m: float = bounded(0.002, ge=0.0)
    """The tool stops this short of the box's front face."""
    attach_tolerance_m: float = bounded(0.01, gt=0.0)
    """The suction-like grasp takes hold when the tool's tip is within this of the face
    after the approach; farther (blocked on the way) -> outcome `no_contact`."""
    joint_speed_scale: float = bounded(0.5, gt=0.0, le=1.0)
    """Fraction of the Panda's joint velocity and acceleration limits the planned paths use."""
    collision_clearance_m: float = bounded(0.004, ge=0.0)
    """Radius around each planning point of the shelf boards (mplib point cloud)."""
    settle_control_steps: int = bounded(2, ge=1)
    """A scene is at rest after this many control steps in a row with every box slower
    than sim.physics.rest_linear_m_s."""
