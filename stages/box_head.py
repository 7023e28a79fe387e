"""Stage box_head: the per-box head over the support model's maps (the work:
clutterbench.support.box_run)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.box_run import BoxHeadPaths, check_datasets, run_box_head
from clutterbench.support.config import SupportEvalConfig


def box_head(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    check_datasets(cfg, params)
    sim = load_section(SimConfig, "sim", params)
    paths = BoxHeadPaths.of(cfg, Path("models/box_head"), Path("reports/box_head"))
    summary = run_box_head(params, base.seed, cfg, sim, paths)
    for out, s in summary.items():
        print(
            f"box_head {out}: precision {s['precision']:.3f} recall {s['recall']:.3f} "
            f"AUROC {s['auroc']:.3f} ECE {s['ece']:.3f}"
        )


if __name__ == "__main__":
    run_stage(box_head)
