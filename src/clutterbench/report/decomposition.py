"""Table 6.3 decomposed: how much of a CP planner's gap to its search oracle is perception
(the collapse predictor) and how much planning (Algorithm 1 itself).

On one stream, three rows see the same scenes and targets: the CP planner (collapse maps
from the network), the same planner fed physics-truth maps (`*_truth`, trials/ch6/truth_maps.py)
and its matching search oracle. Per episode and under each criterion:

    oracle - CP  =  (oracle - truth)  +  (truth - CP)
     the gap        planning part        perception part

each part in points of per-episode success over the episodes all three ran, with a paired
95% bootstrap interval over episodes (the same resampled episodes for every part). A
negative part means the better-informed row did worse on those episodes.

Where the stream also has the planner on truth maps of the trials' own pull
(`*_pull_truth`), the split is three ways:

    oracle - CP  =  (oracle - pull truth) + (pull truth - truth) + (truth - CP)
                      planning               what the map predicts   perception

The planners on the CP's pull head (`*_pull`) have their own chain beside it, two ways
against the planner on truth maps of the pull:

    oracle - pull CP  =  (oracle - pull truth) + (pull truth - pull CP)
                           planning               perception

Where the stream also has the same CP planner under a depth sensor (and masks from depth: a
condition whose records name `sensing` or `perception: depth`), a fourth part stands beside:

    oracle - sensed CP  =  (oracle - CP)  +  (CP - sensed CP)
                             the gap above    sensing
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.report.tables import Column, write_raw_csv, write_table
from clutterbench.trials.ch6 import planners
from clutterbench.trials.condition_sets import NOT_RUN
from clutterbench.trials.config import PULL_MAP_HEADS
from clutterbench.trials.core.stats import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED

TABLE = "table_6_3_decomposition"

CRITERIA = {"success": "collapse-free", "strict_success": "strict"}

COLUMNS = [
    Column("criterion", "criterion", "{}"),
    Column("stream", "stream", "{}"),
    Column("oracle_pct", "oracle %", "{:.1f}"),
    Column("pull_truth_pct", "pull truth maps %", "{:.1f}"),
    Column("truth_pct", "truth maps %", "{:.1f}"),
    Column("cp_pct", "CP %", "{:.1f}"),
    Column("gap_text", "points below the oracle", "{}"),
    Column("planning_text", "planning part (oracle - pull truth, else - truth)", "{}"),
    Column("meaning_text", "what the map predicts (pull truth - truth)", "{}"),
    Column("perception_text", "perception part (truth - CP)", "{}"),
    Column("episodes", "episodes", "{:d}"),
]
SENSED_COLUMNS = [
    Column("sensed_pct", "sensed CP %", "{:.1f}"),
    Column("sensing_text", "sensing part (CP - sensed CP)", "{}"),
    Column("sensed_gap_text", "sensed CP's points below the oracle", "{}"),
]
"""Shown where a CP planner also ran under a sensor on the row's stream."""
ROBUST_COLUMNS = [
    Column("robust_pct", "robust oracle %", "{:.1f}"),
    Column("robust_gap_text", "points below the robust oracle", "{}"),
    Column("robust_episodes", "episodes (robust oracle)", "{:d}"),
]
"""Shown where the noise stage's robust search oracles ran on the row's stream."""


def sensed(record: Mapping[str, Any]) -> bool:
    """Whether a record's planner saw other than exact depth and the simulator's masks."""
    return "sensing" in record or record.get("perception", "instance") != "instance"


def by_planner_stream(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]], of_sensed: bool = False
) -> dict[tuple[str, str], tuple[str, Sequence[Mapping[str, Any]]]]:
    """(planner, stream) -> the first condition of it (and its records) that saw exact depth
    and the simulator's masks; with `of_sensed`, the first that did not."""
    out: dict[tuple[str, str], tuple[str, Sequence[Mapping[str, Any]]]] = {}
    for cond, recs in records_by_condition.items():
        if recs and sensed(recs[0]) == of_sensed:
            out.setdefault((str(recs[0].get("planner")), str(recs[0].get("stream"))), (cond, recs))
    return out


def paired_parts(
    oracle: Sequence[bool],
    truth: Sequence[bool],
    cp: Sequence[bool],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
    pull_truth: Sequence[bool] | None = None,
    sensed_cp: Sequence[bool] | None = None,
) -> dict[str, Any]:
    """Points (100 x mean difference) of the gap, planning and perception parts over paired
    episodes (with `pull_truth`, also the map-meaning part; with `sensed_cp`, the sensing part
    and the sensed row's gap), each with a 95% percentile interval from one seeded bootstrap
    over episodes."""
    o, t, c = (np.asarray(x, dtype=np.float64) for x in (oracle, truth, cp))
    assert len(o) == len(t) == len(c) > 0, "paired outcomes of the same episodes"
    diffs = {"gap": o - c, "planning": o - t, "perception": t - c}
    if pull_truth is not None:
        p = np.asarray(pull_truth, dtype=np.float64)
        assert len(p) == len(o), "paired outcomes of the same episodes"
        diffs |= {"planning": o - p, "meaning": p - t}
    if sensed_cp is not None:
        s = np.asarray(sensed_cp, dtype=np.float64)
        assert len(s) == len(o), "paired outcomes of the same episodes"
        diffs |= {"sensing": c - s, "sensed_gap": o - s}
    return paired_points(diffs, resamples, seed)


def paired_points(
    diffs: Mapping[str, np.ndarray],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> dict[str, Any]:
    """Name -> points (100 x mean) of each per-episode difference of the same episodes,
    `<name>_lo` / `<name>_hi` its 95% percentile interval from one seeded bootstrap over
    episodes (the same resampled episodes for every difference)."""
    n = len(next(iter(diffs.values())))
    picks = np.random.default_rng(seed).integers(0, n, size=(resamples, n))
    out: dict[str, Any] = {}
    for name, d in diffs.items():
        boot = 100.0 * d[picks].mean(axis=1)
        lo, hi = np.percentile(boot, [2.5, 97.5])
        out |= {name: 100.0 * float(d.mean()), f"{name}_lo": float(lo), f"{name}_hi": float(hi)}
    return out


def shared_outcomes(
    runs: Sequence[Sequence[Mapping[str, Any]]], key: str
) -> tuple[list[int], list[list[bool]]]:
    """The episodes every run has an outcome `key` for, and each run's outcomes on them."""
    sets = [{int(r["episode"]): bool(r[key]) for r in rs if key in r} for rs in runs]
    shared = sorted(set.intersection(*(set(s) for s in sets)))
    return shared, [[s[e] for e in shared] for s in sets]


def decompose(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]],
) -> list[dict[str, Any]]:
    """One row per (CP planner, stream, criterion) where the CP row, its truth row and its
    oracle all ran on that stream; sorted as the conditions were given."""
    index = by_planner_stream(records_by_condition)
    sensed_index = by_planner_stream(records_by_condition, of_sensed=True)
    rows = []
    for (planner, stream), (cond, recs) in index.items():
        declared = planners.declared(planner)
        if declared.truth is None:
            continue
        truth = index.get((declared.truth, stream))
        oracle = index.get((declared.ceiling, stream))
        chain = declared.of_the_pull  # its truth row is already of the pull: two ways
        pull = None if chain else index.get((str(declared.pull_truth), stream))
        if truth is None or oracle is None:
            continue
        seen = sensed_index.get((planner, stream))
        for key, criterion in CRITERIA.items():
            runs = [oracle[1], truth[1], recs] + ([pull[1]] if pull is not None else [])
            shared, outcomes = shared_outcomes(runs + ([seen[1]] if seen else []), key)
            if not shared:
                continue
            o, t, c, *p = outcomes
            sc = p.pop() if seen else None
            truth_pct = 100.0 * float(np.mean(t))
            row = {
                "planner": planner,
                "condition": cond,
                "truth_condition": None if chain else truth[0],
                "pull_truth_condition": truth[0] if chain else pull[0] if pull else None,
                "oracle_condition": oracle[0],
                "stream": stream,
                "criterion": criterion,
                "key": key,
                "episodes": len(shared),
                "oracle_pct": 100.0 * float(np.mean(o)),
                "pull_truth_pct": truth_pct
                if chain
                else 100.0 * float(np.mean(p[0]))
                if p
                else None,
                "truth_pct": None if chain else truth_pct,
                "cp_pct": 100.0 * float(np.mean(c)),
            }
            if seen is not None:
                row |= {"sensed_condition": seen[0], "sensed_pct": 100.0 * float(np.mean(sc))}
            row |= paired_parts(o, t, c, pull_truth=p[0] if p else None, sensed_cp=sc)
            rows.append(
                row | robust_gap(index.get((f"{declared.ceiling}_robust", stream)), recs, key)
            )
    return rows


def robust_gap(
    robust: tuple[str, Sequence[Mapping[str, Any]]] | None,
    recs: Sequence[Mapping[str, Any]],
    key: str,
) -> dict[str, Any]:
    """The CP row's points below the robust search oracle (noise stage) over the episodes both
    ran, with its paired 95% interval; {} where none ran on the stream."""
    if robust is None:
        return {}
    shared, (r, c) = shared_outcomes([robust[1], recs], key)
    if not shared:
        return {}
    points = paired_points({"robust_gap": np.asarray(r, float) - np.asarray(c, float)})
    return {
        "robust_condition": robust[0],
        "robust_pct": 100.0 * float(np.mean(r)),
        "robust_episodes": len(shared),
    } | points


def _text(row: Mapping[str, Any], part: str) -> str:
    return f"{row[part]:.1f} [{row[f'{part}_lo']:.1f}, {row[f'{part}_hi']:.1f}]"


PULL_MARKS = {
    "moved": "the boxes that move beyond the label threshold or leave the shelf",
    "collapse": "the boxes that leave the shelf, drop or tip beyond trials.collapse_free",
}
"""What a pull map marks under each trials.ch6.pull_map_meaning."""


def decomposition_table(
    records_by_condition: Mapping[str, Sequence[Mapping[str, Any]]],
    out_dir: Path,
    scale: str,
    pull_map_meaning: str = "moved",
    not_run: Sequence[str] = (),
) -> pd.DataFrame | None:
    """reports/tables/table_6_3_decomposition.{md,csv,png}; None (nothing written) when no
    stream has a CP row, its truth row and its oracle. `pull_map_meaning`: what the pull maps
    mark (trials.ch6.pull_map_meaning), for the notes; `not_run`: the opt-in conditions the
    run left out (trials.opt_in), named in a note (a CP row without its truth row has no row)."""
    rows = decompose(records_by_condition)
    if not rows:
        return None
    shown = []
    for r in rows:
        truths = " / ".join(c for c in (r["truth_condition"], r["pull_truth_condition"]) if c)
        label = f"{r['planner']} [{r['condition']} / {truths} / {r['oracle_condition']}]"
        if "sensed_condition" in r:
            label = label[:-1] + f" / sensed {r['sensed_condition']}]"
        parts = ("gap", "planning", "meaning", "perception", "robust_gap", "sensing", "sensed_gap")
        shown.append(
            {"row": label}
            | {c.key: r.get(c.key) for c in COLUMNS + SENSED_COLUMNS + ROBUST_COLUMNS}
            | {f"{p}_text": _text(r, p) if p in r else None for p in parts}
        )
    head = "CP planner [CP / truth (/ pull truth) / oracle condition]"
    columns = (
        COLUMNS
        + (SENSED_COLUMNS if any("sensed_pct" in r for r in rows) else [])
        + (ROBUST_COLUMNS if any("robust_pct" in r for r in rows) else [])
    )
    frame = pd.DataFrame([{head: s["row"]} | s for s in shown])
    frame = frame[[head, *[c.key for c in columns]]].rename(
        columns={c.key: c.header for c in columns}
    )
    notes = _notes(rows, scale, pull_map_meaning)
    if not_run:
        notes.append(
            f"{NOT_RUN}: {', '.join(not_run)} (opt-in conditions, trials.opt_in; make "
            "repro-full runs them). Where one is a stream's truth or pull-truth row, that "
            "stream's split of its CP rows is missing here or has one part less."
        )
    write_table(
        frame,
        columns,
        out_dir,
        TABLE,
        "Table 6.3 decomposed: points below the oracle, planning vs perception",
        notes,
    )
    raw = write_raw_csv(rows, out_dir / f"{TABLE}.csv")
    _figure(rows, out_dir / f"{TABLE}.png")
    return raw


def _notes(rows: Sequence[Mapping[str, Any]], scale: str, pull_map_meaning: str) -> list[str]:
    """The decomposition table's notes: how each part is taken, and its intervals."""
    notes = [
        f"{scale} scale. Each CP planner's points below its search oracle (Table 6.3), split "
        "over the episodes all three rows ran (same scenes, same targets): planning = oracle - "
        "the same planner fed physics-truth collapse maps; perception = truth-map row - CP row. "
        "The truth map of removing box x: the visible pixels of the boxes that move beyond the "
        "label threshold when x is lifted out of the present state (a fresh world built at that "
        "state, the boxes held there still held), for the decision and for every monitor check "
        "during a pull; the planner, its support rule and thresholds (chosen on validation "
        "scenes with the network's maps) are the CP row's.",
        "Intervals: 95%, one paired bootstrap over episodes (2,000 resamples, seed 0) for all "
        "three numbers of a row. A negative part: the better-informed row did worse there "
        "(e.g. truth maps block more candidates, so the planner gives up or takes a longer path).",
        "Oracles: oracle (one arm) for multi-step, oracle_hold (may hold one box) for bimanual, "
        "as in Table 6.3.",
        "Where the stream has the planner on physics-truth maps of the trials' own pull "
        f"(*_pull_truth: {PULL_MARKS[pull_map_meaning]} when box x is pulled out by the trials' "
        "executor from the present state, bit for bit what executing that pull does; "
        f"trials.ch6.pull_map_meaning: {pull_map_meaning}), the split is three ways: "
        "planning = oracle - pull truth; "
        "what the map predicts = pull truth - truth (deletion maps, as the network's labels); "
        "perception = truth - CP.",
        "Pull chain (multi_step_pull, bimanual_pull: the CP's head of the same meaning, "
        f"{PULL_MAP_HEADS[pull_map_meaning]}, trained on labels of the trials' pull, with support "
        "thresholds chosen against that head's pull truth): planning = "
        "oracle - the planner on pull-truth maps; perception = pull truth - pull CP (in the "
        "columns of the pull truth and the perception part). The pull-truth rows run with the "
        "deletion head's thresholds (they are the three-way split's rows too), so this "
        "perception part also holds the change of support thresholds.",
    ]
    if any("sensed_pct" in r for r in rows):
        notes.append(
            "Sensing (the same CP planner under a depth sensor model and, where its condition "
            "says perception: depth, masks from the sensed depth; docs/sensing.md): sensing = "
            "CP row - sensed CP row, and the sensed row's points below the oracle = the gap + "
            "sensing, over the same paired episodes and bootstrap."
        )
    if any("robust_pct" in r for r in rows):
        notes.append(
            "Robust oracle (noise stage, table_6_3_noise): the matching search oracle whose "
            "every simulated step must also be clean in perturbed worlds; its gap to the CP "
            "row over the episodes both ran, with a paired 95% bootstrap interval."
        )
    return notes


def _figure(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Stacked bars: each CP row's gap to its oracle as planning + perception, per stream and
    criterion."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clutterbench.io import atomic_path

    labels = [f"{r['planner']}\n{r['stream']}\n{r['criterion']}" for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(rows)), 4.0))
    up, down = np.zeros(len(rows)), np.zeros(len(rows))
    parts = [
        ("planning", "planning (oracle - best truth maps)", "#4c72b0"),
        ("meaning", "what the map predicts (pull truth - truth)", "#55a868"),
        ("perception", "perception (truth maps - CP)", "#dd8452"),
    ]
    for key, label, color in parts:
        v = np.array([float(r.get(key) or 0.0) for r in rows])
        if key == "meaning" and not np.any(v):
            continue
        ax.bar(x, v, bottom=np.where(v >= 0, up, down), color=color, label=label)
        up, down = up + np.maximum(v, 0), down + np.minimum(v, 0)
    ax.scatter(x, [r["gap"] for r in rows], color="black", zorder=3, label="gap to the oracle")
    ax.axhline(0, color="grey", lw=0.8)
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("points of per-episode success")
    ax.set_title("Table 6.3: each CP planner's gap to its oracle, decomposed")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png", metadata={"Software": None})
    plt.close(fig)
