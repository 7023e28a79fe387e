"""`clutterbench check`: the committed params.yaml passes; each kind of mistake gives one line
naming its params key and exit 2; and the section registry covers every section the stages
and commands load, so a new stage's section cannot be left unchecked."""

from __future__ import annotations

import ast
import copy
import json
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from clutterbench.cli import app
from clutterbench.cli.check import sections

ROOT = Path(__file__).resolve().parents[2]
PARAMS = yaml.safe_load((ROOT / "params.yaml").read_text())
STACK3 = ROOT / "tests" / "data" / "stack3.json"

runner = CliRunner()


def _check(*args: str) -> tuple[int, list[str], str]:
    """(exit code, stderr lines, stdout) of `clutterbench check ARGS`."""
    result = runner.invoke(app, ["check", *args])
    return result.exit_code, result.stderr.strip().splitlines(), result.stdout


def _params_with(tmp_path: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    params = copy.deepcopy(PARAMS)
    edit(params)
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(params, sort_keys=False))
    return path


def test_the_committed_params_and_a_spec_pass() -> None:
    code, errors, out = _check(str(ROOT / "params.yaml"), "--spec", str(STACK3))
    assert (code, errors) == (0, []), errors
    assert out.startswith("ok: ") and len(out.strip().splitlines()) == 1


def _rename(section: dict[str, Any], old: str, new: str) -> None:
    section[new] = section.pop(old)


def _scale_only(params: dict[str, Any]) -> None:
    params["generate"]["datasets"]["ch5"]["n_scenes"] = {"tiny": 0, "default": 9, "paper": 9}


MISTAKES: dict[str, tuple[Callable[[dict[str, Any]], None], str]] = {
    "typo'd key": (
        lambda p: _rename(p["trials"]["ch6"], "max_steps", "max_stepz"),
        "error: trials.ch6.max_stepz: unknown key (allowed: ",
    ),
    "bad value": (
        lambda p: p["detector"].update(lr=-1),
        "error: detector.lr: -1.0 is out of range (must be > 0.0)",
    ),
    "unknown sensor of the detector": (
        lambda p: p["detector"]["sensing"].update(preset="d435"),
        "error: detector.sensing.preset: 'd435' is not one of ideal, structured_light, d415",
    ),
    "unknown planner": (
        lambda p: p["trials"]["conditions"]["oracle"].update(planner="oracel"),
        "error: trials.conditions.oracle.planner: unknown planner 'oracel' (did you mean",
    ),
    "unknown stream": (
        lambda p: p["trials"]["conditions"]["oracle"].update(stream="ch6_3_01"),
        "error: trials.conditions.oracle.stream: unknown stream 'ch6_3_01' (not in trials.streams",
    ),
    "unknown opt-in condition": (
        lambda p: p["trials"]["opt_in"].update(conditions=["multi_step_truth_35"]),
        "error: trials.opt_in.conditions: unknown condition 'multi_step_truth_35' (not in "
        "trials.conditions; did you mean 'multi_step_truth_3_5'?)",
    ),
    "an oracle opt-in": (
        lambda p: p["trials"]["opt_in"].update(conditions=["oracle_10"]),
        "error: trials.opt_in.conditions: 'oracle_10' is a search oracle's row",
    ),
    "a thesis row opt-in": (
        lambda p: p["trials"]["opt_in"].update(conditions=["single_step_10"]),
        "error: trials.opt_in.conditions: 'single_step_10' runs Table 6.3's thesis row "
        "single_step/10 (the README's results at a glance quote it)",
    ),
    "an opt-in row replayed": (
        lambda p: p["noise"].update(conditions=["multi_step_truth_10"]),
        "error: noise.conditions: 'multi_step_truth_10' is opt-in and not run",
    ),
    "unknown model of a run": (
        lambda p: p["evaluate"]["runs"]["fcn8s_ch5"].update(model="fcn8"),
        "error: evaluate.runs.fcn8s_ch5.model: unknown model 'fcn8' (not in train.models",
    ),
    "unknown dataset of a model": (
        lambda p: p["train"]["models"]["fcn8s"].update(dataset="ch_5"),
        "error: train.models.fcn8s.dataset: unknown dataset 'ch_5' (not in generate.datasets",
    ),
    "unknown section": (
        lambda p: p.update(trails={"workers": 1}),
        "error: trails: unknown section; no stage or command reads it (did you mean 'trials'?)",
    ),
    "one scale profile's value": (
        _scale_only,
        "error: generate.datasets.ch5.n_scenes: 0 is out of range (must be >= 1) (scale tiny)",
    ),
    "a network's field": (
        lambda p: _rename(p["train"]["models"]["cp_focal"]["net"], "output_stride", "outpt_stride"),
        "error: train.models.cp_focal.net.outpt_stride: unknown key (allowed: ",
    ),
}


@pytest.mark.parametrize("mistake", MISTAKES)
def test_a_mistake_is_one_line_naming_its_key(tmp_path: Path, mistake: str) -> None:
    edit, expected = MISTAKES[mistake]
    code, errors, out = _check(str(_params_with(tmp_path, edit)))
    assert code == 2 and out == ""
    assert len(errors) == 1 and errors[0].startswith(expected), errors


def test_every_problem_is_named_not_just_the_first(tmp_path: Path) -> None:
    """Several in one section (where a stage's parse stops at the first) and in another."""

    def seven(p: dict[str, Any]) -> None:
        _rename(p["trials"]["ch6"], "max_steps", "max_stepz")
        p["trials"]["ch6"]["pull_increment_m"] = -0.02
        for name in ("oracle", "oracle_hold"):
            p["trials"]["conditions"][name].update(planner="nope", episodes=0)
        p["detector"]["lr"] = 0

    code, errors, _ = _check(str(_params_with(tmp_path, seven)))
    assert code == 2
    assert [e.split(":")[1].strip() for e in errors] == [
        "trials.ch6.max_stepz",
        "trials.ch6.pull_increment_m",
        "trials.conditions.oracle.episodes",
        "trials.conditions.oracle_hold.episodes",
        "trials.conditions.oracle.planner",
        "trials.conditions.oracle_hold.planner",
        "detector.lr",
    ], errors


def test_bad_yaml_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("base:\n  seed: 0\n trials: [\n")
    code, errors, _ = _check(str(path))
    assert code == 2 and len(errors) == 1, errors
    assert "is not valid YAML: " in errors[0] and "(line 3, column 2)" in errors[0]


def test_a_bad_spec_is_one_line_naming_the_file(tmp_path: Path) -> None:
    spec = json.loads(STACK3.read_text())
    spec["boxes"][1]["pose"] = spec["boxes"][1]["pose"][:3]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(spec))
    code, errors, _ = _check(str(ROOT / "params.yaml"), "--spec", str(STACK3), "--spec", str(path))
    assert code == 2 and len(errors) == 1, errors
    assert errors[0].startswith(f"error: {path}: box 1: pose: expected a list of 7"), errors


# -- the registry is complete -----------------------------------------------------------------
def load_section_calls(text: str) -> list[tuple[str, str]]:
    """(class name, section) of every load_section(Cls, "section", ...) call in a source."""
    out = []
    for node in ast.walk(ast.parse(text)):
        if not (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "load_section"):
            continue
        cls, section = node.args[:2]
        if isinstance(cls, ast.Name) and isinstance(section, ast.Constant):
            out.append((cls.id, section.value))
    return out


def unregistered(calls: list[tuple[str, str]], registry: dict[str, type]) -> list[str]:
    """The calls whose section is not the registry's (a top-level section with that class,
    or a field of that class below one: "yamakuzushi.pile")."""
    out = []
    for name, section in calls:
        top, *path = section.split(".")
        cls: Any = registry.get(top)
        for part in path:
            cls = typing.get_type_hints(cls).get(part) if cls is not None else None
        if getattr(cls, "__name__", None) != name:
            out.append(f"{name} {section}")
    return out


def test_every_loaded_section_is_checked() -> None:
    files = [*(ROOT / "stages").glob("*.py"), *(ROOT / "src").rglob("*.py")]
    calls = [c for f in files for c in load_section_calls(f.read_text())]
    assert len({s for _, s in calls}) > 20  # the scan finds the stages' calls
    assert unregistered(calls, sections()) == []


def test_an_unregistered_section_is_found() -> None:
    stage = 'cfg = load_section(FooConfig, "foo", params)\n'
    stage += 'pile = load_section(PileConfig, "yamakuzushi.pile", params)\n'
    stage += 'scan = load_section(PileConfig, "yamakuzushi.scan", params)\n'
    assert unregistered(load_section_calls(stage), sections()) == [
        "FooConfig foo",
        "PileConfig yamakuzushi.scan",
    ]


def test_every_section_of_the_registry_is_in_params() -> None:
    assert set(sections()) == set(PARAMS)
