"""Table 6.3 paired: each CP planner against physics from depth on the same episodes.

Both read one depth image per decision and nothing else of the world: the CP planner through
the collapse predictor, physics from depth through boxes fitted to the image and simulated
(planning/ch6/physics_depth.py). Their Table 6.3 rows ran the same scenes and targets, so they
compare episode by episode, under each criterion: the episodes won only by one row and only
by the other, the difference in points with a paired 95% bootstrap interval over episodes,
and McNemar's exact p. The rows that hold a box meet the physics-from-depth row that may
hold one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.report.decomposition import (
    CRITERIA,
    by_planner_stream,
    paired_points,
    shared_outcomes,
)
from clutterbench.report.tables import Column, write_raw_csv, write_table
from clutterbench.trials.ch6 import planners
from clutterbench.trials.core.stats import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED

TABLE = "table_6_3_paired"

COLUMNS = [
    Column("criterion", "criterion", "{}"),
    Column("stream", "stream", "{}"),
    Column("cp_pct", "CP %", "{:.1f}"),
    Column("baseline_pct", "physics from depth %", "{:.1f}"),
    Column("only_cp", "won only by CP", "{:d}"),
    Column("only_baseline", "won only by physics from depth", "{:d}"),
    Column("difference_text", "CP - physics from depth (points)", "{}"),
    Column("p", "McNemar p", "{:.2g}"),
    Column("episodes", "episodes", "{:d}"),
]


def mcnemar_p(b: int, c: int) -> float:
    """Two-sided exact McNemar p of paired binary outcomes: b pairs won by the first only, c
    by the second only (a binomial test of b against (b + c) / 2)."""
    n = b + c
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(b, c) + 1)) / 2**n
    return min(1.0, 2 * tail)


def paired_rows(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> list[dict[str, Any]]:
    """One row per (CP planner, stream, criterion) where the CP row and its physics-from-depth
    row both ran on that stream and saw alike (exact depth and the simulator's masks, or the
    same sensor and masks), over the episodes both ran; in the conditions' order, the rows
    under a sensor after."""
    rows = []
    for of_sensed in (False, True):
        index = by_planner_stream(records_by_condition, of_sensed)
        for (planner, stream), (cond, recs) in index.items():
            baseline = index.get((str(planners.declared(planner).baseline), stream))
            if baseline is not None and _seen(baseline[1][0]) == _seen(recs[0]):
                rows += _pair(planner, stream, (cond, recs), baseline, resamples, seed)
    return rows


def _seen(record: Mapping[str, Any]) -> tuple[str, str]:
    return str(record.get("sensing", "ideal")), str(record.get("perception", "instance"))


def _pair(
    planner: str,
    stream: str,
    cp_run: tuple[str, Sequence[Mapping[str, Any]]],
    baseline: tuple[str, Sequence[Mapping[str, Any]]],
    resamples: int,
    seed: int,
) -> list[dict[str, Any]]:
    """The CP run against its baseline run under each criterion."""
    (cond, recs), rows = cp_run, []
    for key, criterion in CRITERIA.items():
        shared, outcomes = shared_outcomes([recs, baseline[1]], key)
        if not shared:
            continue
        cp, base = (np.array(x, dtype=np.float64) for x in outcomes)
        d = cp - base
        only_cp, only_base = int((d > 0).sum()), int((d < 0).sum())
        rows.append(
            {
                "planner": planner,
                "condition": cond,
                "baseline_condition": baseline[0],
                "stream": stream,
                "criterion": criterion,
                "key": key,
                "episodes": len(shared),
                "cp_pct": 100.0 * float(cp.mean()),
                "baseline_pct": 100.0 * float(base.mean()),
                "only_cp": only_cp,
                "only_baseline": only_base,
            }
            | paired_points({"difference": d}, resamples, seed)
            | {"p": mcnemar_p(only_cp, only_base)}
            | ({} if _seen(recs[0]) == ("ideal", "instance") else {"seen": _seen(recs[0])})
        )
    return rows


def _seen_note(row: Mapping[str, Any]) -> str:
    if "seen" not in row:
        return ""
    sensing, perception = row["seen"]
    return f" ({sensing}, {'masks from depth' if perception == 'depth' else 'simulator masks'})"


def paired_table(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]], out_dir: Path, scale: str
) -> pd.DataFrame | None:
    """reports/tables/table_6_3_paired.{md,csv}; None (nothing written) when no stream has a
    CP row and its physics-from-depth row."""
    rows = paired_rows(records_by_condition)
    if not rows:
        return None
    head = "CP planner [CP / physics-from-depth condition]"
    shown = [
        {head: f"{r['planner']} [{r['condition']} / {r['baseline_condition']}]{_seen_note(r)}"}
        | {c.key: r.get(c.key) for c in COLUMNS}
        | {
            "difference_text": f"{r['difference']:+.1f} "
            f"[{r['difference_lo']:+.1f}, {r['difference_hi']:+.1f}]"
        }
        for r in rows
    ]
    frame = pd.DataFrame(shown)[[head, *[c.key for c in COLUMNS]]]
    frame = frame.rename(columns={c.key: c.header for c in COLUMNS})
    notes = [
        f"{scale} scale. Each CP planner of Table 6.3 against physics from depth (search on "
        "boxes fitted to the same depth image), episode by episode over the episodes both rows "
        "ran (same scenes, same targets): physics_from_depth for the one-arm planners, "
        "physics_from_depth_hold (may hold one box) for those that hold.",
        "Interval: 95%, a paired bootstrap over episodes (2,000 resamples, seed 0). McNemar: "
        "two-sided exact test on the episodes won by one row only; a difference whose p is "
        "large is within what the scenes drawn can give either way.",
    ]
    write_table(
        frame,
        COLUMNS,
        out_dir,
        TABLE,
        "Table 6.3 paired: the CP planners against physics from depth",
        notes,
    )
    return write_raw_csv(
        rows, out_dir / f"{TABLE}.csv", counts=("episodes", "only_cp", "only_baseline")
    )
