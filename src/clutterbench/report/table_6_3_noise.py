"""Table 6.3 under task noise: each condition's recorded episodes replayed in perturbed worlds
(stage noise, trials/noise), beside the table's own rate; and the robust search oracles."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.report.tables import Column, write_raw_csv, write_table

TABLE = "table_6_3_noise"

COLUMNS = [
    Column("stream", "stream", "{}"),
    Column("table", "collapse-free: the table's run", "{}"),
    Column("perturbed", "in perturbed worlds: mean ± sd over draws", "{}"),
    Column("range", "lowest - highest draw", "{}"),
    Column("survive", "the table's successes that succeed in a draw", "{}"),
    Column("every_draw", "episodes succeeding in every draw", "{}"),
    Column("strict_table", "strict: the table's run", "{}"),
    Column("strict_perturbed", "strict in perturbed worlds", "{}"),
    Column("strict_survive", "strict successes surviving", "{}"),
    Column("episodes", "episodes", "{:d}"),
]


def pct(x: float) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f}%"


def noise_text(s: Mapping[str, Any]) -> str:
    """'mean% ± sd (kept% of the table's successes)': one condition's cell in Table 6.3."""
    return f"{pct(s['mean_rate'])} ± {100 * s['sd_rate']:.1f} ({pct(s['survive'])} kept)"


def _cells(s: Mapping[str, Any]) -> dict[str, Any]:
    n = s["n"]
    rates = [k / n for k in s["draw_k"]] if n else []
    return {
        "table": f"{s['nominal_k']}/{n} = {pct(s['nominal_k'] / n if n else float('nan'))}",
        "perturbed": f"{pct(s['mean_rate'])} ± {100 * s['sd_rate']:.1f}",
        "range": f"{pct(min(rates))} - {pct(max(rates))}" if rates else None,
        "survive": pct(s["survive"]),
        "every_draw": f"{s['all_draws_k']}/{n}",
    }


def noise_table(
    summary: Mapping[str, Any], rows: Mapping[str, str], out_dir: Path, scale: str
) -> pd.DataFrame:
    """reports/tables/table_6_3_noise.{md,csv,png}: Table 6.3's conditions (`rows`: row ->
    condition, as report.table_6_3) that the noise stage replayed, then its robust oracles."""
    conds = summary["conditions"]
    order = [c for c in dict.fromkeys(rows.values()) if c in conds]
    order += [c for c, row in conds.items() if row.get("robust_of") and c not in order]
    shown, raw = [], []
    for c in order:
        row = conds[c]
        label = f"{row['planner']} [{c}]"
        s, t = row["success"], row["strict_success"]
        strict = _cells(t)
        shown.append(
            {"condition": label, "stream": row["stream"], **_cells(s)}
            | {
                "strict_table": strict["table"],
                "strict_perturbed": strict["perturbed"],
                "strict_survive": strict["survive"],
                "episodes": s["n"],
            }
        )
        raw.append(
            {
                "condition": c,
                "planner": row["planner"],
                "stream": row["stream"],
                "robust_of": row.get("robust_of"),
            }
            | {
                f"{k}_{m}": v
                for k, d in (("success", s), ("strict_success", t))
                for m, v in d.items()
                if m != "draw_k"
            }
            | {f"success_draw{i}_k": k for i, k in enumerate(s["draw_k"])}
        )
    head = "planner [condition]"
    frame = pd.DataFrame([{head: r.pop("condition")} | r for r in shown])
    frame = frame[[head, *[c.key for c in COLUMNS]]].rename(
        columns={c.key: c.header for c in COLUMNS}
    )
    cfg = summary["noise"]
    notes = [
        f"{scale} scale. Each condition's recorded actions (pull box x, the second arm holding "
        "y or none, for as many increments as in the table's run) replayed from the same start "
        f"in {cfg['draws']} perturbed worlds per episode, under the trials' own step, judgement "
        "and episode protocol (open loop: the planner is not asked again). A world: friction "
        f"x U(1 ± {cfg['friction_rel']}), each box's mass x U(1 ± {cfg['mass_rel']}), pull "
        f"speed x U(1 ± {cfg['pull_speed_rel']}), each box of every step's start moved by up "
        f"to {1000 * cfg['jitter_m']:.1f} mm (never down). Worlds are seeded by stream, episode "
        "and draw: every condition on a stream meets the same worlds.",
        "mean ± sd: the per-episode rate in each draw, their mean and standard deviation over "
        "draws. kept: of the table's successes, the share that succeed in a draw (pooled over "
        "draws). A ceiling that needs a knife edge loses more of its successes than the "
        "planners below it.",
        f"Robust oracles (*_robust): the search oracle, but a simulated step counts as clean "
        f"only when it is clean in the table's world and in {cfg['robust_draws']} perturbed "
        "worlds drawn apart from the replays'; executed in the table's world. Their gap to each "
        "planner is in table_6_3_decomposition.",
    ]
    write_table(frame, COLUMNS, out_dir, TABLE, "Table 6.3 under task noise", notes)
    _figure(conds, order, out_dir / f"{TABLE}.png")
    return write_raw_csv(raw, out_dir / f"{TABLE}.csv")


def _figure(conds: Mapping[str, Any], order: list[str], path: Path) -> None:
    """Per condition: the table's rate and each draw's (collapse-free)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clutterbench.io import atomic_path

    fig, ax = plt.subplots(figsize=(max(6.0, 0.32 * len(order)), 4.0))
    x = np.arange(len(order))
    for i, c in enumerate(order):
        s = conds[c]["success"]
        rates = [100 * k / s["n"] for k in s["draw_k"]] if s["n"] else []
        ax.scatter(
            [i] * len(rates),
            rates,
            s=10,
            color="#4c72b0",
            alpha=0.7,
            label="a perturbed world" if i == 0 else None,
        )
    table = [
        100 * conds[c]["success"]["nominal_k"] / max(1, conds[c]["success"]["n"]) for c in order
    ]
    ax.scatter(x, table, marker="_", s=120, color="black", label="the table's run")
    ax.set_xticks(x, order, rotation=90, fontsize=6)
    ax.set_ylabel("collapse-free success per episode (%)")
    ax.set_title("Table 6.3 under task noise")
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png", metadata={"Software": None})
    plt.close(fig)
