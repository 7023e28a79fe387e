"""`make bench`, train_profile part: where a slice of a cp_focal training epoch spends its time.

Trains cp_focal at default scale as collapse.train does (its network, Adam, loss, autocast,
memory format, GroupedLoader over the training sampler, collapse.train.train_step) on a
synthetic ch6-shaped dataset (data.synthetic: the generate stage's shards, decompressed and
turned into masks, labels, noise and flips by the real torch Dataset), and profiles
PROFILE_STEPS steps after WARMUP_STEPS with torch.profiler, followed by the validation
batches an epoch has per that many training steps (the ch6 split's val / train share).
Every operator's self time is put into one group: data loading and decoding (the loader's
batches), validation (its batches, their loading included), the optimiser (Adam's step and
zero_grad), convolutions (forward and backward, with the bf16 casts and memory-format
copies torch makes for them), and normalisation and element-wise ops (BatchNorm, ReLU,
upsampling, concatenation, the loss, other casts); what no operator covers (Python, the
autograd engine's bookkeeping between ops) is listed apart. The data loading is also timed
on its own, without training. Not in the slice: the per-epoch MCAP heatmap and checkpoint.
Writes reports/bench/train_profile.{json,md}.
"""

from __future__ import annotations

import dataclasses
import itertools
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import torch
from torch.profiler import ProfilerActivity, profile, record_function

from clutterbench.bench import header, write_result
from clutterbench.bench.cpu_rates import THREADS, least_disturbed, torch_threads
from clutterbench.bench.train_rate_md import pct
from clutterbench.bench.train_steps import (
    PROFILED,
    build_training,
    default_params,
    synthetic_pairs,
)
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.train import evaluate_loss, loss_fn, train_step
from clutterbench.config import load_section
from clutterbench.data.dataset import GroupedLoader
from clutterbench.data.split import SplitConfig
from clutterbench.platform_info import cpu_description

PROFILE_STEPS = 48
WARMUP_STEPS = 5
DATA_SCENES = 400
"""Synthetic scenes written (8 default shards): more than the slice reads, so that its
batches decompress shards as an epoch does."""
LOADING_BATCHES = 60
"""Batches of the loader timed on their own."""
TOP_OPS = 25

DATA, VALIDATION, OPTIMISER = "data loading and decoding", "validation", "optimiser"
CONV, ELEMENTWISE = "convolutions", "normalisation and element-wise ops"
OVERHEAD = "no operator (Python, autograd engine)"
GROUPS = (CONV, ELEMENTWISE, DATA, VALIDATION, OPTIMISER, OVERHEAD)
REGIONS = {"data_loading": DATA, "validation": VALIDATION}
"""record_function names of this profile -> their group."""


def op_group(names: Iterable[str]) -> str:
    """The group of an operator from its own name and its ancestors' (innermost first):
    a region of this profile (data loading, validation) or the optimiser wins over the op's
    kind; an op is a convolution when it or an enclosing op is one."""
    names = list(names)
    for n in names:
        if n in REGIONS:
            return REGIONS[n]
        if n.startswith("Optimizer."):
            return OPTIMISER
    if any("conv" in n.lower() for n in names):
        return CONV
    return ELEMENTWISE


def group_times(events: Iterable[Any]) -> tuple[dict[str, float], dict[tuple[str, str], list]]:
    """Self CPU seconds per group, and per (group, op name) [seconds, calls], over profiler
    events (each with name, self_cpu_time_total in us and cpu_parent)."""
    groups = dict.fromkeys(GROUPS, 0.0)
    ops: dict[tuple[str, str], list] = {}
    for e in events:
        names, p = [e.name], e.cpu_parent
        while p is not None:
            names.append(p.name)
            p = p.cpu_parent
        g = op_group(names)
        s = e.self_cpu_time_total / 1e6
        groups[g] += s
        entry = ops.setdefault((g, e.name), [0.0, 0])
        entry[0] += s
        entry[1] += 1
    return groups, ops


def shares(groups: dict[str, float], wall_s: float) -> dict[str, dict[str, float]]:
    """Each group's seconds and share of `wall_s`, the time not inside any op going to
    OVERHEAD (never below 0)."""
    out = dict(groups)
    out[OVERHEAD] = max(0.0, wall_s - sum(v for k, v in groups.items() if k != OVERHEAD))
    return {k: {"seconds": v, "share": v / wall_s} for k, v in out.items()}


def val_batches_per_slice(
    steps: int, train_fraction: float, val_fraction: float, batch: int, val_batch: int
) -> int:
    """Validation batches an epoch runs per `steps` training steps (at least 1): val pairs
    per train pair (the split's fractions) times the ratio of batch sizes."""
    return max(1, round(steps * (val_fraction / train_fraction) * batch / val_batch))


def _batches(loader: GroupedLoader) -> Iterator[dict[str, torch.Tensor]]:
    """The loader's batches, epoch after epoch."""
    while True:
        yield from loader


def bench_train_profile(out_dir: Path = Path("reports/bench")) -> dict[str, Any]:
    params = default_params()
    cfg = load_section(TrainConfig, "train", params)
    mcfg = cfg.models[PROFILED]
    fractions = load_section(SplitConfig, "split", params).datasets[mcfg.dataset]
    val_batch = max(mcfg.batch_size, 32)  # as train.py
    n_val = val_batches_per_slice(
        PROFILE_STEPS, fractions.train, fractions.val, mcfg.batch_size, val_batch
    )
    with torch_threads(THREADS), tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        train_ds = synthetic_pairs(params, cfg, mcfg, root, DATA_SCENES)
        val_ds = synthetic_pairs(params, cfg, mcfg, root, DATA_SCENES, "val", augment=False)
        sampler = train_ds.group_sampler(mcfg.batch_size, mcfg.scene_group, 0)

        batches = _batches(GroupedLoader(train_ds, sampler=sampler))
        model, opt, loss = build_training(cfg, mcfg, cfg.channels_last)
        heads = tuple(mcfg.labels)
        one_head = dataclasses.replace(mcfg, labels=heads[:1])
        head_loss = loss_fn(cfg, one_head) if heads[1:] else None  # as train.py
        val_loader = GroupedLoader(val_ds, batch_size=val_batch)
        model.train()
        for _ in range(WARMUP_STEPS):
            train_step(model, next(batches), opt, loss, cfg)

        def measure() -> dict[str, Any]:
            return {
                "loading": _loading_alone(batches),
                "plain_s": _unprofiled(model, batches, opt, loss, cfg),
                **_profiled(model, batches, opt, loss, cfg, val_loader, n_val, head_loss),
            }

        best = least_disturbed(measure)
        groups, ops, wall_s = best["groups"], best["ops"], best["wall_s"]
    result: dict[str, Any] = {
        "model": PROFILED,
        "precision": "bf16" if cfg.bf16 else "fp32",
        "channels_last": cfg.channels_last,
        "batch_size": mcfg.batch_size,
        "image_size": mcfg.net.input_size,
        "steps": PROFILE_STEPS,
        "warmup_steps": WARMUP_STEPS,
        "val_batches": n_val,
        "val_batch_size": val_batch,
        "synthetic_scenes": DATA_SCENES,
        "profiled_seconds": wall_s,
        "profiled_train_seconds": best["train_s"],
        "unprofiled_train_seconds": best["plain_s"],
        "groups": shares(groups, wall_s),
        "top_ops": [
            {"group": g, "op": name, "seconds": s, "calls": n, "share": s / wall_s}
            for (g, name), (s, n) in sorted(ops.items(), key=lambda kv: -kv[1][0])[:TOP_OPS]
        ],
        "data_loading_alone": best["loading"],
        "threads": THREADS,
        "torch": torch.__version__,
        "others_cpu": best["others"],
        "attempts": best["attempts"],
        **cpu_description(),
        "torch_threads": THREADS,
    }
    write_result(out_dir, "train_profile", result, markdown(result))
    return result


def _loading_alone(batches: Iterator[dict[str, torch.Tensor]]) -> dict[str, float]:
    """LOADING_BATCHES of the loader on their own, without training."""
    t0 = time.perf_counter()
    pairs = sum(len(next(batches)["target"]) for _ in range(LOADING_BATCHES))
    load_s = time.perf_counter() - t0
    return {
        "batches": LOADING_BATCHES,
        "pairs": pairs,
        "seconds": load_s,
        "ms_per_batch": 1e3 * load_s / LOADING_BATCHES,
        "pairs_per_s": pairs / load_s,
    }


def _unprofiled(model, batches, opt, loss, cfg: TrainConfig) -> float:
    """Seconds of PROFILE_STEPS training steps without the profiler."""
    model.train()
    t0 = time.perf_counter()
    for _ in range(PROFILE_STEPS):
        train_step(model, next(batches), opt, loss, cfg)
    return time.perf_counter() - t0


def _profiled(
    model, batches, opt, loss, cfg: TrainConfig, val_loader, n_val: int, head_loss
) -> dict[str, Any]:
    """PROFILE_STEPS training steps and n_val validation batches under torch.profiler: the
    seconds of both, and the operators' self times by group and by (group, op)."""
    heads = tuple(cfg.models[PROFILED].labels)
    model.train()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        t0 = time.perf_counter()
        for _ in range(PROFILE_STEPS):
            with record_function("data_loading"):
                batch = next(batches)
            train_step(model, batch, opt, loss, cfg)
        train_s = time.perf_counter() - t0
        with record_function("validation"):
            val = list(itertools.islice(val_loader, n_val))
            # a list of batches stands in for the loader: evaluate_loss iterates it
            evaluate_loss(model, val, loss, cfg, cfg.val_threshold, heads, head_loss)  # type: ignore[arg-type]
        wall_s = time.perf_counter() - t0
    groups, ops = group_times(prof.events())
    return {"train_s": train_s, "wall_s": wall_s, "groups": groups, "ops": ops}


def markdown(result: dict[str, Any]) -> list[str]:
    r = result
    lines = header(f"Where a slice of a {r['model']} training epoch goes (CPU)", r)
    lines += [
        f"{r['steps']} training steps (after {r['warmup_steps']} warm-up) of {r['model']} at "
        f"default scale (batch {r['batch_size']}, {r['image_size']} px, {r['precision']}, "
        f"channels-last {r['channels_last']}), each loading its batch from a synthetic "
        f"ch6-shaped dataset of {r['synthetic_scenes']} scenes through the real Dataset, then "
        f"the {r['val_batches']} validation batches (of {r['val_batch_size']}) an epoch runs "
        f"per {r['steps']} steps; torch.profiler, self CPU time of every operator. Profiled: "
        f"{r['profiled_seconds']:.1f} s ({r['profiled_train_seconds']:.1f} s of training; "
        f"the same steps unprofiled: {r['unprofiled_train_seconds']:.1f} s). Other processes "
        f"used {pct(r['others_cpu'])} of the CPUs meanwhile (shared cores: /proc/stat less "
        "this process; the slice waits for idle cores and is run again, the least disturbed "
        "run kept, while others use them).",
        "",
        "| group | s | share |",
        "|---|---|---|",
    ]
    for g, v in r["groups"].items():
        lines.append(f"| {g} | {v['seconds']:.2f} | {100 * v['share']:.1f} % |")
    d = r["data_loading_alone"]
    lines += [
        "",
        f"Data loading alone (the loader without training, {d['batches']} batches): "
        f"{d['ms_per_batch']:.1f} ms per batch, {d['pairs_per_s']:.0f} pairs/s.",
        "",
        f"## Top {len(r['top_ops'])} operators by self time",
        "",
        "| group | operator | calls | s | share |",
        "|---|---|---|---|---|",
    ]
    for o in r["top_ops"]:
        lines.append(
            f"| {o['group']} | {o['op']} | {o['calls']} | {o['seconds']:.2f} | "
            f"{100 * o['share']:.1f} % |"
        )
    return lines
