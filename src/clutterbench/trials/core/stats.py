"""Trial records -> rates with Wilson 95% intervals -> one table row per condition.

The one aggregator of every trials table (thesis Tables 4.1, 5.2, 6.3). A record is one
episode (a line of its condition's records.jsonl) with named booleans judged from
physics: `success`, optionally `strict_success`, and per step in `steps`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.errors import ClutterbenchError

Z95 = 1.959963984540054
"""Two-sided 95% standard normal quantile."""

OPTIONAL_MEANS = {"n_disturbed": "mean_n_disturbed", "disturbance_m": "mean_disturbance_m"}
"""Episode fields averaged when records have them -> their column."""


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial rate k/n; (nan, nan) when n == 0."""
    if n == 0:
        return (math.nan, math.nan)
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    p, z2 = k / n, z * z
    denom = 1.0 + z2 / n
    center = (p + z2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom
    # The bounds are exactly 0 and 1 at k == 0 and k == n; say so rather than round.
    lo = 0.0 if k == 0 else center - half
    hi = 1.0 if k == n else center + half
    return (lo, hi)


@dataclasses.dataclass(frozen=True)
class Rate:
    """k successes out of n trials."""

    k: int
    n: int

    @property
    def rate(self) -> float:
        return self.k / self.n if self.n else math.nan

    @property
    def ci95(self) -> tuple[float, float]:
        return wilson_interval(self.k, self.n)

    def text(self) -> str:
        """'3/4 = 75.0% [30.1, 95.4]': percent, Wilson 95% interval; '—' when n == 0."""
        if self.n == 0:
            return "—"
        lo, hi = self.ci95
        return f"{self.k}/{self.n} = {100 * self.rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"


def _where(record: Mapping[str, Any]) -> str:
    return f"trial record (condition {record.get('condition')!r}, episode {record.get('episode')})"


def _flag(value: Any, key: str, where: str) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise ClutterbenchError(f"{where}: '{key}' must be true or false, got {value!r}")
    return bool(value)


def rate(records: Sequence[Mapping[str, Any]], key: str) -> Rate:
    """Episodes whose boolean `key` is true, out of all of them."""
    k = sum(_flag(r.get(key), key, _where(r)) for r in records)
    return Rate(k, len(records))


def _steps(record: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    steps = record["steps"]
    if not isinstance(steps, list):
        raise ClutterbenchError(f"{_where(record)}: 'steps' must be a list")
    return steps


COUNTED_BY = {"success": "counted", "strict_success": "strict_counted"}
"""A step's success under a criterion counts where the step is counted under it."""
OLD_COUNTED_BY = {"success": "judged", "strict_success": "strict_judged"}
"""The same flags in records written before they were renamed (there `judged` meant counted;
now it says the step was judged from physics)."""


def _counted(step: Mapping[str, Any], key: str = "success") -> bool:
    """A step counts in per-step success when it is counted under the criterion of `key`
    (trials/core/protocol.py): an executed pull that took its box out or disturbed the pile.
    Records of the older schemas: the flag under its old name; without it, from the
    others_still flag; without `executed`, every step."""
    names = COUNTED_BY if "counted" in step else OLD_COUNTED_BY
    flag = names.get(key, names["success"])
    if flag in step:
        return bool(step[flag])
    if "executed" not in step:
        return True
    return bool(step["executed"] and (step["extracted"] or not step["others_still"]))


def _episode_steps(record: Mapping[str, Any], key: str) -> tuple[int, int]:
    """(successes, counted steps) of one episode under `key`; strict: over the strict
    episode only, the prefix up to the first strict failure (criteria.py)."""
    from clutterbench.criteria import strict_prefix

    steps = _steps(record)
    if key == "strict_success":
        steps = strict_prefix(steps)
    k = n = 0
    for i, step in enumerate(steps):
        if _counted(step, key):
            k += _flag(step.get(key), key, f"{_where(record)}, step {i}")
            n += 1
    return k, n


def step_rate(records: Sequence[Mapping[str, Any]], key: str = "success") -> Rate:
    """Judged steps whose boolean `key` is true, pooled over every episode's steps (thesis
    Table 6.3 rates are per extraction step); aborts that moved nothing are left out."""
    k = n = 0
    for r in records:
        dk, dn = _episode_steps(r, key)
        k, n = k + dk, n + dn
    return Rate(k, n)


BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0


def cluster_bootstrap_interval(
    per_episode: Sequence[tuple[int, int]],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """95% percentile interval of a pooled rate sum(k) / sum(n) whose units (steps) cluster
    in episodes: episodes are resampled with replacement, each keeping all its steps, so
    the steps of one episode are not taken as independent. Seeded: the same records give the
    same interval. (nan, nan) when there are no units."""
    kn = np.asarray(per_episode, dtype=np.float64).reshape(-1, 2)
    if kn[:, 1].sum() == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(kn), size=(resamples, len(kn)))
    k, n = kn[picks, 0].sum(axis=1), kn[picks, 1].sum(axis=1)
    rates = k[n > 0] / n[n > 0]
    lo, hi = np.percentile(rates, [2.5, 97.5])
    return (float(lo), float(hi))


def _step_columns(records: Sequence[Mapping[str, Any]], key: str) -> dict[str, Any]:
    """Per-step k/n and rate with the episode-cluster bootstrap interval (not Wilson: the
    steps of one episode are not independent)."""
    per = [_episode_steps(r, key) for r in records]
    k, n = sum(p[0] for p in per), sum(p[1] for p in per)
    lo, hi = cluster_bootstrap_interval(per)
    return {
        f"step_{key}_k": k,
        f"step_{key}_n": n,
        f"step_{key}_rate": k / n if n else math.nan,
        f"step_{key}_lo": lo,
        f"step_{key}_hi": hi,
    }


def _has(records: Sequence[Mapping[str, Any]], key: str, group: Any) -> bool:
    """Whether this group's records carry `key`: all of them or none (one harness run
    writes one schema; a mix means records from different runs were concatenated)."""
    have = sum(key in r for r in records)
    if 0 < have < len(records):
        raise ClutterbenchError(
            f"trial records of {group!r}: {have} of {len(records)} have '{key}'; "
            "records of one condition must share one schema"
        )
    return have > 0


def _rate_columns(prefix: str, r: Rate) -> dict[str, Any]:
    lo, hi = r.ci95
    return {
        f"{prefix}_k": r.k,
        f"{prefix}_n": r.n,
        f"{prefix}_rate": r.rate,
        f"{prefix}_lo": lo,
        f"{prefix}_hi": hi,
    }


def _mean(records: Sequence[Mapping[str, Any]], key: str) -> float:
    try:
        return float(np.mean([float(r[key]) for r in records]))
    except (TypeError, ValueError):
        raise ClutterbenchError(f"trial records: '{key}' must be a number in each") from None


def aggregate(records: Sequence[Mapping[str, Any]], group_by: str = "condition") -> pd.DataFrame:
    """One row per value of `group_by` (in order of first appearance): episode success
    k/n, rate and Wilson 95% bounds; with per-episode `steps`, the pooled per-step success
    over counted steps with an episode-cluster bootstrap interval, the mean steps and the
    aborts without a collapse (`aborts`; of them `aborts_before_motion`, and `aborts_moved`:
    after motion, another box moved beyond the label threshold); the means of `n_disturbed` /
    `disturbance_m` and the `strict_success` rate where the records have them (columns absent
    where no record has the field)."""
    groups: dict[Any, list[Mapping[str, Any]]] = {}
    for r in records:
        if group_by not in r:
            raise ClutterbenchError(f"{_where(r)} has no '{group_by}'")
        groups.setdefault(r[group_by], []).append(r)
    rows = []
    for value, recs in groups.items():
        row: dict[str, Any] = {group_by: value, "episodes": len(recs)}
        row |= _rate_columns("success", rate(recs, "success"))
        if _has(recs, "steps", value):
            row |= _step_columns(recs, "success")
            if all("strict_success" in s for r in recs for s in _steps(r)):
                row |= _step_columns(recs, "strict_success")
            row["mean_steps"] = float(np.mean([len(_steps(r)) for r in recs]))
            if all("aborted_before_motion" in s for r in recs for s in _steps(r)):
                row["aborts"] = sum(
                    bool(s["aborted_before_motion"] or s["aborted_after_motion"])
                    and not _counted(s)
                    for r in recs
                    for s in _steps(r)
                )
                row["aborts_before_motion"] = sum(
                    bool(s["aborted_before_motion"]) for r in recs for s in _steps(r)
                )
                # of the aborts without a collapse: those that moved another box beyond the
                # label threshold (strict failures)
                row["aborts_moved"] = sum(
                    bool(s["aborted_after_motion"]) and not _counted(s) and not s["others_still"]
                    for r in recs
                    for s in _steps(r)
                )
        for key, column in OPTIONAL_MEANS.items():
            if _has(recs, key, value):
                row[column] = _mean(recs, key)
        if _has(recs, "strict_success", value):
            row |= _rate_columns("strict_success", rate(recs, "strict_success"))
        if _has(recs, "success_held", value):
            row |= _rate_columns("success_held", rate(recs, "success_held"))
        if _has(recs, "strict_success_held", value):
            row |= _rate_columns("strict_success_held", rate(recs, "strict_success_held"))
        rows.append(row)
    always = [group_by, "episodes", *_rate_columns("success", Rate(0, 0))]
    order = [
        *always,
        *_rate_columns("step_success", Rate(0, 0)),
        *_rate_columns("step_strict_success", Rate(0, 0)),
        "mean_steps",
        "aborts",
        "aborts_before_motion",
        "aborts_moved",
        *OPTIONAL_MEANS.values(),
        *_rate_columns("strict_success", Rate(0, 0)),
        *_rate_columns("success_held", Rate(0, 0)),
        *_rate_columns("strict_success_held", Rate(0, 0)),
    ]
    present = {c for row in rows for c in row}
    columns = [c for c in order if c in present or c in always]
    frame = pd.DataFrame.from_records(rows, columns=columns)
    # Counts stay integers where a group lacks a field (nullable, not float NaN).
    counts = [
        c
        for c in columns
        if c in ("episodes", "aborts", "aborts_before_motion", "aborts_moved")
        or c.endswith(("_k", "_n"))
    ]
    return frame.astype(dict.fromkeys(counts, "Int64"))


def aggregate_games(records: Sequence[Mapping[str, Any]]) -> pd.DataFrame:
    """Chapter 3 games (records with `pieces_removed`, `end` and per-slide `steps`): per
    condition the `aggregate` columns (games with >= 1 piece as episode success, per-slide
    success with the game-cluster bootstrap interval, slides per game), plus the mean pieces
    per game with a game-bootstrap interval, observations per slide, and how games ended."""
    frame = aggregate(records)
    means, los, his, obs, ends = [], [], [], [], []
    for variant in frame["condition"]:
        mine = [r for r in records if r["condition"] == variant]
        pieces = [(r["pieces_removed"], 1) for r in mine]
        lo, hi = cluster_bootstrap_interval(pieces)
        means.append(float(np.mean([p for p, _ in pieces])))
        los.append(lo)
        his.append(hi)
        slides = [s for r in mine for s in r["steps"]]
        obs.append(float(np.mean([s["observations"] for s in slides])) if slides else np.nan)
        counts: dict[str, int] = {}
        for r in mine:
            counts[r["end"]] = counts.get(r["end"], 0) + 1
        ends.append(", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    frame["mean_pieces"] = means
    frame["mean_pieces_lo"] = los
    frame["mean_pieces_hi"] = his
    frame["observations_per_slide"] = obs
    frame["ends"] = ends
    return frame
