"""Stage train@<model>: train one collapse network; best checkpoint to models/<model>/."""

import sys
from pathlib import Path

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import TrainPaths, train_model
from clutterbench.config import BaseConfig, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage


def train(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    cfg = load_section(TrainConfig, "train", params)
    if name not in cfg.models:
        raise ClutterbenchError(
            f"train.models.{name}: no such model (known: {', '.join(cfg.models)})"
        )
    dataset = cfg.models[name].dataset
    gen = load_section(GenerateConfig, "generate", params)
    if dataset not in gen.datasets:
        raise ClutterbenchError(f"train.models.{name}.dataset: unknown dataset '{dataset}'")
    paths = TrainPaths(
        gen_dir=Path("data/generate"),
        split_file=Path(f"data/split/{dataset}.json"),
        model_dir=Path(f"models/{name}"),
        report_dir=Path(f"reports/train/{name}"),
        timing_file=Path(f"reports/timing/train_{name}.json"),
    )
    threshold_m = gen.datasets[dataset].moved_threshold_m
    fovy_deg = load_section(SimConfig, "sim", params).camera.fovy_deg
    summary = train_model(
        name, cfg, threshold_m, base.seed, paths, label_thresholds(params), fovy_deg
    )
    print(f"{name}: best epoch {summary['best']['epoch']} of {summary['epochs_run']}")


if __name__ == "__main__":
    run_stage(train)
