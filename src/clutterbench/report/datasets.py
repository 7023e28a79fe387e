"""The datasets table: what was generated, beside the thesis' dataset sizes."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.data.dataset import load_scenes
from clutterbench.data.labels import moved_matrix
from clutterbench.io import read_json
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table

# Our dataset -> the thesis' dataset it stands in for (row of thesis_figures.yaml `datasets`).
THESIS_DATASET = {
    "ch4_same": "ch4_fcn_pairs",
    "ch4_various": "ch4_fcn_pairs",
    "ch5": "ch5_collapse_map_train",
    "ch6": "ch6_cp_total",
    "ch6_test": "ch6_cp_test",
}

COLUMNS = [
    Column("n_scenes", "scenes", "{:d}"),
    Column("n_samples", "samples", "{:d}"),
    Column("train", "train scenes", "{:d}"),
    Column("val", "val scenes", "{:d}"),
    Column("test", "test scenes", "{:d}"),
    Column("objects_mean", "objects / scene", "{:.2f}"),
    Column("moved_per_removal", "moved / removal", "{:.2f}"),
    Column("rejected", "rejected scenes", "{:d}"),
]


def dataset_stats(
    gen_dir: Path, split_dir: Path, name: str, threshold_m: float, pulls: bool
) -> dict[str, Any]:
    manifest = read_json(gen_dir / name / "manifest.json")
    split = read_json(split_dir / f"{name}.json")
    assert isinstance(manifest, dict) and isinstance(split, dict)
    scenes = load_scenes(gen_dir, name)
    n_obj = scenes["n_objects"].astype(int)
    moved = [
        moved_matrix(r[:n, :n], threshold_m).sum(axis=1).mean()
        for r, n in zip(scenes["removal_m"], n_obj)
    ]
    # A sample is what the thesis counts: one (scene, target) pair, or (scene, target,
    # support) for ch. 4's pulls.
    samples = int((n_obj * n_obj).sum()) if pulls else int(n_obj.sum())
    return {
        "n_scenes": int(manifest["n_scenes"]),
        "n_samples": samples,
        "train": len(split["train"]),
        "val": len(split["val"]),
        "test": len(split["test"]),
        "objects_mean": float(n_obj.mean()),
        "moved_per_removal": float(np.mean(moved)),
        "rejected": int(sum(manifest["rejected"].values())),
        "rejected_by_reason": manifest["rejected"],
        "families": manifest["families"],
    }


def datasets_table(
    stats: Mapping[str, dict[str, Any]], figures: Mapping[str, Any], out_dir: Path
) -> None:
    rows = [
        (name, s, thesis_row(figures, "datasets", THESIS_DATASET.get(name, "")))
        for name, s in stats.items()
    ]
    frame = comparison_frame(rows, COLUMNS, "dataset")
    write_table(
        frame,
        COLUMNS,
        out_dir,
        "datasets",
        "Generated datasets",
        notes=[
            "samples: (scene, target) pairs; ch4: (scene, target, support) pulls.",
            "thesis column: the dataset the thesis used for the same purpose.",
        ],
    )
