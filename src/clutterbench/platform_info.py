"""The machine a result came from: CPU model, instruction set, logical CPUs, torch threads,
versions.

Results are byte-identical only on the same CPU model and instruction set with the same
thread count and network precision (docs/determinism.md). A model name such as "AMD EPYC"
names neither the instruction set nor whether bf16 runs natively, so every benchmark result,
the report stage's metrics and the cross-check record torch's CPU capability (the kernel
level it dispatches to) and the relevant CPU flags beside it. Nothing here imports SAPIEN
(versions are read from package metadata).
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path
from typing import Any

CPUINFO = Path("/proc/cpuinfo")


def cpu_model(cpuinfo: Path = CPUINFO) -> str:
    """/proc/cpuinfo's first "model name"; else platform.processor(), else the architecture."""
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


FLAGS = ("avx2", "avx512f", "avx512_bf16", "amx_bf16")
"""The CPU flags that decide which network kernels run, and whether bf16 is native."""


def cpu_flags(cpuinfo: Path = CPUINFO) -> dict[str, bool]:
    """Each of FLAGS: present in /proc/cpuinfo's first "flags" line (all False elsewhere)."""
    present: set[str] = set()
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "flags":
                present = set(value.split())
                break
    except OSError:
        pass
    return {flag: flag in present for flag in FLAGS}


def torch_cpu_capability() -> str:
    """The kernel level torch dispatches to: "AVX2", "AVX512", ... (ATEN_CPU_CAPABILITY can
    hold it lower than the CPU allows; imports torch)."""
    import torch

    return str(torch.backends.cpu.get_cpu_capability())


def logical_cpus() -> int:
    return os.cpu_count() or 1


def torch_threads() -> int:
    """torch's intra-op thread count as set in this process (imports torch if needed)."""
    import torch

    return torch.get_num_threads()


def cpu_description() -> dict[str, Any]:
    """CPU model, instruction set (torch's capability and the CPU flags), logical CPUs,
    torch threads and architecture: what byte-identity needs."""
    return {
        "cpu_model": cpu_model(),
        "torch_cpu_capability": torch_cpu_capability(),
        "cpu_flags": cpu_flags(),
        "logical_cpus": logical_cpus(),
        "torch_threads": torch_threads(),
        "machine": platform.machine(),
    }


def instruction_set(description: dict[str, Any]) -> str:
    """One phrase for a cpu_description(): torch's capability and the flags present, e.g.
    "torch AVX2; avx2" or "torch AVX512; avx2 avx512f avx512_bf16"."""
    flags = description.get("cpu_flags") or {}
    present = " ".join(f for f in FLAGS if flags.get(f)) or "none of " + "/".join(FLAGS)
    return f"torch {description.get('torch_cpu_capability', '?')}; {present}"


def package_version(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def environment() -> dict[str, Any]:
    """cpu_description() plus the Python, torch and SAPIEN versions."""
    return {
        **cpu_description(),
        "python": platform.python_version(),
        "torch": package_version("torch"),
        "sapien": package_version("sapien"),
        "platform": f"{platform.system()} {platform.release()}",
    }


PROC_STAT = Path("/proc/stat")


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of the children it has waited for (a
    worker pool's processes once it is shut down)."""
    import resource

    own, children = (
        resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
    )
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def cpu_clock(stat: Path = PROC_STAT) -> dict[str, float | None]:
    """CPU seconds so far: this process and its waited-for children (`own`, cpu_seconds),
    and the whole machine's busy and stolen time from /proc/stat's `cpu` line (`machine`,
    `steal`; None where it cannot be read). Two readings around a job tell whether it had
    the cores (cpu_shares)."""
    own = cpu_seconds()
    machine = steal = None
    try:
        fields = stat.read_text().splitlines()[0].split()
        if fields[0] == "cpu":
            ticks = [int(x) for x in fields[1:]]
            hz = os.sysconf("SC_CLK_TCK")
            # user nice system idle iowait irq softirq steal [guest guest_nice: inside user]
            machine = (sum(ticks[:8]) - ticks[3] - ticks[4] - ticks[7]) / hz
            steal = ticks[7] / hz if len(ticks) > 7 else 0.0
    except (OSError, ValueError, IndexError):
        pass
    return {"own": own, "machine": machine, "steal": steal}


def cpu_shares(start: dict[str, float | None], end: dict[str, float | None], wall_s: float):
    """Cores on average over `wall_s` between two cpu_clock readings: this job's own
    (`busy_cores`), the rest of the machine's busy time (`other_cores`: other jobs on the
    same cores) and the time the hypervisor gave to other machines (`steal_cores`); the
    last two None where /proc/stat was not read."""
    wall = max(wall_s, 1e-9)
    out: dict[str, float | None] = {"busy_cores": round((end["own"] - start["own"]) / wall, 3)}
    for key, name in (("machine", "other_cores"), ("steal", "steal_cores")):
        a, b = start[key], end[key]
        out[name] = None if a is None or b is None else (b - a) / wall
    if out["other_cores"] is not None:
        out["other_cores"] = round(max(out["other_cores"] - out["busy_cores"], 0.0), 3)
    if out["steal_cores"] is not None:
        out["steal_cores"] = round(out["steal_cores"], 3)
    return out
