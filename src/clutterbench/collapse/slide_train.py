"""Training and validation of the chapter 3 slide ConvNet (thesis 3.3, 3.5.1).

Adam on the two-way cross-entropy (softmax, eq. 3.2), mirror augmentation (a crop mirrored
about the slide's axis is the mirrored pile slid the mirrored way: same label), early stopping
on validation loss; the best epoch's weights are models/slide_convnet/best.pt. Reported on
the validation piles (never trained on): accuracy, precision / recall of "success", and a
calibration table and plot (predicted probability vs simulated success rate), because the
planner ranks candidates by that probability.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from clutterbench.config import as_dict, bounded
from clutterbench.denormals import flush_denormals
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.logs.csv_log import CsvLog
from clutterbench.models.slide_convnet import (
    SUCCESS,
    SlideConvNet,
    SlideConvNetConfig,
    save_slide_convnet,
    success_probability,
)
from clutterbench.progress import progress_bar

LOG_COLUMNS = ("epoch", "train_loss", "val_loss", "val_accuracy")
CALIBRATION_BINS = 10


@dataclasses.dataclass(frozen=True)
class SlideTrainConfig:
    net: SlideConvNetConfig = dataclasses.field(default_factory=SlideConvNetConfig)
    epochs: int = bounded(30, ge=1)
    """Most epochs; training stops earlier when validation loss stops improving."""
    patience: int = bounded(5, ge=1)
    """Epochs without a better validation loss before stopping."""
    batch_size: int = bounded(64, ge=1)
    lr: float = bounded(5e-4, gt=0.0)
    weight_decay: float = bounded(1e-4, ge=0.0)
    mirror: bool = True
    """Mirror augmentation about the slide axis (label-preserving)."""


def _targets(labels: np.ndarray) -> torch.Tensor:
    """Class index per sample: SUCCESS (0) for a successful slide, 1 for a failure."""
    return torch.as_tensor(np.where(labels == 1, SUCCESS, 1 - SUCCESS), dtype=torch.int64)


@torch.no_grad()
def _val_loss(model: SlideConvNet, x: torch.Tensor, y: torch.Tensor, batch: int) -> float:
    model.eval()
    total = sum(
        float(F.cross_entropy(model(x[i : i + batch]), y[i : i + batch], reduction="sum"))
        for i in range(0, len(x), batch)
    )
    return total / max(len(x), 1)


def calibration(probs: np.ndarray, labels: np.ndarray, bins: int = CALIBRATION_BINS) -> list:
    """Per probability bin: [low, high, n, mean predicted, simulated success rate]."""
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.clip(np.digitize(probs, edges) - 1, 0, bins - 1)
    rows = []
    for b in range(bins):
        sel = which == b
        n = int(sel.sum())
        rows.append(
            [
                float(edges[b]),
                float(edges[b + 1]),
                n,
                float(probs[sel].mean()) if n else None,
                float(labels[sel].mean()) if n else None,
            ]
        )
    return rows


def classification_metrics(probs: np.ndarray, labels: np.ndarray) -> dict[str, Any]:
    pred = probs >= 0.5
    truth = labels == 1
    tp, fp, fn = int((pred & truth).sum()), int((pred & ~truth).sum()), int((~pred & truth).sum())
    return {
        "n": int(len(labels)),
        "accuracy": float((pred == truth).mean()) if len(labels) else float("nan"),
        "precision": tp / (tp + fp) if tp + fp else float("nan"),
        "recall": tp / (tp + fn) if tp + fn else float("nan"),
        "calibration": calibration(probs, labels.astype(np.float64)),
    }


def _crops(samples: dict[str, np.ndarray], cfg: SlideTrainConfig) -> np.ndarray:
    """The samples' crops as float32, refused unless they are the network's input size."""
    crops = np.asarray(samples["crops"], dtype=np.float32)
    if crops.shape[1:] != (cfg.net.input_size, cfg.net.input_size):
        raise ClutterbenchError(
            f"slide samples are {crops.shape[1]}x{crops.shape[2]} crops but "
            f"yamakuzushi.convnet.net.input_size is {cfg.net.input_size}; make them equal "
            "(yamakuzushi.scan.crop_px)"
        )
    return crops


def _train_epoch(
    model: SlideConvNet,
    opt: torch.optim.Adam,
    xt: torch.Tensor,
    yt: torch.Tensor,
    cfg: SlideTrainConfig,
    gen: torch.Generator,
) -> float:
    """One pass over the training crops in shuffled batches (each crop mirrored with
    probability 1/2 under cfg.mirror); returns the summed loss (batch mean times size)."""
    model.train()
    order = torch.randperm(len(xt), generator=gen)
    total = 0.0
    for i in range(0, len(order), cfg.batch_size):
        idx = order[i : i + cfg.batch_size]
        xb = xt[idx]
        if cfg.mirror:
            flip = torch.rand(len(idx), generator=gen) < 0.5
            xb = torch.where(flip[:, None, None, None], xb.flip(-1), xb)
        loss = F.cross_entropy(model(xb), yt[idx])
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += float(loss.detach()) * len(idx)
    return total


@flush_denormals()
def train_slide_convnet(
    samples: dict[str, np.ndarray],
    cfg: SlideTrainConfig,
    seed: int,
    model_dir: Path,
    report_dir: Path,
) -> dict[str, Any]:
    """Train on the samples with val == 0, select and report on val == 1; writes
    model_dir/best.pt, report_dir/{log.csv, metrics.json}; returns the metrics.

    Denormals are flushed throughout (the decorator, clutterbench.denormals): weight decay
    drives this network's weights and Adam moments below float32's normal range, where
    arithmetic is many times slower on some CPUs. Torch's worker threads take the setting only
    when they are started inside the block, so a stage calls this before any other parallel
    torch work."""
    crops = _crops(samples, cfg)
    val = samples["val"].astype(bool)
    if val.all() or not val.any():
        raise ClutterbenchError("slide samples: need both training and validation piles")
    x = torch.as_tensor(crops[:, None])
    y = _targets(samples["label"])
    xt, yt, xv, yv = x[~val], y[~val], x[val], y[val]
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    model = SlideConvNet(cfg.net)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    log = CsvLog(report_dir / "log.csv", LOG_COLUMNS)
    best = {"epoch": 0, "val_loss": float("inf"), "state": None}
    stale, started = 0, time.perf_counter()
    with progress_bar("train slide ConvNet", total=cfg.epochs) as advance:
        for epoch in range(1, cfg.epochs + 1):
            total = _train_epoch(model, opt, xt, yt, cfg, gen)
            val_loss = _val_loss(model, xv, yv, 256)
            val_acc = classification_metrics(
                success_probability(model, xv[:, 0]).numpy(), samples["label"][val]
            )["accuracy"]
            log.append(
                {
                    "epoch": epoch,
                    "train_loss": total / len(xt),
                    "val_loss": val_loss,
                    "val_accuracy": val_acc,
                }
            )
            advance(1)
            if val_loss < best["val_loss"]:
                state = {k: v.clone() for k, v in model.state_dict().items()}
                best = {"epoch": epoch, "val_loss": val_loss, "state": state}
                stale = 0
            else:
                stale += 1
                if stale >= cfg.patience:
                    break
    model.load_state_dict(best["state"])
    model.eval()
    probs = success_probability(model, xv[:, 0]).numpy()
    metrics = {
        "best_epoch": best["epoch"],
        "epochs_run": epoch,
        "val_loss": best["val_loss"],
        "n_train": int(len(xt)),
        "val": classification_metrics(probs, samples["label"][val]),
        "train_s": round(time.perf_counter() - started, 1),
    }
    meta = {"config": as_dict(cfg), "seed": seed, "best_epoch": best["epoch"]}
    save_slide_convnet(model_dir / "best.pt", model, meta)
    write_json(report_dir / "metrics.json", {k: v for k, v in metrics.items() if k != "train_s"})
    return metrics
