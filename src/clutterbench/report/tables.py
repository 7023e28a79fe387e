"""Build comparison tables (ours | thesis) and write them as Markdown + CSV.

Thesis figures come only from the one data file (reports/thesis_figures.yaml) and appear
only in the "(thesis)" columns.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from clutterbench.errors import ClutterbenchError, yaml_problem
from clutterbench.io import write_text
from clutterbench.trials.core.stats import Rate


def load_thesis_figures(path: Path) -> dict[str, Any]:
    path = Path(path)
    if not path.exists():
        raise ClutterbenchError(f"thesis figures file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ClutterbenchError(
            f"thesis figures file {path} is not valid YAML: {yaml_problem(exc)}"
        ) from None
    if not isinstance(data, dict):
        raise ClutterbenchError(f"thesis figures file {path} must map table ids to tables")
    return data


def thesis_row(figures: Mapping[str, Any], table: str, row: str) -> dict[str, Any]:
    """One row of a thesis table by its `row:` label ({} if the thesis has none)."""
    if table not in figures:
        raise ClutterbenchError(f"thesis figures: no table '{table}'")
    for r in figures[table].get("rows", []):
        if r.get("row") == row:
            return r
    return {}


def thesis_rate_text(row: Mapping[str, Any]) -> str | None:
    """'k/n = x%': counts and the rate as printed in the thesis (not recomputed)."""
    if "success" not in row or "trials" not in row:
        return None
    text = f"{row['success']}/{row['trials']}"
    return f"{text} = {100 * row['success_rate']:.1f}%" if "success_rate" in row else text


def rate_text(agg: Mapping[str, Any], prefix: str) -> str | None:
    """'k/n = x% [lo, hi]' of the `<prefix>_k` / `<prefix>_n` columns of an aggregate row
    (trials.stats.aggregate); None where the row lacks them."""
    if f"{prefix}_k" not in agg or pd.isna(agg[f"{prefix}_k"]):
        return None
    return Rate(int(agg[f"{prefix}_k"]), int(agg[f"{prefix}_n"])).text()


def grouped(used: Mapping[str, Sequence[Mapping[str, Any]]], describe: Callable) -> str:
    """'a (cond, cond); b (cond)': conditions sharing a description named once."""
    groups: dict[str, list[str]] = {}
    for condition, records in used.items():
        groups.setdefault(describe(records), []).append(condition)
    return "; ".join(f"{d} ({', '.join(c)})" for d, c in groups.items())


IDEAL = "ideal"
"""The sensing of a row that names none: the renderer's exact depth."""
SENSORS = {"structured_light": "structured-light sensor", "d415": "D415-class sensor"}
"""How a sensed row's label names its preset (sim/sensor.py PRESETS, docs/sensing.md)."""


def sensed_text(sensing: str) -> str:
    """What a row's label adds for its sensor: '' for the exact depth, else
    ', D415-class sensor (d415)'."""
    return "" if sensing == IDEAL else f", {SENSORS[sensing]} ({sensing})"


def sensed_by_preset(used: Mapping[str, Sequence[Mapping[str, Any]]]) -> str | None:
    """'d415 (cond_a, cond_b)': the conditions of `used` whose records saw through a sensor
    model, by preset; None when none did (a table then says nothing of sensing)."""
    sensed = {c: rs for c, rs in used.items() if any("sensing" in r for r in rs)}
    return grouped(sensed, lambda rs: values_text(rs, "sensing")) if sensed else None


def values_text(records: Iterable[Mapping[str, Any]], key: str) -> str:
    """'a, b': the distinct values of `key` over the records, as text, sorted."""
    return ", ".join(sorted({str(r.get(key)) for r in records}))


@dataclasses.dataclass(frozen=True)
class Column:
    key: str
    """Metric key in our metrics and in the thesis row."""
    header: str
    fmt: str = "{:.3f}"


def _fmt(value: Any, fmt: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, int | float) and not isinstance(value, bool):
        if fmt.endswith("d}"):  # counts turn float in a column that has gaps
            value = int(value)
        return fmt.format(value)
    return str(value)


def comparison_frame(
    rows: Sequence[tuple[str, Mapping[str, Any], Mapping[str, Any]]],
    columns: Sequence[Column],
    row_header: str,
) -> pd.DataFrame:
    """rows: (label, ours, thesis). Each column appears as 'header' and, where the thesis
    reports that figure for some row, 'header (thesis)' beside it."""
    records = []
    for label, ours, thesis in rows:
        rec: dict[str, Any] = {row_header: label}
        for c in columns:
            rec[c.header] = ours.get(c.key)
            rec[f"{c.header} (thesis)"] = thesis.get(c.key)
        records.append(rec)
    frame = pd.DataFrame.from_records(records)
    empty = [f"{c.header} (thesis)" for c in columns if frame[f"{c.header} (thesis)"].isna().all()]
    return frame.drop(columns=empty)


def write_table(
    frame: pd.DataFrame,
    columns: Sequence[Column],
    out_dir: Path,
    name: str,
    title: str,
    notes: Sequence[str] = (),
) -> None:
    """reports/tables/<name>.md (formatted) and <name>.csv (raw values)."""
    fmts = {c.header: c.fmt for c in columns} | {f"{c.header} (thesis)": c.fmt for c in columns}
    header = list(frame.columns)
    lines = [
        f"# {title}",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
    ]
    for _, r in frame.iterrows():
        lines.append("| " + " | ".join(_fmt(r[h], fmts.get(h, "{}")) for h in header) + " |")
    lines += [""] + [f"- {n}" for n in notes]
    write_text(out_dir / f"{name}.md", "\n".join(lines).rstrip() + "\n")
    write_text(out_dir / f"{name}.csv", frame.to_csv(index=False))


def write_raw_csv(
    rows: Sequence[Mapping[str, Any]], path: Path, counts: Sequence[str] = ("episodes",)
) -> pd.DataFrame:
    """A trials table's raw rows as CSV: `counts` and every k / n column stay integers
    (nullable, so a row that lacks one does not turn the column float). Returns the frame."""
    frame = pd.DataFrame.from_records(rows)
    ints = [c for c in frame.columns if c in counts or c.endswith(("_k", "_n"))]
    frame = frame.astype(dict.fromkeys(ints, "Int64"))
    write_text(Path(path), frame.to_csv(index=False))
    return frame
