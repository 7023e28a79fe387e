"""Stage trials_arm: kinematic conditions repeated arm-level (trials.arm_conditions): the same
planner on the same scenes and targets, each pull executed by Pandas in a ManiSkill scene
(trials.arm) instead of moving the box kinematically, judged by the same judge -> per
condition reports/trials_arm/<condition>/records.jsonl (one record per episode, with the arms'
outcome of every step) and summary.json, and data/trials_arm/<condition>/episodes.mcap (the
arms' joint states beside the boxes). The report compares each with its kinematic row,
episode by episode (reports/tables/arm_vs_kinematic.md)."""

import dataclasses
import time
from pathlib import Path

import numpy as np

from clutterbench.config import BaseConfig, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig
from clutterbench.precision import inference_from_params
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.arm.episodes import run_arm_episode
from clutterbench.trials.ch4.episodes import ch4_jobs
from clutterbench.trials.ch6.episodes import condition_jobs, load_planners
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import run_episodes, write_condition

THRESHOLDS = Path("reports/support/thresholds.json")
OUT = Path("reports/trials_arm")
DATA = Path("data/trials_arm")


def trials_arm(params: dict, base: BaseConfig) -> None:
    cfg = load_section(TrialsConfig, "trials", params)
    if not cfg.arm_conditions:
        raise ClutterbenchError("trials.arm_conditions: no conditions to run")
    sim = load_section(SimConfig, "sim", params)
    precision = inference_from_params(params)
    jobs, about = [], {}
    for name, arm in cfg.arm_conditions.items():
        if arm.of in cfg.conditions:
            cond = dataclasses.replace(
                cfg.conditions[arm.of], executor="arm", episodes=arm.episodes
            )
            load_planners(cfg.planner_modules, [cond.planner])
            mine, _, _ = condition_jobs(
                name, cond, trials=cfg, sim=sim, seed=base.seed, thresholds=THRESHOLDS
            )
            chapter = 6
        else:
            cond = dataclasses.replace(
                cfg.ch4_conditions[arm.of], executor="arm", episodes=arm.episodes
            )
            if cond.model is not None and not Path(f"models/{cond.model}/best.pt").exists():
                raise ClutterbenchError(
                    f"models/{cond.model}/best.pt missing; run train@{cond.model}"
                )
            mine = ch4_jobs(name, cond, trials=cfg, sim=sim, seed=base.seed, arm=cfg.arm)
            chapter = 4
        jobs += mine
        about[name] = {
            "condition": name,
            "of": arm.of,
            "chapter": chapter,
            "planner": cond.planner,
            "stream": cond.stream,
            "executor": "arm",
            "scale": base.scale,
            "network_precision": precision,
        }
    parallel = load_section(ParallelConfig, "parallel", params)
    start = time.perf_counter()
    results = run_episodes("trials_arm", run_arm_episode, jobs, cfg.workers, parallel)
    wall = time.perf_counter() - start
    per_episode = [r.wall_s for r in results if r.wall_s is not None]
    for name in cfg.arm_conditions:
        summary = write_condition(name, results, about[name], OUT, DATA)
        print(
            f"{name} (arm-level {about[name]['of']}): "
            f"{summary['success_k']}/{summary['success_n']} succeeded"
        )
    # Wall time is the machine's, not the result's: printed, never written to the outputs.
    print(
        f"trials_arm: {len(results)} episodes in {wall:.0f} s on {cfg.workers} workers "
        f"(median episode {np.median(per_episode):.1f} s, max {np.max(per_episode):.1f} s)"
    )


if __name__ == "__main__":
    run_stage(trials_arm)
