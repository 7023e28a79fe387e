"""The two success criteria of every trial step, from per-box motion (no SAPIEN, no torch).

Every step record carries `box_motion`: for every box on the shelf at the step's start other
than the manipulated ones, and for the manipulated boxes released at the step's end (`held:
true`: the held box, and the pulled box of a pull stopped before it was out), its centre
displacement, its
drop in height, its change of tilt and whether it left the shelf, from the step's start to
the settled end. Both criteria are computed from these fields alone, so a record file can be
re-judged under other thresholds (trials/rejudge.py):

- **collapse-free** (the thesis' trial notion, `success`): no box left the shelf, and no box
  other than the manipulated ones dropped by more than `drop_m` or tipped by more than
  `tilt_deg`; a horizontal slide is disturbance, reported, not a collapse. A released held
  box must stay on the shelf (it may settle lower or be set upright by the gripper).
- **strict** (`strict_success`): collapse-free, and also no box other than the manipulated
  ones moved more than the label threshold. Defined as collapse-free *and* still, so a strict
  success is always a collapse-free one (even for a box that turns in place beyond
  `tilt_deg` without its centre moving) and the strict episode is a prefix of the
  collapse-free one.

Tilt is the angle between the world's up direction seen in the box's own frame at the start
and at the end: a box that tips over changes it by the tipping angle, a box that only turns
about the vertical (a slide with a twist) does not change it at all. The angle of the whole
relative rotation would count such a twist as a tip.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from clutterbench.config import bounded, load_section
from clutterbench.sim.geometry import tilt_change_deg

MOTION_FIELDS = ("box", "held", "displacement_m", "drop_m", "tilt_change_deg", "left_shelf")
"""The fields of each entry of a step's `box_motion`."""


@dataclasses.dataclass(frozen=True)
class CollapseFreeConfig:
    """Thresholds of the collapse-free criterion (fixed before any result was seen)."""

    drop_m: float = bounded(0.010, gt=0.0)
    """A box other than the manipulated ones collapsed when its centre dropped more than this."""
    tilt_deg: float = bounded(15.0, gt=0.0, le=180.0)
    """... or when its tilt (world up in its own frame) changed by more than this (degrees)."""


def label_thresholds(params: Mapping[str, Any]) -> tuple[float, float]:
    """(drop_m, tilt_deg) of trials.collapse_free in `params`: what the pull_collapse labels
    (data.labels.pull_collapse_matrix) call a collapse, so they mean what a trial does."""
    cf = load_section(CollapseFreeConfig, "trials.collapse_free", params)
    return cf.drop_m, cf.tilt_deg


def box_motion(
    poses_start: np.ndarray,
    poses_end: np.ndarray,
    on_shelf_end: np.ndarray,
    others: Iterable[int],
    held: Iterable[int] = (),
) -> list[dict[str, Any]]:
    """Per-box motion of `others` and of the released `held` boxes between two (N, 7) pose
    snapshots ([x, y, z, qw, qx, qy, qz]); `on_shelf_end` (N,) bool. Sorted by box."""
    held = set(held)
    out = []
    for k in sorted(set(others) | held):
        start, end = np.asarray(poses_start[k], float), np.asarray(poses_end[k], float)
        out.append(
            {
                "box": int(k),
                "held": k in held,
                "displacement_m": round(float(np.linalg.norm(end[:3] - start[:3])), 6),
                "drop_m": round(float(start[2] - end[2]), 6),
                "tilt_change_deg": round(tilt_change_deg(start[3:], end[3:]), 4),
                "left_shelf": not bool(on_shelf_end[k]),
            }
        )
    return out


def collapsed(entry: Mapping[str, Any], cf: CollapseFreeConfig) -> bool:
    """Whether one box of `box_motion` counts as collapsed (left the shelf; not held: also
    dropped or tipped beyond the thresholds)."""
    if entry["left_shelf"]:
        return True
    if entry["held"]:
        return False
    return entry["drop_m"] > cf.drop_m or entry["tilt_change_deg"] > cf.tilt_deg


def moved(entry: Mapping[str, Any], moved_m: float) -> bool:
    """Whether one box of `box_motion` moved beyond the label threshold (held ones never)."""
    return not entry["held"] and entry["displacement_m"] > moved_m


def collapse_free(motion: Sequence[Mapping[str, Any]], cf: CollapseFreeConfig) -> bool:
    return not any(collapsed(e, cf) for e in motion)


def still(motion: Sequence[Mapping[str, Any]], moved_m: float, cf: CollapseFreeConfig) -> bool:
    """The strict criterion's `others_still`: collapse-free and no other box moved."""
    return collapse_free(motion, cf) and not any(moved(e, moved_m) for e in motion)


def n_disturbed(motion: Sequence[Mapping[str, Any]], moved_m: float, cf: CollapseFreeConfig) -> int:
    """Boxes that moved beyond the label threshold or collapsed."""
    return sum(moved(e, moved_m) or collapsed(e, cf) for e in motion)


def n_collapsed(motion: Sequence[Mapping[str, Any]], cf: CollapseFreeConfig) -> int:
    return sum(collapsed(e, cf) for e in motion)


def strict_prefix(steps: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The steps a strict episode would have run: up to and including the first step that is
    a strict failure (executed, and another box moved or collapsed). The planner does not know
    the criterion, so the strict episode is this prefix of the collapse-free one."""
    out = []
    for s in steps:
        out.append(s)
        if s["executed"] and not s["others_still"]:
            break
    return out
