"""Stage trials: the chapter 6 extraction trials of every condition (thesis Table 6.3) in one
pool of workers -> per condition reports/trials/<condition>/records.jsonl (one record per
episode) and summary.json, and data/trials/<condition>/episodes.mcap.

One stage, not one per condition: an episode takes about a second, so starting the workers
(torch, a renderer, the networks) once for all conditions saves most of the overhead, and
one pool keeps both cores busy to the end."""

import sys
from pathlib import Path

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch6 import ch6_jobs, chosen_support, load_planners, run_ch6_episode
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.harness import run_episodes, write_mcap
from clutterbench.trials.records import write_records
from clutterbench.trials.stats import aggregate

THRESHOLDS = Path("reports/support/thresholds.json")
OUT = Path("reports/trials")
DATA = Path("data/trials")


def trials(params: dict, base: BaseConfig) -> None:
    cfg = load_section(TrialsConfig, "trials", params)
    only = sys.argv[1:]  # optional: run only these conditions (debugging; dvc runs them all)
    unknown = [n for n in only if n not in cfg.conditions]
    if unknown:
        raise ClutterbenchError(
            f"trials.conditions.{unknown[0]}: no such condition "
            f"(known: {', '.join(cfg.conditions)})"
        )
    conditions = {n: c for n, c in cfg.conditions.items() if not only or n in only}
    if not conditions:
        raise ClutterbenchError("trials.conditions: no conditions to run")
    load_planners(cfg.planner_modules, [c.planner for c in conditions.values()])
    sim = load_section(SimConfig, "sim", params)
    for model in {cfg.ch6.model, cfg.ch6.ch4_model}:
        if not Path(f"models/{model}/best.pt").exists():
            raise ClutterbenchError(f"models/{model}/best.pt missing; run train@{model}")
    jobs, about = [], {}
    for name, cond in conditions.items():
        support = chosen_support(THRESHOLDS, cond.rule)
        cp_max = cfg.ch6.cp_max if cfg.ch6.cp_max is not None else support.score_threshold
        jobs += ch6_jobs(
            name,
            cond,
            cfg,
            cfg.streams[cond.stream],
            base.seed,
            sim.physics,
            sim.camera,
            support,
            cp_max,
            Path(f"models/{cfg.ch6.model}/best.pt"),
        )
        about[name] = {
            "condition": name,
            "planner": cond.planner,
            "stream": cond.stream,
            "rule": cond.rule,
            "scale": base.scale,
            "cp_max": cp_max,
            "support": as_dict(support),
        }
    results = run_episodes("trials", run_ch6_episode, jobs, cfg.workers)
    for name in conditions:
        mine = [r for r in results if r.record["condition"] == name]
        records = [r.record for r in mine]
        write_records(OUT / name / "records.jsonl", records)
        meta = {k: str(v) for k, v in about[name].items() if k != "support"}
        write_mcap(DATA / name / "episodes.mcap", mine, meta)
        row = aggregate(records).iloc[0].to_dict()
        summary = about[name] | {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}
        write_json(OUT / name / "summary.json", summary)
        print(
            f"{name}: episodes {summary['success_k']}/{summary['success_n']} succeeded, "
            f"steps {summary.get('step_success_k')}/{summary.get('step_success_n')}, "
            f"mean steps {summary.get('mean_steps', float('nan')):.2f}"
        )


if __name__ == "__main__":
    run_stage(trials)
