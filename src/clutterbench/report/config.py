"""Params of the report stage."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping


@dataclasses.dataclass(frozen=True)
class ReportConfig:
    thesis_figures: str = "reports/thesis_figures.yaml"
    """The one data file of thesis figures; they appear only as "(thesis)" columns."""
    table_5_1: Mapping[str, str | None] = dataclasses.field(default_factory=dict)
    """Thesis Table 5.1 row -> our evaluate run filling it (null: not run, said in the table)."""
    table_6_1: Mapping[str, str | None] = dataclasses.field(default_factory=dict)
    """Thesis Table 6.1 row -> our evaluate run."""
    table_6_3: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 6.3 row (thesis_figures.yaml `row:` label, or a row of ours) -> trials condition."""
    table_6_2_methods: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 6.2 row: support method (reports/support/scenes.csv) -> label."""
    table_4_1: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 4.1 row '<method>/<box set>' -> trials_ch4 condition (totals added per method)."""
    table_4_1_target: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Predetermined-target row (method) -> trials_ch4 condition."""
    table_5_2: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 5.2 row '<method>/<scene type>' -> trials_ch5 condition (totals added per method)."""
    table_4_2: Mapping[str, str | None] = dataclasses.field(default_factory=dict)
    """Thesis Table 4.2 row (model x ground truth) -> our evaluate run."""
