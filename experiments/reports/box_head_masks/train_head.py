"""The D415-class box head trained on the masks named on the command line (instance | depth |
both: support.box_head.sensed_masks) into data/dev/box_head_<masks>_masks/{model,report}, as
stage box_head_sensed trains its own; run from the repository root as

    python experiments/reports/box_head_masks/train_head.py both

Then stage support, run with that head in models/box_head_sensed/d415/, chooses its sensed
thresholds and fusion (reports/support/thresholds.json, box_fusion.json), which compare.py
reads."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from clutterbench.config import BaseConfig, load_params, load_section
from clutterbench.sim.config import SimConfig
from clutterbench.sim.noise import TrainSensingConfig
from clutterbench.support.box_run import BoxHeadPaths, run_box_head
from clutterbench.support.config import SupportEvalConfig


def main() -> None:
    masks = sys.argv[1]
    params = load_params(Path("params.yaml"))
    base = load_section(BaseConfig, "base", params)
    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    sensing = TrainSensingConfig("d415", cfg.box_head.sensing.spread)
    bh = dataclasses.replace(cfg.box_head, sensing=sensing, sensed_masks=masks)
    out = Path(f"data/dev/box_head_{masks}_masks")
    paths = BoxHeadPaths.of(cfg, out / "model", out / "report")
    print(run_box_head(params, base.seed, dataclasses.replace(cfg, box_head=bh), sim, paths))


if __name__ == "__main__":
    main()
