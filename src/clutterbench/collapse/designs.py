"""Designs of a collapse network compared at equal training time, by validation IoU.

    python -m clutterbench.collapse.designs         # make designs (~4 x 12 min at default scale)

Each design of params `designs.designs` is the network of `train.models.<designs.model>`
with some `net` fields changed (e.g. output_stride: 2, a narrower encoder). Each is trained
as stage train@<model> does (same data, split, seed, loss, batch, augmentation, precision,
cosine schedule), for as many epochs as fit in `designs.minutes` at its own speed: a short
probe times its training steps first. The validation split of the model's dataset scores
every epoch (val IoU at train.val_threshold); the test split is never read. Writes
reports/learning_curve/designs.{csv,md,png}: one row per design and epoch, validation IoU
against training minutes, one curve per design; the design with the best validation IoU at
its best-loss epoch is named. Not a dvc stage: the chosen design goes into
train.models.<model>.net by hand, where dvc tracks it.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import (
    TrainPaths,
    batch_logits,
    loss_fn,
    model_seed,
    train_model,
)
from clutterbench.config import as_dict, bounded, load_base, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import GroupedLoader, open_pairs
from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path, read_json, write_text
from clutterbench.models import build_model, parse_net_config
from clutterbench.stage import run_stage

OUT = Path("reports/learning_curve")


@dataclasses.dataclass(frozen=True)
class DesignsConfig:
    model: str = "cp_focal"
    """The train.models entry whose network, data and training the designs vary."""
    minutes: float = bounded(12.0, gt=0.0)
    """Training time each design gets (validation passes not counted)."""
    probe_batches: int = bounded(12, ge=2)
    """Training steps timed to size each design's epochs (the first is not counted)."""
    designs: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)
    """Design name -> the `net` fields it changes ({} = the model as params have it)."""


def design_net(base_net: Any, arch: str, changes: Mapping[str, Any], key: str) -> Any:
    """The model's net config with `changes` applied (checked as params' own)."""
    return parse_net_config(arch, {**as_dict(base_net), **changes}, key)


def probe_pairs_per_s(
    cfg: TrainConfig,
    model: str,
    net: Any,
    paths: TrainPaths,
    threshold_m: float,
    n: int,
    collapse_free: tuple[float, float] | None = None,
) -> float:
    """Training pairs per second of `net` over n - 1 timed steps (after one warm-up);
    `collapse_free` as train_model's."""
    mcfg = dataclasses.replace(cfg.models[model], net=net)
    seed = model_seed(0, model)
    torch.manual_seed(seed)
    ds = open_pairs(
        net.n_masks,
        paths.gen_dir,
        paths.split_file,
        "train",
        threshold_m,
        labels=mcfg.labels,
        collapse_free=collapse_free,
    )
    loader = GroupedLoader(ds, sampler=ds.group_sampler(mcfg.batch_size, mcfg.scene_group, seed))
    module = build_model(mcfg.arch, net)
    if cfg.channels_last:
        module = module.to(memory_format=torch.channels_last)
    module.train()
    opt = torch.optim.Adam(module.parameters(), lr=mcfg.lr)
    loss = loss_fn(cfg, mcfg)
    pairs, t0 = 0, 0.0
    for step, batch in enumerate(loader):
        if step == 1:
            t0 = time.perf_counter()
        value = loss(batch_logits(module, batch, cfg), batch)
        opt.zero_grad(set_to_none=True)
        value.backward()
        opt.step()
        if step >= 1:
            pairs += len(batch["target"])
        if step + 1 >= n:
            break
    return pairs / max(time.perf_counter() - t0, 1e-9)


def compare_designs(
    params: dict[str, Any], data_dir: Path = Path("data"), out_dir: Path = OUT
) -> list[dict[str, Any]]:
    """Train every design for `minutes`; the per-epoch rows (also written to out_dir)."""
    base = load_base(params)
    dcfg = load_section(DesignsConfig, "designs", params)
    cfg = load_section(TrainConfig, "train", params)
    if dcfg.model not in cfg.models:
        raise ClutterbenchError(f"designs.model: {dcfg.model!r} is not a key of train.models")
    if not dcfg.designs:
        raise ClutterbenchError("designs.designs: no design to compare")
    mcfg = cfg.models[dcfg.model]
    gen = load_section(GenerateConfig, "generate", params)
    threshold_m = gen.datasets[mcfg.dataset].moved_threshold_m
    # the pull_collapse labels' notion of a collapse (trials.collapse_free), where trained
    collapse_free = label_thresholds(params) if "pull_collapse" in mcfg.labels else None
    split_file = data_dir / "split" / f"{mcfg.dataset}.json"
    if not split_file.exists():
        raise ClutterbenchError(f"{split_file} not found; run stage split@{mcfg.dataset} first")
    rows: list[dict[str, Any]] = []
    for name, changes in dcfg.designs.items():
        net = design_net(mcfg.net, mcfg.arch, changes, f"designs.designs.{name}")
        with tempfile.TemporaryDirectory(prefix=f"design-{name}-") as tmp:
            paths = TrainPaths(
                gen_dir=data_dir / "generate",
                split_file=split_file,
                model_dir=Path(tmp) / "model",
                report_dir=Path(tmp) / "report",
                timing_file=Path(tmp) / "timing.json",
            )
            rate = probe_pairs_per_s(
                cfg, dcfg.model, net, paths, threshold_m, dcfg.probe_batches, collapse_free
            )
            n_train = len(read_json(split_file)["train"])
            pairs = _train_pairs(mcfg, paths, threshold_m)
            epochs = max(1, round(dcfg.minutes * 60 * rate / pairs))
            print(
                f"design {name}: {rate:.0f} pairs/s on {pairs} pairs ({n_train} scenes) "
                f"-> {epochs} epochs in {dcfg.minutes:g} min",
                flush=True,
            )
            run = dataclasses.replace(mcfg, net=net, epochs=epochs, patience=epochs)
            run_cfg = dataclasses.replace(cfg, models={**cfg.models, dcfg.model: run})
            summary = train_model(dcfg.model, run_cfg, threshold_m, base.seed, paths, collapse_free)
            rows += _design_rows(name, epochs, rate, summary, paths)
    write_designs(rows, dcfg, base.scale, out_dir)
    return rows


def _train_pairs(mcfg: Any, paths: TrainPaths, threshold_m: float) -> int:
    return len(open_pairs(mcfg.net.n_masks, paths.gen_dir, paths.split_file, "train", threshold_m))


def _design_rows(
    name: str, epochs: int, rate: float, summary: dict[str, Any], paths: TrainPaths
) -> list[dict[str, Any]]:
    """One row per epoch: cumulative training minutes (validation excluded) and scores."""
    import pandas as pd

    log = pd.read_csv(paths.report_dir / "log.csv")
    timing = read_json(paths.timing_file)
    per_epoch = summary["train_pairs"] / rate / 60  # probe rate: validation not counted
    rows = []
    for i, r in enumerate(log.itertuples(index=False)):
        rows.append(
            {
                "design": name,
                "epoch": int(r.epoch),
                "epochs": epochs,
                "minutes": round(per_epoch * (i + 1), 4),
                "wall_minutes": round(sum(timing["epoch_seconds"][: i + 1]) / 60, 4),
                "train_pairs": summary["train_pairs"],
                "train_loss": r.train_loss,
                "val_loss": r.val_loss,
                "val_iou": r.val_iou,
                "val_iou_best": r.val_iou_best,
                "val_best_threshold": r.val_best_threshold,
                "val_precision": r.val_precision,
                "val_recall": r.val_recall,
                "pairs_per_s": round(rate, 1),
                "parameters": summary["parameters"],
                "best_epoch": summary["best"]["epoch"],
            }
        )
    return rows


def best_rows(rows: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Each design's row at its best (lowest validation loss) epoch, in design order."""
    out: dict[str, Mapping[str, Any]] = {}
    for r in rows:
        if r["epoch"] == r["best_epoch"]:
            out[r["design"]] = r
    return list(out.values())


def write_designs(
    rows: list[dict[str, Any]], dcfg: DesignsConfig, scale: str, out_dir: Path
) -> None:
    import pandas as pd

    frame = pd.DataFrame(rows)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_text(out_dir / "designs.csv", frame.to_csv(index=False, float_format="%.6g"))
    best = best_rows(rows)
    chosen = max(best, key=lambda r: r["val_iou_best"])["design"]
    lines = [
        f"# Collapse network designs at equal training time: {dcfg.model} ({scale} scale)",
        "",
        f"Each design trained for {dcfg.minutes:g} minutes (epochs sized by its measured "
        "training speed; validation passes not counted) on the same data, split, seed, loss "
        "and cosine schedule. Scores on the validation split at the best (lowest validation "
        "loss) epoch; the test split is never read. Chosen by 'val IoU, best threshold': the "
        "highest IoU over the evaluate sweep's thresholds (the focal loss keeps "
        "probabilities low, so IoU at 0.5 moves a lot from epoch to epoch).",
        "",
        "| design | net changes | parameters | train pairs/s | epochs | best epoch "
        "| val loss | val IoU, best threshold (at) | val IoU at 0.5 | val precision | val recall |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in best:
        changes = ", ".join(f"{k}: {v}" for k, v in dcfg.designs[r["design"]].items()) or "-"
        mark = " **(chosen)**" if r["design"] == chosen else ""
        lines.append(
            f"| {r['design']}{mark} | {changes} | {r['parameters']:,} | {r['pairs_per_s']:.0f} "
            f"| {r['epochs']} | {r['best_epoch']} | {r['val_loss']:.5f} "
            f"| {r['val_iou_best']:.3f} ({r['val_best_threshold']:.2f}) | {r['val_iou']:.3f} "
            f"| {r['val_precision']:.3f} | {r['val_recall']:.3f} |"
        )
    lines += [
        "",
        f"Chosen by validation IoU: **{chosen}**. Per-epoch rows: designs.csv; the curves: "
        "designs.png.",
    ]
    write_text(out_dir / "designs.md", "\n".join(lines) + "\n")
    _plot(frame, dcfg.model, out_dir / "designs.png")


def _plot(frame: Any, model: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for name, group in frame.groupby("design", sort=False):
        ax.plot(group["minutes"], group["val_iou_best"], "o-", ms=3, label=str(name))
    ax.set_xlabel("training minutes")
    ax.set_ylabel("validation IoU (best threshold)")
    ax.set_title(f"{model}: designs at equal training time")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120, metadata={"Software": None})
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args(argv)

    def run(params: dict[str, Any], base: Any) -> None:
        for r in best_rows(compare_designs(params)):
            print(f"{r['design']}: val IoU {r['val_iou_best']:.3f} at epoch {r['best_epoch']}")

    run_stage(run)


if __name__ == "__main__":
    main()
