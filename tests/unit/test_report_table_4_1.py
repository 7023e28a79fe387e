"""Table 4.1 and the predetermined-target table, from hand-made records into a tmp dir."""

from __future__ import annotations

import pandas as pd
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.report.table_4_1 import table_4_1, table_4_1_target

# Made-up thesis numbers: only the shape of reports/thesis_figures.yaml matters here.
FIGURES = {
    "table_4_1": {
        "caption": "Made-up result",
        "source": "made-up 4.3.3",
        "rows": [
            {"row": "same_model/same_size_5", "success": 3, "trials": 4},
            {"row": "same_model/various_size_5", "success": 2, "trials": 4},
            {"row": "same_model/total", "success": 5, "trials": 8, "success_rate": 0.625},
            {"row": "various_model/same_size_5", "success": 1, "trials": 4},
            {"row": "various_model/total", "success": 1, "trials": 4, "success_rate": 0.25},
        ],
    },
    "ch4_predetermined_target": {
        "caption": None,
        "source": "made-up text",
        "rows": [{"row": "predetermined_target", "success": 7, "trials": 9, "success_rate": 0.7}],
    },
}


def trial(
    condition: str,
    planner: str,
    catalogue: str,
    success: bool,
    *,
    model: str | None = None,
    n_objects: int = 5,
    strict: bool | None = None,
    valid: bool = True,
    n_disturbed: int = 0,
    disturbance_m: float = 0.002,
    perception: str = "instance",
    mode: str = "pair",
) -> dict:
    return {
        "condition": condition,
        "episode": 0,
        "seed": 1,
        "stream": "ch4_stream",
        "family": "pile",
        "n_objects": n_objects,
        "catalogue": catalogue,
        "planner": planner,
        "mode": mode,
        "model": model,
        "perception": perception,
        "extract": 1,
        "support": 2,
        "risk": 0.1 if planner == "risk" else None,
        "n_candidates": 3,
        "valid": valid,
        "success": success,
        "strict_success": success if strict is None else strict,
        "target_out": success,
        "n_left_shelf": 0 if success else 1,
        "n_disturbed": n_disturbed,
        "disturbance_m": disturbance_m,
    }


def cell(condition, planner, catalogue, outcomes, **kw) -> list[dict]:
    return [trial(condition, planner, catalogue, ok, **kw) for ok in outcomes]


RECORDS = {
    # same model, same-size boxes: 2/3 success, one of them not strict, 1 invalid action
    "s_same": [
        trial("s_same", "risk", "same", True, model="ch4_same", n_disturbed=1, disturbance_m=0.01),
        trial("s_same", "risk", "same", True, model="ch4_same", strict=False),
        trial("s_same", "risk", "same", False, model="ch4_same", valid=False, n_disturbed=2),
    ],
    # same model, various-size boxes: 1/2
    "s_var": cell("s_var", "risk", "various", [True, False], model="ch4_same"),
    # various model, same-size boxes: 0/2
    "v_same": cell("v_same", "risk", "same", [False, False], model="ch4_various"),
    "rnd": cell("rnd", "random", "new", [True, False, False, False]),
    "v_depth": cell(
        "v_depth", "risk", "same", [True], model="ch4_various", perception="depth", n_objects=10
    ),
}
ROWS = {
    "same_model/same_size_5": "s_same",
    "various_model/same_size_5": "v_same",
    "same_model/various_size_5": "s_var",
    "random/new_various_size_5": "rnd",
    "various_model_depth/same_size_10": "v_depth",
}


def line_of(md: str, start: str) -> str:
    (line,) = [ln for ln in md.splitlines() if ln.startswith(start)]
    return line


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_table_4_1_rates_totals_and_thesis_beside(tmp_path):
    raw = table_4_1(RECORDS, ROWS, FIGURES, tmp_path, "tiny")
    md = (tmp_path / "table_4_1.md").read_text()
    assert md.startswith("# Table 4.1 (simulated): Made-up result\n")
    header = cells(line_of(md, "| method [our condition]"))
    assert header == [
        "method [our condition]",
        "objects",
        "collapse-free success",
        "collapse-free success (thesis)",
        "strict success (no other box moved > 5 mm)",
        "mean disturbed boxes",
        "mean disturbance (mm)",
        "invalid actions",
        "episodes",
    ]
    same = cells(line_of(md, "| trained with same-size boxes [s_same]"))
    assert same[1] == "5 same-size"
    assert same[2] == "2/3 = 66.7% [20.8, 93.9]"
    assert same[3] == "3/4"  # the thesis cell, as printed (no rate in the figures)
    assert same[4] == "1/3 = 33.3% [6.1, 79.2]"
    assert same[5] == "1.00"  # (1 + 0 + 2) / 3
    assert same[6] == "4.7"  # (10 + 2 + 2) / 3 mm
    assert (same[7], same[8]) == ("1", "3")
    # the same model's total pools its two cells: 3/5 beside the thesis' total
    total = cells(line_of(md, "| trained with same-size boxes: total of 2 cells"))
    assert total[1] == "5 same-size, 5 various-size"
    assert total[2] == "3/5 = 60.0% [23.1, 88.2]"
    assert total[3] == "5/8 = 62.5%"
    assert (total[7], total[8]) == ("1", "5")
    various_total = cells(line_of(md, "| trained with various-size boxes: total of 1 cell |"))
    assert various_total[2].startswith("0/2 = 0.0%") and various_total[3] == "1/4 = 25.0%"
    # rows the thesis lacks: no thesis cell
    rnd = cells(line_of(md, "| random pair (floor) [rnd]"))
    assert rnd[1] == "5 new various-size" and rnd[2].startswith("1/4 = 25.0%") and rnd[3] == "—"
    depth = cells(line_of(md, "| trained with various-size boxes + depth-only segmentation ["))
    assert depth[1] == "10 same-size" and depth[2].startswith("1/1 = 100.0%")
    assert "tiny scale" in md and "4 trials per cell" in md and "dual-arm" in md
    assert "Wilson 95%" in md and "invalid actions:" in md
    # each method's cells, then its total
    assert list(raw["row"]) == [
        "same_model/same_size_5",
        "same_model/various_size_5",
        "same_model/total",
        "various_model/same_size_5",
        "various_model/total",
        "random/new_various_size_5",
        "random/total",
        "various_model_depth/same_size_10",
        "various_model_depth/total",
    ]
    csv = pd.read_csv(tmp_path / "table_4_1.csv")  # the raw numbers, not the formatted text
    assert list(csv.columns) == list(raw.columns)
    t = csv.set_index("row").loc["same_model/total"]
    assert (t["success_k"], t["success_n"], t["strict_success_k"], t["invalid"]) == (3, 5, 2, 1)
    assert t["condition"] == "s_same+s_var" and t["objects"] == "total"
    assert (t["thesis_success_k"], t["thesis_success_n"]) == (5, 8)
    assert t["thesis_success_rate"] == pytest.approx(0.625)
    assert t["mean_disturbance_m"] == pytest.approx((0.01 + 4 * 0.002) / 5)
    assert pd.isna(csv.set_index("row").loc["random/total", "thesis_success_k"])
    for column in ("episodes", "success_k", "success_n", "invalid", "strict_success_k"):
        assert pd.api.types.is_integer_dtype(csv[column]), column
    assert "= " not in (tmp_path / "table_4_1.csv").read_text()  # no formatted rates
    text = pd.read_csv(tmp_path / "table_4_1.csv", dtype=str).set_index("row")
    # thesis counts stay integers in a column with gaps ('3', not '3.0')
    cell_text = text.loc["same_model/same_size_5"]
    assert (cell_text["thesis_success_k"], cell_text["thesis_success_n"]) == ("3", "4")


def test_table_4_1_leaves_out_invalid_actions_when_none(tmp_path):
    table_4_1(RECORDS, {"same_model/various_size_5": "s_var"}, FIGURES, tmp_path, "t")
    md = (tmp_path / "table_4_1.md").read_text()
    assert "invalid actions" not in md
    assert "2/4" in line_of(md, "| trained with same-size boxes [s_var]")  # thesis cell


def test_table_4_1_validates_rows_conditions_and_records(tmp_path):
    with pytest.raises(ClutterbenchError, match=r"report\.table_4_1\.teleport/same_size_5:"):
        table_4_1(RECORDS, {"teleport/same_size_5": "s_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match=r"report\.table_4_1\.same_model/huge_3:"):
        table_4_1(RECORDS, {"same_model/huge_3": "s_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="same_model/total"):
        table_4_1(RECORDS, {"same_model/total": "s_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match=r"condition .gone.; run the trials_ch4 stage"):
        table_4_1(RECORDS, {"same_model/same_size_5": "gone"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran model ch4_various, not ch4_same"):
        table_4_1(RECORDS, {"same_model/same_size_5": "v_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran perception instance, not depth"):
        table_4_1(RECORDS, {"various_model_depth/same_size_5": "v_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran planner risk, not oracle"):
        table_4_1(RECORDS, {"oracle/same_size_5": "s_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran catalogue various, not same"):
        table_4_1(RECORDS, {"same_model/same_size_5": "s_var"}, FIGURES, tmp_path, "t")
    target = {"t": cell("t", "risk", "same", [True], model="ch4_same", mode="target")}
    with pytest.raises(ClutterbenchError, match="ran mode target, not pair"):
        table_4_1(target, {"same_model/same_size_5": "t"}, FIGURES, tmp_path, "t")
    assert not list(tmp_path.iterdir())  # nothing written on error
    assert table_4_1(RECORDS, {}, FIGURES, tmp_path, "t").empty
    assert not list(tmp_path.iterdir())


def sensed(records: list[dict], sensing: str = "d415") -> list[dict]:
    """The records as a condition run again under a sensor writes them."""
    return [{**r, "condition": f"{r['condition']}_{sensing}", "sensing": sensing} for r in records]


def test_table_4_1_sensed_rows_stand_apart_with_no_thesis_figure(tmp_path):
    """A row '<method>/<objects>/<sensing>' reads its sensed twin's records: its own cells and
    total after the exact-depth rows, labelled with the sensor, never the thesis' figure; a
    note names the sensed rows; the exact-depth rows read as they do alone."""
    twin = cell("s_same", "risk", "same", [True, False], model="ch4_same", perception="depth")
    records = {**RECORDS, "s_same_d415": sensed(twin)}
    rows = {**ROWS, "same_model_depth/same_size_5/d415": "s_same_d415"}
    figures = {
        **FIGURES,
        "table_4_1": {
            **FIGURES["table_4_1"],
            "rows": [
                *FIGURES["table_4_1"]["rows"],
                {"row": "same_model_depth/same_size_5", "success": 3, "trials": 4},
                {"row": "same_model_depth/total", "success": 3, "trials": 4, "success_rate": 0.75},
            ],
        },
    }
    raw = table_4_1(records, rows, figures, tmp_path, "tiny")
    md = (tmp_path / "table_4_1.md").read_text()
    label = "| trained with same-size boxes + depth-only segmentation, D415-class sensor (d415)"
    line = cells(line_of(md, f"{label} ["))
    assert line[2].startswith("1/2 = 50.0%") and line[3] == "—"  # no thesis figure beside
    assert cells(line_of(md, f"{label}: total of 1 cell"))[3] == "—"
    assert list(raw["row"])[-2:] == [
        "same_model_depth/same_size_5/d415",
        "same_model_depth/total/d415",
    ]
    assert "sensing (docs/sensing.md): d415 (s_same_d415)" in md
    alone = tmp_path / "alone"
    table_4_1(RECORDS, ROWS, figures, alone, "tiny")

    def table_lines(text: str) -> list[str]:
        return [ln for ln in text.splitlines() if ln.startswith("|") and "d415" not in ln]

    assert table_lines(md) == table_lines((alone / "table_4_1.md").read_text())
    assert "sensing" not in (alone / "table_4_1.md").read_text()


def test_table_4_1_sensed_rows_check_their_sensor(tmp_path):
    twin = cell("d", "risk", "same", [True], model="ch4_same", perception="depth")
    records = {**RECORDS, "d": twin, "d_d415": sensed(twin)}
    row = "same_model_depth/same_size_5"
    with pytest.raises(ClutterbenchError, match="ran sensing d415, not structured_light"):
        table_4_1(records, {f"{row}/structured_light": "d_d415"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran sensing ideal, not d415"):
        table_4_1(records, {f"{row}/d415": "d"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran sensing d415, not ideal"):
        table_4_1(records, {row: "d_d415"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match=r"same_size_5/lidar: a row must read"):
        table_4_1(records, {f"{row}/lidar": "d_d415"}, FIGURES, tmp_path, "t")
    assert not list(tmp_path.iterdir())


def test_a_sensed_row_may_read_the_network_trained_on_its_sensor(tmp_path):
    """trials.ch4_sensed.models: the twin of a various-size row reads another network; the
    table accepts it only through that mapping and names it."""
    twin = sensed(cell("v", "risk", "same", [True], model="ch4_various_d415", perception="depth"))
    records = {**RECORDS, "v_d415": twin}
    rows = {"various_model_depth/same_size_5/d415": "v_d415"}
    with pytest.raises(ClutterbenchError, match="ran model ch4_various_d415, not ch4_various"):
        table_4_1(records, rows, FIGURES, tmp_path, "t")
    table_4_1(records, rows, FIGURES, tmp_path, "t", {"ch4_various": "ch4_various_d415"})
    md = (tmp_path / "table_4_1.md").read_text()
    assert (
        "D415-class sensor (d415), network trained on its images (ch4_various_d415) [v_d415]" in md
    )


TARGET_RECORDS = {
    "tv": cell("tv", "risk", "various", [True, True, False], model="ch4_various", mode="target"),
    "ts": cell("ts", "risk", "various", [True, False], model="ch4_same", mode="target"),
    "to": cell("to", "oracle", "various", [True, True], mode="target"),
}


def test_table_4_1_target_thesis_only_beside_the_various_model(tmp_path):
    rows = {"various_model": "tv", "same_model": "ts", "oracle": "to"}
    raw = table_4_1_target(TARGET_RECORDS, rows, FIGURES, tmp_path, "tiny")
    md = (tmp_path / "table_4_1_target.md").read_text()
    assert md.startswith("# Predetermined target (simulated; thesis 4.3.3)\n")
    various = cells(line_of(md, "| trained with various-size boxes [tv]"))
    assert various[2] == "2/3 = 66.7% [20.8, 93.9]" and various[3] == "7/9 = 70.0%"
    same = cells(line_of(md, "| trained with same-size boxes [ts]"))
    assert same[2].startswith("1/2 = 50.0%") and same[3] == "—"
    assert cells(line_of(md, "| oracle: every support simulated"))[2].startswith("2/2 = 100.0%")
    assert "only its support" in md and "thesis: 9 trials on" in md
    assert list(raw["row"]) == list(rows)  # no totals here
    csv = pd.read_csv(tmp_path / "table_4_1_target.csv").set_index("row")
    assert (csv.loc["various_model", "success_k"], csv.loc["various_model", "success_n"]) == (2, 3)
    assert csv.loc["various_model", "thesis_success_k"] == 7
    assert pd.isna(csv.loc["same_model", "thesis_success_k"])


def test_table_4_1_target_checks_mode_and_method(tmp_path):
    with pytest.raises(ClutterbenchError, match="ran mode pair, not target"):
        table_4_1_target(RECORDS, {"same_model": "s_same"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match=r"report\.table_4_1_target\.same_model_depth:"):
        table_4_1_target(TARGET_RECORDS, {"same_model_depth": "ts"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match="ran model ch4_same, not ch4_various"):
        table_4_1_target(TARGET_RECORDS, {"various_model": "ts"}, FIGURES, tmp_path, "t")
    with pytest.raises(ClutterbenchError, match=r"condition .nope.; run the trials_ch4 stage"):
        table_4_1_target(TARGET_RECORDS, {"random": "nope"}, FIGURES, tmp_path, "t")


def test_tie_break_note_counts_choices_decided_among_equal_risks():
    from clutterbench.report.table_4_1 import tie_break_notes

    used = {
        "a": [
            {"planner": "risk", "risk_ties": 5, "risk": 0.0},
            {"planner": "risk", "risk_ties": 1, "risk": 0.02},
            {"planner": "risk", "risk_ties": 2, "risk": 0.01},
        ],
        "rnd": [{"planner": "random", "risk_ties": None, "risk": None}],
    }
    (note,) = tie_break_notes(used)
    assert "in 2 of the 3 risk-planner choices" in note and "was 0 in 1." in note
    assert tie_break_notes({"rnd": used["rnd"]}) == []
