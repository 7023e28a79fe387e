"""Stage split@<dataset>: train / val / test by scene."""

import sys
from pathlib import Path

from clutterbench.config import BaseConfig, load_section
from clutterbench.data.split import SplitConfig, split_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.stage import run_stage


def split(params: dict, base: BaseConfig) -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else ""
    cfg = load_section(SplitConfig, "split", params)
    if name not in cfg.datasets:
        raise ClutterbenchError(
            f"split.datasets.{name}: no such dataset (known: {', '.join(cfg.datasets)})"
        )
    sizes = split_dataset(
        name, cfg.datasets[name], base.seed, Path("data/generate"), Path("data/split")
    )
    print(f"{name}: {sizes}")


if __name__ == "__main__":
    run_stage(split)
