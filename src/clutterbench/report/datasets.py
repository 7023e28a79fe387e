"""The datasets tables: what was generated, beside the thesis' dataset sizes and beside what
params asked for (family mix, objects per scene), with rejections per family.

Statistics are summed shard by shard, reading only the small per-scene arrays, so a
paper-scale dataset is never held in memory.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.data.config import DatasetConfig
from clutterbench.data.labels import moved_matrix
from clutterbench.data.shards import ShardStore, iter_shards, load_split, read_manifest
from clutterbench.errors import ClutterbenchError
from clutterbench.perception.boxes import ARRANGEMENT_CLASSES
from clutterbench.report.tables import Column, comparison_frame, thesis_row, write_table
from clutterbench.sim.config import REJECT_REASONS

# Our dataset -> the thesis' dataset it stands in for (row of thesis_figures.yaml `datasets`).
THESIS_DATASET = {
    "ch4_same": "ch4_fcn_pairs",
    "ch4_various": "ch4_fcn_pairs",
    "ch4_same_test": "ch4_table_4_2_eval",
    "ch4_various_test": "ch4_table_4_2_eval",
    "ch5": "ch5_collapse_map_train",
    "ch6": "ch6_cp_total",
    "ch6_test": "ch6_cp_test",
    "ch5_arrangement": "ch5_yolo_arrangement",
}

COLUMNS = [
    Column("n_scenes", "scenes", "{:d}"),
    Column("n_samples", "samples", "{:d}"),
    Column("train", "train scenes", "{:d}"),
    Column("val", "val scenes", "{:d}"),
    Column("test", "test scenes", "{:d}"),
    Column("objects_mean", "objects / scene", "{:.2f}"),
    Column("objects_mean_asked", "objects / scene asked", "{:.2f}"),
    Column("moved_per_removal", "moved / removal", "{:.2f}"),
    Column("rejected", "rejected scenes", "{:d}"),
]

FAMILY_COLUMNS = [
    Column("dataset", "dataset", "{}"),
    Column("family", "family", "{}"),
    Column("scenes", "scenes", "{:d}"),
    Column("share", "share", "{:.3f}"),
    Column("share_asked", "share asked", "{:.3f}"),
    *[Column(f"rejected_{r}", f"rejected: {r}", "{:d}") for r in REJECT_REASONS],
    Column("rejected_per_scene", "rejected / scene", "{:.3f}"),
]

OBJECT_COLUMNS = [
    Column("dataset", "dataset", "{}"),
    Column("n_objects", "objects", "{:d}"),
    Column("scenes", "scenes", "{:d}"),
    Column("scenes_asked", "scenes asked", "{:.1f}"),
]

CLUSTER_COLUMNS = [
    Column("dataset", "dataset", "{}"),
    Column("split", "split", "{}"),
    Column("scenes", "scenes", "{:d}"),
    *[Column(c, c, "{:d}") for c in ARRANGEMENT_CLASSES],
    Column("clusters", "clusters", "{:d}"),
]

# The per-scene arrays the statistics need (no images).
READ_KEYS = ("n_objects", "family", "rejected", "removal_m")
CLUSTER_KEYS = ("scene_index", "cluster_class", "cluster_bbox_px")


@dataclasses.dataclass(frozen=True)
class Tally:
    """Counts over some scenes; tallies of disjoint scene sets add up."""

    scenes_by_n: Counter = dataclasses.field(default_factory=Counter)
    """Number of boxes -> scenes."""
    scenes_by_family: Counter = dataclasses.field(default_factory=Counter)
    """Family -> scenes."""
    rejected_by_family: Mapping[str, Counter] = dataclasses.field(default_factory=dict)
    """Family -> reason -> rejected draws before its scenes were accepted."""
    moved_sum: float = 0.0
    """Sum over scenes of the mean number of boxes moved per removal."""

    def __add__(self, other: Tally) -> Tally:
        families = set(self.rejected_by_family) | set(other.rejected_by_family)
        return Tally(
            self.scenes_by_n + other.scenes_by_n,
            self.scenes_by_family + other.scenes_by_family,
            {
                f: self.rejected_by_family.get(f, Counter())
                + other.rejected_by_family.get(f, Counter())
                for f in families
            },
            self.moved_sum + other.moved_sum,
        )


def tally_shard(arrays: Mapping[str, np.ndarray], threshold_m: float) -> Tally:
    """Counts of one shard's scenes (arrays: READ_KEYS)."""
    n_obj = arrays["n_objects"].astype(int)
    families = [str(f) for f in arrays["family"]]
    if arrays["rejected"].shape[1:] != (len(REJECT_REASONS),):
        raise ClutterbenchError(
            f"shards count rejections for {arrays['rejected'].shape[1:]} reasons, not "
            f"{len(REJECT_REASONS)} ({', '.join(REJECT_REASONS)}); rerun generate"
        )
    rejected: dict[str, Counter] = {}
    # The family is drawn once per scene index, before any attempt, so every rejected
    # attempt of a scene was an attempt at that scene's family.
    for family, row in zip(families, arrays["rejected"]):
        rejected.setdefault(family, Counter()).update(
            {r: int(c) for r, c in zip(REJECT_REASONS, row)}
        )
    moved = sum(
        float(moved_matrix(r[:n, :n], threshold_m).sum(axis=1).mean())
        for r, n in zip(arrays["removal_m"], n_obj)
    )
    return Tally(Counter(n_obj.tolist()), Counter(families), rejected, moved)


def shares(weights: Mapping[str, float]) -> dict[str, float]:
    """Weights normalized to sum to 1."""
    total = sum(weights.values())
    return {k: v / total for k, v in sorted(weights.items())}


def uniform_counts(lo: int, hi: int, n_scenes: int) -> dict[int, float]:
    """Expected scenes per box count when it is drawn uniformly from [lo, hi]."""
    return {n: n_scenes / (hi - lo + 1) for n in range(lo, hi + 1)}


def mix_stats(tally: Tally, ds: DatasetConfig | None) -> dict[str, Any]:
    """Realized family shares, box-count histogram and rejections, beside what `ds` asks."""
    n_scenes = sum(tally.scenes_by_n.values())
    lo, hi = ds.n_objects if ds else (min(tally.scenes_by_n), max(tally.scenes_by_n))
    counts = sorted(set(range(lo, hi + 1)) | set(tally.scenes_by_n))
    asked = uniform_counts(lo, hi, n_scenes) if ds else {}
    return {
        "family_share": shares(tally.scenes_by_family),
        "family_share_asked": shares(ds.families) if ds else None,
        "objects_hist": {str(n): tally.scenes_by_n.get(n, 0) for n in counts},
        "objects_hist_asked": {str(n): asked.get(n, 0.0) for n in counts} if ds else None,
        "objects_mean_asked": (lo + hi) / 2 if ds else None,
        "rejected_by_family": {
            f: {r: int(c.get(r, 0)) for r in REJECT_REASONS}
            for f, c in sorted(tally.rejected_by_family.items())
        },
    }


def cluster_counts(gen_dir: Path, name: str, split: Mapping[str, Any]) -> dict[str, Any] | None:
    """Per split, the arrangement clusters (thesis 5.2.1) per class that some pixel shows, as
    the detector sees them; None for shards without clusters."""
    if "cluster_class" not in ShardStore(gen_dir, name, cache_shards=1).array_names():
        return None
    where = {int(i): part for part in ("train", "val", "test") for i in split[part]}
    counts = {part: Counter() for part in ("train", "val", "test")}
    for a in iter_shards(gen_dir, name, CLUSTER_KEYS):
        for s, classes, boxes in zip(a["scene_index"], a["cluster_class"], a["cluster_bbox_px"]):
            seen = (classes >= 0) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
            if int(s) in where:
                counts[where[int(s)]].update(int(c) for c in classes[seen])
    return {
        part: {c: int(counts[part][k]) for k, c in enumerate(ARRANGEMENT_CLASSES)}
        for part in counts
    }


def cluster_rows(name: str, s: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Rows of the clusters table for one dataset's stats: one per split that has scenes
    (none without clusters)."""
    rows = []
    for part, counts in (s.get("clusters") or {}).items():
        if s[part] == 0:
            continue
        total = sum(counts.values())
        rows.append(
            {"dataset": name, "split": part, "scenes": s[part], **counts, "clusters": total}
        )
    return rows


def dataset_stats(
    gen_dir: Path,
    split_dir: Path,
    name: str,
    threshold_m: float,
    pulls: bool,
    ds: DatasetConfig | None = None,
) -> dict[str, Any]:
    """One dataset's figures; with `ds` (its params) also what they asked for."""
    manifest = read_manifest(gen_dir, name)
    split = load_split(split_dir / f"{name}.json", gen_dir)
    tally = sum(
        (tally_shard(a, threshold_m) for a in iter_shards(gen_dir, name, READ_KEYS)), Tally()
    )
    n_obj = np.array(list(tally.scenes_by_n.elements()), dtype=np.int64)
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
        "moved_per_removal": tally.moved_sum / max(len(n_obj), 1),
        "rejected": int(sum(manifest["rejected"].values())),
        "rejected_by_reason": manifest["rejected"],
        "families": manifest["families"],
        "clusters": cluster_counts(gen_dir, name, split),
        **mix_stats(tally, ds),
    }


def family_rows(name: str, s: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Rows of the families table for one dataset's stats: every family realized or asked."""
    asked = s.get("family_share_asked") or {}
    rows = []
    for f in sorted(set(s["family_share"]) | set(asked)):
        scenes = int(s["families"].get(f, 0))
        rejected = s["rejected_by_family"].get(f, dict.fromkeys(REJECT_REASONS, 0))
        rows.append(
            {
                "dataset": name,
                "family": f,
                "scenes": scenes,
                "share": s["family_share"].get(f, 0.0),
                "share_asked": asked.get(f),
                **{f"rejected_{r}": rejected[r] for r in REJECT_REASONS},
                "rejected_per_scene": sum(rejected.values()) / scenes if scenes else None,
            }
        )
    return rows


def object_rows(name: str, s: Mapping[str, Any]) -> list[dict[str, Any]]:
    asked = s.get("objects_hist_asked") or {}
    return [
        {"dataset": name, "n_objects": int(n), "scenes": c, "scenes_asked": asked.get(n)}
        for n, c in s["objects_hist"].items()
    ]


def records_frame(records: list[dict[str, Any]], columns: list[Column]) -> pd.DataFrame:
    """Records keyed by Column.key -> a frame headed by Column.header, in column order."""
    frame = pd.DataFrame.from_records(records, columns=[c.key for c in columns])
    return frame.rename(columns={c.key: c.header for c in columns})


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
            "objects / scene asked: the mean of params' uniform n_objects range.",
            "realized mix: datasets_families.md (families, rejections), datasets_objects.md.",
            "ch5_arrangement: the arrangement detector's data; its samples are its scenes (one "
            "depth image each), its clusters per class in datasets_clusters.md.",
        ],
    )
    families = [r for name, s in stats.items() for r in family_rows(name, s)]
    write_table(
        records_frame(families, FAMILY_COLUMNS),
        FAMILY_COLUMNS,
        out_dir,
        "datasets_families",
        "Scene families: realized vs asked",
        notes=[
            "share asked: params' family weights, normalized.",
            "rejected: draws discarded before the scene was accepted, counted under the "
            "scene's family (drawn once per scene index); rejected / scene per accepted scene.",
        ],
    )
    objects = [r for name, s in stats.items() for r in object_rows(name, s)]
    write_table(
        records_frame(objects, OBJECT_COLUMNS),
        OBJECT_COLUMNS,
        out_dir,
        "datasets_objects",
        "Boxes per scene: realized vs asked",
        notes=["scenes asked: expected count under params' uniform n_objects range."],
    )
    clusters = [r for name, s in stats.items() for r in cluster_rows(name, s)]
    write_table(
        records_frame(clusters, CLUSTER_COLUMNS),
        CLUSTER_COLUMNS,
        out_dir,
        "datasets_clusters",
        "Arrangement clusters per class and split (thesis 5.2.1)",
        notes=[
            "C^h stacked, C^v shelved (and every single box), C^r / C^l leaning right / left "
            "in the image; classes from the settled tilt (sim/clusters.py).",
            "clusters some pixel shows (the detector's ground truth); hidden ones not counted.",
        ],
    )
