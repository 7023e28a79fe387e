"""Success from physics: named booleans from box motion, never from a planner's prediction.

As ManiSkill's `evaluate()`, a judge returns named booleans (`extracted`, `others_still`,
`success`; trials/core/protocol.py judges a step) and the disturbance beside them: how many boxes
other than the manipulated ones moved beyond the threshold, and the sum of their centre
displacements (SafePicking's translation measure).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np


@dataclasses.dataclass(frozen=True)
class Disturbance:
    n_disturbed: int
    """Boxes (other than the manipulated ones) that moved more than the threshold."""
    disturbance_m: float
    """Sum of the centre displacements of those other boxes (all of them, moved or not)."""


def disturbance(
    before_m: np.ndarray,
    after_m: np.ndarray,
    exclude: Iterable[int],
    gone: Iterable[int],
    threshold_m: float,
) -> Disturbance:
    """Motion of the boxes not in `exclude` (the manipulated ones) between two (N, 3) centre
    snapshots; boxes in `gone` (out of the scene before `before_m`) are not counted."""
    assert before_m.shape == after_m.shape and before_m.shape[1:] == (3,), "centres (N, 3) m"
    skip = set(exclude) | set(gone)
    others = np.array([k for k in range(len(before_m)) if k not in skip], dtype=int)
    if others.size == 0:
        return Disturbance(0, 0.0)
    disp = np.linalg.norm(after_m[others] - before_m[others], axis=1)
    return Disturbance(int(np.sum(disp > threshold_m)), float(np.sum(disp)))
