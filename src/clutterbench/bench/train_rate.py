"""`make bench`, train_rate part: how much of this CPU's matrix rate network training reaches.

In one run, on this machine:
- the torch.matmul rate of square matrices (4096, or 2048 where 4096 is slow) in bf16 and
  fp32: GFLOP/s of the best of a few repetitions after a warm-up, the ceiling to compare with;
- a convolution microbenchmark of cp_focal's own conv layers (every conv of a default-scale
  training step: its input, weight, stride and groups, each as often as the step runs it),
  forward + backward under bf16 autocast, in NCHW and channels-last memory;
- for each network of `train.models` at default scale (built as collapse.train builds it,
  from the same config objects), a real training step (train.train_step: its batch size,
  image size, loss, Adam, autocast and memory format) on a batch drawn by the training
  sampler from a small synthetic dataset of the network's dataset (data.synthetic: the
  generate stage's layout, so the batch has the real shapes and scenes per batch): the
  step's FLOPs (torch.utils.flop_counter on one step: convolutions and matmuls, forward and
  backward) over its time, as a share of the bf16 and fp32 matmul rates;
- variants of cp_focal's step: as `train` runs it, NCHW (train.channels_last off),
  torch.compile (inductor on the CPU; in a child process under a time limit, its compile
  time recorded, a failure or a timeout recorded as the result) and a larger batch.

Every measurement is time-boxed; the part takes a few minutes on 2 cores. The 1-minute load
average before and after is recorded: on shared cores another process's load lowers rates.
Writes reports/bench/train_rate.{json,md}. The matmul and conv rates and the shared-core
gate are in bench.cpu_rates, the networks' steps in bench.train_steps, the markdown in
bench.train_rate_md.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from clutterbench.bench import write_result
from clutterbench.bench.cpu_rates import (
    SOFT_LIMIT_S,
    THREADS,
    Gate,
    bench_convs,
    matmul_rates,
    shares_of,
    step_convs,
    torch_threads,
)
from clutterbench.bench.train_rate_md import markdown
from clutterbench.bench.train_steps import (
    PROFILED,
    build_training,
    compiled_step,
    default_params,
    first_batch,
    in_child,
    measure_model,
    step_row,
    synthetic_pairs,
)
from clutterbench.collapse.config import TrainConfig, TrainModelConfig
from clutterbench.config import load_section
from clutterbench.platform_info import cpu_description

COMPILE_TIMEOUT_S = 360.0
"""The torch.compile variant's child process is stopped after this long (compile + steps)."""
COMPILE_STEPS = 6
BIG_BATCH = 2
"""The larger-batch variant: this many times cp_focal's batch size."""


def bench_train_rate(out_dir: Path = Path("reports/bench")) -> dict[str, Any]:
    started = time.perf_counter()
    gate = Gate(deadline=started + SOFT_LIMIT_S)
    conv_gate = dataclasses.replace(gate, idle_wait_s=3.0)
    params = default_params()
    cfg = load_section(TrainConfig, "train", params)
    result: dict[str, Any] = {
        "precision": "bf16" if cfg.bf16 else "fp32",
        "channels_last": cfg.channels_last,
    }
    with torch_threads(THREADS), tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        matmul = matmul_rates(gate)
        peaks = {k: v["gflop_per_s"] for k, v in matmul.items()}
        print("matmul", peaks, flush=True)
        batches = {}
        rows = []
        for name, mcfg in cfg.models.items():
            ds = synthetic_pairs(params, cfg, mcfg, root)
            batches[name] = first_batch(ds, mcfg.batch_size, mcfg.scene_group)
            row = measure_model(name, "as train runs it", cfg, mcfg, batches[name], peaks, gate)
            rows.append(row)
            print(row, flush=True)
        result["models"] = rows

        mcfg = cfg.models[PROFILED]
        batch = batches[PROFILED]
        model, _, _ = build_training(cfg, mcfg, cfg.channels_last)
        result["convs"] = bench_convs(step_convs(model, batch, cfg), peaks, conv_gate)
        result["convs"]["model"] = PROFILED
        print("convs", result["convs"]["total"], flush=True)

        variants = [next(r for r in rows if r["model"] == PROFILED)]
        other = dataclasses.replace(cfg, channels_last=not cfg.channels_last)
        tag = "NCHW" if cfg.channels_last else "channels-last"
        variants.append(measure_model(PROFILED, tag, other, mcfg, batch, peaks, gate))
        print(variants[-1], flush=True)
        big = mcfg.batch_size * BIG_BATCH
        ds = synthetic_pairs(params, cfg, mcfg, root)
        big_batch = first_batch(ds, big, mcfg.scene_group)
        big_cfg = dataclasses.replace(mcfg, batch_size=big)
        variants.append(
            measure_model(PROFILED, f"batch {big}", cfg, big_cfg, big_batch, peaks, gate)
        )
        print(variants[-1], flush=True)
        compiled = _compiled_variant(cfg, mcfg, batch, peaks, gate, root)
        print(compiled, flush=True)
        variants.append(compiled)
        result["variants"] = variants
        # the peaks measured again at the end: the better of the two (shared cores)
        again = matmul_rates(gate)
        print("matmul again", {k: v["gflop_per_s"] for k, v in again.items()}, flush=True)
        result["matmul"] = {
            k: max(matmul[k], again[k], key=lambda m: m["gflop_per_s"]) for k in matmul
        }
        result["matmul_runs"] = {
            k: [matmul[k]["gflop_per_s"], again[k]["gflop_per_s"]] for k in matmul
        }
        shares_of(result, {k: v["gflop_per_s"] for k, v in result["matmul"].items()})
    result |= {
        "threads": THREADS,
        "torch": torch.__version__,
        "seconds": round(time.perf_counter() - started, 1),
        **cpu_description(),
        "torch_threads": THREADS,
    }
    write_result(out_dir, "train_rate", result, markdown(result))
    return result


def _compiled_variant(
    cfg: TrainConfig,
    mcfg: TrainModelConfig,
    batch: dict[str, torch.Tensor],
    peaks: dict[str, float],
    gate: Gate,
    root: Path,
) -> dict[str, Any]:
    """The torch.compile variant's row, measured in a child process (or its error)."""
    gate.wait_idle()
    child_gate = dataclasses.replace(gate, idle_wait_s=5.0)
    args = (cfg, mcfg, batch, THREADS, COMPILE_STEPS, str(root / "inductor"), child_gate)
    got = in_child(compiled_step, args, COMPILE_TIMEOUT_S)
    if "error" in got:
        compiled: dict[str, Any] = {"model": PROFILED, "variant": "torch.compile", **got}
    else:
        compiled = step_row(
            PROFILED,
            "torch.compile",
            batch,
            got["gflop"],
            got["times"],
            peaks,
            got["others"],
            got["attempts"],
        )
        keys = ("compile_s", "warmup_steps_s", "others_cpu_compiling")
        compiled |= {k: got[k] for k in keys}
    return compiled
