"""Opt-in trials conditions (trials.opt_in): the trials stage and the noise replays leave them
out unless switched on (`make repro-full`), a bad opt-in name is one line naming it, and
Table 6.3, its families and its decomposition say "not run" for a row left out."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import pandas as pd
import pytest

from clutterbench.config import load_params, load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.report.decomposition import decomposition_table
from clutterbench.report.table_6_3 import extraction_families_table, extraction_table
from clutterbench.report.tables import load_thesis_figures
from clutterbench.trials.ch6.planners import planner_info
from clutterbench.trials.condition_sets import NOT_RUN, OptInRows
from clutterbench.trials.config import TrialsConfig

ROOT = Path(__file__).resolve().parents[2]
PARAMS = load_params(ROOT / "params.yaml")
OPT_IN = (
    "multi_step_truth_3_5",
    "multi_step_pull_truth_3_5",
    "multi_step_truth_10",
    "multi_step_pull_truth_10",
    "physics_from_depth_hold_10",
)
"""The committed opt-in set: the deletion- and pull-truth rows of the 3-5 and 10-box streams,
and the 10-box stream's training-free holding row (no learned holding row runs there)."""


def _trials(**opt_in) -> TrialsConfig:
    params = copy.deepcopy(PARAMS)
    params["trials"]["opt_in"] = params["trials"]["opt_in"] | opt_in
    return load_section(TrialsConfig, "trials", params)


def test_the_committed_set_is_off_by_default_at_every_scale():
    for scale in ("tiny", "default", "paper"):
        params = copy.deepcopy(PARAMS)
        params["base"]["scale"] = scale
        cfg = load_section(TrialsConfig, "trials", params)
        assert (cfg.opt_in.run, cfg.opt_in.conditions, cfg.opt_in.skipped) == (
            False,
            OPT_IN,
            OPT_IN,
        )


def test_the_stage_runs_the_opt_in_rows_only_when_switched_on():
    off, on = _trials(run=False), _trials(run=True)
    assert list(off.stage_conditions()) == [n for n in off.conditions if n not in OPT_IN]
    assert list(on.stage_conditions()) == list(on.conditions)
    assert on.opt_in.skipped == () and set(OPT_IN) <= set(on.run_conditions)
    # named on the command line (a debugging run), an opt-in row runs, alone
    assert list(off.stage_conditions(["multi_step_truth_10"])) == ["multi_step_truth_10"]
    with pytest.raises(ClutterbenchError, match="trials.conditions.nope: no such condition"):
        off.stage_conditions(["nope"])


def test_the_noise_stage_replays_only_what_the_trials_ran():
    from clutterbench.trials.noise.config import NoiseConfig
    from clutterbench.trials.noise.run import conditions_of

    noise = load_section(NoiseConfig, "noise", PARAMS)
    off, on = _trials(run=False), _trials(run=True)
    assert not set(OPT_IN) & set(conditions_of(noise, off))
    assert set(OPT_IN) <= set(conditions_of(noise, on))
    named = dataclasses.replace(noise, conditions=("multi_step_truth_10",))
    with pytest.raises(ClutterbenchError, match="'multi_step_truth_10' is opt-in and not run"):
        conditions_of(named, off)


@pytest.mark.parametrize(
    ("names", "line"),
    [
        (["multi_step_truth_35"], "opt_in.conditions: no condition 'multi_step_truth_35' in "),
        (["multi_step"], "opt_in.conditions: 'multi_step' is in sensed.of (its sensed row "),
    ],
)
def test_a_bad_opt_in_name_stops_the_parse_in_one_line(names, line):
    with pytest.raises(ClutterbenchError) as err:
        _trials(conditions=names)
    assert str(err.value).startswith(f"trials: {line}") and "\n" not in str(err.value)


def test_an_oracle_or_the_floor_is_never_opt_in():
    planner_of = {"oracle_3_5": "oracle", "random": "random", "multi_step_10": "multi_step"}
    role = lambda planner: planner_info(planner).role  # noqa: E731

    def problem(*names: str) -> str | None:
        return OptInRows(conditions=names).role_problem(planner_of, role)

    assert problem("multi_step_10") is None
    assert problem("oracle_3_5") == (
        "opt_in.conditions: 'oracle_3_5' is a search oracle's row (the other rows are "
        "measured against it); it may not be opt-in"
    )
    assert "'random' is the random floor's row" in str(problem("multi_step_10", "random"))


def _trial(condition: str, planner: str, stream: str, e: int, ok: bool) -> dict:
    step = {"success": ok, "extracted": True, "others_still": ok}
    return {
        "condition": condition,
        "planner": planner,
        "n_objects": 10,
        "stream": stream,
        "family": "random",
        "perception": "instance",
        "episode": e,
        "steps": [step],
        "target_out": ok,
        "success": ok,
        "strict_success": ok,
        "n_disturbed": 0,
        "disturbance_m": 0.0,
    }


RECORDS = {
    cond: [_trial(cond, planner, stream, e, e < wins) for e in range(4)]
    for cond, planner, stream, wins in (
        ("multi_step_10", "multi_step", "ch6_10", 1),
        ("oracle_10", "oracle", "ch6_10", 3),
        ("multi_step", "multi_step", "ch6_3_10", 1),
        ("multi_step_truth", "multi_step_truth", "ch6_3_10", 2),
        ("oracle", "oracle", "ch6_3_10", 3),
    )
}
ROWS = {
    "multi_step/10": "multi_step_10",
    "multi_step_truth/10": "multi_step_truth_10",
    "oracle/10": "oracle_10",
    "multi_step/3-10": "multi_step",
    "multi_step_truth/3-10": "multi_step_truth",
    "oracle/3-10": "oracle",
}
LEFT_OUT = ("multi_step_truth_10",)


def test_table_6_3_says_not_run_for_a_row_left_out_and_its_csv_has_none(tmp_path, root):
    figures = load_thesis_figures(root / "reports/thesis_figures.yaml")
    with pytest.raises(ClutterbenchError, match="no trial records for condition"):
        extraction_table(RECORDS, ROWS, figures, tmp_path, "tiny")  # not said: no silent row
    raw = extraction_table(RECORDS, ROWS, figures, tmp_path, "tiny", not_run=LEFT_OUT)
    md = (tmp_path / "table_6_3.md").read_text()
    (row,) = [ln for ln in md.splitlines() if ln.startswith("|") and "_truth_10]" in ln]
    assert row.count(NOT_RUN) == 2 and "| 10 |" in row  # collapse-free and strict
    assert f"- {NOT_RUN}: multi_step_truth/10 [multi_step_truth_10]. Opt-in" in md
    assert "multi_step_truth_10" not in set(raw["condition"])
    assert list(pd.read_csv(tmp_path / "table_6_3.csv")["row"]) == [
        r for r, c in ROWS.items() if c not in LEFT_OUT
    ]
    families = extraction_families_table(RECORDS, ROWS, tmp_path, "tiny", not_run=LEFT_OUT)
    assert "multi_step_truth_10" not in set(families["condition"])
    assert f"{NOT_RUN}: multi_step_truth/10" in (tmp_path / "table_6_3_families.md").read_text()


def test_the_decomposition_keeps_what_ran_and_names_what_did_not(tmp_path):
    ran = {c: RECORDS[c] for c in ("multi_step", "multi_step_truth", "oracle")}
    decomposition_table(ran, tmp_path / "all", "tiny")
    raw = decomposition_table(RECORDS, tmp_path / "opt_in", "tiny", not_run=LEFT_OUT)
    assert raw is not None and set(raw["stream"]) == {"ch6_3_10"}  # 10 boxes: no truth row
    whole = (tmp_path / "all/table_6_3_decomposition.csv").read_text()
    assert (tmp_path / "opt_in/table_6_3_decomposition.csv").read_text() == whole
    md = (tmp_path / "opt_in/table_6_3_decomposition.md").read_text()
    assert f"- {NOT_RUN}: multi_step_truth_10 (opt-in" in md
    assert NOT_RUN not in (tmp_path / "all/table_6_3_decomposition.md").read_text()
