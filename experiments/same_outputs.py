"""Did a code change change a result? Two checkouts that ran the trials stages (and the report)
on the same networks and upstream outputs, compared byte for byte:

    python -m experiments.same_outputs OLD NEW --out experiments/reports/NAME.md

Every file the OLD checkout's trials stages wrote (reports/<stage>/, their episodes in
data/<stage>/) must be in NEW with the same bytes; where NEW holds more (conditions added since),
OLD's records must be NEW's records line for line (records.jsonl) and OLD's summary entries
NEW's (a stage's summary.json). Every cell of OLD's tables (reports/tables/*.csv) must be the
same string in NEW's table of that name, on the row named by the same leading cells (the fewest
leading columns that name each row once in both tables); NEW may add rows
and columns. Exit 1 when anything differs."""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.io import write_text

STAGES = ("trials", "trials_ch4", "trials_ch5", "trials_arm", "trials_ch3")


def _md5(path: Path) -> str:
    return hashlib.md5(path.read_bytes()).hexdigest()


def same_file(old: Path, new: Path, top: Path) -> bool:
    """OLD's file is NEW's (module docstring: records and a stage summary may hold more)."""
    if not new.is_file():
        return False
    if old.suffix == ".jsonl":
        have = set(new.read_text().splitlines())
        return all(line in have for line in old.read_text().splitlines())
    if old.name == "summary.json" and old.parent == top:
        a, b = json.loads(old.read_text()), json.loads(new.read_text())
        if isinstance(a, dict) and isinstance(b, dict):
            return all(k in b and b[k] == v for k, v in a.items())
    return _md5(old) == _md5(new)


def compare_stage(old: Path, new: Path, stage: str) -> dict[str, Any]:
    out: dict[str, Any] = {"stage": stage}
    for part in ("reports", "data"):
        top = old / part / stage
        files = sorted(p for p in top.rglob("*") if p.is_file()) if top.is_dir() else []
        differ = [
            str(p.relative_to(old))
            for p in files
            if not same_file(p, new / part / stage / p.relative_to(top), top)
        ]
        out[part] = {"files": len(files), "differ": differ}
    return out


def _row_key(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    """The fewest leading columns that name every row once in both tables ([] if none do)."""
    for k in range(1, len(a.columns) + 1):
        key = list(a.columns[:k])
        if all(c in b.columns for c in key) and not (
            a.duplicated(key).any() or b.duplicated(key).any()
        ):
            return key
    return []


def compare_table(old: Path, new: Path) -> dict[str, Any]:
    """OLD's cells in NEW's table (module docstring)."""
    if not new.is_file():
        return {"table": old.stem, "cells": 0, "differ": ["missing in NEW"]}
    if _md5(old) == _md5(new):
        rows = len(pd.read_csv(old, dtype=str, keep_default_na=False))
        return {"table": old.stem, "bytes": True, "cells": None, "rows": rows, "differ": []}
    a = pd.read_csv(old, dtype=str, keep_default_na=False)
    b = pd.read_csv(new, dtype=str, keep_default_na=False)
    key = _row_key(a, b)
    differ = [f"column {c} missing" for c in a.columns if c not in b.columns]
    if key:
        indexed = {tuple(r): i for i, r in enumerate(b[key].itertuples(index=False))}
        for _, row in a.iterrows():
            name = " / ".join(row[key])
            if tuple(row[key]) not in indexed:
                differ.append(f"row {name} missing")
                continue
            got = b.iloc[indexed[tuple(row[key])]]
            differ += [
                f"{name} / {c}: {row[c]} -> {got[c]}"
                for c in a.columns
                if c in b.columns and got[c] != row[c]
            ]
    else:
        differ.append("no leading columns name the rows once each in both tables")
    return {
        "table": old.stem,
        "bytes": False,
        "cells": a.size,
        "rows": len(a),
        "added": f"{len(b) - len(a)} rows, {len(b.columns) - len(a.columns)} columns",
        "differ": differ,
    }


def compare(
    old: Path, new: Path, stages: tuple[str, ...] = STAGES, tables: bool = True
) -> dict[str, Any]:
    """`stages` and (tables) the report's tables: only what both checkouts ran again."""
    csvs = sorted((old / "reports/tables").glob("*.csv")) if tables else []
    return {
        "stages": [compare_stage(old, new, s) for s in stages if (old / "reports" / s).is_dir()],
        "tables": [compare_table(t, new / "reports/tables" / t.name) for t in csvs],
    }


def markdown(result: dict[str, Any], old_label: str, new_label: str) -> str:
    lines = [
        "# Same outputs before and after a code change",
        "",
        f"OLD: {old_label}; NEW: {new_label}. Both ran on the same networks and upstream "
        "outputs (`python -m experiments.same_outputs`: every OLD file byte for byte in "
        "NEW; records and tables may hold more in NEW, conditions added since).",
        "",
        "| stage | report files | differ | episode files (MCAP, data/) | differ |",
        "|---|---|---|---|---|",
    ]
    for s in result["stages"]:
        r, d = s["reports"], s["data"]
        lines.append(
            f"| `{s['stage']}` | {r['files']} | {len(r['differ'])} | {d['files']} | "
            f"{len(d['differ'])} |"
        )
    if result["tables"]:
        lines += ["", "| table | rows | OLD cells | same | NEW adds |", "|---|---|---|---|---|"]
    for t in result["tables"]:
        same = (
            "byte-identical"
            if t.get("bytes")
            else ("every cell" if not t["differ"] else f"{len(t['differ'])} differ")
        )
        cells = "—" if t.get("cells") is None else t["cells"]
        lines.append(
            f"| {t['table']} | {t.get('rows', '—')} | {cells} | {same} | {t.get('added', '—')} |"
        )
    bad = [d for s in result["stages"] for p in ("reports", "data") for d in s[p]["differ"]]
    bad += [f"{t['table']}: {d}" for t in result["tables"] for d in t["differ"]]
    lines += ["", f"**Differences: {len(bad)}.**"]
    lines += [f"- {d}" for d in bad[:50]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--old-label", default="OLD")
    ap.add_argument("--new-label", default="NEW")
    ap.add_argument("--out", type=Path, default=None, help="markdown here (and .json beside)")
    ap.add_argument(
        "--stages", nargs="+", default=list(STAGES), help="the trials stages both ran again"
    )
    ap.add_argument("--no-tables", action="store_true", help="the report was not run again in both")
    args = ap.parse_args(argv)
    unknown = sorted(set(args.stages) - set(STAGES))
    if unknown:
        ap.error(f"--stages: {', '.join(unknown)} not among {', '.join(STAGES)}")
    result = compare(args.old, args.new, tuple(args.stages), not args.no_tables)
    md = markdown(result, args.old_label, args.new_label)
    if args.out is not None:
        write_text(args.out, md)
        write_text(args.out.with_suffix(".json"), json.dumps(result, indent=1) + "\n")
    print(md)
    return 1 if "**Differences: 0.**" not in md else 0


if __name__ == "__main__":
    sys.exit(main())
