"""Which arithmetic the networks run in on this CPU: float32 or bfloat16 autocast.

bfloat16 autocast is ~1.7x faster than float32 on a CPU that runs it natively (AVX-512 with
the BF16 extension, or AMX) and ~10x slower where torch has to emulate it (an AVX2-only CPU:
reports/bench/avx2/models.md). `auto`, the default everywhere, picks bf16 only where it is
native, so a user never gets the emulated path by accident; `fp32` and `bf16` force one. The
precision actually used is recorded beside every result it shaped (checkpoint, training summary,
evaluation metrics, trial summaries), because bits match only on the same instruction set
and precision (docs/determinism.md).
"""

from __future__ import annotations

import dataclasses
import functools
import os
import sys
from collections.abc import Mapping
from typing import Literal

from clutterbench.config import load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.platform_info import cpu_flags, torch_cpu_capability

Precision = Literal["fp32", "bf16"]
PRECISIONS = ("auto", "fp32", "bf16")
"""The values a `precision` parameter takes."""

INFERENCE_ENV = "CLUTTERBENCH_INFERENCE_PRECISION"
"""Set from params (inference.precision) by the stage, so that the trials' worker processes
load their networks in the stage's precision; `auto` when unset."""

_WARNED: set[str] = set()


def native_bf16(capability: str | None = None, flags: Mapping[str, bool] | None = None) -> bool:
    """True when torch runs bf16 convolutions natively on this CPU: torch dispatches to an
    AVX-512 kernel level (not held to AVX2, e.g. by ATEN_CPU_CAPABILITY=avx2) and the CPU has
    AVX512_BF16 or AMX-BF16 instructions."""
    if capability is None and flags is None:
        return _native_here()
    capability = torch_cpu_capability() if capability is None else capability
    flags = cpu_flags() if flags is None else flags
    return capability.upper().startswith("AVX512") and bool(
        flags.get("avx512_bf16") or flags.get("amx_bf16")
    )


@functools.cache
def _native_here() -> bool:
    return native_bf16(torch_cpu_capability(), cpu_flags())


def check_precision(value: str, key: str) -> str:
    """`value` when it is one of PRECISIONS, else one error naming `key`."""
    if value not in PRECISIONS:
        raise ClutterbenchError(f"{key}: {value!r} is not one of {', '.join(PRECISIONS)}")
    return value


def resolve_precision(requested: str, native: bool | None = None) -> Precision:
    """`auto` -> bf16 where the CPU runs it natively, else fp32; `fp32` / `bf16` as given.
    Forcing bf16 on a CPU that emulates it warns once per process (one line on stderr)."""
    check_precision(requested, "precision")
    native = native_bf16() if native is None else native
    if requested == "auto":
        return "bf16" if native else "fp32"
    if requested == "bf16" and not native and "bf16" not in _WARNED:
        _WARNED.add("bf16")
        print(
            f"warning: precision bf16 forced on a CPU without native bf16 (torch capability "
            f"{torch_cpu_capability()}): emulated, ~10x slower than fp32; use auto or fp32",
            file=sys.stderr,
        )
    return "bf16" if requested == "bf16" else "fp32"


def use_for_inference(requested: str) -> Precision:
    """Make `requested` the precision of every network this process and its worker processes
    load for inference (CollapsePredictor's default); returns the resolved one."""
    os.environ[INFERENCE_ENV] = check_precision(requested, "inference.precision")
    return resolve_precision(requested)


def inference_precision() -> Precision:
    """The resolved precision set by `use_for_inference` (auto when none was set)."""
    return resolve_precision(os.environ.get(INFERENCE_ENV, "auto"))


@dataclasses.dataclass(frozen=True)
class InferenceConfig:
    """params.yaml `inference`: how the stages that run trained networks (evaluate, support,
    every trials stage) run them."""

    precision: str = "auto"
    """auto (bf16 autocast where the CPU runs it natively, else fp32), fp32 or bf16."""

    def __post_init__(self) -> None:
        check_precision(self.precision, "inference.precision")


def inference_from_params(params: Mapping[str, object]) -> Precision:
    """Load params' `inference` section and make its precision this process's (and its
    workers') inference precision; returns the resolved one, for the stage's records."""
    return use_for_inference(load_section(InferenceConfig, "inference", params).precision)
