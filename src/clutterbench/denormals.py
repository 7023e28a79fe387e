"""Denormal floats flushed to zero for a block of torch CPU arithmetic.

Weight decay drives many of a small network's weights and Adam moments below float32's
normal range (~1.2e-38). Arithmetic on such denormal numbers is many times slower on some
CPUs (Intel's among them): the slide ConvNet's checkpoint trained without flushing held
648,223 denormal weights, and its training epochs ran ~2.7x slower on an Intel Xeon than on
an AMD EPYC. Flushing (FTZ / DAZ) changes only values below 1.2e-38.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def flush_denormals() -> Iterator[None]:
    """torch's CPU arithmetic with denormals flushed to zero inside the block, IEEE denormals
    again after it (torch's default)."""
    import torch

    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)
