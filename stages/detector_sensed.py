"""Stage detector_sensed: the arrangement detector of Table 5.2's sensed rows (trials.ch5_sensed),
trained as stage detector trains its own but on the images of those rows' sensor (its noise
randomised around the preset, detector.sensing.spread), and scored on the test split as that
sensor returns it -> models/detector_<sensor>, reports/detector_<sensor>. Chosen on val scenes:
make dev-detector-sensing (docs/sensing.md)."""

import dataclasses

from clutterbench.collapse.config import TrainSensingConfig
from clutterbench.collapse.detector import DetectorParams
from clutterbench.collapse.detector_run import run_detector, stage_paths
from clutterbench.config import BaseConfig, load_section, parse
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.condition_sets import SensedRows


def detector_sensed(params: dict, base: BaseConfig) -> None:
    cfg = load_section(DetectorParams, "detector", params)
    if cfg.dataset not in load_section(GenerateConfig, "generate", params).datasets:
        raise ClutterbenchError(f"detector.dataset: unknown dataset '{cfg.dataset}'")
    rows = parse(
        SensedRows, (params.get("trials") or {}).get("ch5_sensed") or {}, "trials.ch5_sensed"
    )
    preset = rows.sensing
    cfg = dataclasses.replace(cfg, sensing=TrainSensingConfig(preset, cfg.sensing.spread))
    fovy_deg = load_section(SimConfig, "sim", params).camera.fovy_deg
    paths = stage_paths(f"detector_{preset}", cfg.dataset)  # what the sensed rows read
    run_detector(cfg, base.seed, paths, fovy_deg, preset)


if __name__ == "__main__":
    run_stage(detector_sensed)
