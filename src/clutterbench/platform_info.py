"""The machine a result came from: CPU model, logical CPUs, torch threads, versions.

Results are byte-identical only on the same CPU model with the same thread count (README:
Determinism), so every benchmark result, the report stage's metrics and the cross-check
record these. Nothing here imports SAPIEN (versions are read from package metadata).
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


def logical_cpus() -> int:
    return os.cpu_count() or 1


def torch_threads() -> int:
    """torch's intra-op thread count as set in this process (imports torch if needed)."""
    import torch

    return torch.get_num_threads()


def cpu_description() -> dict[str, Any]:
    """CPU model, logical CPUs, torch threads and architecture: what byte-identity needs."""
    return {
        "cpu_model": cpu_model(),
        "logical_cpus": logical_cpus(),
        "torch_threads": torch_threads(),
        "machine": platform.machine(),
    }


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
