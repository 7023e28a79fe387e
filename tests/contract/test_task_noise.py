"""Task noise (trials/noise): recorded episodes replayed in the table's world and in perturbed
ones, and the robust search oracle."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from clutterbench.planning.ch6.extraction import Decision
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.ch6.episodes import (
    PLANNERS,
    SearchOracle,
    register_planner,
    run_extraction,
)
from clutterbench.trials.config import SceneStreamConfig
from clutterbench.trials.noise.draws import Draw
from clutterbench.trials.noise.replay import replay_episode
from clutterbench.trials.noise.robust import RobustSearchOracle
from tests.toy_jobs import toy_ch6_jobs

DATA = Path(__file__).resolve().parents[1] / "data"
STACK3, TOWER6 = DATA / "stack3.json", DATA / "tower6.json"


class AbortAfterTwo:
    """Pulls the bottom box first, its collapse score rising past cp_max after two increments
    (an abort after motion), then the target."""

    def __init__(self) -> None:
        self.checks = 0

    def decide(self, obs, target, blocked):
        box = 0 if 0 not in blocked and target != 0 else target
        return Decision(box, None, {"policy": "toy_abort"})

    def collapse_score(self, obs, box, hold):
        self.checks += 1
        return 1.0 if box == 0 and self.checks > 2 else 0.0


if "toy_abort_after_two" not in PLANNERS:
    register_planner("toy_abort_after_two")(lambda job, spec: AbortAfterTwo())


def _job(planner: str):
    stream = SceneStreamConfig(families={"stacked": 1}, n_objects=(3, 5))
    return dataclasses.replace(toy_ch6_jobs("random", stream, _cam())[0], planner=planner)


def _cam():
    from clutterbench.sim.config import CameraConfig

    return CameraConfig(image_size=64)


@pytest.mark.parametrize(
    "planner", ["pull_target", "random", "oracle", "oracle_hold", "toy_abort_after_two"]
)
@pytest.mark.parametrize("spec_path", [STACK3, TOWER6], ids=["stack3", "tower6"])
def test_a_replay_in_the_tables_world_gives_every_record(spec_path, planner):
    """The table's world (Draw.none) replays each recorded episode to the record's outcome,
    end and step count, aborted pulls included."""
    spec = SceneSpec.load(spec_path)
    job = _job(planner)
    aborted = 0
    for target in range(spec.n):
        rec = run_extraction(spec, job, target=target).record
        aborted += sum(s["aborted_after_motion"] for s in rec["steps"])
        got = replay_episode(
            rec, spec, Draw.none(spec.n), job.physics, job.params.pull, job.collapse_free
        )
        want = (rec["success"], rec["strict_success"], rec["end"], len(rec["steps"]))
        assert (got.success, got.strict_success, got.end, got.steps) == want, (planner, target)
    if planner == "toy_abort_after_two":
        assert aborted, "the abort path was not exercised"


def test_a_replay_runs_the_recorded_actions_not_the_planners():
    """The bottom box of the stack pulled first collapses it; a record saying so replays to a
    collapse, and one whose steps run out before the target is out ends as given up."""
    spec = SceneSpec.load(STACK3)
    job = _job("pull_target")
    step = {"box": 0, "hold": None, "increments": 0}
    step |= {"aborted_before_motion": False, "aborted_after_motion": False}
    rec = {"target": 2, "steps": [step]}
    got = replay_episode(
        rec, spec, Draw.none(spec.n), job.physics, job.params.pull, job.collapse_free
    )
    assert got.end == "collapse" and not got.success
    rec = {"target": 0, "steps": [step | {"box": 2}]}
    got = replay_episode(
        rec, spec, Draw.none(spec.n), job.physics, job.params.pull, job.collapse_free
    )
    assert got.end == "gave_up" and not got.success and got.steps == 1


@dataclasses.dataclass(frozen=True)
class Dropped:
    """A world in which every box starts 3 cm above where it rests: every pull collapses."""

    def physics(self, base):
        return base

    def spec(self, spec, base):
        return spec

    def start(self, state, step):
        poses = state.poses.copy()
        poses[:, 2] += 0.03
        return SceneState(poses, state.removed)


def test_the_robust_oracle_needs_its_steps_clean_in_every_world_it_searched():
    spec = SceneSpec.load(STACK3)
    job = _job("oracle")
    p = job.params
    args = (spec, job.physics, job.camera, p.pull, p.search, False, job.collapse_free)
    start = SceneState.start(spec)
    plain, _, _ = SearchOracle(*args).search(start, 0)
    same, _, _ = RobustSearchOracle(*args, draws=[Draw.none(spec.n)]).search(start, 0)
    assert plain is not None and [a for a, _ in same] == [a for a, _ in plain]
    dropped, _, _ = RobustSearchOracle(*args, draws=[Dropped()]).search(start, 0)
    assert dropped is None
    # the oracle's own world is restored after each simulation in another
    oracle = RobustSearchOracle(*args, draws=[Dropped()])
    oracle.simulate(start, (2, None))
    assert oracle.spec is spec and oracle.physics is job.physics
    assert np.array_equal(start.poses, np.asarray(spec.poses))
