"""Results at a glance: every thesis figure beside ours, one row each, read from the tables
the report stage has just written (their CSVs), with links to the full table and to the
docs page that explains it -> reports/tables/summary.md. The README embeds this file between
its summary markers (a unit test checks that the two are byte-identical).

Thesis figures come only from reports/thesis_figures.yaml, and only in the "thesis" column;
every number of ours is read from a table's CSV, never written here. Links start with "/",
the repository root on GitHub, so the same bytes work in reports/tables/ and in the README.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.report import datasets, fig_3_15, table_4_1, table_5_2, table_6_2, table_6_3
from clutterbench.report.tables import rate_text, thesis_rate_text, thesis_row

NAME = "summary"
TABLES = "/reports/tables"
PAGE_NAMES = {
    "ch3": "ch. 3",
    "ch4": "ch. 4",
    "ch5": "ch. 5",
    "networks": "networks",
    "ch6": "ch. 6",
    "scale": "scale profiles",
}
DOCS = {
    "ch3": "/docs/ch3-yamakuzushi.md",
    "ch4": "/docs/ch4-pull-with-support.md",
    "ch5": "/docs/ch5-replenishment.md",
    "networks": "/docs/collapse-networks.md",
    "ch6": "/docs/ch6-support-and-trials.md",
    "scale": "/docs/run-times.md",
}
"""The docs page that explains each group of tables."""

FIGURE_NAMES = {
    "fig_3_15": "Fig. 3.15",
    "table_4_1": "Table 4.1",
    "table_4_1_target": "4.3.3 (text)",
    "table_4_2": "Table 4.2",
    "table_5_1": "Table 5.1",
    "table_5_2": "Table 5.2",
    "table_6_1": "Table 6.1",
    "table_6_2": "Table 6.2",
    "table_6_3": "Table 6.3",
    "datasets": "dataset sizes",
}
"""Our table -> how the thesis names the figure it stands beside."""

HEADER = ("thesis figure", "quantity", "thesis", "ours", "ours, strict", "explained in")


@dataclasses.dataclass(frozen=True)
class Row:
    table: str
    """Our table (reports/tables/<table>.md, .csv)."""
    page: str
    """Key of DOCS."""
    quantity: str
    thesis: str
    ours: str
    strict: str = "—"


def _num(value: Any, fmt: str = "{:.3f}") -> str:
    return "—" if value is None or pd.isna(value) else fmt.format(float(value))


def _nums(row: Mapping[str, Any], keys: Sequence[str]) -> str:
    return " / ".join(_num(row.get(k)) for k in keys)


def _one(frame: pd.DataFrame, table: str, match: Callable[[pd.Series], bool], what: str):
    """The one row of `frame` that `match` picks; one line naming the table otherwise."""
    found = [r for _, r in frame.iterrows() if match(r)]
    if len(found) != 1:
        raise ClutterbenchError(
            f"summary: {len(found)} rows of reports/tables/{table}.csv match {what}; "
            "rerun the report stage"
        )
    return found[0]


def _labelled(frame: pd.DataFrame, table: str, label: str) -> pd.Series:
    """The row of a network table whose first column is '<label> [<run>]'."""
    first = frame.columns[0]
    return _one(frame, table, lambda r: str(r[first]).startswith(f"{label} ["), repr(label))


def _by(frame: pd.DataFrame, table: str, **values: str) -> pd.Series:
    what = ", ".join(f"{k} {v!r}" for k, v in values.items())
    return _one(frame, table, lambda r: all(str(r[k]) == v for k, v in values.items()), what)


def _thesis_rows(figures: Mapping[str, Any], table: str) -> list[Mapping[str, Any]]:
    if table not in figures:
        raise ClutterbenchError(f"thesis figures: no table '{table}'")
    return list(figures[table].get("rows", []))


def _rate_row(
    table: str, page: str, quantity: str, thesis: Mapping[str, Any], ours: pd.Series
) -> Row:
    """A trials row: the thesis' rate beside ours under both criteria."""
    return Row(
        table,
        page,
        quantity,
        thesis_rate_text(thesis) or "—",
        rate_text(ours, "success") or "—",
        rate_text(ours, "strict_success") or "—",
    )


def _fig_3_15(frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any]) -> list[Row]:
    frame, rows = frames["fig_3_15"], []
    for label, key in fig_3_15.VARIANTS.values():
        thesis = thesis_row(figures, fig_3_15.TABLE, key)
        if not thesis:
            continue
        ours = _by(frame, "fig_3_15", variant=label)
        short = label.split(":")[0].split(" (")[0]
        games = thesis["games"]
        quantities = [
            (
                "games with >= 1 piece",
                f"{thesis['games_with_at_least_one_piece']}/{games}"
                if "games_with_at_least_one_piece" in thesis
                else None,
            ),
            ("mean pieces per game", _num(thesis.get("mean_pieces_per_game"), "{:.2f}")),
            ("per-slide success", _num(thesis.get("per_slide_success_rate"), "{:.1%}")),
        ]
        for column, value in quantities:
            if value not in (None, "—"):
                rows.append(Row("fig_3_15", "ch3", f"{short}: {column}", value, ours[column]))
    return rows


def _table_4_1(frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any]) -> list[Row]:
    frame, rows = frames["table_4_1"], []
    for thesis in _thesis_rows(figures, table_4_1.TABLE):
        ours = _by(frame, "table_4_1", row=thesis["row"])
        method = table_4_1.METHODS[ours["method"]].label
        boxes = "total of 4 cells" if thesis["row"].endswith("/total") else ours["boxes"]
        rows.append(
            _rate_row(
                "table_4_1",
                "ch4",
                f"success, {method}, {boxes}",
                thesis,
                ours,
            )
        )
    target = thesis_row(figures, table_4_1.TARGET_FIGURES, table_4_1.TARGET_THESIS_ROW)
    if target:
        ours = _by(
            frames["table_4_1_target"], "table_4_1_target", row=table_4_1.TARGET_THESIS_METHOD
        )
        method = table_4_1.METHODS[table_4_1.TARGET_THESIS_METHOD].label
        rows.append(
            _rate_row(
                "table_4_1_target",
                "ch4",
                f"success, predetermined target, {method}",
                target,
                ours,
            )
        )
    return rows


def _network_rows(
    frames: Mapping[str, pd.DataFrame],
    figures: Mapping[str, Any],
    table: str,
    page: str,
    metrics: Sequence[tuple[str, str]],
) -> list[Row]:
    """One row per thesis row that has a figure: 'a / b / c' of `metrics` (thesis key, our
    column), ours from the row '<label> [<run>]' ('not run' where the table says so)."""
    rows = []
    names = " / ".join(column for _, column in metrics)
    for thesis in _thesis_rows(figures, table):
        if not any(key in thesis for key, _ in metrics):
            continue
        label = thesis.get("label", thesis["row"])
        ours = _labelled(frames[table], table, label)
        not_run = str(ours.iloc[0]).endswith("[not run]")
        rows.append(
            Row(
                table,
                page,
                f"{names}: {label}",
                _nums(thesis, [key for key, _ in metrics]),
                "not run" if not_run else _nums(ours, [column for _, column in metrics]),
            )
        )
    return rows


def _table_5_2(frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any]) -> list[Row]:
    rows = []
    for thesis in _thesis_rows(figures, table_5_2.TABLE):
        method, scene = thesis["row"].split("/")
        ours = _by(frames["table_5_2"], "table_5_2", method=method, scene=scene)
        rows.append(
            _rate_row(
                "table_5_2",
                "ch5",
                f"success, {table_5_2.METHODS[method]}, {scene}",
                thesis,
                ours,
            )
        )
    return rows


def _table_6_2(
    frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any], methods: Mapping[str, str]
) -> list[Row]:
    thesis = thesis_row(figures, table_6_2.TABLE, "mean")
    if not thesis:
        return []
    label = methods[table_6_2.THESIS_METHOD]
    ours = _by(frames["table_6_2"], "table_6_2", method=label)
    return [
        Row(
            "table_6_2",
            "ch6",
            f"mean precision / recall: {label}",
            _nums(thesis, ["precision", "recall"]),
            _nums(ours, ["mean precision", "mean recall"]),
        )
    ]


def _table_6_3(frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any]) -> list[Row]:
    rows = []
    for thesis in _thesis_rows(figures, table_6_3.TABLE):
        method, objects = thesis["method"], str(thesis["n_objects"])
        ours = _by(frames["table_6_3"], "table_6_3", row=f"{method}/{objects}")
        who = f"{table_6_3.row_label(method).split(':')[0].split(' (')[0]}, {objects} boxes"
        if thesis["rate_unit"] == "per_step":
            cells = (
                table_6_3.step_rate_text(ours, "success"),
                table_6_3.step_rate_text(ours, "strict_success"),
            )
            quantity = f"success per step, {who}"
        else:
            cells = (rate_text(ours, "success"), rate_text(ours, "strict_success"))
            quantity = f"success per target (episode), {who}"
        thesis_text = thesis_rate_text(thesis) or "—"
        rows.append(
            Row("table_6_3", "ch6", quantity, thesis_text, cells[0] or "—", cells[1] or "—")
        )
        if "mean_steps" in thesis:
            rows.append(
                Row(
                    "table_6_3",
                    "ch6",
                    f"mean steps per episode, {who}",
                    _num(thesis["mean_steps"], "{:.3g}"),
                    _num(ours["mean_steps"], "{:.3g}"),
                )
            )
    return rows


def _datasets(frames: Mapping[str, pd.DataFrame], figures: Mapping[str, Any]) -> list[Row]:
    rows = []
    for ours in (r for _, r in frames["datasets"].iterrows()):
        key = datasets.THESIS_DATASET.get(str(ours["dataset"]))
        thesis = thesis_row(figures, "datasets", key) if key else {}
        if "n_samples" in thesis:
            rows.append(
                Row(
                    "datasets",
                    "scale",
                    f"samples, {ours['dataset']} (thesis: {key})",
                    _num(thesis["n_samples"], "{:.0f}"),
                    _num(ours["samples"], "{:.0f}"),
                )
            )
    return rows


def summary_rows(
    frames: Mapping[str, pd.DataFrame],
    figures: Mapping[str, Any],
    support_methods: Mapping[str, str],
) -> list[Row]:
    """Every thesis figure that stands beside one of ours, in chapter order. `frames`: our
    tables by name (their CSVs); `support_methods`: report.table_6_2_methods."""
    missing = sorted(set(FIGURE_NAMES) - set(frames))
    if missing:
        raise ClutterbenchError(f"summary: no table {', '.join(missing)}; rerun the report stage")
    return [
        *_fig_3_15(frames, figures),
        *_table_4_1(frames, figures),
        *_network_rows(
            frames,
            figures,
            "table_4_2",
            "ch4",
            [("iou", "avg. IoU"), ("recall", "avg. recall"), ("precision", "avg. precision")],
        ),
        *_network_rows(
            frames,
            figures,
            "table_5_1",
            "networks",
            [("pixel_accuracy", "pixel acc."), ("iou", "IoU")],
        ),
        *_table_5_2(frames, figures),
        *_network_rows(
            frames,
            figures,
            "table_6_1",
            "networks",
            [("pixel_accuracy", "pixel acc."), ("iou", "IoU"), ("precision", "precision")],
        ),
        *_table_6_2(frames, figures, support_methods),
        *_table_6_3(frames, figures),
        *_datasets(frames, figures),
    ]


def summary_markdown(rows: Sequence[Row], others: Sequence[str], scale: str) -> str:
    """The table and its notes; `others`: the names of every other table, linked below."""
    lines = [
        "| " + " | ".join(HEADER) + " |",
        "|" + "|".join("---" for _ in HEADER) + "|",
    ]
    for r in rows:
        figure = f"[{FIGURE_NAMES[r.table]}]({TABLES}/{r.table}.md)"
        page = f"[{PAGE_NAMES[r.page]}]({DOCS[r.page]})"
        cells = (figure, r.quantity, r.thesis, r.ours, r.strict, page)
        lines.append("| " + " | ".join(c.replace("|", "/") for c in cells) + " |")
    more = ", ".join(f"[{name}]({TABLES}/{name}.md)" for name in others)
    lines += [
        "",
        f"- {scale} scale. Ours: simulated in SAPIEN, read from the linked tables (the report "
        "stage writes this one from them); thesis: its figures as printed "
        "(reports/thesis_figures.yaml), real-robot trials on other objects and scenes.",
        "- ours: collapse-free success where a trial has two criteria (the thesis' notion: no "
        "other box left the shelf, dropped or tipped); strict: also no other box moved beyond "
        "the label threshold (ch. 3 games and the networks have one criterion). k/n = rate [95% "
        "interval]; — where there is no such figure.",
        f"- more tables: {more}." if others else "",
    ]
    return "\n".join(lines).rstrip() + "\n"


def summary_table(
    tables_dir: Path, figures: Mapping[str, Any], support_methods: Mapping[str, str], scale: str
) -> None:
    """reports/tables/summary.md from the tables' CSVs in `tables_dir` (written first)."""
    tables_dir = Path(tables_dir)
    frames = {}
    for name in FIGURE_NAMES:
        path = tables_dir / f"{name}.csv"
        if not path.exists():
            raise ClutterbenchError(f"summary: {path} missing; rerun the report stage")
        frames[name] = pd.read_csv(path)
    others = sorted(
        p.stem for p in tables_dir.glob("*.md") if p.stem not in FIGURE_NAMES and p.stem != NAME
    )
    rows = summary_rows(frames, figures, support_methods)
    write_text(tables_dir / f"{NAME}.md", summary_markdown(rows, others, scale))
