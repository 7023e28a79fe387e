"""The physics-from-depth planner's box estimates against the truth: a table of
estimation errors per trial stream (reports/tables/box_estimation.{md,csv}) from the trial
records' `estimate_start` (each episode's first observation, the canonical start, fitted by
perception/box_fit.py and scored by the trials). The figure of estimated vs true boxes over
the depth image of a few scenes (like thesis Fig. 6.8) is the trials stage's, which holds the
scenes (trials/ch6/box_figure.py)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.report.tables import Column, write_raw_csv, write_table

TABLE = "box_estimation"

COLUMNS = [
    Column("stream", "stream", "{}"),
    Column("seen", "depth image, masks (if not exact and the simulator's)", "{}"),
    Column("scenes", "scenes", "{:d}"),
    Column("boxes", "boxes", "{:d}"),
    Column("missing_pct", "missing (hidden or < min_pixels) %", "{:.1f}"),
    Column("centre_median_mm", "centre error median (mm)", "{:.1f}"),
    Column("centre_p90_mm", "centre error p90 (mm)", "{:.1f}"),
    Column("size_median_mm", "size error median (mm)", "{:.1f}"),
    Column("size_wrong_pct", "size off by > 2 mm %", "{:.1f}"),
    Column("tilt_median_deg", "tilt error median (deg)", "{:.2f}"),
    Column("tilt_p90_deg", "tilt error p90 (deg)", "{:.1f}"),
    Column("yaw_median_deg", "yaw error median (deg)", "{:.2f}"),
    Column("yaw_p90_deg", "yaw error p90 (deg)", "{:.1f}"),
    Column("not_at_rest_pct", "estimated scenes not at rest %", "{:.1f}"),
    Column("decisions", "decisions", "{:d}"),
    Column("repair_dropped", "boxes dropped by the repair", "{:d}"),
    Column("repair_outside", "of them: no place in the shelf", "{:d}"),
    Column("perception_failed", "decisions without a model", "{:d}"),
]


def _stream_seen(record: Mapping[str, Any]) -> str:
    """A row's key: the stream, then what a sensed condition's planner saw (its own row)."""
    stream = str(record["stream"])
    if "sensing" not in record and record.get("perception", "instance") == "instance":
        return stream
    return f"{stream} {record.get('sensing', 'ideal')}, {record.get('perception')} masks"


def estimation_rows(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]],
) -> list[dict[str, Any]]:
    """One row per stream of a physics-from-depth condition: the errors of the boxes
    estimated at each episode's start (from the one-arm condition when both ran: both see
    the same first observation), and the share of estimated scenes not at rest over every
    decision of both."""
    starts: dict[str, list[Mapping[str, Any]]] = {}
    rest: dict[str, list[float]] = {}
    repair: dict[str, np.ndarray] = {}
    for recs in records_by_condition.values():
        for r in recs:
            if r.get("estimate_start") is None:  # only physics from depth records its estimates
                continue
            stream = _stream_seen(r)
            rest.setdefault(stream, []).extend(
                [float(r["estimate_not_at_rest"]), float(len(r["estimate_settle_mm"]))]
            )
            repair[stream] = repair.get(stream, np.zeros(3, dtype=np.int64)) + [
                sum(int(d or 0) for d in r.get("estimate_dropped", [])),
                sum(int(d or 0) for d in r.get("estimate_outside", [])),
                int(r.get("perception_failed", 0)),
            ]
            starts.setdefault(stream, [])
            seen = {int(s["episode"]) for s in starts[stream]}
            if int(r["episode"]) not in seen:
                starts[stream].append(r | {"episode": int(r["episode"])})
    rows = []
    for stream in sorted(starts):
        recs = starts[stream]
        boxes = np.array(
            [b[1:] for r in recs for b in r["estimate_start"]["boxes"]], dtype=np.float64
        ).reshape(-1, 4)
        n_boxes = sum(int(r["estimate_start"]["n_boxes"]) for r in recs)
        missing = sum(int(r["estimate_start"]["missing"]) for r in recs)
        not_rest, decisions = np.array(rest[stream]).reshape(-1, 2).sum(axis=0)

        def pct(col: int, q: float, boxes: np.ndarray = boxes) -> float:
            return float(np.percentile(boxes[:, col], q)) if len(boxes) else float("nan")

        rows.append(
            {
                "stream": stream.partition(" ")[0],
                "seen": stream.partition(" ")[2] or None,
                "scenes": len(recs),
                "boxes": n_boxes,
                "estimated": len(boxes),
                "missing": missing,
                "missing_pct": 100.0 * missing / n_boxes if n_boxes else float("nan"),
                "centre_median_mm": pct(0, 50),
                "centre_mean_mm": float(boxes[:, 0].mean()) if len(boxes) else float("nan"),
                "centre_p90_mm": pct(0, 90),
                "size_median_mm": pct(1, 50),
                "size_mean_mm": float(boxes[:, 1].mean()) if len(boxes) else float("nan"),
                "size_wrong_pct": 100.0 * float(np.mean(boxes[:, 1] > 2.0))
                if len(boxes)
                else float("nan"),
                "tilt_median_deg": pct(2, 50),
                "tilt_p90_deg": pct(2, 90),
                "yaw_median_deg": pct(3, 50),
                "yaw_p90_deg": pct(3, 90),
                "not_at_rest": int(not_rest),
                "decisions": int(decisions),
                "not_at_rest_pct": 100.0 * not_rest / decisions if decisions else float("nan"),
                "repair_dropped": int(repair[stream][0]),
                "repair_outside": int(repair[stream][1]),
                "perception_failed": int(repair[stream][2]),
            }
        )
    return [{k: v for k, v in r.items() if k != "seen" or v} for r in rows]


def estimation_table(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]], out_dir: Path, scale: str
) -> pd.DataFrame | None:
    """reports/tables/box_estimation.{md,csv}; None (nothing written) without a
    physics-from-depth condition."""
    rows = estimation_rows(records_by_condition)
    if not rows:
        return None
    columns = [c for c in COLUMNS if c.key != "seen" or any("seen" in r for r in rows)]
    frame = pd.DataFrame([{c.header: r.get(c.key) for c in columns} for r in rows])
    notes = [
        f"{scale} scale. Boxes fitted to the first observation of each episode (the canonical "
        "start, every box in the scene) by perception/box_fit.py: the dominant face's plane "
        "from the masked depth points, the in-plane axes from the minimum-area rectangle, "
        "sizes from the stream catalogue's nearest type (the hidden depth is that type's "
        "third size), scored against the true boxes. One row per stream (the scenes of its "
        "physics-from-depth conditions).",
        "missing: boxes not estimated (fully hidden, or fewer than trials.ch6.min_pixels "
        "visible pixels). centre: distance of the centres; size: mean absolute difference of "
        "the sorted extents (0 when the catalogue type is right); tilt: angle between the "
        "axes nearest to vertical; yaw: about the vertical, of the box's horizontal axes, "
        "modulo 90 degrees.",
        "not at rest: the estimated scene, settled for trials.ch6.physics_depth_settle_s "
        "before the search, had not come to rest (over every decision of both planners).",
        "boxes dropped by the repair: over every decision of both planners, fitted boxes the "
        "repair (sim/estimated.py) left out of the estimated scene, overlapping beyond repair "
        "or with no place in the shelf (a centre in front of the opening or above the top); "
        "decisions without a model: the observation gave no scene (a PerceptionError, "
        "recorded in the step); the planner then pulls the target.",
    ]
    write_table(
        frame, columns, out_dir, TABLE, "Box estimation from one depth image: errors", notes
    )
    return write_raw_csv(rows, out_dir / f"{TABLE}.csv", counts=("scenes", "boxes"))
