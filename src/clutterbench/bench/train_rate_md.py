"""The train_rate part's markdown: the matmul rates, each network's and variant's training
step against them, and the convolutions alone."""

from __future__ import annotations

from typing import Any

from clutterbench.bench import header
from clutterbench.bench.cpu_rates import ATTEMPTS, CLEAN_SHARE, MATMUL_REPS
from clutterbench.bench.train_steps import PROFILED


def pct(x: float | None) -> str:
    return "?" if x is None else f"{100 * x:.1f} %"


def step_table(rows: list[dict[str, Any]], first: str) -> list[str]:
    """Markdown rows of step results (models or variants); `first` names the first column."""
    lines = [
        f"| {first} | batch (scenes) | GFLOP / step | step s (best / median) | GFLOP/s "
        "(best / median) | of bf16 matmul | of fp32 matmul | others' CPU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        label = r["model"] if first == "model" else r["variant"]
        if "error" in r:
            lines.append(f"| {label} | | | | failed: {r['error']} | | | |")
            continue
        if "compile_s" in r:
            busy = r.get("others_cpu_compiling")
            label += f" (compile {r['compile_s']:.0f} s, others' CPU {pct(busy)} meanwhile)"
        lines.append(
            f"| {label} | {r['batch_size']} ({r['scenes_per_batch']}) | "
            f"{r['gflop_per_step']:.2f} | {r['best_step_s']:.3f} / {r['median_step_s']:.3f} | "
            f"{r['gflop_per_s']:.1f} / {r['median_gflop_per_s']:.1f} | {pct(r['of_bf16'])} | "
            f"{pct(r['of_fp32'])} | {pct(r.get('others_cpu'))} |"
        )
    return lines


def markdown(result: dict[str, Any]) -> list[str]:
    mm = result["matmul"]
    lines = header("Training FLOP rate against the matmul rate (CPU)", result)
    lines += [
        f"torch.matmul, square {mm['bf16']['n']} (bf16) and {mm['fp32']['n']} (fp32), best of "
        f"{MATMUL_REPS} at the start and again at the end, the better kept: "
        f"**bf16 {mm['bf16']['gflop_per_s']:.1f} GFLOP/s**, "
        f"**fp32 {mm['fp32']['gflop_per_s']:.1f} GFLOP/s**; {result['seconds']:.0f} s in all.",
        "",
        "Shared cores: before each measurement the part waits (a while) for other processes "
        "to leave the CPUs idle, repeats one during which they used more than "
        f"{CLEAN_SHARE:.0%} of the CPUs (up to {ATTEMPTS} runs) and keeps the fastest run; "
        "others' CPU: their share of the CPUs during the run kept (/proc/stat less this "
        "process). A row with a large share understates the rate.",
        "",
        "## Training step of each network (default scale, as the train stage runs it)",
        "",
        f"A real step (forward, loss, backward, Adam) in {result['precision']}, "
        f"channels-last {result['channels_last']}, on a batch the training sampler drew from "
        "synthetic data of the network's dataset (real shapes and scenes per batch). FLOPs: "
        "FlopCounterMode on one step (convolutions and matmuls, forward and backward); rate "
        "and shares from the best step.",
        "",
        *step_table(result["models"], "model"),
        "",
        f"## Variants of {PROFILED}",
        "",
        "torch.compile: inductor on the CPU with an empty kernel cache, in a child process; "
        "compile: its first two steps (forward and backward compiled).",
        "",
        *step_table(result["variants"], "variant"),
        "",
    ]
    convs = result["convs"]
    tot = convs["total"]
    lines += [
        f"## {convs['model']}'s convolutions alone",
        "",
        "Each distinct conv of one training step, forward + backward (input gradient where "
        "the step needs it) under bf16 autocast, best of repeated runs; count: times per step.",
        "",
        "| conv (input -> out channels) | count | GFLOP | NCHW GFLOP/s | channels-last GFLOP/s "
        "| others' CPU |",
        "|---|---|---|---|---|---|",
    ]
    for r in convs["layers"]:
        others = [r.get(f"{t}_others_cpu") for t in ("nchw", "channels_last")]
        worst = None if None in others else max(others)  # type: ignore[type-var]
        lines.append(
            f"| {r['conv']} | {r['count']} | {r['gflop']:.3f} | {r['nchw_gflop_per_s']:.1f} | "
            f"{r['channels_last_gflop_per_s']:.1f} | {pct(worst)} |"
        )
    lines.append("")
    for tag, label in (("nchw", "NCHW"), ("channels_last", "channels-last")):
        t = tot[tag]
        lines.append(
            f"All of them, {label}: {t['seconds_per_step']:.3f} s per step, "
            f"{t['gflop_per_s']:.1f} GFLOP/s = {pct(t['of_bf16'])} of the bf16 matmul rate."
        )
        lines.append("")
    lines.pop()
    return lines
