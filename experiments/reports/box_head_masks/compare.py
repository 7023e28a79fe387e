"""Box planners under the D415 class with masks from depth, on dev stream dev_ch6_3_10, with
each of two sensed box heads: run from the repository root as

    python experiments/reports/box_head_masks/compare.py EPISODES OUT.jsonl \
        LABEL=HEAD_DIR:THRESHOLDS_DIR ... -- PLANNER ...

HEAD_DIR holds a box head's best.pt; THRESHOLDS_DIR the support stage's thresholds.json and
box_fusion.json chosen with that head (its sensed edge thresholds, fusion and the head's
outcome threshold, cp_max). Every other setting is params.yaml's. Writes one record per
episode (label, planner, episode, success, strict_success, aborts after motion)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from clutterbench.config import BaseConfig, load_params, load_section
from clutterbench.parallel import ParallelConfig
from clutterbench.sim.config import SimConfig
from clutterbench.trials.ch6.episodes import box_fields, ch6_jobs, planner_support, run_ch6_episode
from clutterbench.trials.config import ConditionConfig, TrialsConfig
from clutterbench.trials.core.harness import run_episodes
from experiments.config import load_dev

STREAM = "dev_ch6_3_10"
SENSING, PERCEPTION = "d415", "depth"


def jobs_of(label: str, head: Path, thresholds: Path, planner: str, episodes: int, params):
    base = load_section(BaseConfig, "base", params)
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    dev = load_dev(params)
    rule = "coverage_gap"
    support, cp_max = planner_support(thresholds, planner, rule, trials.ch6, SENSING)
    box, box_cp_max = box_fields(thresholds, planner, trials.ch6, SENSING)
    box = dict(box) | {"box_head_path": head / "best.pt"}
    return ch6_jobs(
        f"{label}:{planner}",
        ConditionConfig(planner, STREAM, episodes, rule, perception=PERCEPTION, sensing=SENSING),
        trials=trials,
        sim=sim,
        seed=base.seed,
        support=support,
        cp_max=box_cp_max if box_cp_max is not None else cp_max,
        model_path=Path(f"models/{trials.ch6.model}/best.pt"),
        stream_cfg=dev.streams[STREAM],
        **box,
    )


def main() -> None:
    args = sys.argv[1:]
    split = args.index("--")
    episodes, out = int(args[0]), Path(args[1])
    heads = [a.split("=", 1) for a in args[2:split]]
    planners = args[split + 1 :]
    params = load_params(Path("params.yaml"))
    jobs = []
    for label, where in heads:
        head, thresholds = where.split(":")
        for planner in planners:
            jobs += jobs_of(
                label, Path(head), Path(thresholds) / "thresholds.json", planner, episodes, params
            )
    trials = load_section(TrialsConfig, "trials", params)
    parallel = load_section(ParallelConfig, "parallel", params)
    results = run_episodes("box head masks", run_ch6_episode, jobs, trials.workers, parallel)
    with out.open("w") as f:
        for r in results:
            rec = r.record
            label, planner = rec["condition"].split(":")
            aborts = sum(s["aborted_after_motion"] for s in rec["steps"])
            row = {"label": label, "planner": planner, "episode": rec["episode"]}
            row |= {k: rec[k] for k in ("success", "strict_success", "end")}
            f.write(json.dumps(row | {"aborts_after_motion": aborts}) + "\n")


if __name__ == "__main__":
    main()
