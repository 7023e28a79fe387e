"""Stage trials_ch5: the chapter 5 replenishment trials of every condition (thesis Table 5.2)
in one pool of workers -> one record per trial (reports/trials_ch5/records.jsonl), a summary
row per condition and one MCAP per condition (data/trials_ch5/<condition>/episodes.mcap).

The collapse region's probability threshold, unless params fix it, is the one evaluate@
<model>_ch5 chose on the ch. 5 validation split: never a test-scene choice."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.parallel import ParallelConfig
from clutterbench.precision import inference_from_params
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.ch5.episodes import (
    ch5_jobs,
    check_models,
    collapse_threshold,
    run_ch5_episode,
)
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.harness import run_episodes, write_mcap
from clutterbench.trials.core.records import write_records
from clutterbench.trials.core.stats import aggregate

OUT = Path("reports/trials_ch5")
DATA = Path("data/trials_ch5")


def trials_ch5(params: dict, base: BaseConfig) -> None:
    cfg = load_section(TrialsConfig, "trials", params)
    if not cfg.ch5_conditions:
        raise ClutterbenchError("trials.ch5_conditions: no conditions to run")
    sim = load_section(SimConfig, "sim", params)
    precision = inference_from_params(params)
    check_models(dict(cfg.ch5_conditions), cfg.ch5)
    prob = collapse_threshold(cfg.ch5)
    with_detector = any(c.perception == "detector" for c in cfg.ch5_conditions.values())
    jobs = []
    for name, cond in cfg.ch5_conditions.items():
        jobs += ch5_jobs(
            name,
            cond,
            trials=cfg,
            sim=sim,
            seed=base.seed,
            prob_threshold=prob,
            scene_type=cond.stream.removeprefix("ch5_"),
            oracle_detector=with_detector,
        )
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("trials_ch5", run_ch5_episode, jobs, cfg.workers, parallel)
    records = [r.record for r in results]
    write_records(OUT / "records.jsonl", records)
    for name, cond in cfg.ch5_conditions.items():
        about = {
            "condition": name,
            "planner": cond.planner,
            "perception": cond.perception,
            "stream": cond.stream,
            "scale": base.scale,
            "network_precision": precision,
            "prob_threshold": str(prob),
        }
        if cond.sensing != "ideal":  # exact-depth conditions keep their old metadata
            about["sensing"] = cond.sensing
        mine = [r for r in results if r.record["condition"] == name]
        write_mcap(DATA / name / "episodes.mcap", mine, about)
    summary = aggregate(records)
    write_text(OUT / "summary.csv", summary.to_csv(index=False))
    write_json(
        OUT / "totals.json",
        {
            "scale": base.scale,
            "network_precision": precision,
            "prob_threshold": prob,
            "trials": len(records),
        },
    )
    for row in summary.itertuples():
        print(f"{row.condition}: success {row.success_k}/{row.success_n}")


if __name__ == "__main__":
    run_stage(trials_ch5)
