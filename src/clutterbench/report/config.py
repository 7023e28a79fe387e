"""Params of the report stage."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class ReportConfig:
    thesis_figures: str = "reports/thesis_figures.yaml"
    """The one data file of thesis figures; they appear only as "(thesis)" columns."""
