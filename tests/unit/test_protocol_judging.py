"""The pull protocol's fixes, on hand-made pull results (no physics): every executed step is
judged with the pulled box included when its pull stopped, a box already off the shelf at a
step's start is not that step's collapse, and the aborts are counted for what they are."""

from __future__ import annotations

import numpy as np

from clutterbench.criteria import CollapseFreeConfig
from clutterbench.sim.pull import PullResult
from clutterbench.trials.core.protocol import judge_episode, judge_pull
from clutterbench.trials.core.stats import aggregate

CF = CollapseFreeConfig()
UP = [1.0, 0.0, 0.0, 0.0]


def result(
    poses_end: list[list[float]],
    on_shelf: list[bool],
    on_shelf_start: list[bool] | None = None,
    increments: int = 3,
    aborted: bool = True,
    extracted: bool = False,
) -> PullResult:
    """Three boxes in a row at x = 0.1 m, their ends as given."""
    start = np.array([[0.1, y, 0.05, *UP] for y in (-0.1, 0.0, 0.1)])
    end = np.array([p + UP for p in poses_end])
    disp = np.linalg.norm(end[:, :3] - start[:, :3], axis=1)
    return PullResult(
        increments,
        aborted,
        extracted,
        disp,
        disp,
        np.array(on_shelf),
        start,
        end,
        None if on_shelf_start is None else np.array(on_shelf_start),
    )


def test_a_stopped_pull_that_drops_its_own_box_off_the_shelf_is_a_collapse():
    # box 0 pulled 60 mm and let go: it fell off the front; the others did not move
    r = result([[-0.05, -0.1, -0.2], [0.1, 0.0, 0.05], [0.1, 0.1, 0.05]], [False, True, True])
    step = judge_pull(r, 0, None, frozenset(), 0.005, CF)
    assert step["aborted_after_motion"] and not step["extracted"]
    assert not step["collapse_free"] and step["counted"] and step["success"] is False
    assert [e["box"] for e in step["box_motion"] if e["held"]] == [0]


def test_a_stopped_pull_whose_box_stays_on_the_shelf_is_an_abort():
    r = result([[0.05, -0.1, 0.05], [0.1, 0.0, 0.05], [0.1, 0.1, 0.05]], [True, True, True])
    step = judge_pull(r, 0, None, frozenset(), 0.005, CF)
    assert step["collapse_free"] and not step["counted"] and step["success"] is None
    assert step["judged"]  # executed: judged from physics, counted apart as an abort


def test_a_box_already_off_the_shelf_is_not_the_next_steps_collapse():
    # box 2 left the shelf in an earlier step (it lies below the front); box 1 comes out cleanly
    ends = [[0.1, -0.1, 0.05], [-0.3, 0.0, 0.05], [-0.05, 0.1, -0.2]]
    r = result(ends, [True, False, False], [True, True, False], aborted=False, extracted=True)
    step = judge_pull(r, 1, None, frozenset(), 0.005, CF)
    assert step["collapse_free"] and step["success"] is True
    assert [e["box"] for e in step["box_motion"]] == [0]
    # without the start's flags (older results), it would count as this step's collapse
    r_old = result(ends, [True, False, False], None, aborted=False, extracted=True)
    assert not judge_pull(r_old, 1, None, frozenset(), 0.005, CF)["collapse_free"]


def test_episode_names_the_target_extracted_and_aggregate_splits_the_aborts():
    still = [[0.1, -0.1, 0.05], [0.1, 0.0, 0.05], [0.1, 0.1, 0.05]]
    nudged = [[0.1, -0.1, 0.05], [0.1, 0.0, 0.05], [0.1, 0.11, 0.05]]  # box 2 slid 10 mm
    steps = [
        judge_pull(result(still, [True] * 3, increments=0), 0, None, frozenset(), 0.005, CF),
        judge_pull(result(nudged, [True] * 3), 0, None, frozenset(), 0.005, CF),
        judge_pull(result(still, [True] * 3), 1, None, frozenset(), 0.005, CF),
    ]
    for s, box in zip(steps, (0, 0, 1), strict=True):
        s["box"] = box
    episode = judge_episode(steps, "gave_up", target=1)
    assert episode["target_extracted"] is False and "target_out" not in episode
    record = {"condition": "c", "episode": 0, "steps": steps} | episode
    row = aggregate([record]).iloc[0]
    assert (row["aborts"], row["aborts_before_motion"], row["aborts_moved"]) == (3, 1, 1)
