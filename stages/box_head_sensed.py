"""Stage box_head_sensed: for each sensor of support.sensing, the per-box head trained as
stage box_head trains its own but on that sensor's depth (train scenes with the noise
randomised around the preset, support.box_head.sensing.spread; val and test scenes through
the preset) -> models/box_head_sensed/<sensor>, reports/box_head_sensed/<sensor>. The support
stage's sensed rows and the trials' sensed box rows read it (support/config.py
box_head_files). Chosen on val scenes (docs/sensing.md)."""

import dataclasses

from clutterbench.config import BaseConfig, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.sim.config import SimConfig
from clutterbench.sim.noise import TrainSensingConfig
from clutterbench.stage import run_stage
from clutterbench.support.box_run import BoxHeadPaths, check_datasets, run_box_head
from clutterbench.support.config import SENSED_BOX_HEADS, SENSED_BOX_REPORTS, SupportEvalConfig


def box_head_sensed(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    check_datasets(cfg, params)
    sim = load_section(SimConfig, "sim", params)
    if "ideal" in cfg.sensing:
        raise ClutterbenchError("support.sensing: ideal is the exact rows' own (stage box_head)")
    spread = cfg.box_head.sensing.spread
    for sensing in cfg.sensing:
        bh = dataclasses.replace(cfg.box_head, sensing=TrainSensingConfig(sensing, spread))
        paths = BoxHeadPaths.of(cfg, SENSED_BOX_HEADS / sensing, SENSED_BOX_REPORTS / sensing)
        summary = run_box_head(params, base.seed, dataclasses.replace(cfg, box_head=bh), sim, paths)
        for out, s in summary.items():
            print(
                f"box_head_sensed {sensing} {out}: precision {s['precision']:.3f} "
                f"recall {s['recall']:.3f}"
            )
    # the sensors it trained for (the folders are never empty, whatever support.sensing holds)
    for folder in (SENSED_BOX_HEADS, SENSED_BOX_REPORTS):
        write_json(folder / "sensors.json", {"sensors": list(cfg.sensing), "spread": spread})


if __name__ == "__main__":
    run_stage(box_head_sensed)
