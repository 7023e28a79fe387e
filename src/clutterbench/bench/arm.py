"""`make bench`, arm part: the costs of an arm-level step -> reports/bench/arm.{json,md}.

Measured in one process (one core, the worker setting) on trial scenes of the ch. 6 stream
ch6_3_10 at default scale: making the ManiSkill env (once per worker), one step's scene
rebuild (reconfigure), one straight approach planned (no motion), a whole one-arm pull of an
accessible front box (approach, pull out, go back, settle: what a trial step costs), the
same with the two-arm env, and the kinematic pull of the same box for comparison; plus the
simulated seconds of arm motion per step (20 control steps a simulated second).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from clutterbench.bench import header, measure_table, write_result
from clutterbench.config import load_params, load_section
from clutterbench.platform_info import cpu_description

N_SCENES = 10
STREAM = "ch6_3_10"


def _front_box(spec) -> int:
    """An accessible box: the one nearest the opening, preferring high ones (a planner's
    first pull in a pile is usually such a box)."""
    return int(np.argmin(spec.poses[:, 0] - 0.2 * spec.poses[:, 2]))


def bench_arm(out_dir: Path = Path("reports/bench")) -> dict:
    import torch

    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.maniskill.executor import ArmExecutor
    from clutterbench.maniskill.motion import face_pose, plan_line
    from clutterbench.parallel import worker_init
    from clutterbench.sim.config import SimConfig
    from clutterbench.sim.pull import SceneState, execute_pull, world_at
    from clutterbench.trials.config import TrialsConfig

    params = load_params("params.yaml")
    params = {**params, "base": {**params["base"], "scale": "default"}}
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    worker_init(1)
    torch.set_num_threads(1)
    specs = [
        draw_trial_spec(
            STREAM, trials.streams[STREAM], 0, i, sim.physics, sim.camera, trials.max_attempts
        )
        for i in range(N_SCENES)
    ]
    inc, lift = trials.ch6.pull_increment_m, trials.ch6.grasp_lift_m
    t0 = time.perf_counter()
    one = ArmExecutor(sim.physics, trials.arm, bimanual=False)
    one._start(specs[0], SceneState.start(specs[0]), 0, None)
    make_s = time.perf_counter() - t0

    def timed(fn) -> tuple[float, list]:
        out, t = [], time.perf_counter()
        for spec in specs:
            out.append(fn(spec))
        return (time.perf_counter() - t) / len(specs), out

    rebuild_s, _ = timed(lambda s: one._start(s, SceneState.start(s), _front_box(s), None))

    def plan(spec):
        one._start(spec, SceneState.start(spec), _front_box(spec), None)
        face = one.u.front_face_m(_front_box(spec))
        face[0] = min(face[0], 0.0) - trials.arm.entry_clearance_m
        return plan_line(one.planners[0], face_pose(face, 0.0), one._qpos(0), one.dt_s, True)[0]

    plan_s, _ = timed(plan)
    pull_s, steps = timed(
        lambda s: one.execute_pull(s, SceneState.start(s), _front_box(s), None, inc, lift)[1]
    )
    two = ArmExecutor(sim.physics, trials.arm, bimanual=True)
    two._start(specs[0], SceneState.start(specs[0]), 0, None)
    pull2_s, _ = timed(
        lambda s: two.execute_pull(s, SceneState.start(s), _front_box(s), None, inc, lift)[1]
    )
    kin_s, _ = timed(
        lambda s: execute_pull(
            world_at(s, SceneState.start(s), sim.physics), _front_box(s), None, inc, lift
        )
    )
    result = {
        **cpu_description(),
        "scenes": N_SCENES,
        "make_env_s": make_s,
        "scene_rebuild_s": rebuild_s,
        "plan_approach_s": plan_s,
        "arm_pull_step_s": pull_s,
        "arm_pull_step_two_arms_s": pull2_s,
        "kinematic_pull_step_s": kin_s,
        "arm_over_kinematic": pull_s / kin_s,
        "simulated_arm_s_per_step": float(np.mean([s.control_steps * one.dt_s for s in steps])),
        "arm_steps_ok": sum(s.outcome == "ok" for s in steps),
    }
    md = header("Arm-level execution costs, one core (ch. 6 trial scenes)", result)
    write_result(out_dir, "arm", result, md + measure_table(result, tuple(cpu_description())))
    for k, v in result.items():
        print(f"{k}: {v}")
    return result
