"""The measured record of a whole run: after `dvc repro` (or `make repro`) from a fresh clone,
`python -m clutterbench.bench.run_times` (`make run-times`) collects the wall time each stage
left in reports/timing/stages/ (clutterbench.stage.record_wall_time) into
reports/run_times/<cpu>.{json,md}: minutes per stage and per stage group, their sum, the
scale, the machine. Run times quoted in the docs come from these records."""

from __future__ import annotations

import argparse
import datetime
import re
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json, write_text
from clutterbench.stage import STAGE_TIMING

OUT = Path("reports/run_times")


def collect(timing_dir: Path = STAGE_TIMING) -> dict[str, Any]:
    """Every stage's timing file -> one record (minutes per stage, in name order). All files
    must come from one machine and one scale: a record mixes nothing."""
    files = sorted(timing_dir.glob("*.json"))
    if not files:
        raise ClutterbenchError(f"{timing_dir}: no stage timings; run dvc repro first")
    runs = [read_json(f) for f in files]
    for key in ("cpu_model", "scale", "cores"):
        seen = {str(r.get(key)) for r in runs}
        if len(seen) > 1:
            raise ClutterbenchError(f"{timing_dir}: stage timings of more than one {key}: {seen}")
    stages = {r["stage"]: round(r["seconds"] / 60.0, 2) for r in runs}
    return {
        "cpu_model": runs[0]["cpu_model"],
        "logical_cpus": runs[0]["logical_cpus"],
        "cores": runs[0]["cores"],
        "scale": runs[0]["scale"],
        "stages": stages,
        "groups": group_minutes(stages),
        "total_minutes": round(sum(stages.values()), 1),
    }


def group_minutes(stages: dict[str, float]) -> dict[str, float]:
    """Minutes per stage group: a foreach stage's runs (train@a, train@b) under its name."""
    out: dict[str, float] = {}
    for name, minutes in stages.items():
        group = name.split("@")[0]
        out[group] = round(out.get(group, 0.0) + minutes, 2)
    return out


def table(record: dict[str, Any]) -> str:
    """The record as Markdown: one row per stage group, its runs, then the sum."""
    lines = [
        f"Measured: {record['scale']} scale, {record['cpu_model']}, {record['cores']} cores "
        f"({record['logical_cpus']} logical CPUs).",
        "",
        "| stage | minutes | runs |",
        "|---|---|---|",
    ]
    for group, minutes in record["groups"].items():
        runs = [s for s in record["stages"] if s.split("@")[0] == group]
        each = ", ".join(
            f"{s.split('@', 1)[1]} {record['stages'][s]:.1f}" for s in runs if "@" in s
        )
        lines.append(f"| `{group}` | {minutes:.1f} | {each} |")
    lines.append(f"| **all stages** | **{record['total_minutes']:.1f}** | |")
    return "\n".join(lines) + "\n"


def slug(cpu: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", cpu.lower()).strip("_") or "cpu"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--timing", type=Path, default=STAGE_TIMING)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    record = collect(args.timing)
    record["date"] = datetime.date.today().isoformat()
    name = f"{record['scale']}_{slug(record['cpu_model'])}"
    write_json(args.out / f"{name}.json", record)
    write_text(args.out / f"{name}.md", f"# Run time of a whole run\n\n{table(record)}")
    print(f"{args.out / name}.md: {record['total_minutes']} min over {len(record['stages'])} runs")


if __name__ == "__main__":
    try:
        main()
    except ClutterbenchError as exc:
        raise SystemExit(f"error: {exc}") from None
