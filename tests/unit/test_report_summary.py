"""The results-at-a-glance table (report/summary.py) on made-up tables and thesis figures,
and the README's copy of reports/tables/summary.md (byte for byte, so it cannot drift)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.report.summary import summary_markdown, summary_rows, summary_table

ROOT = Path(__file__).resolve().parents[2]
BEGIN, END = "<!-- summary:begin -->\n", "<!-- summary:end -->"

FIGURES = {
    "fig_3_15": {
        "rows": [
            {
                "row": "with_convnet",
                "games": 15,
                "games_with_at_least_one_piece": 12,
                "mean_pieces_per_game": 1.47,
                "per_slide_success_rate": 0.595,
            },
            {"row": "without_convnet", "games": 15, "games_with_at_least_one_piece": 7},
        ]
    },
    "table_4_1": {"rows": [{"row": "various_model/total", "success": 64, "trials": 80}]},
    "ch4_predetermined_target": {
        "rows": [{"row": "predetermined_target", "success": 17, "trials": 20}]
    },
    "table_4_2": {
        "rows": [{"row": "a", "label": "A", "iou": 0.3, "recall": 0.5, "precision": 0.4}]
    },
    "table_5_1": {
        "rows": [
            {"row": "b", "label": "B", "pixel_accuracy": 0.9, "iou": 0.4},
            {"row": "c", "label": "C", "pixel_accuracy": 0.8, "iou": 0.2},
        ]
    },
    "table_5_2": {
        "rows": [{"row": "replenish/total", "success": 68, "trials": 100, "success_rate": 0.68}]
    },
    "table_6_1": {"rows": [{"row": "d", "label": "D"}]},  # no figure: no summary row
    "table_6_2": {
        "rows": [
            {"row": "S1", "precision": 0.5},
            {"row": "mean", "precision": 0.867, "recall": 0.928},
        ]
    },
    "table_6_3": {
        "rows": [
            {
                "row": "multi_step_single_arm/per_target",
                "method": "multi_step",
                "n_objects": "3-10",
                "success": 20,
                "trials": 25,
                "rate_unit": "per_target",
                "mean_steps": 2.3,
            }
        ]
    },
    "datasets": {"rows": [{"row": "ch6_cp_total", "n_samples": 50000}]},
}


def _frames() -> dict[str, pd.DataFrame]:
    rate = {"success_k": 3, "success_n": 4, "strict_success_k": 1, "strict_success_n": 4}
    return {
        "fig_3_15": pd.DataFrame(
            [
                {
                    "variant": label,
                    "games with >= 1 piece": f"g{i}",
                    "mean pieces per game": f"m{i}",
                    "per-slide success": f"s{i}",
                }
                for i, label in enumerate(
                    ["with ConvNet (thesis method)", "without ConvNet: least-occluded piece"]
                )
            ]
        ),
        "table_4_1": pd.DataFrame(
            [{"row": "various_model/total", "method": "various_model", "boxes": "x", **rate}]
        ),
        "table_4_1_target": pd.DataFrame([{"row": "various_model", **rate}]),
        "table_4_2": pd.DataFrame(
            [{"run": "A [r]", "avg. IoU": 0.71, "avg. recall": 0.9, "avg. precision": 0.75}]
        ),
        "table_5_1": pd.DataFrame(
            [
                {"run": "B [r]", "pixel acc.": 0.95, "IoU": 0.61},
                {"run": "C [not run]", "pixel acc.": None, "IoU": None},
            ]
        ),
        "table_5_2": pd.DataFrame([{"method": "replenish", "scene": "total", **rate}]),
        "table_6_1": pd.DataFrame([{"run": "D [r]", "pixel acc.": 0.9}]),
        "table_6_2": pd.DataFrame(
            [{"method": "the iou rule", "mean precision": 0.8, "mean recall": 0.7}]
        ),
        "table_6_3": pd.DataFrame([{"row": "multi_step/3-10", **rate, "mean_steps": 1.45}]),
        "datasets": pd.DataFrame(
            [{"dataset": "ch6", "samples": 40525}, {"dataset": "x", "samples": 1}]
        ),
    }


def test_summary_rows_put_each_thesis_figure_beside_ours():
    rows = summary_rows(_frames(), FIGURES, {"iou": "the iou rule"})
    got = [(r.table, r.thesis, r.ours, r.strict) for r in rows]
    assert got == [
        ("fig_3_15", "12/15", "g0", "—"),
        ("fig_3_15", "1.47", "m0", "—"),
        ("fig_3_15", "59.5%", "s0", "—"),
        ("fig_3_15", "7/15", "g1", "—"),
        ("table_4_1", "64/80", "3/4 = 75.0% [30.1, 95.4]", "1/4 = 25.0% [4.6, 69.9]"),
        ("table_4_1_target", "17/20", "3/4 = 75.0% [30.1, 95.4]", "1/4 = 25.0% [4.6, 69.9]"),
        ("table_4_2", "0.300 / 0.500 / 0.400", "0.710 / 0.900 / 0.750", "—"),
        ("table_5_1", "0.900 / 0.400", "0.950 / 0.610", "—"),
        ("table_5_1", "0.800 / 0.200", "not run", "—"),
        ("table_5_2", "68/100 = 68.0%", "3/4 = 75.0% [30.1, 95.4]", "1/4 = 25.0% [4.6, 69.9]"),
        ("table_6_2", "0.867 / 0.928", "0.800 / 0.700", "—"),
        ("table_6_3", "20/25", "3/4 = 75.0% [30.1, 95.4]", "1/4 = 25.0% [4.6, 69.9]"),
        ("table_6_3", "2.3", "1.45", "—"),
        ("datasets", "50000", "40525", "—"),
    ]
    text = summary_markdown(rows, ["extra"], "tiny")
    lines = text.splitlines()
    assert len(lines) == 2 + len(rows) + 4 and lines[0].startswith("| thesis figure |")
    assert "| [Table 4.1](/reports/tables/table_4_1.md) |" in lines[6]
    assert lines[6].endswith("| [ch. 4](/docs/ch4-pull-with-support.md) |")
    assert lines[-3].startswith("- tiny scale.") and "[extra](/reports/tables/extra.md)" in text


def test_summary_refuses_a_missing_or_ambiguous_table(tmp_path: Path):
    frames = _frames()
    del frames["table_5_2"]
    with pytest.raises(ClutterbenchError, match="no table table_5_2"):
        summary_rows(frames, FIGURES, {"iou": "the iou rule"})
    frames = _frames()
    frames["table_4_1"] = pd.concat([frames["table_4_1"]] * 2)
    with pytest.raises(ClutterbenchError, match="2 rows of reports/tables/table_4_1.csv"):
        summary_rows(frames, FIGURES, {"iou": "the iou rule"})
    with pytest.raises(ClutterbenchError, match="missing"):
        summary_table(tmp_path, FIGURES, {"iou": "the iou rule"}, "tiny")


def test_readme_embeds_the_summary_byte_for_byte():
    readme = (ROOT / "README.md").read_text()
    assert readme.count(BEGIN) == 1 and readme.count(END) == 1, "README: summary markers"
    block = readme.split(BEGIN)[1].split(END)[0]
    summary = (ROOT / "reports/tables/summary.md").read_text()
    assert block == summary, "README's summary differs from reports/tables/summary.md: copy it"
