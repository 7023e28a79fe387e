"""Stage trials_ch4: the chapter 4 pull-with-support trials of every condition (thesis Table
4.1 and the predetermined target) in one pool of workers -> one record per trial
(reports/trials_ch4/records.jsonl), a summary row per condition, one MCAP per condition and
a figure like thesis Fig. 4.8.

One stage, not one per condition: a trial takes a fraction of a second, so starting workers
(torch, a renderer, the networks) once for all conditions is most of the saving."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.parallel import ParallelConfig
from clutterbench.precision import inference_from_params
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch4.episodes import ch4_jobs, run_ch4_episode
from clutterbench.trials.ch4.figure import draw_figure
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import run_episodes, write_mcap
from clutterbench.trials.core.records import write_records
from clutterbench.trials.core.stats import aggregate

OUT = Path("reports/trials_ch4")
DATA = Path("data/trials_ch4")


def trials_ch4(params: dict, base: BaseConfig) -> None:
    cfg = load_section(TrialsConfig, "trials", params)
    if not cfg.ch4_conditions:
        raise ClutterbenchError("trials.ch4_conditions: no conditions to run")
    sim = load_section(SimConfig, "sim", params)
    precision = inference_from_params(params)
    jobs = []
    for name, cond in cfg.ch4_conditions.items():
        if cond.model is not None and not Path(f"models/{cond.model}/best.pt").exists():
            raise ClutterbenchError(f"models/{cond.model}/best.pt missing; run train@{cond.model}")
        jobs += ch4_jobs(name, cond, trials=cfg, sim=sim, seed=base.seed)
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("trials_ch4", run_ch4_episode, jobs, cfg.workers, parallel)
    records = [r.record for r in results]
    write_records(OUT / "records.jsonl", records)
    for name, cond in cfg.ch4_conditions.items():
        about = {
            "condition": name,
            "planner": cond.planner,
            "mode": cond.mode,
            "model": str(cond.model),
            "perception": cond.perception,
            "stream": cond.stream,
            "scale": base.scale,
            "network_precision": precision,
        }
        if cond.sensing != "ideal":  # exact-depth conditions keep their old metadata
            about["sensing"] = cond.sensing
        mine = [r for r in results if r.record["condition"] == name]
        write_mcap(DATA / name / "episodes.mcap", mine, about)
    figure = [
        n for n, c in cfg.ch4_conditions.items() if c.planner == "risk" and c.mode == "target"
    ]
    if figure:
        first = next(j for j in jobs if j.condition == figure[0])
        n = cfg.ch4_conditions[figure[0]].episodes
        draw_figure(
            jobs[jobs.index(first) + min(cfg.ch4.figure_episode, n - 1)], OUT / "fig_4_8.png"
        )
    summary = aggregate(records)
    write_text(OUT / "summary.csv", summary.to_csv(index=False))
    totals = {
        "scale": base.scale,
        "network_precision": precision,
        "conditions": len(cfg.ch4_conditions),
        "trials": len(records),
    }
    totals |= {
        "success_rate": sum(r["success"] for r in records) / len(records),
        "strict_success_rate": sum(r["strict_success"] for r in records) / len(records),
    }
    write_json(OUT / "totals.json", totals)
    for row in summary.itertuples():
        print(
            f"{row.condition}: success {row.success_k}/{row.success_n}, strict "
            f"{row.strict_success_k}/{row.strict_success_n}, mean disturbed boxes "
            f"{row.mean_n_disturbed:.2f}"
        )


if __name__ == "__main__":
    run_stage(trials_ch4)
