"""What every stage script shares: params loading, seeding, one-line errors."""

from __future__ import annotations

import os
import random
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from clutterbench.config import BaseConfig, load_base, load_params
from clutterbench.errors import ClutterbenchError


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
        main(params, base)
    except ClutterbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
