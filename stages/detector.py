"""Stage detector: train the arrangement detector (thesis 5.2.1) on its dataset's train split
(val split picks the epoch), then score it on the test split: mAP@0.5, PR curves, figure."""

from pathlib import Path

import pandas as pd

from clutterbench.collapse.detection_metrics import pr_rows
from clutterbench.collapse.detector import (
    DetectorParams,
    DetectorPaths,
    evaluate_detector,
    train_detector,
    truth_of,
)
from clutterbench.collapse.detector_figure import detection_figure, figure_scenes, pr_figure
from clutterbench.config import BaseConfig, load_section
from clutterbench.data.arrangement import load_arrangement_split
from clutterbench.data.config import GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path, write_json
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage


def score(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def detector(params: dict, base: BaseConfig) -> None:
    cfg = load_section(DetectorParams, "detector", params)
    gen = load_section(GenerateConfig, "generate", params)
    if cfg.dataset not in gen.datasets:
        raise ClutterbenchError(f"detector.dataset: unknown dataset '{cfg.dataset}'")
    paths = DetectorPaths(
        gen_dir=Path("data/generate"),
        split_file=Path(f"data/split/{cfg.dataset}.json"),
        model_dir=Path("models/detector"),
        report_dir=Path("reports/detector"),
        timing_file=Path("reports/timing/detector.json"),
    )
    fovy_deg = load_section(SimConfig, "sim", params).camera.fovy_deg  # detector.sensing's focal
    detector, summary = train_detector(cfg, base.seed, paths, fovy_deg)
    test = load_arrangement_split(paths.gen_dir, paths.split_file, "test")
    metrics, prs, at_threshold = evaluate_detector(detector, test, cfg)
    out = paths.report_dir
    about = {"dataset": cfg.dataset, "split": "test"}
    write_json(out / "metrics.json", about | metrics | {"train": summary})
    with atomic_path(out / "pr.csv") as tmp:
        pd.DataFrame(pr_rows(prs), columns=["class", "score", "recall", "precision"]).to_csv(
            tmp, index=False, float_format="%.6g"
        )
    title = f"{cfg.dataset} test: mAP@0.5 {score(metrics['map50'])}"
    pr_figure(prs, title, out / "pr.png")
    shown = figure_scenes(test.classes, cfg.figure_samples)
    detection_figure(
        test.depth_m[shown],
        [at_threshold[i] for i in shown],
        [truth_of(test)[i] for i in shown],
        f"{title} (boxes scoring >= {cfg.score_threshold:.2f}, NMS IoU {cfg.nms_iou:.2f})",
        out / "figure.png",
    )
    aps = ", ".join(f"{k} {score(v['ap50'])}" for k, v in metrics["per_class"].items())
    best = summary["best"]["epoch"]
    print(f"detector: best epoch {best}; test mAP@0.5 {score(metrics['map50'])} ({aps})")


if __name__ == "__main__":
    run_stage(detector)
