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
Writes reports/bench/train_rate.{json,md}.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import multiprocessing as mp
import os
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.overrides import TorchFunctionMode
from torch.utils.flop_counter import FlopCounterMode

from clutterbench.bench import header, write_result
from clutterbench.collapse.config import TrainConfig, TrainModelConfig
from clutterbench.collapse.train import Loss, loss_fn, train_step
from clutterbench.config import load_params, load_section
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import PairDataset, open_pairs
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.models import build_model
from clutterbench.platform_info import cpu_description

THREADS = 2
MATMUL_SIZES = (4096, 2048)
"""Matmul sizes tried in order: the first whose warm-up takes at most MATMUL_SLOW_S."""
MATMUL_SLOW_S = 3.0
MATMUL_REPS = 5
STEP_BUDGET_S = 8.0
"""Seconds of timed training steps per network or variant (at least MIN_STEPS steps)."""
MIN_STEPS, MAX_STEPS, WARMUP_STEPS = 3, 20, 2
IDLE_WAIT_S = 20.0
"""Seconds a measurement waits at most for other processes to leave the CPUs idle."""
ATTEMPTS = 3
"""Runs of a measurement at most, while other processes used the CPUs during it."""
CLEAN_SHARE = 0.05
"""Other processes' share of the CPUs up to which a measurement counts as undisturbed."""
SOFT_LIMIT_S = 420.0
"""After this long the part stops waiting and repeating (it keeps what it has)."""
CONV_BUDGET_S = 0.6
"""Seconds of timed repetitions per conv shape and memory format."""
COMPILE_TIMEOUT_S = 360.0
"""The torch.compile variant's child process is stopped after this long (compile + steps)."""
COMPILE_STEPS = 6
BIG_BATCH = 2
"""The larger-batch variant: this many times cp_focal's batch size."""
PROFILED = "cp_focal"
SYNTHETIC_SCENES = 150
"""Scenes of each synthetic dataset (three default-scale shards of 50)."""


# --- arithmetic ---------------------------------------------------------------------------


def matmul_flops(n: int) -> int:
    """FLOPs of an n x n by n x n matmul: n^2 outputs, n multiply-adds each."""
    return 2 * n**3


def gflops_per_s(flops: float, seconds: float) -> float:
    """A FLOP count done in `seconds` as GFLOP/s."""
    if seconds <= 0:
        raise ValueError(f"seconds must be > 0, got {seconds}")
    return flops / seconds / 1e9


def rate_row(gflop: float, seconds: float, peaks: dict[str, float]) -> dict[str, float]:
    """GFLOP/s of `gflop` in `seconds` and its share of each peak rate (GFLOP/s) in `peaks`
    (as `of_<name>`)."""
    rate = gflops_per_s(gflop * 1e9, seconds)
    return {"gflop_per_s": rate, **{f"of_{k}": rate / v for k, v in peaks.items()}}


def combined_rate(rows: list[dict[str, Any]]) -> float:
    """GFLOP/s of a set of timed ops run `count` times each: total FLOPs over total time."""
    flops = sum(r["gflop"] * r["count"] for r in rows)
    seconds = sum(r["seconds"] * r["count"] for r in rows)
    return gflops_per_s(flops * 1e9, seconds)


# --- timing -------------------------------------------------------------------------------


def timed(
    fn: Callable[[], object],
    budget_s: float,
    warmup: int = 1,
    min_reps: int = 3,
    max_reps: int = 50,
) -> list[float]:
    """Seconds of repeated calls of `fn` after `warmup` untimed ones: at least `min_reps`, then
    more while the timed total stays under `budget_s` (at most `max_reps`)."""
    for _ in range(warmup):
        fn()
    times: list[float] = []
    while len(times) < max_reps and (len(times) < min_reps or sum(times) < budget_s):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return times


PROC_STAT = Path("/proc/stat")


def machine_busy_seconds() -> float | None:
    """CPU seconds all processes have run so far, summed over CPUs (/proc/stat's cpu line:
    everything but idle and iowait); None where there is no /proc/stat."""
    try:
        fields = PROC_STAT.read_text().splitlines()[0].split()
    except (OSError, IndexError):
        return None
    ticks = [int(x) for x in fields[1:9]]  # user nice system idle iowait irq softirq steal
    return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")


def own_seconds() -> float:
    t = os.times()
    return t.user + t.system


def others_share(busy_s: float, own_s: float, wall_s: float, cpus: int) -> float:
    """The share of the machine's CPUs that other processes used: busy CPU seconds of all
    processes less this one's, over wall time x CPUs (never below 0)."""
    return max(0.0, busy_s - own_s) / (wall_s * cpus) if wall_s > 0 else 0.0


class Contention:
    """Measures, over a `with` block, the share of the CPUs other processes used (`others`:
    0 on an otherwise idle machine, 0.5 where they kept one of two cores busy; None where
    /proc/stat is missing)."""

    others: float | None = None

    def __enter__(self) -> Contention:
        self._busy, self._own = machine_busy_seconds(), own_seconds()
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        busy = machine_busy_seconds()
        if busy is None or self._busy is None:
            return
        wall = time.perf_counter() - self._t0
        self.others = others_share(
            busy - self._busy, own_seconds() - self._own, wall, os.cpu_count() or 1
        )


@dataclasses.dataclass
class Gate:
    """Measurements on shared cores: before each, wait up to `idle_wait_s` for the other
    processes to leave the CPUs idle (their share <= `clean`); a measurement during which
    they used more is repeated, `attempts` times at most, and the fastest attempt kept with
    its share. Past `deadline` (time.perf_counter) no more waiting or repeats."""

    idle_wait_s: float = IDLE_WAIT_S
    attempts: int = ATTEMPTS
    clean: float = CLEAN_SHARE
    deadline: float = float("inf")

    def wait_idle(self) -> None:
        waited = 0.0
        while waited < self.idle_wait_s and time.perf_counter() < self.deadline:
            with Contention() as c:
                time.sleep(0.5)
            if c.others is None or c.others <= self.clean:
                return
            waited += 0.5

    def run(self, measure: Callable[[int], list[float]]) -> tuple[list[float], float | None, int]:
        """(times, others' share, attempts) of the fastest attempt of `measure(attempt)`."""
        best: tuple[list[float], float | None] | None = None
        attempt = 0
        for attempt in range(1, self.attempts + 1):
            self.wait_idle()
            with Contention() as c:
                times = measure(attempt)
            if best is None or min(times) < min(best[0]):
                best = (times, c.others)
            late = time.perf_counter() >= self.deadline
            if c.others is None or c.others <= self.clean or late:
                break
        assert best is not None
        return best[0], best[1], attempt


def matmul_rate(
    dtype: torch.dtype, sizes: tuple[int, ...] = MATMUL_SIZES, gate: Gate | None = None
) -> dict[str, Any]:
    """Best-of-MATMUL_REPS GFLOP/s of torch.matmul of random square matrices in `dtype`."""
    gate = gate or Gate(attempts=1, idle_wait_s=0.0)
    for n in sizes:
        g = torch.Generator().manual_seed(0)
        a, b = (torch.randn(n, n, generator=g).to(dtype) for _ in range(2))
        t0 = time.perf_counter()
        torch.matmul(a, b)  # warm-up
        if time.perf_counter() - t0 <= MATMUL_SLOW_S or n == sizes[-1]:
            mm = functools.partial(torch.matmul, a, b)
            reps = functools.partial(timed, mm, 0.0, 0, MATMUL_REPS, MATMUL_REPS)
            times, others, _ = gate.run(lambda _, reps=reps: reps())
            return {
                "n": n,
                "dtype": str(dtype).removeprefix("torch."),
                "best_s": min(times),
                "gflop_per_s": gflops_per_s(matmul_flops(n), min(times)),
                "others_cpu": others,
            }
    raise ValueError("no matmul sizes")


def matmul_rates(gate: Gate | None = None) -> dict[str, dict[str, Any]]:
    """matmul_rate in bf16 and fp32."""
    dtypes = (("bf16", torch.bfloat16), ("fp32", torch.float32))
    return {k: matmul_rate(d, gate=gate) for k, d in dtypes}


def shares_of(result: dict[str, Any], peaks: dict[str, float]) -> None:
    """Every rate's share of the peaks (`of_<name>`) in `result` recomputed for `peaks`."""
    rows = [*result["models"], *result["variants"], *result["convs"]["total"].values()]
    for r in rows:
        if "gflop_per_s" in r:
            r |= {f"of_{k}": r["gflop_per_s"] / v for k, v in peaks.items()}


# --- networks on synthetic data -----------------------------------------------------------


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


# --- convolution microbenchmark -----------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class ConvShape:
    input: tuple[int, ...]
    weight: tuple[int, ...]
    stride: tuple[int, int]
    padding: tuple[int, int]
    groups: int
    input_grad: bool
    """Whether the training step needs the gradient of the input (not for a first layer)."""

    def label(self) -> str:
        n, c, h, w = self.input
        o, _, kh, kw = self.weight
        g = f" g{self.groups}" if self.groups > 1 else ""
        s = f" /{self.stride[0]}" if self.stride[0] > 1 else ""
        return f"{n}x{c}x{h}x{w} -> {o} {kh}x{kw}{s}{g}"


def _pair(v: Any) -> tuple[int, int]:
    return (int(v), int(v)) if isinstance(v, int) else (int(v[0]), int(v[1]))


class _ConvRecorder(TorchFunctionMode):
    """Records every conv2d call (module or functional) with its shapes."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[ConvShape] = []

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func in (torch.conv2d, torch.nn.functional.conv2d):
            names = ("input", "weight", "bias", "stride", "padding", "dilation", "groups")
            a = dict(zip(names, args)) | kwargs
            x, w = a["input"], a["weight"]
            self.calls.append(
                ConvShape(
                    tuple(x.shape),
                    tuple(w.shape),
                    _pair(a.get("stride", 1)),
                    _pair(a.get("padding", 0)),
                    int(a.get("groups", 1)),
                    bool(x.requires_grad),
                )
            )
        return func(*args, **kwargs)


def step_convs(
    model: torch.nn.Module, batch: dict[str, torch.Tensor], cfg: TrainConfig
) -> list[tuple[ConvShape, int]]:
    """The distinct convolutions of one training forward of `model` on `batch`, with how
    many times each runs, in first-call order."""
    from clutterbench.collapse.train import batch_logits

    recorder = _ConvRecorder()
    with recorder:
        batch_logits(model.train(), batch, cfg)
    counts: dict[ConvShape, int] = {}
    for c in recorder.calls:
        counts[c] = counts.get(c, 0) + 1
    return list(counts.items())


def conv_case(
    shape: ConvShape, channels_last: bool
) -> tuple[Callable[[], None], Callable[[], object]]:
    """(fwd + bwd under bf16 autocast, its single forward) for one conv shape."""
    memory = torch.channels_last if channels_last else torch.contiguous_format
    g = torch.Generator().manual_seed(0)
    x = torch.randn(shape.input, generator=g).contiguous(memory_format=memory)
    x.requires_grad_(shape.input_grad)
    w = (0.1 * torch.randn(shape.weight, generator=g)).contiguous(memory_format=memory)
    w.requires_grad_(True)
    stride, padding, groups = shape.stride, shape.padding, shape.groups

    def forward() -> torch.Tensor:
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return torch.nn.functional.conv2d(x, w, None, stride, padding, 1, groups)

    grad = torch.randn(forward().shape, generator=g).to(torch.bfloat16)
    grad = grad.contiguous(memory_format=memory)

    def step() -> None:
        y = forward()
        torch.autograd.backward(y, grad)
        w.grad = None
        x.grad = None

    return step, forward


def bench_convs(
    convs: list[tuple[ConvShape, int]],
    peaks: dict[str, float],
    gate: Gate,
    budget_s: float = CONV_BUDGET_S,
) -> dict[str, Any]:
    """Each conv's forward + backward in NCHW and channels-last: GFLOP/s and the combined
    rate of all, weighted by how often a step runs each."""
    rows = []
    for shape, count in convs:
        step, _ = conv_case(shape, False)
        with FlopCounterMode(display=False) as counter:
            step()
        gflop = counter.get_total_flops() / 1e9
        row: dict[str, Any] = {"conv": shape.label(), "count": count, "gflop": gflop}
        for tag, cl in (("nchw", False), ("channels_last", True)):
            step, _ = conv_case(shape, cl)
            reps = functools.partial(timed, step, budget_s, 1, 5, 200)
            times, others, _ = gate.run(lambda _, reps=reps: reps())
            row[f"{tag}_s"] = min(times)
            row[f"{tag}_gflop_per_s"] = gflops_per_s(gflop * 1e9, min(times))
            row[f"{tag}_others_cpu"] = others
        rows.append(row)
    total = {}
    for tag in ("nchw", "channels_last"):
        timed_rows = [{**r, "seconds": r[f"{tag}_s"]} for r in rows]
        rate = combined_rate(timed_rows)
        total[tag] = {
            "gflop_per_s": rate,
            **{f"of_{k}": rate / v for k, v in peaks.items()},
            "seconds_per_step": sum(r["seconds"] * r["count"] for r in timed_rows),
        }
    return {"layers": rows, "total": total}


# --- the part -----------------------------------------------------------------------------


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


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
