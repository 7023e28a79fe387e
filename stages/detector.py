"""Stage detector: train the arrangement detector (thesis 5.2.1) on its dataset's train split
(val split picks the epoch), then score it on the test split: mAP@0.5, PR curves, figure."""

from clutterbench.collapse.detector import DetectorParams
from clutterbench.collapse.detector_run import run_detector, stage_paths
from clutterbench.config import BaseConfig, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage


def detector(params: dict, base: BaseConfig) -> None:
    cfg = load_section(DetectorParams, "detector", params)
    gen = load_section(GenerateConfig, "generate", params)
    if cfg.dataset not in gen.datasets:
        raise ClutterbenchError(f"detector.dataset: unknown dataset '{cfg.dataset}'")
    fovy_deg = load_section(SimConfig, "sim", params).camera.fovy_deg  # detector.sensing's focal
    run_detector(cfg, base.seed, stage_paths("detector", cfg.dataset), fovy_deg, "ideal")


if __name__ == "__main__":
    run_stage(detector)
