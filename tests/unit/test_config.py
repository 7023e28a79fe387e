"""params.yaml parsing: scale resolution and one-line errors naming the key."""

from __future__ import annotations

import dataclasses

import pytest

from clutterbench.collapse.config import EvaluateConfig, TrainConfig
from clutterbench.config import load_params, load_section, parse, resolve_scale
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.split import Fractions, SplitConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.report.config import ReportConfig
from clutterbench.sim.config import SimConfig


def test_resolve_scale_picks_entry_and_leaves_other_mappings():
    value = {"n": {"tiny": 1, "default": 2, "paper": 3}, "families": {"random": 1}}
    assert resolve_scale(value, "paper", "x") == {"n": 3, "families": {"random": 1}}
    assert resolve_scale(value, "tiny", "x")["n"] == 1


def test_repo_params_parse_at_every_scale(root):
    params = load_params(root / "params.yaml")
    for scale in ("tiny", "default", "paper"):
        p = {**params, "base": {**params["base"], "scale": scale}}
        gen = load_section(GenerateConfig, "generate", p)
        load_section(SimConfig, "sim", p)
        split = load_section(SplitConfig, "split", p)
        report = load_section(ReportConfig, "report", p)
        assert set(split.datasets) == set(gen.datasets)
        train = load_section(TrainConfig, "train", p)
        evaluate = load_section(EvaluateConfig, "evaluate", p)
        assert {m.dataset for m in train.models.values()} <= set(gen.datasets)
        assert {r.model for r in evaluate.runs.values()} <= set(train.models)
        for table in (report.table_5_1, report.table_6_1, report.table_4_2):
            assert {r for r in table.values() if r is not None} <= set(evaluate.runs)
    ch4 = [evaluate.for_run(r).threshold for r in report.table_4_2.values() if r is not None]
    assert len(ch4) == 4 and set(ch4) == {0.4}  # thesis 4.4.1's pixel threshold
    assert evaluate.for_run("cmn_bs32_ch5").threshold == evaluate.threshold
    tiny = {**params, "base": {**params["base"], "scale": "tiny"}}
    assert load_section(SimConfig, "sim", tiny).camera.image_size == 64


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"n_scenes": 3, "families": {"random": 1}, "colour": 1}, "ds.colour: unknown key"),
        ({"n_scenes": "many", "families": {"random": 1}}, "ds.n_scenes: expected an integer"),
        ({"n_scenes": 0, "families": {"random": 1}}, "ds.n_scenes: 0 is out of range"),
        ({"n_scenes": 3, "families": {"bogus": 1}}, "families.bogus: unknown family"),
        ({"n_scenes": 3, "families": {"random": 1}, "n_objects": [9, 5]}, "n_objects"),
        ({"n_scenes": 3, "families": {"random": 1}, "catalogue": "huge"}, "ds.catalogue"),
        (
            {
                "n_scenes": 3,
                "families": {"random": 1, "replenish_stacked": 1},
                "n_objects": [20, 20],
            },
            "n_objects: family replenish_stacked arranges at most 7 boxes",
        ),
        ({"families": {"random": 1}}, "ds.n_scenes: missing required key"),
    ],
)
def test_bad_dataset_params_name_the_key(data, message):
    with pytest.raises(ClutterbenchError, match=message.replace(".", r"\.")) as info:
        parse(DatasetConfig, data, "ds")
    assert "\n" not in str(info.value)


def test_fractions_must_sum_to_one():
    with pytest.raises(ClutterbenchError, match="sum to 1"):
        parse(Fractions, {"train": 0.5, "val": 0.1, "test": 0.1}, "split.datasets.x")


def test_unknown_scale_is_rejected():
    with pytest.raises(ClutterbenchError, match="base.scale"):
        load_section(ReportConfig, "report", {"base": {"scale": "huge"}, "report": {}})


def test_a_params_file_that_is_not_yaml_is_one_line_naming_file_and_line(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("base:\n  seed: [1\n")
    with pytest.raises(ClutterbenchError) as err:
        load_params(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"params file {path} is not valid YAML")
    assert "(line 3, column 1)" in message
    path.write_text("base:\n  seed: 0\n  cores: auto\n")
    assert load_params(path) == {"base": {"seed": 0, "cores": "auto"}}


def test_configs_are_frozen():
    cfg = parse(Fractions, {}, "f")
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.train = 0.3  # type: ignore[misc]


MODEL = {"arch": "collapse_map", "dataset": "ch4_same", "batch_size": 4, "lr": 1e-3, "epochs": 1}


@pytest.mark.parametrize(
    ("model", "message"),
    [
        ({"net": {"n_masks": 2, "n_classes": 4}, "loss": "bce"}, "m.loss: bce does not fit"),
        ({"net": {"n_masks": 1}, "loss": "ce"}, "m.loss: ce does not fit n_classes 1"),
        ({"net": {"n_masks": 1, "n_classes": 4}, "loss": "ce"}, "m.net.n_classes: 1-mask"),
        ({"net": {"n_masks": 2, "n_classes": 3}, "loss": "ce"}, "m.net.n_classes: 2-mask"),
        ({"net": {"n_masks": 3}}, "m.net.n_masks: no samples give 3 masks"),
        ({"net": {"n_masks": 0}}, "m.net.n_masks: 0 is out of range"),
    ],
)
def test_masks_classes_and_loss_must_fit(model, message):
    with pytest.raises(ClutterbenchError, match=message.replace(".", r"\.")) as info:
        parse(TrainConfig, {"models": {"m": {**MODEL, **model}}}, "train")
    assert "\n" not in str(info.value)
    ok = {"net": {"n_masks": 2, "n_classes": 4}, "loss": "ce"}
    net = parse(TrainConfig, {"models": {"m": {**MODEL, **ok}}}, "train").models["m"].net
    assert (net.n_masks, net.n_classes) == (2, 4)


@pytest.mark.parametrize(
    ("arm_conditions", "message"),
    [
        ({"x_arm": {"of": "nope"}}, "arm_conditions.x_arm.of: unknown condition 'nope'"),
        ({"x_arm": {"of": "k", "episodes": 9}}, "arm_conditions.x_arm.episodes: 9 is more"),
        ({"x_arm": {"of": "k", "executor": "arm"}}, "executor: unknown key"),
    ],
)
def test_bad_arm_conditions_name_the_key(arm_conditions, message):
    """An arm-level condition repeats a kinematic one it names, on no more episodes."""
    from clutterbench.trials.config import TrialsConfig

    data = {
        "streams": {"s": {"families": {"random": 1}}},
        "conditions": {"k": {"planner": "multi_step", "stream": "s", "episodes": 5}},
        "arm_conditions": arm_conditions,
    }
    with pytest.raises(ClutterbenchError, match=message.replace(".", r"\.")) as info:
        parse(TrialsConfig, data, "trials")
    assert "\n" not in str(info.value)
    ok = {**data, "arm_conditions": {"x_arm": {"of": "k", "episodes": 5}}}
    assert parse(TrialsConfig, ok, "trials").arm_conditions["x_arm"].of == "k"


def test_the_families_caps_are_the_params_check_s():
    """The cap the params are checked against is the one scene drawing applies."""
    from clutterbench.sim.config import FAMILY_MAX_OBJECTS
    from clutterbench.sim.families import FAMILIES

    assert {n: f.max_objects for n, f in FAMILIES.items() if f.max_objects} == FAMILY_MAX_OBJECTS
