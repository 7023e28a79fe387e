"""Stage trials: the chapter 6 extraction trials of every condition (thesis Table 6.3; the
opt-in ones only when trials.opt_in.run, make repro-full) in one pool of workers -> per
condition reports/trials/<condition>/records.jsonl (one record per episode) and summary.json,
and data/trials/<condition>/episodes.mcap.

One stage, not one per condition: an episode takes about a second, so starting the workers
(torch, a renderer, the networks) once for all conditions saves most of the overhead, and
one pool keeps both cores busy to the end."""

import sys
from pathlib import Path

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.parallel import ParallelConfig
from clutterbench.precision import inference_from_params
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch6.episodes import condition_jobs, load_planners, run_ch6_episode
from clutterbench.trials.ch6.planners import planner_info
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import run_episodes, write_condition

THRESHOLDS = Path("reports/support/thresholds.json")
OUT = Path("reports/trials")
DATA = Path("data/trials")
FIGURE_SCENES = 4


def trials(params: dict, base: BaseConfig) -> None:
    cfg = load_section(TrialsConfig, "trials", params)
    only = sys.argv[1:]  # optional: run only these (debugging; dvc: all but the opt-in ones)
    conditions = cfg.stage_conditions(only)
    if not conditions:
        raise ClutterbenchError("trials.conditions: no conditions to run")
    load_planners(cfg.planner_modules, [c.planner for c in cfg.conditions.values()])
    planner_of = {n: c.planner for n, c in cfg.conditions.items()}
    if problem := cfg.opt_in.role_problem(planner_of, lambda p: planner_info(p).role):
        raise ClutterbenchError(f"trials.{problem}")
    if cfg.opt_in.skipped and not only:
        print(f"not run (opt-in, make repro-full runs them): {', '.join(cfg.opt_in.skipped)}")
    sim = load_section(SimConfig, "sim", params)
    precision = inference_from_params(params)
    jobs, about = [], {}
    for name, cond in conditions.items():
        mine, support, cp_max = condition_jobs(
            name, cond, trials=cfg, sim=sim, seed=base.seed, thresholds=THRESHOLDS
        )
        jobs += mine
        about[name] = {
            "condition": name,
            "planner": cond.planner,
            "stream": cond.stream,
            "rule": cond.rule,
            "scale": base.scale,
            "network_precision": precision,
            "cp_max": cp_max,
            "support": as_dict(support),
        }
        if (cond.sensing, cond.perception) != ("ideal", "instance"):  # as its records say
            about[name] |= {"sensing": cond.sensing, "perception": cond.perception}
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("trials", run_ch6_episode, jobs, cfg.workers, parallel)
    pfd = [c for c in conditions.values() if planner_info(c.planner).world == "fitted"]
    if pfd:  # estimated vs true boxes of a few scenes of the first such stream
        from clutterbench.trials.ch6.box_figure import estimate_panels, estimation_figure

        panels = estimate_panels(
            pfd[0].stream,
            cfg.streams[pfd[0].stream],
            base.seed,
            list(range(min(FIGURE_SCENES, pfd[0].episodes))),
            sim.physics,
            sim.camera,
            cfg.max_attempts,
            cfg.ch6.min_pixels,
        )
        estimation_figure(panels, OUT / "box_estimation.png")
    for name in conditions:
        summary = write_condition(name, results, about[name], OUT, DATA)
        print(
            f"{name}: episodes {summary['success_k']}/{summary['success_n']} succeeded, "
            f"steps {summary.get('step_success_k')}/{summary.get('step_success_n')}, "
            f"mean steps {summary.get('mean_steps', float('nan')):.2f}"
        )


if __name__ == "__main__":
    run_stage(trials)
