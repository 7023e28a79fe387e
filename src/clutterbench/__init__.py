"""clutterbench: collapse-aware manipulation in clutter, reproduced in SAPIEN simulation."""

__version__ = "0.1.0"
