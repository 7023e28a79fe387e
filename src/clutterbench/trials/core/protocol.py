"""The episode protocol every chapter's trials share (thesis 6.3.2; ARCHITECTURE "one episode
protocol").

- **One canonical start per step.** A step is executed in a fresh world built from the state
  the previous step left (`BoxWorld.from_state`): simulating an action from a state (the
  oracles' search) and executing it give the same bits.
- **Release, then judge.** The pulled box leaves the scene (or, aborted, is let go where it
  is); the scene settles with the second arm still holding (the *held* judgement, kept as a
  second column); then every held box is released, the scene settles again, and the step is
  judged from physics: no box other than the manipulated ones (pulled, held) may have moved
  beyond the threshold or left the shelf, and the released box must still be on the shelf.
- **Two criteria, one run** (criteria.py): a step is *collapse-free* when no box left
  the shelf and no box other than the manipulated ones dropped or tipped beyond the
  `trials.collapse_free` thresholds (`success`), and *strict* when also no such box moved
  beyond the label threshold (`strict_success`). **An episode ends at its first
  collapse-free failure**, when the target is out, when the target is no longer on the shelf
  (fell: a failure), or when the planner gives up; the planner does not know the criterion,
  so the strict episode is the prefix up to its first strict failure (`criteria.strict_prefix`),
  and every strict count is taken over that prefix only.
- **An abort before any motion is an abort, not a collapse:** nothing was executed, so
  nothing is judged. Every executed step is judged from physics (`judged`), aborted or not,
  the released box included; an abort after motion that disturbed nothing is an abort too.
  Per-step success counts the *counted* steps (`counted`, `strict_counted`): the executed
  pulls that took the box out or disturbed the pile under that criterion.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from clutterbench import criteria
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.sim.pull import PullResult, moved_others

STEP_FIELDS = (
    "executed",
    "aborted_before_motion",
    "aborted_after_motion",
    "extracted",
    "others_still",
    "collapse_free",
    "judged",
    "counted",
    "strict_counted",
    "success",
    "strict_success",
    "others_still_held",
    "success_held",
    "box_motion",
)
"""The named outcome of every step record. `judged`: the step was executed and judged from
physics after the release (false only where nothing was executed). `success`
(collapse-free) and `strict_success` are booleans on the steps counted in per-step success
under that criterion (`counted`, `strict_counted`) and None on an abort that disturbed
nothing under it (neither a success nor a failure: the episode goes on). `others_still` is
the strict criterion's, `collapse_free` the other's; `*_held` is the strict judgement while
the second arm still held. `box_motion`: per box, its motion over the step (criteria.py)."""

EPISODE_ENDS = ("target_out", "collapse", "target_fell", "gave_up", "max_steps", "missed_grasp")
"""Why an episode ended: the target left the shelf after a clean step; a step moved another
box beyond the threshold; the target left the shelf without being pulled; the planner had no
action left; the attempt cap; the planner pulled (or held) a segment of depth perception whose
grasp takes no box."""


def judge_pull(
    result: PullResult | None,
    box: int,
    hold: int | None,
    gone: frozenset[int],
    threshold_m: float,
    cf: CollapseFreeConfig,
) -> dict[str, Any]:
    """A step's named outcome from physics under both criteria (criteria.py). `result`
    None: aborted before any motion (nothing was simulated, nothing moved). Judged after the
    release (what the released box carried or leaned on has settled; the released box itself
    may settle lower, but must stay on the shelf) and, strict, as a second column while still
    held. An abort that disturbed nothing under a criterion is neither a success nor a failure
    under it (`success` / `strict_success` None; the episode goes on)."""
    if result is None or result.increments == 0:
        return {
            "executed": False,
            "aborted_before_motion": True,
            "aborted_after_motion": False,
            "extracted": False,
            "others_still": True,
            "collapse_free": True,
            "judged": False,
            "counted": False,
            "strict_counted": False,
            "success": None,
            "strict_success": None,
            "others_still_held": True,
            "success_held": None,
            "n_disturbed": 0,
            "n_collapsed": 0,
            "disturbance_m": 0.0,
            "box_motion": [] if result is None else _motion(result, box, hold, gone),
        }
    manipulated = {box} | ({hold} if hold is not None else set())
    motion = _motion(result, box, hold, gone)
    _, total = moved_others(result.displacement_m, result.on_shelf, manipulated, gone, threshold_m)
    n_held, _ = moved_others(
        result.displacement_held_m, np.ones_like(result.on_shelf), manipulated, gone, threshold_m
    )
    step = {
        "executed": True,
        "aborted_before_motion": False,
        "aborted_after_motion": result.aborted,
        "extracted": result.extracted,
        "others_still": criteria.still(motion, threshold_m, cf),
        "collapse_free": criteria.collapse_free(motion, cf),
    }
    counts, strict_counts = counted(step), strict_counted(step)
    return step | {
        "judged": True,
        "counted": counts,
        "strict_counted": strict_counts,
        "success": result.extracted and step["collapse_free"] if counts else None,
        "strict_success": result.extracted and step["others_still"] if strict_counts else None,
        "others_still_held": n_held == 0,
        "success_held": result.extracted and n_held == 0 if strict_counts else None,
        "n_disturbed": criteria.n_disturbed(motion, threshold_m, cf),
        "n_collapsed": criteria.n_collapsed(motion, cf),
        "disturbance_m": total,
        "box_motion": motion,
    }


def _motion(
    result: PullResult, box: int, hold: int | None, gone: frozenset[int]
) -> list[dict[str, Any]]:
    """Per-box motion of every box on the shelf at the step's start but the pulled one; the
    manipulated boxes released at the step's end are marked `held` (must stay on the shelf):
    the held one, and the pulled one when its pull stopped before it was out (let go where it
    is). A box already off the shelf at the step's start (an earlier step left it there) is
    not this step's."""
    n = len(result.displacement_m)
    start = result.on_shelf_start
    present = [k for k in range(n) if k not in gone and (start is None or bool(start[k]))]
    others = [k for k in present if k != box and k != hold]
    held = [k for k in (hold,) if k is not None and k in present]
    if not result.extracted and result.increments > 0 and box in present:
        held.append(box)
    return criteria.box_motion(result.poses_start, result.poses_end, result.on_shelf, others, held)


def counted(step: dict[str, Any]) -> bool:
    """Whether a step counts in collapse-free per-step success: an executed pull that took
    its box out or made a box collapse (an abort that collapsed nothing is an abort)."""
    return bool(step["executed"] and (step["extracted"] or not step["collapse_free"]))


def strict_counted(step: dict[str, Any]) -> bool:
    """Whether a step counts in strict per-step success: an executed pull that took its box
    out or disturbed the pile beyond the label threshold."""
    return bool(step["executed"] and (step["extracted"] or not step["others_still"]))


def episode_end(step: dict[str, Any], target_out: bool, target_on_shelf: bool) -> str | None:
    """Why the episode ends after `step`, or None to go on: at its first collapse-free failure
    (thesis 6.3.2: each failed episode has exactly one failed step)."""
    if step["executed"] and not step["collapse_free"]:
        return "collapse"
    if target_out:
        return "target_out"
    if not target_on_shelf:
        return "target_fell"
    return None


def judge_episode(steps: list[dict[str, Any]], end: str, target: int) -> dict[str, Any]:
    """The episode's named outcome: `success` (collapse-free) when the target came out and no
    step made a box collapse (the episode ended at "target_out"); `target_extracted` when the
    target came out at all (a step that took it out may still have made a box collapse);
    `strict_success` when, in addition, no step disturbed the pile beyond the label threshold
    (the strict episode, the prefix up to its first strict failure, ended with the target
    out); their counted steps (per-step success under each criterion).
    `success_held`: the strict judgement while the second arm still held, where that is
    decidable (it differs only when the strict episode's last step pulled the target and its
    release disturbed the pile)."""
    assert end in EPISODE_ENDS, end
    prefix = criteria.strict_prefix(steps)
    strict_ok = (
        end == "target_out" and len(prefix) == len(steps) and all(s["others_still"] for s in steps)
    )
    last = prefix[-1] if prefix else None
    released_only = (
        not strict_ok
        and last is not None
        and last["box"] == target
        and last["executed"]
        and not last["others_still"]
        and bool(last["success_held"])
    )
    return {
        "end": end,
        # the target came out in some step, whether or not that step made a box collapse
        # (`success` also needs no collapse; this field was `target_out` before)
        "target_extracted": any(s["extracted"] and s["box"] == target for s in steps),
        "others_still": all(s["others_still"] for s in steps),
        "success": end == "target_out",
        "strict_success": strict_ok,
        "strict_steps": len(prefix),
        "success_held": strict_ok or released_only,
        "aborted_before_motion": sum(bool(s["aborted_before_motion"]) for s in steps),
        "aborted_after_motion": sum(bool(s["aborted_after_motion"]) for s in steps),
        "counted_steps": sum(counted(s) for s in steps),
        "strict_counted_steps": sum(strict_counted(s) for s in prefix),
    }


STEP_NOTES = ("no_plan", "idle_hold", "feared_hold")
"""The notes of a pull planner's decision a step record carries: no_plan (no plan
was left: how the pull was chosen), idle_hold (the bimanual idle arm held a box),
feared_hold (the second arm held the box the unheld pull's score feared for)."""


def step_notes(state: dict[str, Any]) -> dict[str, Any]:
    """The step record's fields from a decision's notes (STEP_NOTES): no_plan's value, and
    true for a hold (the held box is the record's `hold`)."""
    return {k: state[k] if k == "no_plan" else True for k in STEP_NOTES if k in state}
