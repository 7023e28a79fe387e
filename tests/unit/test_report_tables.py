"""The text helpers every trials table shares (report/tables.py), on hand-made values."""

from __future__ import annotations

import pandas as pd

from clutterbench.report.tables import grouped, rate_text, thesis_rate_text, values_text

USED = {
    "a": [{"stream": "s1", "family": "random"}, {"stream": "s1", "family": "shelved"}],
    "b": [{"stream": "s1", "family": "shelved"}, {"stream": "s1", "family": "random"}],
    "c": [{"stream": "s2"}],
}


def test_grouped_names_conditions_sharing_a_description_once():
    streams = grouped(USED, lambda rs: "stream " + values_text(rs, "stream"))
    assert streams == "stream s1 (a, b); stream s2 (c)"
    assert grouped(USED, lambda rs: values_text(rs, "family")) == "random, shelved (a, b); None (c)"
    assert grouped({}, lambda rs: "x") == ""


def test_values_text_is_distinct_values_sorted_as_text():
    assert values_text([{"n": 10}, {"n": 3}, {"n": 10}], "n") == "10, 3"


def test_rate_text_of_an_aggregate_row():
    assert rate_text({"success_k": 3, "success_n": 4}, "success") == "3/4 = 75.0% [30.1, 95.4]"
    assert rate_text({"step_success_k": 0, "step_success_n": 0}, "step_success") == "—"
    assert rate_text({"success_k": pd.NA, "success_n": pd.NA}, "success") is None
    assert rate_text({}, "success") is None


def test_thesis_rate_text_as_printed():
    row = {"success": 52, "trials": 57, "success_rate": 0.912}
    assert thesis_rate_text(row) == "52/57 = 91.2%"
    assert thesis_rate_text({"success": 3, "trials": 4}) == "3/4"
    assert thesis_rate_text({"success": 3}) is None
    assert thesis_rate_text({}) is None
