"""`make bench`, memory part: peak RSS of a training epoch over sharded data (its rows and
markdown section go into reports/bench/models.{json,md}, written by the models part).

Each measurement runs in a fresh process over a synthetic dataset (clutterbench.data.
synthetic) with the generate stage's shard layout: the data of a whole epoch (every train and
validation batch) passes through the loaders, while Adam steps run on the first batches only
(the network's peak is reached on the first step; the rest would only cost time). Run at the
default ch6 size and at several times that many scenes, RSS should not grow with the dataset.
"""

from __future__ import annotations

import multiprocessing as mp
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import torch

from clutterbench.collapse.config import TrainConfig, TrainModelConfig
from clutterbench.collapse.train import loss_fn, train_step
from clutterbench.config import load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import CollapseDataset, GroupedLoader
from clutterbench.data.split import SplitConfig, split_dataset
from clutterbench.io import load_npz
from clutterbench.models import build_model
from clutterbench.platform_info import cpu_description
from clutterbench.sim.config import SimConfig

DATASET = "ch6"
MODEL = "cp_focal"
SCENE_FACTORS = (1, 4)
"""Dataset sizes measured, in multiples of the default ch6 n_scenes."""
TRAIN_BATCHES = 10
"""Adam steps per measured epoch."""


def peak_rss_mb() -> float:
    """This process's peak resident set (VmHWM): unlike ru_maxrss it is not inherited from
    the parent across fork + exec."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def epoch_peak_rss(
    gen_dir: Path,
    split_file: Path,
    cfg: TrainConfig,
    mcfg: TrainModelConfig,
    threshold_m: float,
    train_batches: int,
    threads: int = 2,
    collapse_free: tuple[float, float] | None = None,
) -> dict[str, Any]:
    """One epoch of train.py's data path (run in a fresh process); its peak RSS
    (`collapse_free` as train_model's)."""
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    t0 = time.perf_counter()
    noise = cfg.noise if mcfg.noise else None
    labels = mcfg.labels  # one label channel per head, as train.py reads them
    kinds = {"labels": labels, "collapse_free": collapse_free}
    train_ds = CollapseDataset(
        gen_dir, split_file, "train", threshold_m, noise, mcfg.flip, 0, **kinds
    )
    val_ds = CollapseDataset(gen_dir, split_file, "val", threshold_m, **kinds)
    index_s = time.perf_counter() - t0
    model = build_model(mcfg.arch, mcfg.net).train()
    if cfg.channels_last:
        model = model.to(memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=mcfg.lr)
    loss = loss_fn(cfg, mcfg)
    sampler = train_ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0)
    for b, batch in enumerate(GroupedLoader(train_ds, sampler=sampler)):
        if b < train_batches:
            train_step(model, batch, opt, loss, cfg)
    for _ in GroupedLoader(val_ds, batch_size=max(mcfg.batch_size, 32)):
        pass
    return {
        "train_pairs": len(train_ds),
        "val_pairs": len(val_ds),
        "index_seconds": round(index_s, 1),
        "epoch_seconds": round(time.perf_counter() - t0, 1),
        "peak_rss_mb": round(peak_rss_mb(), 1),
        **cpu_description(),
    }


def _in_fresh_process(fn, *args) -> dict[str, Any]:
    # spawn: a new interpreter, so the peak counts only what one training run holds.
    with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def bench_train_memory(
    params: dict[str, Any],
    scale: str = "default",
    factors: tuple[int, ...] = SCENE_FACTORS,
    train_batches: int = TRAIN_BATCHES,
) -> list[dict[str, Any]]:
    """Peak RSS of a cp_focal epoch (at `scale`) on ch6-shaped data of growing size: the
    `factors` times the scale's n_scenes, with the arrays generate writes for that dataset."""
    # Imported here: the measured process imports this module, and should hold only what
    # training holds (synthetic data pulls in the simulator).
    from clutterbench.data.synthetic import write_synthetic_dataset

    params = {**params, "base": {**params.get("base", {}), "scale": scale}}
    gen = load_section(GenerateConfig, "generate", params)
    size = load_section(SimConfig, "sim", params).camera.image_size
    cfg = load_section(TrainConfig, "train", params)
    fractions = load_section(SplitConfig, "split", params).datasets[DATASET]
    ds, mcfg = gen.datasets[DATASET], cfg.models[MODEL]
    rows = []
    for factor in factors:
        n_scenes = ds.n_scenes * factor
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp)
            t0 = time.perf_counter()
            write_synthetic_dataset(
                root / "gen",
                DATASET,
                n_scenes,
                gen.shard_size,
                size,
                ds.n_objects,
                ds.families,
                pull_outcomes=ds.pull_outcomes,  # as generate writes it: the pull head's labels
            )
            split_dataset(DATASET, fractions, 0, root / "gen", root / "split")
            write_s = time.perf_counter() - t0
            first = load_npz(root / "gen" / DATASET / "shard-00000.npz")
            per_scene = sum(a.nbytes for a in first.values()) / len(first["scene_index"])
            run = _in_fresh_process(
                epoch_peak_rss,
                root / "gen",
                root / "split" / f"{DATASET}.json",
                cfg,
                mcfg,
                ds.moved_threshold_m,
                train_batches,
                2,
                label_thresholds(params),
            )
        rows.append(
            {
                "dataset": f"{DATASET} synthetic x{factor}",
                "scenes": n_scenes,
                "image_size": size,
                "shard_size": gen.shard_size,
                "model": MODEL,
                "batch_size": mcfg.batch_size,
                "train_batches": train_batches,
                # What a load-everything loader held: every scene decompressed.
                "decompressed_dataset_mb": round(per_scene * n_scenes / 2**20, 1),
                "write_seconds": round(write_s, 1),
                **run,
            }
        )
        print(rows[-1], flush=True)
    return rows


def memory_markdown(rows: list[dict]) -> list[str]:
    """The models.md section for bench_train_memory's rows."""
    first = rows[0]
    lines = [
        "",
        "## Peak memory of a training epoch",
        "",
        f"{first['model']} at default scale (batch {first['batch_size']}, {first['image_size']} "
        f"px, shards of {first['shard_size']} scenes) on synthetic ch6-shaped data: every "
        f"train and val batch of one epoch is loaded, Adam steps on the first "
        f"{first['train_batches']}. Peak RSS of a fresh process (VmHWM).",
        "",
        "| data | scenes | train pairs | decompressed data MB | peak RSS MB | epoch s |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['dataset']} | {r['scenes']} | {r['train_pairs']} | "
            f"{r['decompressed_dataset_mb']:.0f} | {r['peak_rss_mb']:.0f} | "
            f"{r['epoch_seconds']:.0f} |"
        )
    lines += [
        "",
        "Shards are read lazily with a cache of a few shards, so peak RSS should not grow "
        "with the number of scenes (decompressed data MB: what a load-everything loader held).",
    ]
    return lines
