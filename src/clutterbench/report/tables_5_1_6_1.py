"""Tables 5.1 and 6.1: collapse prediction pixel metrics, ours beside the thesis'.

Every row also says which network it is and how its settings differ from the thesis': ours
from the checkpoint's metadata and the training summary, the thesis' from the `settings`
of the table and row in reports/thesis_figures.yaml (the one home of thesis numbers).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.models.checkpoint import load_checkpoint
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table

COLUMNS = [
    Column("pixel_accuracy", "pixel acc."),
    Column("iou", "IoU"),
    Column("precision", "precision"),
    Column("recall", "recall"),
    Column("iou_at_val_chosen", "IoU at val-chosen threshold"),
    Column("val_chosen_threshold", "val-chosen threshold", "{:.2f}"),
    Column("pairs", "test pairs", "{:d}"),
    Column("network", "network", "{}"),
    Column("epochs_run", "epochs run", "{:d}"),
    Column("differs", "differs from thesis", "{}"),
]


def _pretrained(x: bool) -> str:
    return "ImageNet-pretrained" if x else "from scratch"


# Thesis setting -> how a difference reads, given (ours, thesis).
SETTING_TEXT: dict[str, Callable[[Any, Any], str]] = {
    "image_size": lambda o, t: f"{o} px (thesis {t})",
    "encoder_width": lambda o, t: f"VGG width {o} (thesis {t})",
    "imagenet_pretrained": lambda o, t: f"{_pretrained(o)} (thesis {_pretrained(t)})",
    "lr": lambda o, t: f"lr {o:g} (thesis {t:g})",
    "epochs": lambda o, t: f"{o} epochs max (thesis {t})",
    "lr_schedule": lambda o, t: f"{o} lr (thesis {t})",
    "batch_size": lambda o, t: f"batch {o} (thesis {t})",
    "loss": lambda o, t: f"{o} loss (thesis {t})",
    "objects_per_scene": lambda o, t: f"trained on scenes of {o} boxes (thesis {t})",
    "decoder_output_stride": lambda o, t: (
        f"decoder to 1/{o} of the input, logits upsampled (thesis {'full size' if t == 1 else t})"
    ),
}
TABLE_SETTINGS = ("test_images",)
"""Settings of the whole table (its test set), said in the notes rather than per row."""


@dataclasses.dataclass(frozen=True)
class RunSources:
    """Where one evaluate run's numbers and its model's settings are read from."""

    eval_dir: Path
    """reports/evaluate/: <run>/metrics.json."""
    model_dir: Path
    """models/: <model>/best.pt (its meta: image size, training config, net config)."""
    train_dir: Path
    """reports/train/: <model>/summary.json (epochs actually run)."""


def load_run_metrics(eval_dir: Path, run: str) -> dict[str, Any]:
    path = eval_dir / run / "metrics.json"
    if not path.exists():
        raise ClutterbenchError(f"{path} not found; run stage evaluate@{run}")
    metrics = read_json(path)
    assert isinstance(metrics, dict)
    return metrics


def model_settings(model_dir: Path, train_dir: Path, model: str) -> dict[str, Any]:
    """Our model's settings, in the keys of SETTING_TEXT, from what training recorded."""
    path = model_dir / model / "best.pt"
    ckpt = load_checkpoint(path)
    summary = read_json(train_dir / model / "summary.json")
    assert isinstance(summary, dict)
    train = ckpt.meta.get("train", {})
    try:
        return {
            "arch": ckpt.arch,
            "dataset": ckpt.meta["dataset"],
            "image_size": ckpt.meta["image_size"],
            "encoder_width": ckpt.net.encoder.width,
            "imagenet_pretrained": ckpt.net.encoder.pretrained is not None,
            # networks without the option (fcn8s) predict at full size
            "decoder_output_stride": getattr(ckpt.net, "output_stride", 1),
            **{k: train[k] for k in ("lr", "epochs", "lr_schedule", "batch_size", "loss")},
            "epochs_run": summary["epochs_run"],
        }
    except KeyError as exc:
        raise ClutterbenchError(f"{path}: its metadata lacks {exc}; rerun train@{model}") from None


def thesis_settings(figures: Mapping[str, Any], table: str, row: str) -> dict[str, Any]:
    """The table's settings overridden by the row's; null means the thesis does not say."""
    merged = {
        **figures[table].get("settings", {}),
        **thesis_row(figures, table, row).get("settings", {}),
    }
    unknown = sorted(set(merged) - set(SETTING_TEXT) - set(TABLE_SETTINGS))
    if unknown:
        raise ClutterbenchError(
            f"thesis figures: {table} settings.{unknown[0]}: unknown setting "
            f"(known: {', '.join([*SETTING_TEXT, *TABLE_SETTINGS])})"
        )
    return {k: v for k, v in merged.items() if v is not None}


def settings_differences(ours: Mapping[str, Any], thesis: Mapping[str, Any]) -> str:
    """'<ours> px (thesis <theirs>); lr <ours> (thesis <theirs>)', for the settings the
    thesis states and ours differ from (a setting we did not record is left out); 'none'
    when none differ."""
    diffs = []
    for key, text in SETTING_TEXT.items():
        if key not in thesis or key not in ours:
            continue
        o, t = ours[key], thesis[key]
        same = math.isclose(o, t) if isinstance(o, float) or isinstance(t, float) else o == t
        if not same:
            diffs.append(text(o, t))
    return "; ".join(diffs) if diffs else "none"


def collapse_table(
    table: str,
    rows: Mapping[str, str | None],
    run_models: Mapping[str, str],
    threshold: float,
    figures: Mapping[str, Any],
    sources: RunSources,
    out_dir: Path,
    scale: str,
) -> dict[str, dict[str, Any]]:
    """One comparison table: thesis row -> our evaluate run (None: not run, said so).

    run_models: evaluate run -> its model (evaluate.runs); threshold: evaluate.threshold."""
    records, ours_all, not_run = [], {}, []
    for row, run in rows.items():
        thesis = thesis_row(figures, table, row)
        label = thesis.get("label", row)
        if run is None:
            not_run.append(label)
            records.append((f"{label} [not run]", {}, thesis))
            continue
        if run not in run_models:
            raise ClutterbenchError(f"report.{table}.{row}: no evaluate run '{run}'")
        ours = load_run_metrics(sources.eval_dir, run)
        if ours.get("threshold") != threshold:
            raise ClutterbenchError(
                f"{sources.eval_dir / run}/metrics.json is at threshold {ours.get('threshold')}, "
                f"not evaluate.threshold {threshold}; rerun evaluate@{run}"
            )
        model = run_models[run]
        settings = model_settings(sources.model_dir, sources.train_dir, model)
        head = ours.get("head", "deletion")  # evaluate runs of other heads record theirs
        ours = ours | {
            "run": run,
            "network": f"{model}: {settings['arch']}, {settings['loss']} loss, "
            f"trained on {settings['dataset']}"
            + (f"; its {head} head, on {head} labels" if head != "deletion" else ""),
            "epochs_run": settings["epochs_run"],
            "differs": settings_differences(settings, thesis_settings(figures, table, row)),
        }
        ours_all[row] = ours
        records.append((f"{label} [{run}]", ours, thesis))
    frame = comparison_frame(records, COLUMNS, "method [our evaluate run]")
    caption = figures[table].get("caption", table)
    number = table.removeprefix("table_").replace("_", ".")
    notes = _notes(table, figures, ours_all, threshold, scale)
    if not_run:
        notes = [
            f"not run: {', '.join(not_run)}. They need ImageNet VGG-16 weights, which cannot be "
            "downloaded here; give a local torchvision vgg16 .pth as "
            "train.models.<m>.net.encoder.pretrained (with width 1.0) and map the row to its "
            f"run in report.{table}.",
            *notes,
        ]
    write_table(frame, COLUMNS, out_dir, table, f"Table {number}: {caption}", notes)
    return ours_all


def _notes(
    table: str,
    figures: Mapping[str, Any],
    ours: Mapping[str, Mapping[str, Any]],
    threshold: float,
    scale: str,
) -> list[str]:
    """The table's notes, every number read from params, metrics or thesis_figures.yaml."""
    spec = figures[table]
    test_images = spec.get("settings", {}).get("test_images")
    thesis_size = f"thesis: {test_images} images" if test_images else "thesis: size not stated"
    test_sets = _grouped(
        ours,
        lambda m: (
            f"{m['dataset']} '{m['split']}' split, {m['scenes']} scenes, "
            f"{m['pairs']} (scene, target) pairs"
        ),
    )
    val_sets = _grouped(ours, lambda m: f"{m['val_dataset']} 'val' split, {m['val_pairs']} pairs")
    thesis_threshold = (
        f"thesis: {spec['eval_threshold']:g}"
        if spec.get("eval_threshold") is not None
        else "the thesis states none for this table"
    )
    heads = sorted({m.get("head", "deletion") for m in ours.values()} - {"deletion"})
    head_note = (
        [
            f"{', '.join(heads)} head rows: the network's output channel trained on labels of "
            "the trials' pull (train.models.<m>.labels; pull: a box is collapse when it moves "
            "beyond the label threshold or leaves the shelf as the trials' executor pulls the "
            "target out, data.labels.pull_moved_matrix; pull_collapse: only when it leaves the "
            "shelf, drops or tips beyond trials.collapse_free, data.labels."
            "pull_collapse_matrix), each scored on the same scenes' labels of its own kind, its "
            "threshold chosen on those labels of the val split; the other rows: deletion labels "
            "(the target lifted out). The thesis has no such row."
        ]
        if heads
        else []
    )
    return [
        f"{scale} scale. test set ({thesis_size}): {test_sets}.",
        f"pixel acc., IoU, precision, recall: a pixel counts as collapse when its probability "
        f"> {threshold:g} (evaluate.threshold; {thesis_threshold}); counts summed over all "
        "test pixels.",
        "val-chosen threshold: the sweep threshold with the best IoU on a validation split, "
        f"never the test set: {val_sets}. IoU at val-chosen threshold: the test IoU there.",
        "network: our model, its loss and training data (checkpoint metadata). differs from "
        "thesis: our settings against the thesis' (settings in reports/thesis_figures.yaml); "
        "epochs run: until early stopping (reports/train/<model>/summary.json).",
        "files: reports/evaluate/<run>/figure.png, sweep.csv (test), val_sweep.csv.",
        *head_note,
    ]


def _grouped(ours: Mapping[str, Mapping[str, Any]], describe: Callable[[Any], str]) -> str:
    """'description (run, run); description (run)': rows sharing a set named once."""
    groups: dict[str, list[str]] = {}
    for m in ours.values():
        groups.setdefault(describe(m), []).append(m["run"])
    return "; ".join(f"{d} ({', '.join(runs)})" for d, runs in groups.items()) or "none run"
