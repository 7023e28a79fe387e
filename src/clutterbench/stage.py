"""What every stage script shares: params loading, seeding, one-line errors."""

from __future__ import annotations

import hashlib
import os
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import BaseConfig, load_base, load_params
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json
from clutterbench.platform_info import cpu_clock, cpu_model, cpu_shares

STAGE_TIMING = Path("reports/timing/stages")
"""Where each stage run leaves its wall time (no dvc output: a rerun leaves every tracked
output byte-identical); `python -m clutterbench.bench.run_times` collects them after a whole
run into the measured record."""


def seed_everything(seed: int, torch_threads: int | None = None) -> None:
    """The one seeding block: Python, NumPy and (when imported) torch."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    if "torch" in sys.modules:
        import torch

        torch.manual_seed(seed)
        if torch_threads:
            torch.set_num_threads(torch_threads)


def run_stage(main: Callable[[dict[str, Any], BaseConfig], None]) -> None:
    """Call `main(params, base)`; a ClutterbenchError becomes one line on stderr and exit 2."""
    os.environ.setdefault("PYTHONHASHSEED", "0")
    try:
        params = load_params("params.yaml")
        base = load_base(params)
        seed_everything(base.seed, base.torch_threads)
        started, clock = time.perf_counter(), cpu_clock()
        main(params, base)
        record_wall_time(time.perf_counter() - started, base, clock)
    except ClutterbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)


MAX_STAGE_NAME = 120
"""A longer name (a debugging run of many conditions: stages/trials.py a b c ...) is cut to
its first argument, a count and a digest of the rest, so its timing file can be written."""


def stage_name(argv: list[str]) -> str:
    """dvc's name of the stage a command line runs: stages/train.py cp_focal -> train@cp_focal;
    a command line of many arguments: trials@<first>_and_<n>_more_<digest of them all>."""
    stem = Path(argv[0]).stem
    name = f"{stem}@{'_'.join(argv[1:])}" if argv[1:] else stem
    if len(name) <= MAX_STAGE_NAME:
        return name
    digest = hashlib.sha256("\0".join(argv[1:]).encode()).hexdigest()[:12]
    return f"{stem}@{argv[1][:60]}_and_{len(argv) - 2}_more_{digest}"


def record_wall_time(
    seconds: float, base: BaseConfig, clock: dict[str, float | None] | None = None
) -> None:
    """reports/timing/stages/<stage>.json: this run's wall time, scale and machine; with the
    cpu_clock reading taken at its start, the cores it kept busy and what else ran on the
    machine meanwhile (platform_info.cpu_shares: a time measured beside other work is too
    long, and the record says so)."""
    name = stage_name(sys.argv)
    shares = cpu_shares(clock, cpu_clock(), seconds) if clock is not None else {}
    write_json(
        STAGE_TIMING / f"{name}.json",
        {
            "stage": name,
            "seconds": round(seconds, 3),
            "scale": base.scale,
            "cores": base.cores,
            "cpu_model": cpu_model(),
            "logical_cpus": os.cpu_count(),
        }
        | shares,
    )
