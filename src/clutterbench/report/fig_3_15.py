"""Thesis Fig. 3.15 (Yamakuzushi games) as a table and a histogram: per variant, games with
at least one piece, mean pieces per game, per-slide success, observations per slide, and
the distribution of pieces removed per game; the thesis figures beside ours."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from clutterbench.io import atomic_path  # noqa: E402
from clutterbench.report.tables import thesis_row, write_raw_csv, write_table  # noqa: E402
from clutterbench.trials.core.stats import Rate  # noqa: E402

TABLE = "fig_3_15"
VARIANTS = {
    "convnet": ("with ConvNet (thesis method)", "with_convnet"),
    "no_convnet": ("without ConvNet: least-occluded piece", "without_convnet"),
    "convnet_no_pomdp": ("ConvNet's best piece slid at once, no POMDP", None),
    "random": ("random candidate, slid at once (floor)", None),
    "oracle": ("oracle: every slide simulated, first success (ceiling)", None),
}
"""variant -> (row label, thesis_figures.yaml row or None)."""
NOTE = (
    "a game: a pile of 9-10 simulated Shogi pieces; target selection, then the POMDP (observe "
    "from another viewpoint or slide), then the slide, until a slide fails or nothing is worth "
    "sliding. A slide succeeds when the piece leaves the board and no other piece moves more "
    "than the threshold, judged from physics after the rest settled. The ConvNet is trained on "
    "labels from simulated slides, not on hand annotations as in the thesis. Intervals: games "
    "with >= 1 piece Wilson 95%; mean pieces and per-slide success: 95% bootstrap over games "
    "(slides of one game are not independent)."
)


def _thesis(figures: Mapping[str, Any], row: str | None) -> dict[str, str]:
    if row is None:
        return {}
    t = thesis_row(figures, TABLE, row)
    out = {}
    if "games_with_at_least_one_piece" in t:
        k, n = t["games_with_at_least_one_piece"], t["games"]
        out["games_1"] = f"{k}/{n} ({100 * k / n:.1f}%)"
    if "mean_pieces_per_game" in t:
        out["mean_pieces"] = f"{t['mean_pieces_per_game']:.2f}"
    if "per_slide_success_rate" in t:
        out["per_slide"] = f"{100 * t['per_slide_success_rate']:.1f}%"
    return out


def fig_3_15_table(
    summary: pd.DataFrame,
    records: Sequence[Mapping[str, Any]],
    figures: Mapping[str, Any],
    convnet_val: Mapping[str, Any] | None,
    out_dir: Path,
    figure_path: Path,
    scale: str,
    notes: Sequence[str] = (),
) -> pd.DataFrame:
    """reports/tables/fig_3_15.{md,csv} and the histogram of pieces removed per game."""
    from clutterbench.report.tables import Column

    rows, raw = [], []
    for s in summary.to_dict("records"):
        label, thesis_key = VARIANTS.get(s["condition"], (s["condition"], None))
        games = Rate(int(s["success_k"]), int(s["success_n"]))
        per_slide = Rate(int(s["step_success_k"]), int(s["step_success_n"]))
        slide_ci = f"[{100 * s['step_success_lo']:.1f}, {100 * s['step_success_hi']:.1f}]"
        ours = {
            "games_1": games.text(),
            "mean_pieces": (
                f"{s['mean_pieces']:.2f} [{s['mean_pieces_lo']:.2f}, {s['mean_pieces_hi']:.2f}]"
            ),
            "per_slide": (
                f"{per_slide.k}/{per_slide.n} = {100 * per_slide.rate:.1f}% {slide_ci}"
                if per_slide.n
                else "—"
            ),
            "observations": f"{s['observations_per_slide']:.2f}",
            "ends": s["ends"],
        }
        thesis = _thesis(figures, thesis_key)
        rows.append(
            {
                "variant": label,
                "games with >= 1 piece": ours["games_1"],
                "games with >= 1 piece (thesis)": thesis.get("games_1"),
                "mean pieces per game": ours["mean_pieces"],
                "mean pieces per game (thesis)": thesis.get("mean_pieces"),
                "per-slide success": ours["per_slide"],
                "per-slide success (thesis)": thesis.get("per_slide"),
                "observations per slide": ours["observations"],
                "how games ended": ours["ends"],
            }
        )
        raw.append({"variant": s["condition"], **{k: v for k, v in s.items() if k != "condition"}})
    frame = pd.DataFrame.from_records(rows)
    columns = [Column(c, c, "{}") for c in frame.columns]
    notes = [NOTE, *notes, f"scale: {scale}; {int(summary['episodes'].max())} games per variant"]
    if convnet_val is not None:
        notes.append(
            f"slide ConvNet on validation piles: accuracy {convnet_val['accuracy']:.3f}, "
            f"precision {convnet_val['precision']:.3f}, recall {convnet_val['recall']:.3f} "
            f"(n {convnet_val['n']}; the thesis reports no accuracy)"
        )
    write_table(frame, columns, out_dir, TABLE, "Fig. 3.15: Yamakuzushi games", notes)
    write_raw_csv(raw, out_dir / f"{TABLE}_raw.csv")
    pieces_histogram(records, figure_path)
    return frame


def pieces_histogram(records: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Games by pieces removed, one bar group per count, one colour per variant (thesis Fig.
    3.15 shows the 15 games of its method)."""
    variants = list(dict.fromkeys(r["condition"] for r in records))
    most = max((r["pieces_removed"] for r in records), default=0)
    counts = np.arange(most + 1)
    width = 0.8 / max(len(variants), 1)
    fig, ax = plt.subplots(figsize=(6.0, 3.4))
    for i, v in enumerate(variants):
        removed = np.array([r["pieces_removed"] for r in records if r["condition"] == v])
        hist = np.bincount(removed, minlength=most + 1)
        label = f"{v} (mean {removed.mean():.2f})"
        ax.bar(counts + (i - (len(variants) - 1) / 2) * width, hist, width, label=label)
    ax.set_xticks(counts)
    ax.set_xlabel("pieces removed in a game")
    ax.set_ylabel("games")
    ax.set_title("Yamakuzushi games by pieces removed (thesis Fig. 3.15)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
