"""Every registered environment, made with defaults (ManiSkill's checks on its own tasks):
make by id, reset(seed) deterministic and equal to the pipeline's episode, 5 random steps,
the same bits from the same seed and varied actions whatever ran before, every obs mode and
the four standard control modes, get/set_state (across episodes with other box counts),
rgb_array / sensors rendering and a recorded video, success and fail, gym.make_vec (async;
refused in one line when it would fork a process that holds the renderer), gymnasium's
check_env, NaN, a box count out of range, a spec of the wrong type and a spec-less arm env
with no scene source refused in one line, dense reward; the planning env
replays committed trial episodes step for step and, fed the multi-step planner, writes the
trials' records."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from clutterbench.envs import ENV_IDS, NO_BOX, PLAN_ENV_ID  # noqa: E402
from clutterbench.errors import ActionError, ClutterbenchError  # noqa: E402
from clutterbench.sim.spec import SceneSpec  # noqa: E402
from clutterbench.trials.core.protocol import STEP_FIELDS  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
STACK3 = ROOT / "tests" / "data" / "stack3.json"
MANISKILL_IDS = [i for i in ENV_IDS if i != PLAN_ENV_ID]


def _records(condition: str) -> dict[int, dict]:
    path = ROOT / "reports" / "trials" / condition / "records.jsonl"
    return {r["episode"]: r for r in map(json.loads, path.read_text().splitlines())}


def _random_action(env, info):
    if env.unwrapped.spec.id == PLAN_ENV_ID:
        pull, hold = env.action_space.sample(mask=info["action_mask"])
        return pull, NO_BOX if hold == pull else hold  # it holds another box or none
    return env.action_space.sample()


def _equal(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    return np.array_equal(np.asarray(a), np.asarray(b))


@pytest.fixture(scope="module", params=ENV_IDS)
def env(request):
    e = gym.make(request.param)  # no arguments at all
    yield e
    e.close()


def test_registered_ids_cover_every_env():
    ours = {k for k, v in gym.registry.items() if "clutterbench" in str(v.entry_point)}
    ours |= {k for k in gym.registry if k.startswith("ClutterShelf")}
    assert ours == set(ENV_IDS)


def test_defaults_reset_seeded_and_five_random_steps(env):
    env.action_space.seed(0)
    obs, info = env.reset(seed=3)
    first = obs
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(_random_action(env, info))
        if terminated or truncated:
            obs, info = env.reset()
    env.reset(seed=4)
    again, _ = env.reset(seed=3)
    assert _equal(first, again)
    if env.unwrapped.spec.id == PLAN_ENV_ID:
        assert env.observation_space.contains(first)


def test_seed_i_is_the_pipelines_episode_i(env):
    """The scene and target of reset(seed=i) are those of the committed trial records of
    stream ch6_3_10 (episode i). (Episodes whose draw rejected the same starts as on the CPU
    the records were made on: on this one a few draws, e.g. episodes 0, 1 and 13, reject
    starts the other did not, and settle to another scene.)"""
    records = _records("multi_step")
    u = env.unwrapped
    for i in (2, 5):
        env.reset(seed=i)
        if u.spec.id == PLAN_ENV_ID:
            spec, target = u.episode.spec, u.episode.target
        else:
            spec, target = u.scene_spec, u.target
        rec = records[i]
        assert (spec.n, spec.family, target) == (rec["n_objects"], rec["family"], rec["target"])


def test_reset_info_names_the_scene_and_its_source(env):
    """Every id's reset info carries `scene` (the start's hash) and `scene_source`."""
    from clutterbench.sim import benchmark

    _, info = env.reset(seed=2)
    u = env.unwrapped
    spec = u.episode.spec if u.spec.id == PLAN_ENV_ID else u.scene_spec
    assert {k: info[k] for k in ("scene", "scene_source")} == benchmark.scene_fields(spec)
    assert info["scene_source"] in ("benchmark", "drawn")


@pytest.mark.parametrize("stream", ["ch5_shelved", "ch5_stacked"])
def test_a_ch5_streams_episode_starts_from_table_5_2s_start(env, stream):
    """reset(seed=i, stream=<a ch. 5 stream>) starts from the start the ch. 5 trials drew
    for episode i (read from the benchmark scenes, the committed Table 5.2 records' hash),
    not from a live draw that skips the episode's new box."""
    path = ROOT / "reports" / "trials_ch5" / "records.jsonl"
    records = [json.loads(line) for line in path.read_text().splitlines()]
    want = next(r for r in records if r["stream"] == stream and r["episode"] == 1)
    _, info = env.reset(seed=1, options={"stream": stream})
    env.reset(seed=0, options={"stream": "ch6_3_10"})  # the other tests' stream again
    assert (info["scene"], info["scene_source"]) == (want["scene"], "benchmark")


def _run_actions(env, seed: int, steps: int) -> list:
    """reset(seed) then `steps` varied actions (the action space's draws from seed 0, the
    planning env's within its action mask, so each run draws the same sequence while it sees
    the same observations) -> every observation and, on an arm id, the final state."""
    u = env.unwrapped
    env.action_space.seed(0)
    obs, info = env.reset(seed=seed)
    seen = [obs]
    for _ in range(steps):
        obs, _, terminated, truncated, info = env.step(_random_action(env, info))
        seen.append(obs)
        if terminated or truncated:
            break
    return seen if u.spec.id == PLAN_ENV_ID else [*seen, u.get_state()]


def test_a_seed_and_varied_actions_give_the_same_bits_after_a_rebuild(env):
    """reset(seed=i) then the same varied actions (30 of them; a few pulls on the planning
    env) give the same observations and state, bit for bit, on the first run, on a second
    run straight after it (the same episode again) and after another episode. Constant
    actions never showed it: a bimanual run whose tool met two shelf boards at once ended
    with arm 1's joints elsewhere in a scene that had been stepped before."""
    steps = 3 if env.unwrapped.spec.id == PLAN_ENV_ID else 30
    first = _run_actions(env, 123, steps)
    again = _run_actions(env, 123, steps)
    _run_actions(env, 7, 2)
    rebuilt = _run_actions(env, 123, steps)
    for other in (again, rebuilt):
        assert len(other) == len(first)
        assert all(_equal(x, y) for x, y in zip(first, other, strict=True))


def test_reset_options_naming_the_scene_rebuild_it(stack3):
    """reset(options={"target": k}) takes effect whether or not the env stepped before (the
    scene options rebuild the scene; they were once dropped by a reset that reused it)."""
    e = gym.make("ClutterShelfExtract-v1", spec=stack3, target=2)
    e.reset(seed=0)
    _, info = e.reset(options={"target": 1})
    assert e.unwrapped.target == 1 and bool(info["reconfigure"])
    e.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("n_objects", [[0, 5], 0, (6, 3), (1, 31), "five"])
def test_a_box_count_out_of_range_is_refused_at_make(env_id, n_objects):
    """n_objects of no box (or low > high, over 30, not integers) is refused when the env is
    made, in one line naming it and the allowed range, not by numpy deep in the scene draw."""
    with pytest.raises(ClutterbenchError, match=r"n_objects=.*1 <= low <= high <= 30") as exc:
        gym.make(env_id, n_objects=n_objects)
    assert "\n" not in str(exc.value)


def test_a_box_count_out_of_range_is_refused_as_a_reset_option_and_by_the_draw(env):
    from clutterbench.sim.labelling import draw_scene_setup

    with pytest.raises(ClutterbenchError, match=r"reset options n_objects=\[0, 5\]: .*<= 30"):
        env.reset(seed=0, options={"n_objects": [0, 5]})
    with pytest.raises(ClutterbenchError, match=r"^n_objects=\(0, 5\): .*<= 30$"):
        draw_scene_setup(0, "env", 0, {"shelved": 1.0}, (0, 5))


@pytest.mark.parametrize("env_id", MANISKILL_IDS)
@pytest.mark.parametrize("spec", [{"n": 3}, str(STACK3), STACK3], ids=["dict", "str", "path"])
def test_a_spec_of_the_wrong_type_is_refused_in_one_line(stack3, env_id, spec):
    """spec= takes a SceneSpec (SceneSpec.load(path) reads one): a dict or a path is refused
    in one line naming spec and the type expected (a TypeError too), at make and at reset."""
    from clutterbench.maniskill.tasks import SpecTypeError

    kind = type(spec).__name__
    with pytest.raises(SpecTypeError, match=rf"^spec=.* \(a {kind}\): expected a .*SceneSpec"):
        gym.make(env_id, spec=spec, target=0)
    assert issubclass(SpecTypeError, ClutterbenchError) and issubclass(SpecTypeError, TypeError)
    e = gym.make(env_id, spec=stack3, target=2)
    with pytest.raises(SpecTypeError, match=rf"^reset options spec=.* \(a {kind}\)"):
        e.reset(options={"spec": spec})
    e.close()


def test_nan_actions_are_refused(env):
    _, info = env.reset(seed=0)
    action = _random_action(env, info)
    if isinstance(action, dict):  # two arms: one action each
        action = {k: np.asarray(v, dtype=np.float64) * np.nan for k, v in action.items()}
    else:
        action = np.asarray(action, dtype=np.float64) * np.nan
    with pytest.raises(ValueError, match="NaN.*refused"):  # one line naming it
        env.step(action)


@pytest.mark.parametrize("env_id", MANISKILL_IDS)
def test_get_state_set_state_round_trips(env_id):
    """... in an episode of 10 boxes, then in one of 6 (the states keyed alike: box_0..box_29,
    one flat size), a box taken out of the scene and put back by the state; a state of the
    other episode's scene is refused in one line (never written into the arm's joints)."""
    e = gym.make(env_id)
    u = e.unwrapped
    e.reset(seed=1)
    for _ in range(3):
        e.step(e.action_space.sample())
    state, obs = u.get_state(), u.get_obs()
    keys = list(u.get_state_dict()["actors"])
    for _ in range(5):
        e.step(e.action_space.sample())
    assert not _equal(obs, u.get_obs())
    u.set_state(state)
    assert _equal(obs, u.get_obs())
    n = u.scene_spec.n
    e.reset(seed=1000)
    assert u.scene_spec.n < n
    for _ in range(2):
        e.step(e.action_space.sample())
    before = u.get_state()
    u.park(0)
    parked, obs_parked = u.get_state(), u.get_obs()
    assert parked.shape == state.shape and list(u.get_state_dict()["actors"]) == keys
    for _ in range(3):
        e.step(e.action_space.sample())
    u.set_state(before)
    assert 0 not in u.removed and not u.bodies[0].kinematic
    u.set_state(parked)
    assert 0 in u.removed and _equal(obs_parked, u.get_obs())
    with pytest.raises(ClutterbenchError, match=f"boxes 0..{n - 1};.*reset to the state"):
        u.set_state(state)
    e.close()


@pytest.fixture(scope="module")
def stack3() -> SceneSpec:
    return SceneSpec.load(STACK3)


EXTRACT_OBS_MODES = [
    "none",
    "state_dict",
    "sensor_data",
    "rgb",
    "depth",
    "segmentation",
    "rgbd",
    "rgb+depth",
    "rgb+segmentation",
    "depth+segmentation",
    "rgb+depth+segmentation",
    "pointcloud",
]
BIMANUAL_OBS_MODES = ["none", "state_dict", "sensor_data", "depth+segmentation", "pointcloud"]


def test_the_obs_mode_test_covers_every_mode_listed():
    from clutterbench.maniskill.tasks import ClutterShelfEnv

    assert {"state", *EXTRACT_OBS_MODES} == set(ClutterShelfEnv.SUPPORTED_OBS_MODES)


@pytest.mark.parametrize(
    "env_id, obs_mode",
    [("ClutterShelfExtract-v1", m) for m in EXTRACT_OBS_MODES]
    + [("ClutterShelfBimanual-v1", m) for m in BIMANUAL_OBS_MODES],
)
def test_every_obs_mode_builds_and_steps(env_id, obs_mode):
    """(state: the default, covered above.) On a hand-built 3-stack, as `spec=` still works:
    every mode the task lists with one arm, one of each kind with two."""
    e = gym.make(env_id, spec=SceneSpec.load(STACK3), target=2, obs_mode=obs_mode)
    assert obs_mode in e.unwrapped.SUPPORTED_OBS_MODES
    e.reset(seed=0)
    for _ in range(2):
        obs, *_ = e.step(e.action_space.sample())
    if obs_mode == "sensor_data":
        assert all(v.numel() for v in obs["sensor_data"]["shelf_camera"].values())
    elif obs_mode not in ("none", "state_dict", "pointcloud"):  # the textures asked for
        cam = obs["sensor_data"]["shelf_camera"]
        want = set(obs_mode.replace("rgbd", "rgb+depth").split("+"))  # and only those
        assert set(cam) == want
        assert all(int(cam[k].max()) > 0 for k in want)
    if obs_mode == "pointcloud":
        cloud = obs["pointcloud"]
        assert int(cloud["segmentation"].max()) > 0 and bool((cloud["xyzw"][..., 3] > 0).any())
    e.close()


def test_other_obs_modes_are_refused_with_maniskills_error(stack3):
    with pytest.raises(NotImplementedError, match="Unsupported obs mode: normal"):
        gym.make("ClutterShelfExtract-v1", spec=stack3, obs_mode="normal")


@pytest.mark.parametrize("env_id", MANISKILL_IDS)
@pytest.mark.parametrize(
    "control_mode", ["pd_joint_delta_pos", "pd_joint_pos", "pd_ee_delta_pos", "pd_ee_delta_pose"]
)
def test_the_standard_control_modes_step(stack3, env_id, control_mode):
    e = gym.make(env_id, spec=stack3, target=2, control_mode=control_mode)
    got = e.unwrapped.control_mode  # two arms: one mode per arm uid
    assert set(got.values() if isinstance(got, dict) else [got]) == {control_mode}
    e.reset(seed=0)
    for _ in range(2):
        obs, reward, *_ = e.step(e.action_space.sample())
    assert bool(obs.isfinite().all()) and bool(reward.isfinite().all())
    e.close()


@pytest.mark.parametrize("env_id", MANISKILL_IDS)
def test_rgb_array_and_sensors_render_and_a_video_is_recorded(stack3, env_id, tmp_path):
    """With defaults but the picture's size: render_mode rgb_array (the render camera) and
    sensors (the shelf camera) on the CPU, and ManiSkill's RecordEpisode writes the video."""
    from mani_skill.utils.wrappers.record import RecordEpisode

    small = dict(width=48, height=48)
    e = gym.make(env_id, spec=stack3, target=2, render_mode="sensors", sensor_configs=small)
    e.reset(seed=0)
    picture = e.render()  # the shelf camera's pictures side by side
    assert picture.shape[:2] == (1, 48) and picture.shape[3] == 3 and float(picture.max()) > 0
    e.close()
    e = gym.make(
        env_id, spec=stack3, target=2, render_mode="rgb_array", human_render_camera_configs=small
    )
    e = RecordEpisode(e, str(tmp_path), save_trajectory=False, video_fps=5)
    e.reset(seed=0)
    frame = e.render()
    assert tuple(frame.shape) == (1, 48, 48, 3) and float(frame.float().std()) > 1.0
    for _ in range(3):
        e.step(e.action_space.sample())
    e.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0


def test_success_and_fail_robot_uids_and_num_envs(stack3):
    """evaluate() gives `success` and `fail` (ManiSkill: either ends the episode); a reset
    that reconfigures gives the same start; the task's own robot_uids is accepted, another
    refused in one line, as num_envs > 1 (make_vec)."""
    e = gym.make("ClutterShelfExtract-v1", spec=stack3, target=2)
    obs, info = e.reset(seed=0)
    assert {"success", "fail"} <= set(info) and not bool(info["fail"].any())
    again, _ = e.reset(seed=0, options={"reconfigure": True})
    assert _equal(obs, again)
    uid = e.unwrapped.robot_uids
    e.close()
    gym.make("ClutterShelfExtract-v1", spec=stack3, target=2, robot_uids=uid).close()
    with pytest.raises(ClutterbenchError, match="robot_uids='panda'.*leave robot_uids out"):
        gym.make("ClutterShelfExtract-v1", spec=stack3, robot_uids="panda")
    with pytest.raises(ClutterbenchError, match="num_envs=2.*make_vec"):
        gym.make("ClutterShelfExtract-v1", spec=stack3, num_envs=2)


def test_the_arm_ids_draw_the_streams_envs_plugs_in_and_refuse_without_a_source(monkeypatch):
    """`import clutterbench.envs` plugs the pipeline's streams into the ManiSkill tasks (the arm
    level names nothing of the trials); with no source plugged in and none passed, a spec-less
    arm env is refused in one line that says where a source comes from."""
    from clutterbench.maniskill import tasks
    from clutterbench.trials.sources import stream_source

    assert tasks.resolve_scene_source(None) is stream_source
    monkeypatch.setattr(tasks, "_default_scene_source", None)
    with pytest.raises(ClutterbenchError, match="import clutterbench.envs") as err:
        gym.make("ClutterShelfExtract-v1")
    assert "\n" not in str(err.value)


VEC_SCRIPT = """
import sys
import gymnasium as gym
import clutterbench.envs
from clutterbench.sim.spec import SceneSpec
from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper

spec = SceneSpec.load(sys.argv[1])
for env_id, kwargs in (
    ("ClutterShelfPlan-v1", dict(scale="tiny")),
    ("ClutterShelfExtract-v1", dict(spec=spec, target=2, wrappers=[CPUGymWrapper])),
    ("ClutterShelfBimanual-v1", dict(spec=spec, target=2, wrappers=[CPUGymWrapper])),
):
    v = gym.make_vec(env_id, num_envs=2, vectorization_mode="async", **kwargs)
    v.action_space.seed(0)
    obs, info = v.reset(seed=[2, 3])
    action = v.action_space.sample()
    if env_id == "ClutterShelfPlan-v1":
        action[:] = 30  # NO_BOX: give up (no pull to wait for)
    obs, reward, terminated, truncated, info = v.step(action)
    assert reward.shape == terminated.shape == truncated.shape == (2,), env_id
    if env_id == "ClutterShelfPlan-v1":
        assert obs["depth_m"].shape[0] == 2 and terminated.all()
    else:
        assert obs.shape == (2, *v.single_observation_space.shape), obs.shape
    v.close()
    print("ok", env_id)
"""


def test_make_vec_async_runs_two_envs_of_every_id():
    """gym.make_vec(id, num_envs=2, vectorization_mode="async") from a fresh process (one env
    per worker process; the ManiSkill tasks with CPUGymWrapper: numpy, unbatched), as
    docs/environments.md shows."""
    import subprocess
    import sys

    assert NO_BOX == 30  # as the script gives up
    run = subprocess.run(
        [sys.executable, "-c", VEC_SCRIPT, str(STACK3)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    want = [PLAN_ENV_ID, "ClutterShelfExtract-v1", "ClutterShelfBimanual-v1"]
    assert run.stdout.split() == [w for env_id in want for w in ("ok", env_id)]


DOCS_VEC_SCRIPT = """
import gymnasium as gym
import clutterbench.envs
from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper

for env_id in ("ClutterShelfExtract-v1", "ClutterShelfBimanual-v1"):
    arm = gym.make_vec(env_id, num_envs=2, vectorization_mode="async",
                       wrappers=[CPUGymWrapper])
    obs, info = arm.reset(seed=[2, 3])
    assert list(info["scene_source"]) == ["benchmark"] * 2, info["scene_source"]
    obs, reward, terminated, truncated, info = arm.step(arm.action_space.sample())
    assert obs.shape == (2, *arm.single_observation_space.shape), obs.shape
    arm.close()
    print("ok", env_id)
"""


def test_the_docs_make_vec_snippet_runs_for_the_arm_ids_drawing_scenes():
    """docs/environments.md's make_vec of the arm ids as written (no spec: the env draws its
    scenes from the stream; gymnasium makes one env in the parent before forking the
    workers): making an env renders nothing, so the forked workers may render."""
    import subprocess
    import sys

    run = subprocess.run(
        [sys.executable, "-c", DOCS_VEC_SCRIPT], capture_output=True, text=True, timeout=400
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["ok", "ClutterShelfExtract-v1", "ok", "ClutterShelfBimanual-v1"]


def test_a_worker_forked_after_rendering_is_refused_in_one_line():
    """SAPIEN's renderer does not survive a fork (the child hangs): a forked child refuses
    to render, naming spawn / forkserver, instead of hanging."""
    import os

    from clutterbench.sim.renderer import ensure_renderer

    ensure_renderer()
    pid = os.fork()
    if pid == 0:  # the child: refuse at once, never render
        try:
            ensure_renderer()
        except ClutterbenchError as exc:
            os._exit(7 if "forkserver" in str(exc) and "\n" not in str(exc) else 1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 7
    ensure_renderer()  # the parent renders on


FORK_AFTER_RENDER_SCRIPT = """
import sys
import gymnasium as gym
import clutterbench.envs
from clutterbench.sim.renderer import ensure_renderer
from clutterbench.sim.spec import SceneSpec

if sys.argv[1] == "rendered":  # the parent rendered, then forks (gymnasium's default)
    ensure_renderer()
    gym.make_vec("ClutterShelfPlan-v1", num_envs=2, vectorization_mode="async", scale="tiny")
else:  # the env gymnasium makes in the parent opens a camera, then forks
    spec = SceneSpec.load(sys.argv[2])
    gym.make_vec("ClutterShelfExtract-v1", num_envs=2, vectorization_mode="async",
                 spec=spec, target=2, obs_mode="depth")
print("workers started")
"""


def test_a_vector_env_forking_after_rendering_is_refused_in_one_line():
    """gym.make_vec(..., "async") forks its workers by default; from a process that holds the
    renderer (it rendered, or the env made in the parent opened a camera) it is refused in
    the parent before any worker starts: the user sees our one line (naming spawn and
    forkserver) as the error, and no worker's trace (gymnasium printed each worker's, some
    40 lines, or, when a worker refused while being made, only a broken pipe)."""
    import subprocess
    import sys

    runs = [
        subprocess.Popen(
            [sys.executable, "-c", FORK_AFTER_RENDER_SCRIPT, case, str(STACK3)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for case in ("rendered", "camera")
    ]
    for run in runs:
        out, err = run.communicate(timeout=300)
        lines = err.strip().splitlines()
        assert run.returncode == 1 and "workers started" not in out, err[-2000:]
        assert lines[-1].startswith("clutterbench.errors.ClutterbenchError: "), err[-2000:]
        assert "spawn or forkserver" in lines[-1]
        assert err.count("Traceback") == 1 and "Worker" not in err, err[-2000:]
        assert sum("forkserver" in line for line in lines) == 1  # the message: one line


def test_the_fork_refusal_reads_how_the_vector_env_starts_its_workers():
    """The refusal applies only to workers started by fork (a spawned or forkserver worker
    imports afresh and makes its own renderer), and to nothing made outside a vector env;
    reading multiprocessing's default does not fix it."""
    import multiprocessing

    from gymnasium.vector import AsyncVectorEnv

    from clutterbench.maniskill.tasks import _start_method_of_vector_env

    class Probe(AsyncVectorEnv):
        def __init__(self, context):  # the frame gymnasium's own __init__ is read from
            self.method = _start_method_of_vector_env()

    for context in ("fork", "forkserver", "spawn"):
        assert Probe(context).method == context
    default = multiprocessing.get_start_method(allow_none=True)
    assert Probe(None).method == (default or multiprocessing.get_all_start_methods()[0])
    assert multiprocessing.get_start_method(allow_none=True) == default
    assert _start_method_of_vector_env() is None


def test_dense_reward_is_target_progress_minus_the_others_displacement(physics):
    import sapien

    spec = SceneSpec.load(STACK3)
    e = gym.make("ClutterShelfExtract-v1", spec=spec, target=2, reward_mode="dense")
    e.reset(seed=0)
    u = e.unwrapped

    def reward() -> float:
        info = u.evaluate()
        return float(u.compute_dense_reward(None, None, info).item())

    assert reward() == pytest.approx(0.0, abs=1e-6)
    top = spec.poses[2]
    u.bodies[2].entity.set_pose(sapien.Pose(top[:3] - [u.target_back0_m / 2, 0, 0], top[3:]))
    assert reward() == pytest.approx(0.5, abs=1e-3)  # half way out, nothing else moved
    mid = spec.poses[1]
    assert not bool(u.evaluate()["fail"])
    u.bodies[1].entity.set_pose(sapien.Pose(mid[:3] + [0, 0.1, 0], mid[3:]))
    assert reward() == pytest.approx(0.0, abs=1e-3)  # one of the two others moved: -1/2
    assert bool(u.evaluate()["fail"])  # another box moved: the episode has failed
    u.park(2)
    u.bodies[1].entity.set_pose(sapien.Pose(mid[:3], mid[3:]))
    assert reward() == pytest.approx(2.0, abs=1e-3)  # out, the others still: success
    assert float(u.compute_normalized_dense_reward(None, None, u.evaluate()).item()) == (
        pytest.approx(1.0, abs=1e-3)
    )
    e.close()


@pytest.fixture(scope="module")
def plan_env():
    e = gym.make(PLAN_ENV_ID)
    yield e
    e.close()


# Committed episodes with no abort (an abort needs the planner's monitor) that end by the env's
# own rule (the target out, or a collapse; giving up is a planner's, not the env's): several
# steps, strict and not, a collapse, a hold. Their starts are the benchmark scenes on every CPU;
# the actions' physics differs between CPUs by micrometres (the trials stage reproduces
# records only so on another CPU), so the outcome is compared, not the bits, and each episode
# was picked with every box's displacement, drop and tilt at least ~75% of its threshold away
# from it (bimanual 137: 56%, the best such collapse in the records; an outcome another CPU
# cannot flip).
REPLAYED = [
    ("multi_step", 101),  # three clean steps
    ("multi_step", 16),  # three steps, collapse-free but not strict
    ("multi_step", 66),  # a collapse at the third step
    ("bimanual", 129),  # two steps with a hold, clean
    ("bimanual", 91),  # two steps with a hold, not strict
    ("bimanual", 137),  # three steps with a hold, a collapse
]
OUTCOME = [k for k in STEP_FIELDS if k != "box_motion"] + [
    "box",
    "hold",
    "increments",
    "n_disturbed",
]


@pytest.mark.parametrize("condition, episode", REPLAYED)
def test_the_plan_env_replays_a_committed_episode(plan_env, condition, episode):
    """The committed record's decisions (pull, hold), fed to the planning env, give the
    record's steps (every named outcome) and the episode's end under both criteria."""
    rec = _records(condition)[episode]
    obs, info = plan_env.reset(seed=episode)
    assert int(obs["target"]) == rec["target"]
    done = False
    for want in rec["steps"]:
        assert not done
        hold = NO_BOX if want["hold"] is None else want["hold"]
        obs, reward, terminated, truncated, info = plan_env.step((want["box"], hold))
        assert {k: info["step"][k] for k in OUTCOME} == {k: want[k] for k in OUTCOME}
        assert {k: info[k] for k in STEP_FIELDS} == {k: info["step"][k] for k in STEP_FIELDS}
        done = terminated or truncated
        if not done:  # the next decision's view: the box taken out is gone from it
            assert not (obs["instance"] == want["box"] + 1).any()
    assert terminated and info["end"] == rec["end"]
    assert reward == float(rec["success"])
    mine = plan_env.unwrapped.episode_result().record
    keys = ("end", "success", "strict_success", "counted_steps", "strict_steps")
    assert {k: mine[k] for k in keys} == {k: rec[k] for k in keys}
    # records before the pull-outcome labels named it target_out
    assert mine["target_extracted"] == rec.get("target_extracted", rec.get("target_out"))


def test_giving_up_ends_the_episode(plan_env):
    plan_env.reset(seed=2)
    *_, terminated, truncated, info = plan_env.step((NO_BOX, NO_BOX))
    assert terminated and not truncated and info["end"] == "gave_up"
    assert plan_env.unwrapped.episode_result().record["steps"] == []


def test_actions_naming_no_box_of_the_scene_are_no_ops(plan_env):
    """Every action of the space is valid: one naming a box the scene does not have (or
    holding the pulled box) changes nothing and says why; a malformed one is refused."""
    obs, _ = plan_env.reset(seed=2)
    n = plan_env.unwrapped.episode.spec.n
    for action, why in (((n, NO_BOX), "not a box in the scene"), ((0, 0), "hold 0")):
        again, reward, terminated, truncated, info = plan_env.step(action)
        assert why in info["invalid_action"] and info["end"] is None
        assert (reward, terminated, truncated) == (0.0, False, False) and _equal(obs, again)
    for bad in ((NO_BOX + 1, NO_BOX), (-1, NO_BOX), (0.5, NO_BOX), (0,)):
        with pytest.raises(ActionError, match="action"):
            plan_env.step(bad)


def test_the_plan_env_passes_gymnasiums_check_env():
    """check_env (warnings are errors): random actions of the whole space, finite bounds,
    seeded determinism, render_mode rgb_array."""
    import warnings

    from gymnasium.utils.env_checker import check_env

    e = gym.make(PLAN_ENV_ID, scale="tiny", render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(e.unwrapped)
    e.reset(seed=0)
    assert e.render().shape == (*e.observation_space["depth_m"].shape, 3)
    e.close()


class _AbortAfterFirstIncrement:
    """Pull the target; its collapse score is 0 on the observation it decided on and 1 on
    every later one, so each pull aborts after one increment (the monitor's path)."""

    cp_max = 0.5

    def decide(self, obs, target, blocked):
        from clutterbench.planning.ch6.extraction import Decision

        self.seen = obs
        return Decision(target, None, {"policy": "toy_abort"})

    def collapse_score(self, obs, box, hold=None):
        return 0.0 if obs is self.seen else 1.0

    # the same as an agent of the planning env
    def act(self, obs):
        self.seen = obs
        return int(obs["target"]), NO_BOX


def _trials_records(env, planner: str, episodes: int, support, cp_max: float, cp: Path):
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import ch6_jobs, run_ch6_episode
    from clutterbench.trials.config import ConditionConfig

    src = env.unwrapped.source
    cond = ConditionConfig(planner=planner, stream=src.name, episodes=episodes, rule="coverage")
    jobs = ch6_jobs(
        planner,
        cond,
        trials=src.trials,
        sim=SimConfig(physics=src.physics, camera=src.camera),
        seed=src.seed,
        support=support,
        cp_max=cp_max,
        model_path=cp,
        stream_cfg=src.cfg,
    )
    return [run_ch6_episode(dataclasses.replace(j, record_images=False)).record for j in jobs]


def _same_records(got, want):
    drop = {"rule", "support_method"}  # the agent's record does not know its support rule
    assert [{k: v for k, v in r.items() if k not in drop} for r in got] == [
        {k: v for k, v in r.items() if k not in drop} for r in want
    ]


@pytest.mark.parametrize(
    ("planner", "prob_threshold"),
    [("multi_step", 0.5), ("multi_step", 0.4), ("multi_step_pull", 0.5), ("bimanual_pull", 0.4)],
)
def test_a_cp_planner_as_an_agent_gives_the_trials_records(
    planner, prob_threshold, tiny_cp, tiny_cp_three_heads
):
    """evaluate-agent's loop with the project's CP planners wrapped as agents writes, on the
    tiny profile, exactly the records the trials stage writes for that planner (the same
    scenes, targets, decisions and outcomes, bit for bit; collapses at 0.5, give-ups at 0.4);
    the *_pull agents on a three-head network's head of trials.ch6.pull_map_meaning, as the
    trials stage's *_pull rows."""
    from clutterbench.envs.agents import PlannerAgent
    from clutterbench.envs.evaluate import run_agent
    from clutterbench.parallel import worker_init
    from clutterbench.planning.ch6.support import SupportParams

    worker_init(1)
    support = SupportParams("coverage", prob_threshold, 0.3, 2, 0.0)
    cp = tiny_cp_three_heads if planner.endswith("_pull") else tiny_cp
    env = gym.make(PLAN_ENV_ID, scale="tiny", name=planner)
    agent = PlannerAgent(env, planner, rule="coverage", support=support, cp_max=0.5, model_path=cp)
    got = [r.record for r in run_agent(env, agent, range(3))]
    want = _trials_records(env, planner, 3, support, 0.5, cp)
    _same_records(got, want)
    assert {r["end"] for r in got} >= {"target_out"}
    env.close()


def test_a_monitored_pull_aborts_in_the_env_as_in_the_trials():
    """A policy's collapse score stops its pull in the env exactly as the trials' monitor
    stops a planner's (aborted after motion, blocked, the episode goes on)."""
    from clutterbench.envs.evaluate import run_agent
    from clutterbench.trials.ch6.episodes import PLANNERS, register_planner

    if "toy_abort" not in PLANNERS:
        register_planner("toy_abort")(lambda job, spec: _AbortAfterFirstIncrement())
    env = gym.make(PLAN_ENV_ID, scale="tiny", name="toy_abort")
    got = [r.record for r in run_agent(env, _AbortAfterFirstIncrement(), range(1))]
    want = _trials_records(env, "toy_abort", 1, None, 0.5, Path("unused"))
    _same_records(got, want)
    steps = got[0]["steps"]
    assert steps[0]["aborted_after_motion"] and steps[0]["increments"] == 1
    env.close()
