"""One training code path for every collapse network (thesis 5.2.2, 6.2.1).

Adam, per-pixel BCE or focal loss on a collapse map, or cross-entropy over the B / E / S / C
classes of thesis ch. 4 (4.3.1), early stopping on validation loss; the best epoch's
weights are saved as models/<name>/best.pt. Each epoch appends a row to the CSV log (dvc
plots) and a record plus a validation heatmap to the run's MCAP file (Foxglove). Wall times
go to a separate timing file that is no dvc output, so a rerun leaves every tracked output
byte-identical.
"""

from __future__ import annotations

import dataclasses
import os
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from clutterbench.collapse.config import TrainConfig, TrainModelConfig
from clutterbench.collapse.losses import bce_loss, ce_loss, focal_loss
from clutterbench.collapse.metrics import PixelCounts, best_iou_row
from clutterbench.collapse.predict import collapse_probs, forward_logits, forward_probs
from clutterbench.config import as_dict
from clutterbench.data.dataset import GroupedLoader, PairDataset, open_pairs
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.logs.csv_log import CsvLog
from clutterbench.logs.mcap_episode import EpisodeWriter
from clutterbench.models import build_model
from clutterbench.models.checkpoint import DEFAULT_HEADS, save_checkpoint
from clutterbench.progress import progress_bar
from clutterbench.sim.noise import DepthAugmentation

DEVICE_ENV = "CLUTTERBENCH_TRAIN_DEVICE"
"""Where training runs: cpu (the default), cuda, or auto (cuda when torch sees a GPU). It
changes where the numbers are computed, not what: no dvc parameter, results agree
statistically (bf16 autocast is a CPU setting, train.precision; on a GPU training runs in
float32 and records fp32)."""

LOG_COLUMNS = (
    "epoch",
    "train_loss",
    "val_loss",
    "val_pixel_accuracy",
    "val_iou",
    "val_precision",
    "val_recall",
    "val_iou_best",
    "val_best_threshold",
)
"""val_iou / precision / recall at train.val_threshold; val_iou_best: the best IoU over the
evaluate sweep's thresholds (at val_best_threshold), steadier from epoch to epoch where a
focal loss keeps probabilities low. A network with several heads (train.models.<m>.labels)
logs the summed loss as val_loss, its first head's scores unsuffixed, and every head's
loss and scores again with the head's name (HEAD_SCORES)."""
HEAD_SCORES = ("loss", "pixel_accuracy", "iou", "precision", "recall", "iou_best", "best_threshold")
"""Per-head validation columns of a multi-head network: val_<score>_<head>."""


def log_columns(heads: tuple[str, ...]) -> tuple[str, ...]:
    """The CSV log's columns: LOG_COLUMNS, and with several heads each head's own."""
    if len(heads) == 1:
        return LOG_COLUMNS
    return LOG_COLUMNS + tuple(f"val_{k}_{h}" for h in heads for k in HEAD_SCORES)


@dataclasses.dataclass(frozen=True)
class TrainPaths:
    gen_dir: Path
    split_file: Path
    model_dir: Path
    """models/<name>/: best.pt and train.mcap."""
    report_dir: Path
    """reports/train/<name>/: log.csv and summary.json."""
    timing_file: Path
    """Wall times (JSON); varies run to run, so kept out of dvc's outputs."""


def model_seed(base_seed: int, name: str) -> int:
    """Each model's own seed, stable across Python runs (no hash randomisation)."""
    return (base_seed * 1_000_003 + zlib.crc32(name.encode())) % 2**31


Loss = Callable[[torch.Tensor, dict[str, torch.Tensor]], torch.Tensor]
"""(logits, batch) -> mean loss; the loss picks its labels from the batch."""


def loss_fn(cfg: TrainConfig, mcfg: TrainModelConfig) -> Loss:
    """The model's loss; with several heads (labels) the sum over heads of the loss of each
    output channel on its own labels (batch["collapse"] has a channel per head)."""
    if mcfg.loss == "ce":
        return lambda logits, batch: ce_loss(logits, batch["classes"])
    if mcfg.loss == "focal":
        one: Loss = lambda logits, batch: focal_loss(logits, batch["collapse"], cfg.focal)  # noqa: E731
    else:
        one = lambda logits, batch: bce_loss(logits, batch["collapse"])  # noqa: E731
    if len(mcfg.labels) == 1:
        return one
    return lambda logits, batch: sum(
        one(logits[:, k : k + 1], _head_batch(batch, k)) for k in range(len(mcfg.labels))
    )


def _head_batch(batch: dict[str, torch.Tensor], k: int) -> dict[str, torch.Tensor]:
    """The batch with head k's labels only (channel k of collapse)."""
    return batch | {"collapse": batch["collapse"][:, k : k + 1]}


def image_size(ds: PairDataset) -> int:
    h, w = ds.scenes["depth_m"].shape[-2:]
    if h != w:
        raise ClutterbenchError(f"images are {h}x{w}; the networks take square images")
    return int(h)


def train_device(value: str | None = None) -> torch.device:
    """The device named by `value` (default: $CLUTTERBENCH_TRAIN_DEVICE, else cpu)."""
    name = (value if value is not None else os.environ.get(DEVICE_ENV, "cpu")).strip().lower()
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise ClutterbenchError(
            f"{DEVICE_ENV}=cuda but this torch build ({torch.__version__}) sees no GPU; "
            "install a CUDA build (TORCH_SPEC/TORCH_INDEX_URL, docs/platform.md) or use cpu"
        )
    if name not in ("cpu", "cuda"):
        raise ClutterbenchError(f"{DEVICE_ENV}={name!r}: use cpu, cuda or auto")
    return torch.device(name)


def to_device(batch: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    """The batch's tensors on `device` (the same objects when already there)."""
    return {k: v.to(device) for k, v in batch.items()}


def evaluate_loss(
    model: nn.Module,
    loader: GroupedLoader,
    loss: Loss,
    cfg: TrainConfig,
    threshold: float,
    heads: tuple[str, ...] = ("deletion",),
    head_loss: Loss | None = None,
) -> tuple[float, dict[str, float]]:
    """Mean loss and pixel scores of the collapse class over `loader` (eval mode, no grad).
    With several `heads`: the summed loss, the first head's scores, and each head's loss
    (`head_loss` on its channel) and scores suffixed _<head>."""
    model.eval()
    device = next(model.parameters()).device
    multi = len(heads) > 1
    counts = [PixelCounts(threshold) for _ in heads]
    totals, total, n = [0.0] * len(heads), 0.0, 0
    with torch.no_grad():
        for batch in loader:
            batch = to_device(batch, device)
            logits = batch_logits(model, batch, cfg)
            total += float(loss(logits, batch)) * len(logits)
            n += len(logits)
            if not multi:
                counts[0].update(collapse_probs(logits).cpu(), batch["collapse"].cpu())
                continue
            assert head_loss is not None, "a multi-head network needs the loss of one head"
            for k in range(len(heads)):
                head = _head_batch(batch, k)
                totals[k] += float(head_loss(logits[:, k : k + 1], head)) * len(logits)
                counts[k].update(collapse_probs(logits, k).cpu(), head["collapse"].cpu())
    per_head = []
    for c in counts:
        best = best_iou_row(c.sweep())
        per_head.append(
            c.summary() | {"iou_best": best["iou"], "best_threshold": best["threshold"]}
        )
    scores = dict(per_head[0])
    if multi:
        for head, t, sc in zip(heads, totals, per_head):
            scores |= {f"loss_{head}": t / max(n, 1)} | {f"{k}_{head}": v for k, v in sc.items()}
    return total / max(n, 1), scores


def train_model(
    name: str,
    cfg: TrainConfig,
    threshold_m: float,
    base_seed: int,
    paths: TrainPaths,
    collapse_free: tuple[float, float] | None = None,
    fovy_deg: float = 42.0,
) -> dict[str, Any]:
    """Train train.models[name]; returns the summary also written to summary.json.
    `collapse_free`: (drop_m, tilt_deg) of trials.collapse_free, for pull_collapse labels;
    `fovy_deg`: sim.camera's, for a sensor model's augmentation (train.sensing)."""
    mcfg = cfg.models[name]
    seed = model_seed(base_seed, name)
    torch.manual_seed(seed)
    heads = tuple(mcfg.labels)
    noise = cfg.augmentation(name, fovy_deg)
    train_ds, val_ds, size = _open_splits(name, cfg, threshold_m, seed, paths, collapse_free, noise)
    device = train_device()
    precision = ("bf16" if cfg.bf16 else "fp32") if device.type == "cpu" else "fp32"
    model = build_model(mcfg.arch, mcfg.net).to(device)
    if cfg.channels_last:
        model = model.to(memory_format=torch.channels_last)
    opt, loss, head_loss, schedule = _optimiser(model, cfg, mcfg)
    # Shard-local shuffle (a uniform one would decompress a shard for nearly every pair),
    # each scene's targets together so that its depth image is encoded once.
    train_loader = GroupedLoader(
        train_ds, sampler=train_ds.group_sampler(mcfg.batch_size, mcfg.scene_group, seed)
    )
    val_loader = GroupedLoader(val_ds, batch_size=max(mcfg.batch_size, 32))
    log = CsvLog(paths.report_dir / "log.csv", log_columns(heads))
    sample = val_ds[len(val_ds) // 2]  # the heatmap followed epoch by epoch in the MCAP
    best = {"epoch": 0, "val_loss": float("inf")}
    stale, started, epoch_s = 0, time.perf_counter(), []
    meta = _checkpoint_meta(name, mcfg, threshold_m, size, seed, precision)
    with EpisodeWriter(paths.model_dir / "train.mcap", {"model": name, **meta}) as mcap:
        _write_truth(mcap, sample, heads)
        for epoch in range(1, mcfg.epochs + 1):
            t0 = time.perf_counter()
            train_loss = _train_epoch(model, train_loader, opt, loss, cfg, f"{name} {epoch}")
            if schedule is not None:
                schedule.step()
            val_loss, scores = evaluate_loss(
                model, val_loader, loss, cfg, cfg.val_threshold, heads, head_loss
            )
            row = {"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss}
            row |= {f"val_{k}": v for k, v in scores.items()}
            log.append(row)
            epoch_s.append(round(time.perf_counter() - t0, 1))
            _write_epoch(mcap, row, model, sample, device, cfg, heads, name)
            if val_loss < best["val_loss"]:
                best = {
                    "epoch": epoch,
                    "val_loss": val_loss,
                    **{f"val_{k}": v for k, v in scores.items()},
                }
                save_checkpoint(
                    paths.model_dir / "best.pt", mcfg.arch, model, meta | {"epoch": epoch}
                )
                stale = 0
            else:
                stale += 1
                if stale >= mcfg.patience:
                    break
        summary = _summary(name, mcfg, epoch, best, (train_ds, val_ds), model, precision)
        sensing = cfg.sensing_of(name)
        if mcfg.noise and sensing.preset != "ideal":  # the sensor its images passed through
            summary["sensing"] = {"preset": sensing.preset, "spread": sensing.spread}
        mcap.set_outcome({"best_epoch": best["epoch"], "best_val_loss": best["val_loss"]})
    write_json(paths.report_dir / "summary.json", summary)
    timing = {"model": name, "seconds": time.perf_counter() - started, "epoch_seconds": epoch_s}
    write_json(paths.timing_file, timing)
    return summary


def _open_splits(
    name: str,
    cfg: TrainConfig,
    threshold_m: float,
    seed: int,
    paths: TrainPaths,
    collapse_free: tuple[float, float] | None,
    noise: DepthAugmentation | None,
) -> tuple[PairDataset, PairDataset, int]:
    """The model's train and val pairs (train with noise and flips) and their image size;
    a one-line error when a split is empty or the images do not fit the network."""
    mcfg = cfg.models[name]
    n_masks, heads = mcfg.net.n_masks, tuple(mcfg.labels)
    train_ds = open_pairs(
        n_masks,
        paths.gen_dir,
        paths.split_file,
        "train",
        threshold_m,
        noise,
        mcfg.flip,
        seed,
        labels=heads,
        collapse_free=collapse_free,
    )
    val_ds = open_pairs(
        n_masks,
        paths.gen_dir,
        paths.split_file,
        "val",
        threshold_m,
        labels=heads,
        collapse_free=collapse_free,
    )
    for split, ds in (("train", train_ds), ("val", val_ds)):
        if len(ds) == 0:
            raise ClutterbenchError(f"train@{name}: dataset '{mcfg.dataset}' has no {split} pairs")
    size = image_size(train_ds)
    if size != mcfg.net.input_size:
        raise ClutterbenchError(
            f"train.models.{name}.net.input_size is {mcfg.net.input_size} but dataset "
            f"'{mcfg.dataset}' has {size}x{size} images (sim.camera.image_size)"
        )
    return train_ds, val_ds, size


def _optimiser(
    model: nn.Module, cfg: TrainConfig, mcfg: TrainModelConfig
) -> tuple[torch.optim.Optimizer, Loss, Loss | None, Any]:
    """Adam over the trainable parameters, the loss, the loss of one head (several heads
    only) and the learning-rate schedule (None: constant)."""
    heads = tuple(mcfg.labels)
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=mcfg.lr)
    loss = loss_fn(cfg, mcfg)
    head_loss = loss_fn(cfg, dataclasses.replace(mcfg, labels=heads[:1])) if heads[1:] else None
    schedule = (
        torch.optim.lr_scheduler.CosineAnnealingLR(opt, mcfg.epochs, eta_min=mcfg.lr / 100)
        if mcfg.lr_schedule == "cosine"
        else None
    )
    return opt, loss, head_loss, schedule


def _checkpoint_meta(
    name: str,
    mcfg: TrainModelConfig,
    threshold_m: float,
    size: int,
    seed: int,
    precision: str,
) -> dict[str, Any]:
    """What the checkpoint and the MCAP file record of the run."""
    heads = tuple(mcfg.labels)
    train_meta = as_dict(dataclasses.replace(mcfg, net={}))
    if heads == DEFAULT_HEADS:  # deletion-only checkpoints stay byte for byte as before heads
        del train_meta["labels"]
    if mcfg.sensing is None:  # networks of train.sensing stay byte for byte as before
        del train_meta["sensing"]
    meta = {
        "name": name,
        "dataset": mcfg.dataset,
        "moved_threshold_m": threshold_m,
        "image_size": size,
        "train": train_meta,
        "seed": seed,
        "precision": precision,
    }
    if heads != DEFAULT_HEADS:
        meta["heads"] = list(heads)  # output channel k predicts labels of kind heads[k]
    return meta


def _write_truth(
    mcap: EpisodeWriter, sample: dict[str, torch.Tensor], heads: tuple[str, ...]
) -> None:
    """The followed sample's depth image, masks and each head's labels, at time 0."""
    mcap.write_depth(0.0, sample["depth_m"][0].numpy())
    for mask, topic in zip(sample["target"], ("/val/target", "/val/support")):
        mcap.write_mono8(0.0, topic, _to_mono8(mask))
    for k, topic in enumerate(_head_topics(heads)):
        mcap.write_mono8(0.0, f"{topic}/truth", _to_mono8(sample["collapse"][k]))


def _write_epoch(
    mcap: EpisodeWriter,
    row: dict[str, Any],
    model: nn.Module,
    sample: dict[str, torch.Tensor],
    device: torch.device,
    cfg: TrainConfig,
    heads: tuple[str, ...],
    name: str,
) -> None:
    """The epoch's log row and each head's heatmap of the followed sample to the MCAP file,
    and a line to stdout."""
    epoch = row["epoch"]
    mcap.write_json(float(epoch), "/train/epoch", row)
    depth, target = (sample[k][None].to(device) for k in ("depth_m", "target"))
    for k, topic in enumerate(_head_topics(heads)):
        channel = k if len(heads) > 1 else None
        heat = forward_probs(model, depth, target, cfg.bf16, channel=channel)
        mcap.write_mono8(float(epoch), f"{topic}/heatmap", _to_mono8(heat[0, 0].cpu()))
    print(
        f"{name} epoch {epoch}: train {row['train_loss']:.4f} val {row['val_loss']:.4f} "
        f"IoU {row['val_iou']:.3f}",
        flush=True,
    )


def _summary(
    name: str,
    mcfg: TrainModelConfig,
    epoch: int,
    best: dict[str, Any],
    splits: tuple[PairDataset, PairDataset],
    model: nn.Module,
    precision: str,
) -> dict[str, Any]:
    """summary.json: the epochs run, the best epoch's row, the data and the network's size."""
    summary = {
        "model": name,
        "epochs_run": epoch,
        "stopped_early": epoch < mcfg.epochs,
        "best": best,
        "train_pairs": len(splits[0]),
        "val_pairs": len(splits[1]),
        "parameters": sum(p.numel() for p in model.parameters()),
        "precision": precision,
    }
    if tuple(mcfg.labels) != DEFAULT_HEADS:
        summary["heads"] = list(mcfg.labels)
    return summary


def train_step(
    model: nn.Module,
    batch: dict[str, torch.Tensor],
    opt: torch.optim.Optimizer,
    loss: Loss,
    cfg: TrainConfig,
) -> torch.Tensor:
    """One optimizer step on one batch; returns the (detached) loss before the step."""
    batch = to_device(batch, next(model.parameters()).device)
    logits = batch_logits(model, batch, cfg)
    value = loss(logits, batch)
    opt.zero_grad(set_to_none=True)
    value.backward()
    opt.step()
    return value.detach()


def batch_logits(
    model: nn.Module, batch: dict[str, torch.Tensor], cfg: TrainConfig
) -> torch.Tensor:
    """Logits of a batch (its samples' depth images by batch["scene_of"] when grouped)."""
    scene_of = batch.get("scene_of")
    return forward_logits(
        model, batch["depth_m"], batch["target"], cfg.bf16, cfg.channels_last, scene_of
    )


def _train_epoch(
    model: nn.Module,
    loader: GroupedLoader,
    opt: torch.optim.Optimizer,
    loss: Loss,
    cfg: TrainConfig,
    desc: str,
) -> float:
    model.train()
    total, n = 0.0, 0
    with progress_bar(desc, len(loader.dataset)) as advance:
        for batch in loader:
            value = train_step(model, batch, opt, loss, cfg)
            k = len(batch["target"])
            total += float(value) * k
            n += k
            advance(k)
    return total / max(n, 1)


def _head_topics(heads: tuple[str, ...]) -> list[str]:
    """MCAP topic prefix of each head's validation images: /val for the first (as a
    one-head network's), /val/<head> for the others."""
    return ["/val", *(f"/val/{h}" for h in heads[1:])]


def _to_mono8(image: torch.Tensor) -> np.ndarray:
    return (image.detach().float().clamp(0, 1) * 255).round().to(torch.uint8).numpy()
