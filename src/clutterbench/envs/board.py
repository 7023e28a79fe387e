"""An agent's row on the leaderboard (`clutterbench evaluate-agent`): its success under both
criteria with 95% intervals, and paired against every trials condition that ran the same
episodes of the same stream (reports/trials/<condition>/records.jsonl): episodes won only by
the agent and only by that planner, the difference in points and McNemar's exact p. Written
to reports/leaderboard/agents/<name>.json; the leaderboard's planner section lists them
(support.scorecard.leaderboard)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json
from clutterbench.report.paired import mcnemar_p
from clutterbench.trials.core.records import read_records
from clutterbench.trials.core.stats import wilson_interval

CRITERIA = ("success", "strict_success")
BOARD = Path("reports/leaderboard")
TESTSET_DIRS = ("data/testset", "data/published/testset")
"""Where the leaderboard's test set lies, in the order it is looked for (as evaluate-predictor
looks, cli/predictors.py): the run's own (stage testset), then the copy git keeps
(`clutterbench publish-testset`)."""


def rate(records: Sequence[Mapping[str, Any]], key: str) -> dict[str, Any]:
    k, n = sum(bool(r[key]) for r in records), len(records)
    lo, hi = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None, "interval_95": [lo, hi]}


def paired(
    mine: Sequence[Mapping[str, Any]], theirs: Sequence[Mapping[str, Any]], key: str
) -> dict[str, Any] | None:
    """The agent against one planner over the episodes both ran (None: none shared)."""
    a = {int(r["episode"]): bool(r[key]) for r in mine}
    b = {int(r["episode"]): bool(r[key]) for r in theirs}
    shared = sorted(set(a) & set(b))
    if not shared:
        return None
    only_a = sum(a[e] and not b[e] for e in shared)
    only_b = sum(b[e] and not a[e] for e in shared)
    return {
        "episodes": len(shared),
        "agent_k": sum(a[e] for e in shared),
        "baseline_k": sum(b[e] for e in shared),
        "only_agent": only_a,
        "only_baseline": only_b,
        "points": 100.0 * (only_a - only_b) / len(shared),
        "p": mcnemar_p(only_a, only_b),
    }


def baselines_on(stream: str, trials_dir: Path) -> dict[str, list[dict[str, Any]]]:
    """Every trials condition whose records ran on `stream` (reports/trials/*/)."""
    out = {}
    for path in sorted(trials_dir.glob("*/records.jsonl")):
        recs = read_records(path)
        if recs and recs[0].get("stream") == stream:
            out[path.parent.name] = recs
    return out


def agent_card(
    records: Sequence[Mapping[str, Any]], about: Mapping[str, Any], trials_dir: Path
) -> dict[str, Any]:
    """The agent's row: its rates and its pairing with every baseline on its stream."""
    if not records:
        raise ClutterbenchError(f"agent {about['name']}: no episodes to score")
    stream = str(records[0]["stream"])
    base = baselines_on(stream, trials_dir)
    card: dict[str, Any] = dict(about) | {"stream": stream, "episodes": len(records)}
    for key in CRITERIA:
        card[key] = rate(records, key)
        card[f"{key}_paired"] = {
            cond: p for cond, recs in base.items() if (p := paired(records, recs, key))
        }
    return card


def write_agent_row(card: Mapping[str, Any], board: Path = BOARD) -> Path:
    """agents/<name>.json, then the leaderboard rewritten with it (and with the predictor
    rows of the project's test set, the first of TESTSET_DIRS beside reports/ that holds
    one)."""
    from clutterbench.support.scorecard import leaderboard

    path = board / "agents" / f"{card['name']}.json"
    write_json(path, dict(card))
    manifests = [board.parent.parent / d / "manifest.json" for d in TESTSET_DIRS]
    found = [m for m in manifests if m.is_file()]
    leaderboard(board, board, read_json(found[0]).get("sha256") if found else None)
    return path
