"""Table 4.2: the ch. 4 networks' collapsing region C on each ground truth, ours beside the
thesis'.

Rows: the model trained on same-size or on various-size boxes x the ground truth of
same-size or various-size targets (each dataset's test split). Thesis 4.4.1 averages IoU,
recall and precision of class C over its test samples, a pixel being C when P(C) > 0.4; ours
are the per-pair means of the evaluate runs (collapse.metrics.pair_means), the IoU summed
over all test pixels beside them.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table
from clutterbench.report.tables_5_1_6_1 import (
    RunSources,
    load_run_metrics,
    model_settings,
    settings_differences,
    thesis_settings,
)

TABLE = "table_4_2"
COLUMNS = [
    Column("iou", "avg. IoU"),
    Column("recall", "avg. recall"),
    Column("precision", "avg. precision"),
    Column("iou_empty_as_one", "avg. IoU, empty pairs = 1"),
    Column("iou_pixels", "IoU over all pixels"),
    Column("pairs", "test pairs", "{:d}"),
    Column("pairs_empty_both", "pairs empty in both", "{:d}"),
    Column("network", "network", "{}"),
    Column("epochs_run", "epochs run", "{:d}"),
    Column("differs", "differs from thesis", "{}"),
]


def table_row(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """Our figures of one evaluate run in the thesis' keys (iou, recall, precision)."""
    try:
        return {
            "iou": metrics["pair_mean_iou"],
            "recall": metrics["pair_mean_recall"],
            "precision": metrics["pair_mean_precision"],
            "iou_empty_as_one": metrics["pair_mean_iou_empty_as_one"],
            "iou_pixels": metrics["iou"],
            "pairs": metrics["pairs"],
            "pairs_empty_both": metrics["samples_empty_both"],
        }
    except KeyError as exc:
        raise ClutterbenchError(f"metrics lack {exc}; rerun the evaluate run") from None


def table_4_2(
    rows: Mapping[str, str | None],
    run_models: Mapping[str, str],
    run_thresholds: Mapping[str, float],
    figures: Mapping[str, Any],
    sources: RunSources,
    out_dir: Path,
    scale: str,
    objects_per_scene: Mapping[str, tuple[int, int]] | None = None,
) -> dict[str, dict[str, Any]]:
    """reports/tables/table_4_2.{md,csv}: thesis row -> our evaluate run (None: not run).

    run_models: evaluate run -> its model; run_thresholds: evaluate run -> its pixel
    threshold (EvaluateConfig.for_run(run).threshold); objects_per_scene: dataset -> its
    (min, max) boxes per scene (generate.datasets.<d>.n_objects), compared with the piles
    the thesis trained on."""
    records, ours_all = [], {}
    for row, run in rows.items():
        thesis = thesis_row(figures, TABLE, row)
        if not thesis:
            raise ClutterbenchError(f"report.{TABLE}.{row}: the thesis table has no such row")
        label = thesis.get("label", row)
        if run is None:
            records.append((f"{label} [not run]", {}, thesis))
            continue
        if run not in run_models:
            raise ClutterbenchError(f"report.{TABLE}.{row}: no evaluate run '{run}'")
        metrics = load_run_metrics(sources.eval_dir, run)
        if metrics.get("threshold") != run_thresholds[run]:
            raise ClutterbenchError(
                f"{sources.eval_dir / run}/metrics.json is at threshold "
                f"{metrics.get('threshold')}, not {run_thresholds[run]}; rerun evaluate@{run}"
            )
        model = run_models[run]
        settings = model_settings(sources.model_dir, sources.train_dir, model)
        if objects_per_scene and settings["dataset"] in objects_per_scene:
            lo, hi = objects_per_scene[settings["dataset"]]
            settings["objects_per_scene"] = str(lo) if lo == hi else f"{lo}-{hi}"
        ours = table_row(metrics) | {
            "run": run,
            "dataset": metrics["dataset"],
            "split": metrics["split"],
            "scenes": metrics["scenes"],
            "threshold": metrics["threshold"],
            "network": f"{model}: {settings['arch']}, {settings['loss']} loss, "
            f"trained on {settings['dataset']}",
            "epochs_run": settings["epochs_run"],
            "differs": settings_differences(settings, thesis_settings(figures, TABLE, row)),
        }
        ours_all[row] = ours
        records.append((f"{label} [{run}]", ours, thesis))
    frame = comparison_frame(records, COLUMNS, "model / ground truth [our evaluate run]")
    caption = figures[TABLE].get("caption", TABLE)
    notes = _notes(figures[TABLE], ours_all, scale)
    write_table(frame, COLUMNS, out_dir, TABLE, f"Table 4.2: {caption}", notes)
    return ours_all


def _notes(spec: Mapping[str, Any], ours: Mapping[str, Mapping[str, Any]], scale: str) -> list[str]:
    """The table's notes, every number read from params, metrics or thesis_figures.yaml."""
    thresholds = sorted({f"{m['threshold']:g}" for m in ours.values()}) or ["—"]
    sets = sorted(
        {
            f"{m['dataset']} '{m['split']}' split: {m['scenes']} scenes, {m['pairs']} pairs"
            for m in ours.values()
        }
    )
    thesis_n = spec.get("eval_samples")
    thesis_t = spec.get("eval_threshold")
    return [
        f"{scale} scale. Ground truth: {'; '.join(sets) or 'none run'} (thesis: "
        f"{thesis_n if thesis_n is not None else 'size not stated'} samples). A pair is one "
        "(extracted, supported) box pair of a test scene, both visible.",
        f"Class C (collapsing region) only; a pixel is C when P(C) > {', '.join(thresholds)} "
        f"(evaluate.runs.<run>.threshold; thesis: {thesis_t if thesis_t is not None else '—'}).",
        "avg. IoU / recall / precision: each pair's own ratio averaged over the pairs where it "
        "is defined (the thesis averages over its samples but does not say how it counts a "
        "ratio 0 / 0): a pair with no C pixel in both "
        "truth and prediction has no IoU and counts in none of the three averages (pairs "
        "empty in both); a pair with C in the truth but none predicted has IoU 0 and recall 0 "
        "and no precision; one with C predicted but none true has IoU 0, precision 0 and no "
        "recall. avg. IoU, empty pairs = 1: every pair, the pairs empty in both counting as 1.",
        "IoU over all pixels: TP / (TP + FP + FN) summed over the whole test split (the rule "
        "of Tables 5.1 / 6.1).",
        "network: our model, its loss and training data (checkpoint metadata). differs from "
        "thesis: our settings against thesis 4.3.1's (settings in reports/thesis_figures.yaml).",
        "files: reports/evaluate/<run>/metrics.json, figure.png (extracted green, supported "
        "blue, collapse red).",
    ]
