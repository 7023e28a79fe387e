"""Params of the report stage."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

TABLE_6_2_METHODS = {
    "iou": "CP + IoU rule (thesis 6.2.2, exactly)",
    "iou_gap": "CP + IoU rule + surface-gap test (ours)",
    "coverage": "CP + coverage rule (eq. 6.2)",
    "coverage_gap": "CP + coverage rule + surface-gap test (ours; the trials' rule)",
    "oracle_iou": "oracle collapse map + IoU rule",
    "oracle_coverage": "oracle collapse map + coverage rule",
    "oracle_coverage_gap": "oracle collapse map + coverage rule + surface-gap test",
    "pull_coverage_gap": (
        "CP pull head + coverage rule + surface-gap test, against pull truth (the pull "
        "planners' rule)"
    ),
    "pull_oracle_coverage_gap": (
        "pull-truth collapse map + coverage rule + surface-gap test, against pull truth"
    ),
    "pull_collapse_coverage_gap": (
        "CP pull_collapse head + coverage rule + surface-gap test, against pull-collapse truth"
    ),
    "pull_collapse_oracle_coverage_gap": (
        "pull-collapse-truth map + coverage rule + surface-gap test, against pull-collapse truth"
    ),
    "pull_box": (
        "box head: per-box pull and contact probabilities, no pixel rule, against pull truth"
    ),
    "pull_collapse_box": (
        "box head: per-box pull-collapse and contact probabilities, no pixel rule, "
        "against pull-collapse truth"
    ),
    "pull_box_fused": (
        "box head + physics from depth, fused per box (logistic, chosen on val), against pull truth"
    ),
    "pull_collapse_box_fused": (
        "box head + physics from depth, fused per box (logistic, chosen on val), against "
        "pull-collapse truth"
    ),
    "pull_physics_pull": (
        "physics from depth: the trials' pull simulated in the fitted boxes, the box "
        "head's contact, against pull truth"
    ),
    "pull_collapse_physics_pull": (
        "physics from depth: the trials' pull simulated in the fitted boxes, the box "
        "head's contact, against pull-collapse truth"
    ),
    "physics_from_depth": (
        "physics from depth: removals simulated in the boxes fitted to the depth image + "
        "the oracle map's rule"
    ),
    "random": "random edges between pseudo-contact pairs",
}
"""Table 6.2 row labels: support method (reports/support/scenes.csv) -> how its row reads.
The default of report.table_6_2_methods (params.yaml may override any)."""


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
    table_6_2_methods: Mapping[str, str] = dataclasses.field(
        default_factory=lambda: dict(TABLE_6_2_METHODS)
    )
    """Table 6.2 row: support method (reports/support/scenes.csv) -> label (default:
    TABLE_6_2_METHODS)."""
    table_4_1: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 4.1 row '<method>/<box set>' -> trials_ch4 condition (totals added per method)."""
    table_4_1_target: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Predetermined-target row (method) -> trials_ch4 condition."""
    table_5_2: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Table 5.2 row '<method>/<scene type>' -> trials_ch5 condition (totals added per method)."""
    table_4_2: Mapping[str, str | None] = dataclasses.field(default_factory=dict)
    """Thesis Table 4.2 row (model x ground truth) -> our evaluate run."""
