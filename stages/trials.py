"""Stage trials@<condition>: simulated robot trials of one condition -> records + MCAP."""

import sys
from pathlib import Path

from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from clutterbench.planning.support import SupportParams
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch6 import ch6_jobs, run_ch6_episode
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.harness import run_episodes, write_mcap
from clutterbench.trials.records import write_records
from clutterbench.trials.stats import aggregate

THRESHOLDS = Path("reports/support/thresholds.json")


def support_params(rule: str) -> SupportParams:
    chosen = read_json(THRESHOLDS)
    try:
        return SupportParams(**chosen["chosen"][rule])
    except (KeyError, TypeError) as exc:
        raise ClutterbenchError(
            f"{THRESHOLDS}: no usable thresholds for rule '{rule}' ({exc}); rerun the support stage"
        ) from None


def trials(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    cfg = load_section(TrialsConfig, "trials", params)
    if name not in cfg.conditions:
        raise ClutterbenchError(
            f"trials.conditions.{name}: no such condition (known: {', '.join(cfg.conditions)})"
        )
    cond = cfg.conditions[name]
    sim = load_section(SimConfig, "sim", params)
    support = support_params(cond.rule)
    cp_max = cfg.ch6.cp_max if cfg.ch6.cp_max is not None else support.score_threshold
    jobs = ch6_jobs(
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
    results = run_episodes(f"trials {name}", run_ch6_episode, jobs, cfg.workers)
    records = [r.record for r in results]
    write_records(Path(f"reports/trials/{name}/records.jsonl"), records)
    about = {"condition": name, "planner": cond.planner, "stream": cond.stream, "scale": base.scale}
    write_mcap(
        Path(f"data/trials/{name}/episodes.mcap"), results, about | {"cp_max": f"{cp_max:.3f}"}
    )
    row = aggregate(records).iloc[0].to_dict()
    summary = (
        about
        | {"cp_max": cp_max, "support": as_dict(support)}
        | {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}
    )
    write_json(Path(f"reports/trials/{name}/summary.json"), summary)
    print(
        f"{name}: episodes {summary['success_k']}/{summary['success_n']} succeeded, "
        f"steps {summary.get('step_success_k')}/{summary.get('step_success_n')}, "
        f"mean steps {summary.get('mean_steps', float('nan')):.2f}"
    )


if __name__ == "__main__":
    run_stage(trials)
