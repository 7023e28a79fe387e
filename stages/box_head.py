"""Stage box_head: the per-box head over the support model's maps (the work:
clutterbench.support.box_run)."""

from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.box_run import BoxHeadPaths, run_box_head
from clutterbench.support.config import SupportEvalConfig


def box_head(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    for key, name in (
        ("val_dataset", cfg.val_dataset),
        ("box_head.test_dataset", cfg.box_head.test_dataset),
    ):
        if name not in gen.datasets:
            raise ClutterbenchError(f"support.{key}: unknown dataset '{name}'")
    paths = BoxHeadPaths(
        cp_model=Path(f"models/{cfg.model}/best.pt"),
        gen_dir=Path("data/generate"),
        split_file=Path(f"data/split/{cfg.val_dataset}.json"),
        model_dir=Path("models/box_head"),
        out=Path("reports/box_head"),
    )
    summary = run_box_head(params, base.seed, cfg, sim, paths)
    for out, s in summary.items():
        print(
            f"box_head {out}: precision {s['precision']:.3f} recall {s['recall']:.3f} "
            f"AUROC {s['auroc']:.3f} ECE {s['ece']:.3f}"
        )


if __name__ == "__main__":
    run_stage(box_head)
