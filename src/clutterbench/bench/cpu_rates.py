"""The CPU's own rates for the train_rate part, and measuring on shared cores.

The torch.matmul rate of square matrices in bf16 and fp32 (the ceiling network training is
compared with), a convolution microbenchmark of a training step's own conv layers (forward +
backward under bf16 autocast, NCHW and channels-last), the FLOP-rate arithmetic, and the
shared-core discipline of every measurement of the bench's training parts: wait for idle
cores, measure the other processes' share of the CPUs meanwhile (/proc/stat), repeat a
disturbed run (Gate).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import torch
from torch.overrides import TorchFunctionMode
from torch.utils.flop_counter import FlopCounterMode

from clutterbench.collapse.config import TrainConfig

THREADS = 2
MATMUL_SIZES = (4096, 2048)
"""Matmul sizes tried in order: the first whose warm-up takes at most MATMUL_SLOW_S."""
MATMUL_SLOW_S = 3.0
MATMUL_REPS = 5
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


def own_seconds(children: bool = False) -> float:
    """CPU seconds this process has run; with `children`, those of its waited-for child
    processes too."""
    t = os.times()
    return t.user + t.system + (t.children_user + t.children_system if children else 0.0)


def others_share(busy_s: float, own_s: float, wall_s: float, cpus: int) -> float:
    """The share of the machine's CPUs that other processes used: busy CPU seconds of all
    processes less this one's, over wall time x CPUs (never below 0)."""
    return max(0.0, busy_s - own_s) / (wall_s * cpus) if wall_s > 0 else 0.0


class Contention:
    """Measures, over a `with` block, the share of the CPUs other processes used (`others`:
    0 on an otherwise idle machine, 0.5 where they kept one of two cores busy; None where
    /proc/stat is missing). `children`: this process's child processes, waited for within
    the block, count as its own."""

    others: float | None = None

    def __init__(self, children: bool = False) -> None:
        self.children = children

    def __enter__(self) -> Contention:
        self._busy, self._own = machine_busy_seconds(), own_seconds(self.children)
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        busy = machine_busy_seconds()
        if busy is None or self._busy is None:
            return
        wall = time.perf_counter() - self._t0
        self.others = others_share(
            busy - self._busy,
            own_seconds(self.children) - self._own,
            wall,
            os.cpu_count() or 1,
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


def least_disturbed(
    measure: Callable[[], dict[str, Any]],
    idle_wait_s: float = 60.0,
    limit_s: float = SOFT_LIMIT_S,
    children: bool = False,
) -> dict[str, Any]:
    """`measure()` on shared cores: wait for idle ones, and repeat a run other processes
    disturbed (Gate: ATTEMPTS at most, none started after `limit_s`); the least disturbed
    run's dict, with the others' CPU share (`others`) and its attempt (`attempts`).
    `children`: the child processes `measure` waits for count as this one (Contention)."""
    gate = Gate(idle_wait_s=idle_wait_s, deadline=time.perf_counter() + limit_s)
    best: dict[str, Any] | None = None
    for attempt in range(1, gate.attempts + 1):
        gate.wait_idle()
        with Contention(children) as c:
            got = measure()
        got |= {"others": c.others, "attempts": attempt}
        print({k: v for k, v in got.items() if isinstance(v, int | float | str)}, flush=True)
        if best is None or (c.others or 0.0) < (best["others"] or 0.0):
            best = got
        if c.others is None or c.others <= gate.clean or time.perf_counter() > gate.deadline:
            break
    assert best is not None
    return best


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
