"""`make bench`, envs part: every registered environment made with defaults, reset(seed) and
stepped 5 random steps, each in a fresh process on one core -> reports/bench/envs.{json,md}.

What a newcomer's first `gym.make(id); env.reset(seed=0); env.step(...)` costs: the import
(torch, SAPIEN, ManiSkill), the make (ManiSkill: the robots, the scene, inverse kinematics of
the ready pose), the reset (the stream's scene drawn and settled, the first picture, whose
shaders compile once per process) and 5 random steps (the planning env: 5 protocol steps,
each a pull, a release and a settle, or an episode's end and the next reset). Target: make +
reset + 5 steps < 10 s per id.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from pathlib import Path
from typing import Any

from clutterbench.bench import header, write_result
from clutterbench.platform_info import cpu_description

SEED = 0
TARGET_S = 10.0


def _one(env_id: str) -> dict[str, Any]:
    """In a fresh process on one core: the costs of env `env_id` with defaults."""
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    t0 = time.perf_counter()
    import gymnasium as gym
    import torch

    import clutterbench.envs  # noqa: F401  (registers them)
    from clutterbench.envs import NO_BOX, PLAN_ENV_ID

    torch.set_num_threads(1)
    t1, c1 = time.perf_counter(), time.process_time()
    env = gym.make(env_id)
    t2 = time.perf_counter()
    _, info = env.reset(seed=SEED)
    t3 = time.perf_counter()
    env.action_space.seed(SEED)
    for _ in range(5):
        if env_id == PLAN_ENV_ID:
            pull, hold = env.action_space.sample(mask=info["action_mask"])
            action = (pull, NO_BOX if hold == pull else hold)
        else:
            action = env.action_space.sample()
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            _, info = env.reset()
    t4, c4 = time.perf_counter(), time.process_time()
    env.close()
    return {
        "import_s": t1 - t0,
        "make_s": t2 - t1,
        "reset_s": t3 - t2,
        "five_steps_s": t4 - t3,
        "make_reset_steps_s": t4 - t1,
        "make_reset_steps_cpu_s": c4 - c1,
        "load_average_1min": os.getloadavg()[0],
    }


def bench_envs(out_dir: Path = Path("reports/bench")) -> dict:
    from clutterbench.envs import ENV_IDS

    ctx = mp.get_context("spawn")
    per_id = {}
    for env_id in ENV_IDS:
        with ctx.Pool(1) as pool:
            per_id[env_id] = pool.apply(_one, (env_id,))
        print(env_id, {k: round(v, 2) for k, v in per_id[env_id].items()})
    result = {
        **cpu_description(),
        "torch_threads": 1,
        "seed": SEED,
        "target_s": TARGET_S,
        "envs": per_id,
        "all_within_target": all(v["make_reset_steps_s"] < TARGET_S for v in per_id.values()),
        "all_cpu_within_target": all(
            v["make_reset_steps_cpu_s"] < TARGET_S for v in per_id.values()
        ),
    }
    md = header("Environments with defaults: make, reset(seed), 5 random steps (one core)", result)
    md += [
        "Each id in a fresh process pinned to one core (its first picture compiles the "
        f"shaders); target: make + reset + 5 steps < {TARGET_S:g} s. CPU s: the process's "
        "CPU time over the same span (all its threads; what it costs a core whatever else "
        "runs), beside the machine's 1-minute load average.",
        "",
        "| env id | import (s) | make (s) | reset (s) | 5 steps (s) | make + reset + 5 steps "
        "(s) | the same, CPU s | load |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for env_id, v in per_id.items():
        md.append(
            f"| {env_id} | {v['import_s']:.2f} | {v['make_s']:.2f} | {v['reset_s']:.2f} | "
            f"{v['five_steps_s']:.2f} | {v['make_reset_steps_s']:.2f} | "
            f"{v['make_reset_steps_cpu_s']:.2f} | {v['load_average_1min']:.1f} |"
        )
    write_result(out_dir, "envs", result, md)
    return result
