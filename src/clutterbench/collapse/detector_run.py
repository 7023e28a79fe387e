"""What stages detector and detector_sensed do: train the arrangement detector (thesis 5.2.1) on
its dataset's train split (val picks the epoch), score it on the test split as the sensor of its
images returns them, and write its report: metrics.json, pr.csv, pr.png, figure.png."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

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
from clutterbench.data.arrangement import load_arrangement_split
from clutterbench.io import atomic_path, write_json
from clutterbench.sim.sensor import sense_images


def score(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def run_detector(
    cfg: DetectorParams, seed: int, paths: DetectorPaths, fovy_deg: float, test_sensing: str
) -> dict[str, Any]:
    """Train `cfg`'s detector, score it on the test images through `test_sensing` (ideal: as
    rendered), write the report under paths.report_dir -> its metrics."""
    detector, summary = train_detector(cfg, seed, paths, fovy_deg)
    test = load_arrangement_split(paths.gen_dir, paths.split_file, "test")
    if test_sensing != "ideal":
        sensed = sense_images(test.depth_m, test_sensing, fovy_deg, seed)
        test = dataclasses.replace(test, depth_m=sensed)
    metrics, prs, at_threshold = evaluate_detector(detector, test, cfg)
    out = paths.report_dir
    about = {"dataset": cfg.dataset, "split": "test"}
    if test_sensing != "ideal":  # the thesis detector's report keeps its old fields
        about["test_sensing"] = test_sensing
    write_json(out / "metrics.json", about | metrics | {"train": summary})
    with atomic_path(out / "pr.csv") as tmp:
        pd.DataFrame(pr_rows(prs), columns=["class", "score", "recall", "precision"]).to_csv(
            tmp, index=False, float_format="%.6g"
        )
    seen = "" if test_sensing == "ideal" else f" ({test_sensing} depth)"
    title = f"{cfg.dataset} test{seen}: mAP@0.5 {score(metrics['map50'])}"
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
    print(f"detector: best epoch {best}; test{seen} mAP@0.5 {score(metrics['map50'])} ({aps})")
    return metrics


def stage_paths(name: str, dataset: str) -> DetectorPaths:
    """The pipeline's files of the detector `name`: detector (stage detector), detector_<sensor>
    (stage detector_sensed)."""
    return DetectorPaths(
        gen_dir=Path("data/generate"),
        split_file=Path(f"data/split/{dataset}.json"),
        model_dir=Path(f"models/{name}"),
        report_dir=Path(f"reports/{name}"),
        timing_file=Path(f"reports/timing/{name}.json"),
    )
