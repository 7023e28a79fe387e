"""Training steps of the networks for the train_rate part, timed and counted.

Each network of `train.models` at default scale, built as collapse.train builds it (from the
same config objects), takes real training steps (train.train_step: its batch size, image
size, loss, Adam, autocast and memory format) on a batch the training sampler draws from a
small synthetic dataset of the network's dataset (data.synthetic: the generate stage's
layout): the step's FLOPs (torch.utils.flop_counter) over its time. The torch.compile
variant runs in a spawned child process under a time limit.
"""

from __future__ import annotations

import functools
import multiprocessing as mp
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from clutterbench.bench.cpu_rates import Contention, Gate, gflops_per_s, rate_row, timed
from clutterbench.collapse.config import TrainConfig, TrainModelConfig
from clutterbench.collapse.train import Loss, loss_fn, train_step
from clutterbench.config import load_params, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import PairDataset, open_pairs
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.models import build_model

STEP_BUDGET_S = 8.0
"""Seconds of timed training steps per network or variant (at least MIN_STEPS steps)."""
MIN_STEPS, MAX_STEPS, WARMUP_STEPS = 3, 20, 2
PROFILED = "cp_focal"
SYNTHETIC_SCENES = 150
"""Scenes of each synthetic dataset (three default-scale shards of 50)."""


def default_params(path: Path | str = "params.yaml") -> dict[str, Any]:
    params = load_params(path)
    return {**params, "base": {**params["base"], "scale": "default"}}


def collapse_free(params: dict[str, Any]) -> tuple[float, float]:
    """trials.collapse_free, for pull_collapse labels (as the train stage passes it)."""
    from clutterbench.criteria import label_thresholds

    return label_thresholds(params)


def synthetic_pairs(
    params: dict[str, Any],
    cfg: TrainConfig,
    mcfg: TrainModelConfig,
    root: Path,
    n_scenes: int = SYNTHETIC_SCENES,
    split: str = "train",
    augment: bool = True,
) -> PairDataset:
    """The training (or validation) pairs of a synthetic dataset shaped like `mcfg.dataset`
    (its image size, boxes, families, shard size and label arrays), opened as train.py opens
    its data; written under `root` once per dataset."""
    gen = load_section(GenerateConfig, "generate", params)
    ds = gen.datasets[mcfg.dataset]
    split_file = root / "split" / f"{mcfg.dataset}.json"
    if not split_file.exists():
        from clutterbench.data.synthetic import write_synthetic_dataset

        write_synthetic_dataset(
            root / "gen",
            mcfg.dataset,
            n_scenes,
            gen.shard_size,
            mcfg.net.input_size,
            ds.n_objects,
            ds.families,
            pulls=ds.pulls,
            pull_outcomes=ds.pull_outcomes,
        )
        split_dataset(mcfg.dataset, Fractions(0.9, 0.1, 0.0), 0, root / "gen", root / "split")
    return open_pairs(
        mcfg.net.n_masks,
        root / "gen",
        split_file,
        split,
        ds.moved_threshold_m,
        (cfg.noise if mcfg.noise else None) if augment else None,
        mcfg.flip and augment,
        0,
        labels=mcfg.labels,
        collapse_free=collapse_free(params),
    )


def first_batch(ds: PairDataset, batch_size: int, group: int) -> dict[str, torch.Tensor]:
    """The first batch the training sampler draws (scenes grouped as in training)."""
    return ds.batch(next(iter(ds.group_sampler(batch_size, group, 0))))


def build_training(
    cfg: TrainConfig, mcfg: TrainModelConfig, channels_last: bool
) -> tuple[torch.nn.Module, torch.optim.Optimizer, Loss]:
    """Network, Adam and loss as collapse.train.train_model builds them."""
    torch.manual_seed(0)
    model = build_model(mcfg.arch, mcfg.net).train()
    if channels_last:
        model = model.to(memory_format=torch.channels_last)
    params = [p for p in model.parameters() if p.requires_grad]
    return model, torch.optim.Adam(params, lr=mcfg.lr), loss_fn(cfg, mcfg)


def step_flops(
    model: torch.nn.Module,
    batch: dict[str, torch.Tensor],
    opt: torch.optim.Optimizer,
    loss: Loss,
    cfg: TrainConfig,
) -> float:
    """GFLOPs of one training step (FlopCounterMode: convolutions and matmuls, forward and
    backward; element-wise ops, normalisation and the optimiser count nothing)."""
    with FlopCounterMode(display=False) as counter:
        train_step(model, batch, opt, loss, cfg)
    return counter.get_total_flops() / 1e9


def step_seconds(
    model: torch.nn.Module,
    batch: dict[str, torch.Tensor],
    opt: torch.optim.Optimizer,
    loss: Loss,
    cfg: TrainConfig,
    gate: Gate,
) -> tuple[list[float], float | None, int]:
    """Seconds of training steps (WARMUP_STEPS untimed first, one before a repeat) through
    `gate`: the times, the others' CPU share and the attempts."""

    def measure(attempt: int) -> list[float]:
        warmup = WARMUP_STEPS if attempt == 1 else 1
        step = functools.partial(train_step, model, batch, opt, loss, cfg)
        return timed(step, STEP_BUDGET_S, warmup, MIN_STEPS, MAX_STEPS)

    return gate.run(measure)


def step_row(
    name: str,
    variant: str,
    batch: dict[str, torch.Tensor],
    gflop: float,
    times: list[float],
    peaks: dict[str, float],
    others: float | None = None,
    attempts: int = 1,
) -> dict[str, Any]:
    """One network / variant's result: its batch, FLOPs, step times and rates (the rate and
    shares from the best step; the median's rate beside), and the share of the CPUs other
    processes used meanwhile."""
    best, median = min(times), float(np.median(times))
    return {
        "model": name,
        "variant": variant,
        "batch_size": len(batch["target"]),
        "scenes_per_batch": len(batch["depth_m"]),
        "image_size": int(batch["target"].shape[-1]),
        "gflop_per_step": gflop,
        "steps": len(times),
        "best_step_s": best,
        "median_step_s": median,
        "median_gflop_per_s": gflops_per_s(gflop * 1e9, median),
        **rate_row(gflop, best, peaks),
        "others_cpu": others,
        "attempts": attempts,
    }


def measure_model(
    name: str,
    variant: str,
    cfg: TrainConfig,
    mcfg: TrainModelConfig,
    batch: dict[str, torch.Tensor],
    peaks: dict[str, float],
    gate: Gate,
) -> dict[str, Any]:
    """A real training step of train.models[name] on `batch` as `cfg` sets it up."""
    model, opt, loss = build_training(cfg, mcfg, cfg.channels_last)
    times, others, attempts = step_seconds(model, batch, opt, loss, cfg, gate)
    gflop = step_flops(model, batch, opt, loss, cfg)
    return step_row(name, variant, batch, gflop, times, peaks, others, attempts)


def compiled_step(
    cfg: TrainConfig,
    mcfg: TrainModelConfig,
    batch: dict[str, torch.Tensor],
    threads: int,
    steps: int,
    cache: str,
    gate: Gate,
    out: Any,
) -> None:
    """In a child process: torch.compile the network (inductor, its kernel cache in the
    empty directory `cache`), time its first two steps (the forward and backward compiled)
    and `steps` more; put a dict (or the error) on queue `out`."""
    os.environ["TORCHINDUCTOR_CACHE_DIR"] = cache  # cold: no kernels of an earlier run
    try:
        torch.set_num_threads(threads)
        model, opt, loss = build_training(cfg, mcfg, cfg.channels_last)
        gflop = step_flops(model, batch, opt, loss, cfg)  # eager: the same arithmetic
        compiled = torch.compile(model)
        step = functools.partial(train_step, compiled, batch, opt, loss, cfg)
        with Contention() as during_compile:
            warm = timed(step, 0.0, 0, 2, 2)
        times, others, attempts = gate.run(lambda _: timed(step, 0.0, 1, steps, steps))
        out.put(
            {
                "gflop": gflop,
                "compile_s": sum(warm),
                "warmup_steps_s": warm,
                "others_cpu_compiling": during_compile.others,
                "times": times,
                "others": others,
                "attempts": attempts,
            }
        )
    except Exception as exc:  # any compile failure is the result, not a crash of the bench
        lines = traceback.format_exception_only(type(exc), exc)
        out.put({"error": " ".join(" ".join(lines).split())[:300]})


def in_child(fn: Callable[..., None], args: tuple, timeout_s: float) -> dict[str, Any]:
    """Run fn(*args, queue) in a spawned process; its dict, or an error after `timeout_s`."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=fn, args=(*args, queue))
    t0 = time.perf_counter()
    proc.start()
    try:
        return queue.get(timeout=timeout_s)
    except Exception:
        return {"error": f"no result within {timeout_s:.0f} s (stopped)"}
    finally:
        proc.join(timeout=max(0.0, timeout_s - (time.perf_counter() - t0)) + 5)
        if proc.is_alive():
            proc.kill()
            proc.join()
