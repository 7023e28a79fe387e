"""`make bench` (`python -m clutterbench.bench`): how fast this CPU runs the pipeline.

Parts, in order (`__main__.PARTS`): simulation throughput and label replay (`sim`), network
train / inference speed plus the peak RSS of a training epoch (`models`, `memory`), the
grouped (scene encoded once) vs per-pair paths of the collapse networks (`grouped`), and
support-graph latency and wall time per trial (`trials`), a Yamakuzushi game's parts
(`ch3`), an arm-level step against the kinematic one (`arm`), the physics-from-depth
planner's decision time per step (`physics_depth`), every registered environment made
with defaults, reset and stepped (`envs`), the same simulation jobs on both parallel
backends, processes and Ray, with 1 and 2 workers (`ray`: `bench/scaling.py`, its
workloads built in `bench/workloads.py`; it also costs the paper scale from them), and how
much of this CPU's matmul rate training the networks reaches (`train_rate`), where a
slice of a training epoch spends its time (`train_profile`), where each simulation stage's
wall time goes, by kind of work, with a sample of it profiled and the whole stage
extrapolated (`sim_profile`), what dvc's own YAML work costs per stage (`dvc`) and what a
trusted score costs: 200 fresh scenes drawn, labelled and scored, and 200 fresh episodes of
an agent (`fresh`). Results go to reports/bench/: one JSON per part and a markdown table
beside most; each records the CPU model it ran on.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.io import write_json, write_text
from clutterbench.platform_info import instruction_set
from clutterbench.precision import native_bf16


def machine_line(result: Mapping[str, Any]) -> str:
    """The markdown line under a title naming the machine (keys of cpu_description()): the
    model name, and the instruction set that decides the network kernels and precision."""
    isa = ""
    if "torch_cpu_capability" in result:
        native = native_bf16(result["torch_cpu_capability"], result.get("cpu_flags") or {})
        isa = f" ({instruction_set(result)}; bf16 {'native' if native else 'emulated'})"
    return (
        f"Machine: {result['cpu_model']}{isa}, {result['logical_cpus']} logical CPUs, "
        f"{result['torch_threads']} torch threads, {result['machine']}."
    )


def header(title: str, result: Mapping[str, Any]) -> list[str]:
    """A result's markdown title and machine line."""
    return [f"# {title}", "", machine_line(result), ""]


def measure_table(result: Mapping[str, Any], skip: tuple[str, ...] = ()) -> list[str]:
    """A two-column markdown table of a flat result; floats to 3 decimals."""
    lines = ["| measure | value |", "|---|---|"]
    lines += [
        f"| {k} | {v:.3f} |" if isinstance(v, float) else f"| {k} | {v} |"
        for k, v in result.items()
        if k not in skip
    ]
    return lines


def write_result(
    out_dir: Path, name: str, result: Mapping[str, Any], markdown: list[str] | None = None
) -> None:
    """`result` as out_dir/<name>.json and, when given, the markdown lines as <name>.md."""
    write_json(out_dir / f"{name}.json", result)
    if markdown is not None:
        write_text(out_dir / f"{name}.md", "\n".join(markdown) + "\n")


def bench_ch6_jobs(
    planner: str, episodes: int, trials: Any, sim: Any, support: Any, cp_max: float, model: Path
) -> list[Any]:
    """Ch. 6 planner `planner`'s first `episodes` jobs on stream ch6_3_10, seed 99, condition
    "bench": the trials, grouped and physics-depth benches' episodes."""
    from clutterbench.trials.ch6.episodes import ch6_jobs
    from clutterbench.trials.config import ConditionConfig

    cond = ConditionConfig(planner=planner, stream="ch6_3_10", episodes=episodes)
    kw = {"support": support, "cp_max": cp_max, "model_path": model}
    return ch6_jobs("bench", cond, trials=trials, sim=sim, seed=99, **kw)
