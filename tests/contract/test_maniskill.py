"""The ManiSkill tasks and the arm-level executor on hand-built scenes: the env's judge is the
project's, an arm that cannot reach is never a success, a held box is let go before the judge."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from clutterbench.criteria import CollapseFreeConfig  # noqa: E402
from clutterbench.maniskill.config import ArmConfig  # noqa: E402
from clutterbench.maniskill.executor import ArmExecutor  # noqa: E402
from clutterbench.sim.pull import SceneState, execute_pull, world_at  # noqa: E402
from clutterbench.sim.spec import SceneSpec  # noqa: E402
from clutterbench.trials.config import TrialsConfig  # noqa: E402
from clutterbench.trials.core.protocol import judge_pull  # noqa: E402

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
THR = 0.005
CF = CollapseFreeConfig()
PARAMS = TrialsConfig().ch6


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


def side_by_side() -> SceneSpec:
    """Two boxes on the shelf floor near the opening, right (y < 0) and left."""
    size = np.array([0.1, 0.1, 0.08])
    poses = np.array([[0.08, y, 0.04, 1.0, 0.0, 0.0, 0.0] for y in (-0.07, 0.07)])
    return SceneSpec(sizes_m=np.stack([size, size]), poses=poses)


def _kinematic(spec, physics, box, hold=None):
    state = SceneState.start(spec)
    world = world_at(spec, state, physics)
    result = execute_pull(world, box, hold, PARAMS.pull_increment_m, PARAMS.grasp_lift_m)
    return judge_pull(result, box, hold, state.removed, THR, CF), SceneState.of(world)


@pytest.mark.parametrize("box", [0, 2])
def test_env_evaluate_agrees_with_the_project_judge(stack3, physics, box):
    """The kinematic executor pulls a box of a 3-stack (the bottom: the stack falls; the top:
    clean); the ManiSkill env, put in the same end state, judges it the same way."""
    from sapien import physx

    import clutterbench.maniskill.tasks  # noqa: F401

    def settings():
        body, shape, mat = (
            physx.get_body_config(),
            physx.get_shape_config(),
            physx.get_default_material(),
        )
        return (body.solver_position_iterations, shape.contact_offset, mat.restitution)

    before = settings()
    step, end = _kinematic(stack3, physics, box)
    env = gym.make(
        "ClutterShelfExtract-v1",
        spec=stack3,
        target=box,
        physics=physics,
        moved_threshold_m=THR,
        obs_mode="state",
        reward_mode="sparse",
    )
    env.reset()
    assert settings() == before  # a ManiSkill env leaves every BoxWorld's PhysX settings alone
    u = env.unwrapped
    for k in range(stack3.n):
        if k in end.removed:
            u.park(k)
        else:
            u.bodies[k].entity.set_pose(
                __import__("sapien").Pose(end.poses[k, :3], end.poses[k, 3:])
            )
    info = {k: bool(v.item()) for k, v in u.evaluate().items()}
    assert info["target_out"] == step["extracted"]
    assert info["others_still"] == step["others_still"]
    assert info["success"] == bool(step["success"])
    assert info["success"] == (box == 2)  # both outcomes are exercised
    env.close()


def test_an_arm_pull_of_the_top_box_agrees_with_the_kinematic_pull(stack3, physics):
    """A tiny arm episode: the Panda takes the top box of a stack out, judged a success
    exactly as the kinematic executor's pull."""
    ex = ArmExecutor(physics, ArmConfig(), bimanual=False)
    result, arm, end = ex.execute_pull(
        stack3, SceneState.start(stack3), 2, None, PARAMS.pull_increment_m, PARAMS.grasp_lift_m
    )
    step = judge_pull(result, 2, None, frozenset(), THR, CF)
    kin, _ = _kinematic(stack3, physics, 2)
    assert arm.outcome == "ok" and arm.joint_log
    assert step["extracted"] and step["success"] and kin["success"]
    assert end.removed == frozenset({2})


def test_an_unreachable_face_is_an_abort_never_a_success(stack3, physics):
    """An approach the arm cannot make (the entry point put far behind its base) is named
    `unreachable`; nothing is pulled, so the step is no success."""
    ex = ArmExecutor(physics, ArmConfig(entry_clearance_m=1.5), bimanual=False)
    result, arm, end = ex.execute_pull(
        stack3, SceneState.start(stack3), 2, None, PARAMS.pull_increment_m, PARAMS.grasp_lift_m
    )
    step = judge_pull(result, 2, None, frozenset(), THR, CF)
    assert arm.outcome == "unreachable" and arm.failed_arm == "pull"
    assert result.increments == 0 and not result.extracted
    assert not step["success"] and not step["extracted"]
    assert not end.removed


def test_the_held_box_is_released_before_the_judge(physics):
    """Bimanual: one Panda holds the left box while the other pulls the right one out; the
    holder lets go (and the box is dynamic again) before the final displacements are read."""
    spec = side_by_side()
    ex = ArmExecutor(physics, ArmConfig(), bimanual=True)
    result, arm, end = ex.execute_pull(
        spec, SceneState.start(spec), 0, 1, PARAMS.pull_increment_m, PARAMS.grasp_lift_m
    )
    assert arm.outcome == "ok", arm
    assert arm.pull_arm == 0  # the arm on the right pulls the right box
    assert ex.u.attached == {}
    assert not ex.u.bodies[1].kinematic
    disp, _ = ex.u.displacements()
    assert result.displacement_m[1] == pytest.approx(disp[1])
    assert result.extracted and end.removed == frozenset({0})
    step = judge_pull(result, 0, 1, frozenset(), THR, CF)
    assert step["success"]


def test_an_arm_that_gave_up_after_moving_a_box_is_a_judged_failure():
    """An approach that stopped short (no increment pulled) but knocked a box over is a
    failed step (the episode ends in collapse), never an abort that disturbed nothing; one
    that moved nothing is the abort."""
    from clutterbench.sim.pull import PullResult
    from clutterbench.trials.core.executors import judge_arm_step
    from clutterbench.trials.core.protocol import episode_end

    still = np.zeros(3)
    knocked = np.array([0.0, 0.03, 0.0])
    on_shelf = np.ones(3, dtype=bool)
    start = np.tile([0.1, 0.0, 0.05, 1.0, 0.0, 0.0, 0.0], (3, 1))
    fell = start.copy()
    fell[1, 2] -= 0.03
    quiet = judge_arm_step(
        PullResult(0, False, False, still, still, on_shelf, start, start),
        0,
        None,
        frozenset(),
        THR,
        CF,
    )
    assert not quiet["judged"] and not quiet["counted"] and quiet["success"] is None
    hit = judge_arm_step(
        PullResult(0, False, False, knocked, knocked, on_shelf, start, fell),
        0,
        None,
        frozenset(),
        THR,
        CF,
    )
    assert not hit["aborted_before_motion"] and hit["aborted_after_motion"]
    assert hit["judged"] and hit["counted"] and hit["success"] is False and hit["n_disturbed"] == 1
    assert episode_end(hit, False, True) == "collapse"
