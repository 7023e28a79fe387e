"""An agent's row on the leaderboard (`clutterbench evaluate-agent`): its success under both
criteria with 95% intervals, and paired against every trials condition that ran the same
episodes of the same stream (reports/trials/<condition>/records.jsonl): episodes won only by
the agent and only by that planner, the difference in points and McNemar's exact p. Written
to reports/leaderboard/agents/<name>.json (fresh episodes: fresh/agent-<name>.json, paired
with nothing: no planner ran them); the leaderboard's planner section lists them
(support.scorecard.leaderboard).

A row keeps the episodes the agent won (`episodes_won`), so its pairings can be recomputed
from the records alone: when the trials are rerun, `python -m clutterbench.envs.board`
re-pairs every agent row with the committed records and rewrites the leaderboard (a unit test
fails while a row and the records disagree)."""

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
    card["episodes_won"] = {
        key: sorted(int(r["episode"]) for r in records if r[key]) for key in CRITERIA
    }
    for key in CRITERIA:
        card[key] = rate(records, key)
        card[f"{key}_paired"] = {
            cond: p for cond, recs in base.items() if (p := paired(records, recs, key))
        }
    return card


def card_records(card: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The per-episode outcomes a row keeps (episodes_won over its episodes), as records."""
    first, n = int(card["first_episode"]), int(card["episodes"])
    won = {key: set(card["episodes_won"][key]) for key in CRITERIA}
    return [
        {"stream": card["stream"], "episode": e} | {key: e in won[key] for key in CRITERIA}
        for e in range(first, first + n)
    ]


def repaired(card: Mapping[str, Any], trials_dir: Path) -> dict[str, Any]:
    """The row recomputed from its own outcomes and the trials records now in trials_dir."""
    if "episodes_won" not in card:
        raise ClutterbenchError(
            f"agent row {card.get('name')}: keeps no episodes_won (made before rows kept "
            "them): rerun `clutterbench evaluate-agent ... --leaderboard`"
        )
    keep = {k: v for k, v in card.items() if k not in CRITERIA and not k.endswith("_paired")}
    about = {k: v for k, v in keep.items() if k not in ("stream", "episodes", "episodes_won")}
    return agent_card(card_records(card), about, trials_dir)


def benchmark_pin(root: Path) -> str | None:
    """The benchmark scenes' manifest sha256 that root's params.yaml pins (the published
    starts a stream's episodes are read from), or None."""
    from clutterbench.config import load_params

    path = root / "params.yaml"
    if not path.is_file():
        return None
    return (load_params(path).get("benchmark") or {}).get("manifest_sha256")


def write_agent_row(card: Mapping[str, Any], board: Path = BOARD) -> Path:
    """agents/<name>.json (fresh episodes: fresh/agent-<name>.json), then the leaderboard
    rewritten with it."""
    from clutterbench.support.scorecard import is_fresh

    fresh = is_fresh(dict(card))
    path = (
        board / ("fresh" if fresh else "agents") / f"{'agent-' if fresh else ''}{card['name']}.json"
    )
    write_json(path, dict(card))
    rewrite_leaderboard(board)
    return path


def rewrite_leaderboard(board: Path = BOARD) -> None:
    """The leaderboard rewritten from every row under `board`, with the predictor rows of the
    project's test set (the first of TESTSET_DIRS beside reports/ that holds one) and of its
    sensed tracks beside it."""
    from clutterbench.data.testset_sensed import sensed_tracks
    from clutterbench.support.scorecard import leaderboard

    manifests = [board.parent.parent / d / "manifest.json" for d in TESTSET_DIRS]
    found = [m for m in manifests if m.is_file()]
    sha = read_json(found[0]).get("sha256") if found else None
    leaderboard(board, board, sha, sensed_tracks(found[0].parent) if found else {})


def repair_rows(board: Path = BOARD) -> list[str]:
    """Every agent row under `board` re-paired with the trials records beside it
    (board/../trials) and rewritten where that changed it, then the leaderboard; returns the
    rows that changed."""
    changed = []
    for path in sorted(board.glob("*/*.json")):
        card = read_json(path)
        if card.get("kind") != "agent":
            continue
        new = repaired(card, board.parent / "trials")
        if new != card:
            write_json(path, new)
            changed.append(str(path))
    rewrite_leaderboard(board)
    return changed


if __name__ == "__main__":
    try:
        for row in repair_rows() or ["every agent row already matches the trials records"]:
            print(row)
    except ClutterbenchError as exc:
        raise SystemExit(f"error: {exc}") from None
