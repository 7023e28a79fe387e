"""Offline evaluation of a checkpoint on a test split (thesis 5.3.1, 4.4.1; Tables 5.1,
6.1, 4.2).

Metrics of the collapse class are reported at the fixed params threshold (the thesis' rule),
summed over all test pixels (Tables 5.1, 6.1) and averaged over test samples (Table 4.2), and
at the threshold with the best IoU on a validation split, chosen without looking at the test
set.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from collections.abc import Set as AbstractSet
from pathlib import Path
from typing import Any

import numpy as np
import torch

from clutterbench.collapse.config import EvaluateConfig
from clutterbench.collapse.metrics import PixelCounts, best_iou_row, sweep_row
from clutterbench.collapse.predict import CollapsePredictor, forward_probs
from clutterbench.data.dataset import GroupedLoader, PairDataset, open_pairs
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.models.checkpoint import check_compatible, head_channel, load_checkpoint
from clutterbench.progress import progress_bar

ProbSource = Callable[[dict[str, torch.Tensor]], torch.Tensor]
"""A batch of P samples grouped by scene (Dataset.batch: depth_m (S, 1, H, W), scene_of
(P,), target (P, n_masks, H, W), collapse (P, 1, H, W)) -> collapse probabilities
(P, 1, H, W). The network in the stage; tests inject others (e.g. the
truth)."""

SCORES = ("pixel_accuracy", "iou", "precision", "recall")


@dataclasses.dataclass(frozen=True)
class SplitRef:
    """One split of one generated dataset, with the label threshold of that dataset."""

    dataset: str
    split_file: Path
    split: str
    threshold_m: float
    """A box counts as moved above this displacement (generate.datasets.<d>)."""
    collapse_free: tuple[float, float] | None = None
    """(drop_m, tilt_deg) of trials.collapse_free: what the pull_collapse labels call a
    collapse (None: no such labels are read)."""

    def load(self, gen_dir: Path, n_masks: int = 1, head: str = "deletion") -> PairDataset:
        """The samples of a network with `n_masks` input masks (1: targets, 2: pulls),
        labelled for its head `head` (data.labels.LABEL_KINDS)."""
        ds = open_pairs(
            n_masks,
            gen_dir,
            self.split_file,
            self.split,
            self.threshold_m,
            labels=(head,),
            collapse_free=self.collapse_free,
        )
        if len(ds) == 0:
            raise ClutterbenchError(
                f"{self.split_file}: the '{self.split}' split holds no (scene, target) pairs"
            )
        return ds


@dataclasses.dataclass(frozen=True)
class EvalResult:
    metrics: dict[str, Any]
    """Test scores at the params threshold (summed over pixels, and per-sample means) and at
    the val-chosen one, set sizes, choice."""
    sweep: list[dict[str, float]]
    """Test scores at every sweep threshold."""
    val_sweep: list[dict[str, float]]
    """Validation scores at every sweep threshold (the threshold is chosen from these)."""
    samples: dict[str, np.ndarray]
    """Test pairs for the figure: depth_m, target (n_masks, H, W each), truth, prob."""


def check_val_split(test: SplitRef, val: SplitRef, trained_on: str | None, key: str) -> None:
    """The threshold is chosen on a val split of the evaluated dataset or, where it has none
    (ch6_test), of the dataset the model was trained on; never on the evaluated split."""
    if (val.dataset, val.split) == (test.dataset, test.split):
        raise ClutterbenchError(f"{key}: would choose the threshold on the evaluated split itself")
    if val.dataset not in (test.dataset, trained_on):
        raise ClutterbenchError(
            f"{key}: '{val.dataset}' is neither the evaluated dataset '{test.dataset}' nor "
            f"the model's training dataset '{trained_on}'"
        )


def network_probs(predictor: CollapsePredictor) -> ProbSource:
    def probs(batch: dict[str, torch.Tensor]) -> torch.Tensor:
        return forward_probs(
            predictor.model,
            batch["depth_m"],
            batch["target"],
            predictor.bf16,
            predictor.channels_last,
            batch["scene_of"],
            predictor.channel,
        )

    return probs


def accumulate(
    ds: PairDataset,
    probs: ProbSource,
    threshold: float,
    batch_size: int,
    picks: AbstractSet[int] = frozenset(),
    desc: str = "evaluate",
) -> tuple[PixelCounts, dict[str, list[np.ndarray]]]:
    """Pixel counts of the whole set at `threshold` (plus the sweep histogram), and the
    arrays of the pairs in `picks` for the figure."""
    counts = PixelCounts(threshold)
    samples: dict[str, list[np.ndarray]] = {k: [] for k in ("depth_m", "target", "truth", "prob")}
    loader = GroupedLoader(ds, batch_size=batch_size)
    with torch.no_grad(), progress_bar(desc, len(ds)) as advance:
        start = 0
        for batch in loader:
            prob = probs(batch)
            counts.update(prob, batch["collapse"])
            for j in range(len(prob)):
                if start + j in picks:
                    depth = batch["depth_m"][int(batch["scene_of"][j]), 0]
                    samples["depth_m"].append(depth.numpy())
                    samples["target"].append(batch["target"][j].numpy())
                    samples["truth"].append(batch["collapse"][j, 0].numpy())
                    samples["prob"].append(prob[j, 0].numpy())
            start += len(prob)
            advance(len(prob))
    return counts, samples


def choose_on_val(
    val_ds: PairDataset, probs: ProbSource, cfg: EvaluateConfig, desc: str = "evaluate"
) -> tuple[dict[str, float], list[dict[str, float]]]:
    """The threshold sweep row with the best IoU on `val_ds` (the chosen threshold), and the
    whole val sweep; a one-line error where the split holds no collapse pixel."""
    val_counts, _ = accumulate(val_ds, probs, cfg.threshold, cfg.batch_size, desc=f"{desc} val")
    if val_counts.tp + val_counts.fn == 0:
        raise ClutterbenchError(
            f"{desc}: the validation split holds no collapse pixels; no threshold can be chosen"
        )
    val_sweep = val_counts.sweep()
    return best_iou_row(val_sweep), val_sweep


def val_chosen_threshold(
    ckpt_path: Path, gen_dir: Path, val: SplitRef, cfg: EvaluateConfig, head: str = "deletion"
) -> dict[str, float]:
    """The val sweep row a checkpoint's threshold is chosen by, as evaluate_checkpoint chooses
    it (its `threshold` and `iou`), scoring no other split."""
    ckpt = load_checkpoint(ckpt_path)
    channel = head_channel(ckpt, ckpt_path, head)
    val_ds = val.load(gen_dir, ckpt.net.n_masks, head)
    check_compatible(ckpt, ckpt_path, int(val_ds.scenes["depth_m"].shape[-1]))
    predictor = CollapsePredictor(ckpt.model(), channel=channel, head=head)
    return choose_on_val(val_ds, network_probs(predictor), cfg, f"val {ckpt_path.parent.name}")[0]


def evaluate_sets(
    test_ds: PairDataset,
    val_ds: PairDataset,
    probs: ProbSource,
    cfg: EvaluateConfig,
    desc: str = "evaluate",
) -> EvalResult:
    """Choose the threshold on `val_ds`, then score `test_ds` at the params threshold and
    at the chosen one (sweep rows count prob > t like the summary, so reading the test sweep
    at the chosen threshold is exact)."""
    chosen, val_sweep = choose_on_val(val_ds, probs, cfg, desc)
    picks = figure_pairs(test_ds, cfg.figure_samples)
    counts, samples = accumulate(
        test_ds, probs, cfg.threshold, cfg.batch_size, picks, desc=f"{desc} test"
    )
    sweep = counts.sweep()
    at_chosen = sweep_row(sweep, chosen["threshold"])
    n_pos, n_all = counts.tp + counts.fn, counts.tp + counts.fn + counts.fp + counts.tn
    metrics = {
        **counts.summary(),
        **counts.pair_means(),
        "threshold": cfg.threshold,
        "pairs": len(test_ds),
        "scenes": int(len(test_ds.scenes["n_objects"])),
        "positive_pixel_fraction": n_pos / max(n_all, 1),
        "val_chosen_threshold": chosen["threshold"],
        "val_iou_at_chosen": chosen["iou"],
        "val_pairs": len(val_ds),
        "val_scenes": int(len(val_ds.scenes["n_objects"])),
        **{f"{k}_at_val_chosen": at_chosen[k] for k in SCORES},
    }
    stacked = {k: np.stack(v) for k, v in samples.items()}
    return EvalResult(metrics, sweep, val_sweep, stacked)


def evaluate_checkpoint(
    ckpt_path: Path,
    gen_dir: Path,
    test: SplitRef,
    val: SplitRef,
    cfg: EvaluateConfig,
    val_key: str = "val_dataset",
    head: str = "deletion",
) -> EvalResult:
    """Rebuild the network from its checkpoint alone and evaluate its head `head` (see
    evaluate_sets) on the samples its inputs take (its n_masks), labelled for that head."""
    ckpt = load_checkpoint(ckpt_path)
    channel = head_channel(ckpt, ckpt_path, head)
    n_masks = ckpt.net.n_masks
    test_ds, val_ds = test.load(gen_dir, n_masks, head), val.load(gen_dir, n_masks, head)
    for ds in (test_ds, val_ds):
        check_compatible(ckpt, ckpt_path, int(ds.scenes["depth_m"].shape[-1]))
    check_val_split(test, val, ckpt.meta.get("dataset"), val_key)
    predictor = CollapsePredictor(ckpt.model(), channel=channel, head=head)
    desc = f"evaluate {ckpt_path.parent.name}"
    return evaluate_sets(test_ds, val_ds, network_probs(predictor), cfg, desc)


def write_sweep_csv(path: Path, sweep: list[dict[str, float]]) -> None:
    header = list(sweep[0])
    lines = [",".join(header)] + [",".join(f"{r[h]:.6g}" for h in header) for r in sweep]
    write_text(path, "\n".join(lines) + "\n")


def figure_pairs(ds: PairDataset, n: int) -> set[int]:
    """`n` pairs spread evenly over the set, from those where something collapses (the
    interesting ones in thesis Fig. 4.8 / 5.8 / 6.5), topped up with quiet ones if too few."""
    collapsing, quiet = [], []
    for i in range(len(ds)):
        (collapsing if ds.pair_collapses(i) else quiet).append(i)
    chosen = _spread(collapsing, n)
    return set(chosen + _spread(quiet, n - len(chosen)))


def _spread(items: list[int], n: int) -> list[int]:
    if n <= 0 or not items:
        return []
    if len(items) <= n:
        return list(items)
    return [items[int(k)] for k in np.linspace(0, len(items) - 1, n).round()]
