"""The paired statistics every dev-stream recheck reports: two conditions met on the same
episodes compared episode by episode (McNemar's exact test), under both success criteria."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.report.paired import mcnemar_p

CRITERIA = {"success": "success", "strict_success": "strict success"}
"""Record key -> its name in the report: collapse-free (the thesis' notion), strict."""
ALPHA = 0.05
"""Family-wise level of the paired tests (Bonferroni over every stream and criterion)."""


def paired(records: Sequence[Mapping[str, Any]], a: str, b: str, stream: str, key: str) -> dict:
    """Condition a against b on one stream under criterion `key`, episode by episode."""
    outcome: dict[str, dict[int, bool]] = {a: {}, b: {}}
    for r in records:
        label, on = r["condition"].split("/")
        if on == stream and label in outcome:
            outcome[label][r["episode"]] = bool(r[key])
    if outcome[a].keys() != outcome[b].keys():
        raise ClutterbenchError(f"{stream}: piles {a} and {b} ran different episodes")
    only_a = sum(outcome[a][e] and not outcome[b][e] for e in outcome[a])
    only_b = sum(outcome[b][e] and not outcome[a][e] for e in outcome[a])
    n = len(outcome[a])
    return {
        "stream": stream,
        "criterion": key,
        "piles": a,
        "against": b,
        "only_piles": only_a,
        "only_against": only_b,
        "episodes": n,
        "difference_points": 100 * (only_a - only_b) / n if n else math.nan,
        "p": mcnemar_p(only_a, only_b),
    }


def plain(v: Any) -> Any:
    return v.item() if hasattr(v, "item") else v


def rate_text(row: Mapping[str, Any], key: str) -> str:
    from clutterbench.trials.core.stats import Rate

    return Rate(row[f"{key}_k"], row[f"{key}_n"]).text()


def below_oracle_text(row: Mapping[str, Any]) -> str:
    """A summary row's points below its oracle, "success / strict" ("—" for the oracle)."""
    if row["success_below_oracle_points"] is None:
        return "—"
    return (
        f"{row['success_below_oracle_points']:.0f} / "
        f"{row['strict_success_below_oracle_points']:.0f}"
    )


def paired_cells(p: Mapping[str, Any]) -> str:
    """A paired comparison's last table cells: won only by each side, the difference, p."""
    return (
        f"{p['only_piles']} | {p['only_against']} | {p['difference_points']:+.1f} | {p['p']:.2g} |"
    )


def current_variant(variants: Mapping[str, Mapping[str, Any]], params: Any) -> str | None:
    """The variant whose every override is what `params` (a trials section) already set
    (None: none is)."""
    return next(
        (
            n
            for n, over in variants.items()
            if all(getattr(params, k) == v for k, v in over.items())
        ),
        None,
    )
