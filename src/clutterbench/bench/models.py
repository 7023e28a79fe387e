"""`make bench`, networks part: training / inference speed on this CPU -> reports/bench/.

Measures a train step per image for every network of `train.models` in both precisions
(fp32 and bf16 autocast) with and without channels-last memory, at 1 and 2 threads, and says
which precision `auto` picks on this CPU (clutterbench.precision: bf16 only where it is
native; emulated bf16 is ~10x slower than fp32). Then the inference API in both precisions:
ms per collapse map at default and paper sizes, and ms for all targets of a 10-object scene
in one batched call. When a trained checkpoint exists, also how far bf16 inference moves its
probabilities from float32 on real validation images. Last, the peak RSS of a training epoch
over sharded data of growing size (clutterbench.bench.memory).
"""

from __future__ import annotations

import itertools
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from clutterbench.bench import header, write_result
from clutterbench.bench.memory import bench_train_memory, memory_markdown
from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.losses import bce_loss, ce_loss
from clutterbench.collapse.predict import CollapsePredictor, predict_collapse
from clutterbench.config import load_params, load_section
from clutterbench.data.dataset import CollapseDataset
from clutterbench.models import build_model
from clutterbench.platform_info import cpu_description
from clutterbench.precision import PRECISIONS, native_bf16, resolve_precision

BATCH = 16
STEPS = 3
SCENE_OBJECTS = 10
MEASURED = tuple(p for p in PRECISIONS if p != "auto")
"""Both precisions are timed on every CPU, whichever `auto` picks."""


def _inputs(
    n: int, size: int, n_masks: int = 1, n_classes: int = 1
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """depth, masks and labels: a 0/1 collapse map per sigmoid channel (one mask: a head per
    channel) or class indices (two masks, several classes: thesis ch. 4)."""
    g = torch.Generator().manual_seed(0)
    depth = 0.5 + 0.3 * torch.rand(n, 1, size, size, generator=g)
    target = (torch.rand(n, n_masks, size, size, generator=g) > 0.95).float()
    if softmax_classes(n_masks, n_classes):
        return depth, target, torch.randint(0, n_classes, (n, size, size), generator=g)
    return depth, target, (torch.rand(n, n_classes, size, size, generator=g) > 0.9).float()


def softmax_classes(n_masks: int, n_classes: int) -> bool:
    """Whether the outputs are softmax classes (ch. 4), not sigmoid collapse maps."""
    return n_masks > 1 and n_classes > 1


def time_train_step(
    arch: str, net: Any, channels_last: bool, bf16: bool, batch: int = BATCH, steps: int = STEPS
) -> float:
    """ms per image of one Adam step (forward, BCE or CE, backward, update), batch `batch`,
    median of `steps` after one warm-up step."""
    torch.manual_seed(0)
    model = build_model(arch, net).train()
    depth, target, truth = _inputs(batch, net.input_size, net.n_masks, net.n_classes)
    if channels_last:
        model = model.to(memory_format=torch.channels_last)
        depth, target = (x.contiguous(memory_format=torch.channels_last) for x in (depth, target))
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    times = []
    for _ in range(steps + 1):  # the first step warms up oneDNN kernels
        t0 = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            logits = model(depth, target)
        ce = softmax_classes(net.n_masks, net.n_classes)
        loss = ce_loss(logits, truth) if ce else bce_loss(logits, truth)
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times[1:])) / batch


def bf16_over_fp32(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Per model: bf16 train ms / fp32 train ms at 2 threads, channels-last (the defaults):
    below 1 where bf16 is native, ~10 where it is emulated."""
    ms = {
        (r["model"], r["precision"]): r["train_ms_per_image"]
        for r in rows
        if r["threads"] == 2 and r["channels_last"]
    }
    models = dict.fromkeys(m for m, _ in ms)
    return {m: ms[(m, "bf16")] / ms[(m, "fp32")] for m in models}


def time_predict(predictor: CollapsePredictor, n_targets: int, repeats: int = 5) -> float:
    """ms for one predict_collapse call over `n_targets` masks of one depth image."""
    size = predictor.input_size
    depth, target, _ = _inputs(n_targets, size)
    depth_np, masks = depth[0, 0].numpy(), target[:, 0].numpy()
    predict_collapse(predictor, depth_np, masks)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        predict_collapse(predictor, depth_np, masks)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def bf16_agreement(ckpt: Path, gen_dir: Path, split_file: Path, threshold_m: float) -> dict:
    """Max |p_bf16 - p_fp32| and the fraction of pixels whose 0.5 decision flips."""
    fp32 = CollapsePredictor.from_checkpoint(ckpt, precision="fp32")
    bf16 = CollapsePredictor.from_checkpoint(ckpt, precision="bf16")
    ds = CollapseDataset(gen_dir, split_file, "val", threshold_m)
    worst, flips, pixels = 0.0, 0, 0
    for i in range(0, len(ds), max(1, len(ds) // 64)):
        item = ds[i]
        d, t = item["depth_m"][0].numpy(), item["target"].numpy()
        a, b = predict_collapse(fp32, d, t), predict_collapse(bf16, d, t)
        worst = max(worst, float(np.abs(a - b).max()))
        flips += int(((a > 0.5) != (b > 0.5)).sum())
        pixels += a.size
    return {"max_abs_prob_diff": worst, "decision_flip_fraction": flips / max(pixels, 1)}


def bench_models(out_dir: Path = Path("reports/bench")) -> dict:
    params = load_params("params.yaml")
    by_scale = {
        scale: load_section(TrainConfig, "train", {**params, "base": {"scale": scale}})
        for scale in ("default", "paper")
    }
    default = by_scale["default"]
    rows = []
    seen = set()
    for name, m in default.models.items():
        key = (m.arch, m.net)
        if key in seen:
            continue
        seen.add(key)
        for threads, cl, precision in itertools.product((1, 2), (False, True), MEASURED):
            torch.set_num_threads(threads)
            ms = time_train_step(m.arch, m.net, cl, precision == "bf16")
            rows.append(
                {
                    "model": name,
                    "threads": threads,
                    "channels_last": cl,
                    "precision": precision,
                    "train_ms_per_image": ms,
                }
            )
            print(rows[-1], flush=True)
    torch.set_num_threads(2)
    cp = "cp_focal" if "cp_focal" in default.models else next(iter(default.models))
    inference = {}
    for scale, cfg in by_scale.items():
        m = cfg.models[cp]
        model = build_model(m.arch, m.net)
        for precision in MEASURED:
            predictor = CollapsePredictor(model, batch_size=SCENE_OBJECTS, precision=precision)
            tag = f"{scale}_{m.net.input_size}px_{precision}"
            # emulated bf16 at paper size takes minutes per call: fewer repeats
            slow = scale == "paper" and precision == "bf16" and not native_bf16()
            inference[f"ms_per_map_{tag}"] = time_predict(predictor, 1, repeats=1 if slow else 5)
            inference[f"ms_scene_{SCENE_OBJECTS}_targets_{tag}"] = time_predict(
                predictor, SCENE_OBJECTS, repeats=1 if slow else 3 if scale == "paper" else 5
            )
            print(tag, inference[f"ms_per_map_{tag}"], flush=True)
    result: dict[str, Any] = {
        "bf16_native": native_bf16(),
        "auto_picks": resolve_precision("auto"),
        "bf16_over_fp32": bf16_over_fp32(rows),
        "train_step": rows,
        "inference_model": cp,
        "inference": inference,
        "threads": 2,
        "machine": f"{platform.processor() or platform.machine()}, torch {torch.__version__}",
        **{k: v for k, v in cpu_description().items() if k != "machine"},
    }
    gen = params["generate"]["datasets"]
    m = default.models[cp]
    ckpt = Path(f"models/{cp}/best.pt")
    if ckpt.exists():
        result["bf16_vs_fp32_on_val"] = bf16_agreement(
            ckpt,
            Path("data/generate"),
            Path(f"data/split/{m.dataset}.json"),
            float(gen[m.dataset]["moved_threshold_m"]),
        )
    result["train_epoch_memory"] = bench_train_memory(params)
    write_result(out_dir, "models", result, _markdown(result))
    return result


def _markdown(result: dict) -> list[str]:
    lines = header("Network benchmark (CPU)", result) + [
        f"Train step: Adam, batch {BATCH}, per image (median of {STEPS}).",
        "",
        "| model | threads | channels-last | precision | train ms / image |",
        "|---|---|---|---|---|",
    ]
    for r in result["train_step"]:
        lines.append(
            f"| {r['model']} | {r['threads']} | {r['channels_last']} | {r['precision']} | "
            f"{r['train_ms_per_image']:.1f} |"
        )
    native = "native" if result["bf16_native"] else "emulated"
    ratios = ", ".join(f"{m} {x:.2f}x" for m, x in result["bf16_over_fp32"].items())
    lines += [
        "",
        f"bf16 is {native} on this CPU; `precision: auto` picks **{result['auto_picks']}**. "
        f"bf16 / fp32 train time at 2 threads, channels-last: {ratios}.",
    ]
    lines += [
        "",
        f"Inference ({result['inference_model']}, 2 threads):",
        "",
        "| measure | ms |",
        "|---|---|",
    ]
    lines += [f"| {k} | {v:.1f} |" for k, v in result["inference"].items()]
    if "bf16_vs_fp32_on_val" in result:
        agree = result["bf16_vs_fp32_on_val"]
        lines += [
            "",
            f"bf16 vs float32 inference of the trained checkpoint on validation images: max "
            f"|dp| = {agree['max_abs_prob_diff']:.4f}, decisions flipped at 0.5: "
            f"{100 * agree['decision_flip_fraction']:.4f} % of pixels.",
        ]
    lines += ["", "Target: <= 20 ms per collapse map at default size on 2 cores."]
    if "train_epoch_memory" in result:
        lines += memory_markdown(result["train_epoch_memory"])
    return lines
