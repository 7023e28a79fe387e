"""Scene spec validation: one line naming the box for anything a world cannot hold."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from clutterbench.cli import app
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.geometry import obb_penetration_m, quat_from_axis_angle
from clutterbench.sim.spec import SceneSpec

STACK3 = Path(__file__).resolve().parents[1] / "data" / "stack3.json"
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def stack3() -> dict:
    return json.loads(STACK3.read_text())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["boxes"][1]["pose"].__setitem__(2, float("nan")), "box 1 has a NaN"),
        (lambda d: d["boxes"][2]["size_m"].__setitem__(0, 0.0), "box 2: size"),
        (lambda d: d["boxes"][0].__setitem__("pose", [0.14, 0, 0.01, 0, 0, 0, 0]), "box 0: quat"),
        (lambda d: d["boxes"][1]["pose"].__setitem__(1, 5.0), "box 1: centre"),
        (lambda d: d["boxes"][2].__setitem__("pose", list(d["boxes"][1]["pose"])), "boxes 1 and 2"),
        (lambda d: d["boxes"][0].__setitem__("density_kg_m3", -1.0), "box 0: density"),
    ],
)
def test_bad_box_is_named(edit, message):
    d = stack3()
    edit(d)
    with pytest.raises(ClutterbenchError, match=message):
        SceneSpec.from_dict(d)


def test_interpenetration_gives_the_depth():
    d = stack3()
    d["boxes"][2]["pose"][2] = d["boxes"][1]["pose"][2] + 0.015  # 5 mm into box 1
    with pytest.raises(ClutterbenchError, match=r"boxes 1 and 2 interpenetrate by 5\.0 mm"):
        SceneSpec.from_dict(d)


def test_near_unit_quaternion_is_normalized_exact_one_untouched():
    d = stack3()
    q = np.array(d["boxes"][0]["pose"][3:]) * 1.0005
    d["boxes"][0]["pose"][3:] = q.tolist()
    spec = SceneSpec.from_dict(d)
    assert np.linalg.norm(spec.poses[0, 3:]) == pytest.approx(1.0, abs=1e-12)
    exact = SceneSpec.from_dict(stack3())
    assert exact.poses.tolist() == [b["pose"] for b in stack3()["boxes"]]  # bits kept


def test_obb_penetration_hand_values():
    size = np.array([0.1, 0.1, 0.02])
    assert obb_penetration_m([0, 0, 0], IDENTITY, size, [0, 0, 0.015], IDENTITY, size) == (
        pytest.approx(0.005)
    )
    assert obb_penetration_m([0, 0, 0], IDENTITY, size, [0, 0, 0.021], IDENTITY, size) == 0.0
    # rotated 45 deg about z: corner reaches 0.05 * sqrt(2) from the centre along x
    q45 = quat_from_axis_angle([0, 0, 1], np.pi / 4)
    depth = obb_penetration_m([0, 0, 0], IDENTITY, size, [0.12, 0, 0], q45, size)
    assert depth == pytest.approx(0.05 + 0.05 * np.sqrt(2) - 0.12)


def test_cli_refuses_a_bad_spec_with_one_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    d = stack3()
    d["boxes"][2]["pose"] = list(d["boxes"][1]["pose"])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    for args in (
        ["scene", "act", str(bad), "--remove", "0"],
        ["scene", "show", str(bad), "-o", "x.png"],
    ):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "boxes 1 and 2 interpenetrate" in lines[0]
    assert not (tmp_path / "x.png").exists()
