"""ManiSkill 3 tasks built from scene specs (`import clutterbench.maniskill` registers
ClutterShelfExtract-v1 and ClutterShelfBimanual-v1) and the arm-level executor of the
trials (maniskill/executor.py)."""

from clutterbench.maniskill import tasks  # noqa: F401  (registers the environments)
