"""The box head's data, training and scores (stage box_head): pair features of every scene
from the frozen collapse predictor, a few minutes of training on the train split's pairs,
the epoch and each output's threshold chosen on the val split's, the test dataset's pairs
scored in Table 6.1's terms (precision, recall, AUROC, calibration) beside the pixel heads
read per box (each head's mean over the box), per family and box count."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd
import torch

from clutterbench.collapse.box_head import (
    OUTPUTS,
    BoxHead,
    feature_names,
    off_diagonal,
    pair_features,
    pair_labels,
    predict_pairs,
)
from clutterbench.collapse.box_predict import cp_probs_of
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.progress import progress_bar
from clutterbench.support.config import BoxHeadConfig
from clutterbench.support.evaluate import Scene

THRESHOLDS = np.round(np.arange(0.05, 0.96, 0.05), 2)
"""Each output's decision threshold is chosen among these on val pairs (best f1)."""
CALIBRATION_BINS = 10


@dataclasses.dataclass
class Pairs:
    """Every ordered pair (pulled x, other y) of some scenes: features, labels, who they are."""

    x: np.ndarray  # (n, F) float32
    y: np.ndarray  # (n, len(OUTPUTS)) float32
    rows: pd.DataFrame  # scene, family, n_objects, visible, pulled, other

    def __len__(self) -> int:
        return len(self.x)


def cp_probs(predictor: CollapsePredictor, scene: Scene) -> np.ndarray:
    """cp_probs_of a scene's visible boxes."""
    return cp_probs_of(predictor, scene.depth_m, scene.masks)


def scene_pairs(scene: Scene, probs: np.ndarray) -> Pairs:
    """One scene's pairs (its gaps_m and pull truth must have been read)."""
    assert scene.gaps_m is not None, "box-head pairs need the scene's surface gaps"
    feats = off_diagonal(pair_features(probs, scene.masks, scene.depth_m, scene.gaps_m))
    labels = off_diagonal(pair_labels(scene.moved_by, scene.contact))
    k = len(scene.ids)
    xi, yi = np.nonzero(~np.eye(k, dtype=bool))
    ids = np.asarray(scene.ids)
    rows = pd.DataFrame(
        {
            "scene": scene.index,
            "family": scene.family,
            "n_objects": scene.n_objects,
            "visible": k,
            "pulled": ids[xi],
            "other": ids[yi],
        }
    )
    return Pairs(feats, labels, rows)


def collect(scenes: Iterable[Scene], predictor: CollapsePredictor, label: str, total: int) -> Pairs:
    """The pairs of every scene with two or more visible boxes."""
    parts: list[Pairs] = []
    with progress_bar(label, total=total) as advance:
        for scene in scenes:
            if len(scene.ids) > 1:
                parts.append(scene_pairs(scene, cp_probs(predictor, scene)))
            advance(1)
    n_feat = len(feature_names(()))  # geometry only when no scene had pairs
    if not parts:
        return Pairs(
            np.zeros((0, n_feat), np.float32),
            np.zeros((0, len(OUTPUTS)), np.float32),
            pd.DataFrame(),
        )
    return Pairs(
        np.concatenate([p.x for p in parts]),
        np.concatenate([p.y for p in parts]),
        pd.concat([p.rows for p in parts], ignore_index=True),
    )


def _loss(model: BoxHead, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    return torch.nn.functional.binary_cross_entropy_with_logits(model(x), y)


def train_box_head(
    train: Pairs, val: Pairs, cfg: BoxHeadConfig, seed: int
) -> tuple[BoxHead, pd.DataFrame, int]:
    """The model of least val loss over cfg.epochs, the per-epoch log and that epoch."""
    torch.manual_seed(seed)
    model = BoxHead(train.x.shape[1], cfg.hidden)
    x, y = torch.from_numpy(train.x), torch.from_numpy(train.y)
    model.mean.copy_(x.mean(0))
    model.std.copy_(x.std(0).clamp_min(1e-6))
    xv, yv = torch.from_numpy(val.x), torch.from_numpy(val.y)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    gen = torch.Generator().manual_seed(seed)
    best, best_epoch, best_state, log = float("inf"), 0, None, []
    with progress_bar("box_head: epochs", total=cfg.epochs) as advance:
        for epoch in range(1, cfg.epochs + 1):
            model.train()
            total = 0.0
            for idx in torch.randperm(len(x), generator=gen).split(cfg.batch_size):
                opt.zero_grad()
                loss = _loss(model, x[idx], y[idx])
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(idx)
            model.eval()
            with torch.no_grad():
                val_loss = float(_loss(model, xv, yv)) if len(xv) else float("nan")
            log.append({"epoch": epoch, "train_loss": total / max(len(x), 1), "val_loss": val_loss})
            if val_loss < best or best_state is None:
                best, best_epoch = val_loss, epoch
                best_state = {k: v.clone() for k, v in model.state_dict().items()}
            advance(1)
    assert best_state is not None
    model.load_state_dict(best_state)
    return model.eval(), pd.DataFrame(log), best_epoch


def average_ranks(p: np.ndarray) -> np.ndarray:
    """1-based ranks of finite `p`, ties given their mean rank: pandas' rank(method="average"),
    value for value, without its per-call overhead (the test set's bootstrap calls it ~10^4
    times)."""
    order = np.argsort(p, kind="stable")
    ordered = p[order]
    new = np.empty(len(p), dtype=bool)
    new[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=new[1:])
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], len(p))
    ranks = np.empty(len(p), dtype=np.float64)
    ranks[order] = np.repeat((starts + 1 + ends) / 2.0, ends - starts)
    return ranks


def auroc(p: np.ndarray, y: np.ndarray) -> float:
    """Area under the ROC curve (ties averaged); NaN without both classes."""
    y = y.astype(bool)
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if not n_pos or not n_neg:
        return float("nan")
    p = np.asarray(p, dtype=np.float64)
    if np.isnan(p).any():  # pandas leaves a NaN unranked, and the sum NaN where it is positive
        ranks = pd.Series(p).rank(method="average").to_numpy()
    else:
        ranks = average_ranks(p)
    return float((ranks[y].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def calibration(p: np.ndarray, y: np.ndarray, bins: int = CALIBRATION_BINS) -> pd.DataFrame:
    """Reliability bins: mean prediction, observed rate and count per equal-width bin."""
    which = np.minimum((p * bins).astype(int), bins - 1)
    rows = []
    for b in range(bins):
        sel = which == b
        if sel.any():
            rows.append(
                {
                    "bin": b,
                    "predicted": float(p[sel].mean()),
                    "observed": float(y[sel].mean()),
                    "n": int(sel.sum()),
                }
            )
    return pd.DataFrame(rows, columns=["bin", "predicted", "observed", "n"])


def binary_scores(p: np.ndarray, y: np.ndarray, threshold: float) -> dict[str, float]:
    """Precision, recall, f1 at `threshold`, AUROC, expected calibration error, Brier score."""
    y = y.astype(bool)
    pred = p > threshold
    tp = int((pred & y).sum())
    precision = tp / int(pred.sum()) if pred.any() else float("nan")
    recall = tp / int(y.sum()) if y.any() else float("nan")
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else float("nan")
    cal = calibration(p, y)
    ece = float((cal["n"] * (cal["predicted"] - cal["observed"]).abs()).sum() / max(len(p), 1))
    return {
        "n": int(len(p)),
        "positives": int(y.sum()),
        "threshold": float(threshold),
        "precision": precision,
        "recall": recall,
        "f1": f1,
        "auroc": auroc(p, y),
        "ece": ece,
        "brier": float(((p - y) ** 2).mean()) if len(p) else float("nan"),
    }


def choose_threshold(p: np.ndarray, y: np.ndarray) -> float:
    """The threshold of THRESHOLDS with the best f1 on these (val) pairs (ties: the lowest)."""
    best, best_f1 = float(THRESHOLDS[len(THRESHOLDS) // 2]), -1.0
    for t in THRESHOLDS:
        f1 = binary_scores(p, y, float(t))["f1"]
        if np.isfinite(f1) and f1 > best_f1:
            best, best_f1 = float(t), f1
    return best


def predictors_of(model: BoxHead, pairs: Pairs, heads: Sequence[str]) -> dict[str, np.ndarray]:
    """method -> (n, len(OUTPUTS)) probability per pair: the box head, and each pixel head
    of the collapse predictor read per box (its mean over the box; NaN for contact)."""
    out = {"box_head": predict_pairs(model, pairs.x)}
    names = feature_names(heads)
    for h in heads:
        if h in OUTPUTS:
            cols = np.full((len(pairs), len(OUTPUTS)), np.nan, np.float32)
            cols[:, OUTPUTS.index(h)] = pairs.x[:, names.index(f"{h}_mean")]
            out[f"pixel_{h}"] = cols
    return out


def score_methods(
    methods: dict[str, np.ndarray],
    val_methods: dict[str, np.ndarray],
    test: Pairs,
    val: Pairs,
) -> tuple[pd.DataFrame, dict[str, dict[str, float]]]:
    """Per method and output: the val-chosen threshold, then the test scores overall, per
    family and per visible-box count."""
    rows, chosen = [], {}
    groups: list[tuple[str, Any]] = [("all", slice(None))]
    if len(test):
        groups += [
            (f"family={f}", test.rows["family"].to_numpy() == f)
            for f in sorted(set(test.rows["family"]))
        ]
        vis = test.rows["visible"].to_numpy()
        groups += [("visible=2-5", vis <= 5), ("visible=6-10", vis >= 6)]
    for method, probs in methods.items():
        for j, out in enumerate(OUTPUTS):
            if np.isnan(probs[:, j]).all():
                continue
            t = choose_threshold(val_methods[method][:, j], val.y[:, j])
            chosen.setdefault(method, {})[out] = t
            for group, sel in groups:
                s = binary_scores(probs[sel, j], test.y[sel, j], t)
                rows.append({"method": method, "output": out, "group": group} | s)
    return pd.DataFrame(rows), chosen
