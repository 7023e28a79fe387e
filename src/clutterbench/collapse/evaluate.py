"""Offline evaluation of a checkpoint on a test split (thesis 5.3.1, Table 5.1 / 6.1)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.collapse.metrics import PixelCounts
from clutterbench.collapse.predict import CollapsePredictor, forward_probs
from clutterbench.data.dataset import CollapseDataset
from clutterbench.data.labels import moved_matrix
from clutterbench.errors import ClutterbenchError
from clutterbench.progress import progress_bar


def evaluate_checkpoint(
    ckpt_path: Path,
    gen_dir: Path,
    split_file: Path,
    split: str,
    threshold_m: float,
    cfg: EvaluateConfig,
) -> tuple[dict[str, Any], list[dict[str, float]], dict[str, np.ndarray]]:
    """Returns (metrics at cfg.threshold, threshold sweep rows, figure samples)."""
    ds = CollapseDataset(gen_dir, split_file, split, threshold_m)
    if len(ds) == 0:
        raise ClutterbenchError(f"{split_file}: the '{split}' split holds no (scene, target) pairs")
    size = int(ds.scenes["depth_m"].shape[-1])
    predictor = CollapsePredictor.from_checkpoint(ckpt_path, image_size=size)
    counts = PixelCounts(cfg.threshold)
    picks = figure_pairs(ds, cfg.figure_samples)
    samples: dict[str, list[np.ndarray]] = {k: [] for k in ("depth_m", "target", "truth", "prob")}
    loader = DataLoader(ds, batch_size=cfg.batch_size)
    with torch.no_grad(), progress_bar(f"evaluate {ckpt_path.parent.name}", len(ds)) as advance:
        start = 0
        for batch in loader:
            d, t, y = batch["depth_m"], batch["target"], batch["collapse"]
            prob = forward_probs(predictor.model, d, t, predictor.bf16, predictor.channels_last)
            counts.update(prob, y)
            for j in range(len(d)):
                if start + j in picks:
                    samples["depth_m"].append(d[j, 0].numpy())
                    samples["target"].append(t[j, 0].numpy())
                    samples["truth"].append(y[j, 0].numpy())
                    samples["prob"].append(prob[j, 0].numpy())
            start += len(d)
            advance(len(d))
    metrics = {
        **counts.summary(),
        "threshold": cfg.threshold,
        "pairs": len(ds),
        "scenes": int(len(ds.scenes["n_objects"])),
        "positive_pixel_fraction": (counts.tp + counts.fn)
        / max(counts.tp + counts.fn + counts.fp + counts.tn, 1),
    }
    return metrics, counts.sweep(), {k: np.stack(v) for k, v in samples.items()}


def figure_pairs(ds: CollapseDataset, n: int) -> set[int]:
    """`n` pairs spread evenly over the set, from those where something collapses (the
    interesting ones in thesis Fig. 5.8 / 6.5), topped up with quiet ones if too few."""
    collapsing, quiet = [], []
    for i, (s, x) in enumerate(ds.pairs):
        n_obj = int(ds.scenes["n_objects"][s])
        moved = moved_matrix(ds.scenes["removal_m"][s, :n_obj, :n_obj], ds.threshold_m)[x]
        (collapsing if moved.any() else quiet).append(i)
    chosen = _spread(collapsing, n)
    return set(chosen + _spread(quiet, n - len(chosen)))


def _spread(items: list[int], n: int) -> list[int]:
    if n <= 0 or not items:
        return []
    if len(items) <= n:
        return list(items)
    return [items[int(k)] for k in np.linspace(0, len(items) - 1, n).round()]
