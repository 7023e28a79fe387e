"""The sensed rows of each chapter's trials: trials.sensed, trials.ch4_sensed and
trials.ch5_sensed add, for each condition they name, its twin under the sensor, and the
tables read the twin as the row '<row>/<sensing>'."""

from __future__ import annotations

import pytest

from clutterbench.collapse.config import TrainConfig
from clutterbench.config import load_params, load_section
from clutterbench.trials.condition_sets import SensedRows
from clutterbench.trials.config import TrialsConfig

STREAMS = {"s": {"families": {"pile": 1}, "n_objects": [5, 5]}}


def _trials(**extra) -> TrialsConfig:
    params = {"base": {"scale": "default"}, "trials": {"streams": STREAMS, **extra}}
    return load_section(TrialsConfig, "trials", params)


def test_each_group_gets_its_twins_with_only_the_sensor_and_masks_changed():
    cfg = _trials(
        conditions={"r": {"planner": "random", "stream": "s"}},
        sensed={"sensing": "d415", "perception": "depth", "of": ["r"]},
        ch4_conditions={"x": {"planner": "random", "stream": "s"}},
        ch4_sensed={"sensing": "structured_light", "perception": "depth", "of": ["x"]},
        ch5_conditions={"y": {"planner": "random", "perception": "detector", "stream": "s"}},
        ch5_sensed={"sensing": "d415", "of": ["y"]},
    )
    assert list(cfg.conditions) == ["r", "r_d415"]
    assert (cfg.conditions["r_d415"].sensing, cfg.conditions["r_d415"].perception) == (
        "d415",
        "depth",
    )
    assert list(cfg.ch4_conditions) == ["x", "x_structured_light"]
    twin = cfg.ch4_conditions["x_structured_light"]
    assert (twin.sensing, twin.perception, twin.episodes) == ("structured_light", "depth", 100)
    assert cfg.ch4_conditions["x"].sensing == "ideal"
    # no perception given: each keeps its own (the ch. 5 detector reads the sensed depth)
    assert cfg.ch5_conditions["y_d415"].perception == "detector"
    assert cfg.ch5_conditions["y_d415"].sensing == "d415"


@pytest.mark.parametrize(
    ("key", "group"),
    [("sensed", "conditions"), ("ch4_sensed", "ch4_conditions"), ("ch5_sensed", "ch5_conditions")],
)
def test_a_twin_of_no_condition_is_a_one_line_error(key, group):
    with pytest.raises(Exception, match=rf"{key}\.of: no condition 'nope' in trials\.{group}"):
        _trials(**{key: {"of": ["nope"]}})


def test_a_twin_reads_the_network_trained_for_its_sensor():
    cfg = _trials(
        ch4_conditions={
            "r": {"planner": "risk", "model": "m", "perception": "depth", "stream": "s"},
            "x": {"planner": "random", "stream": "s"},
        },
        ch4_sensed={"perception": "depth", "of": ["r", "x"], "models": {"m": "m_d415"}},
    )
    assert (cfg.ch4_conditions["r"].model, cfg.ch4_conditions["r_d415"].model) == ("m", "m_d415")
    assert cfg.ch4_conditions["x_d415"].model is None


def test_table_rows_add_the_twins_after_the_rows():
    rows = {"a/5": "a", "b/5": "b"}
    assert SensedRows(sensing="d415", of=("b",)).table_rows(rows) == {
        "a/5": "a",
        "b/5": "b",
        "b/5/d415": "b_d415",
    }
    assert SensedRows().table_rows(rows) == rows


def test_params_yaml_twins_table_4_1_s_depth_rows_and_table_5_2_s_planners():
    cfg = load_section(TrialsConfig, "trials", load_params())
    ch4 = [n for n, c in cfg.ch4_conditions.items() if c.sensing != "ideal"]
    assert ch4 and all(cfg.ch4_conditions[n].perception == "depth" for n in ch4)
    train = load_section(TrainConfig, "train", load_params())
    for name in ch4:  # each network a sensed row reads was trained on that sensor's images
        model = cfg.ch4_conditions[name].model
        assert model is None or train.sensing_of(model).preset == cfg.ch4_sensed.sensing
    assert all(n.removesuffix(f"_{cfg.ch4_sensed.sensing}") in cfg.ch4_conditions for n in ch4)
    ch5 = [c for c in cfg.ch5_conditions.values() if c.sensing != "ideal"]
    assert ch5 and all(c.perception == "detector" for c in ch5)
