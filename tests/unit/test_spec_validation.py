"""Scene spec validation: one line naming the box for anything a world cannot hold."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from clutterbench.cli import app
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import FAMILY_NAMES, CameraConfig
from clutterbench.sim.geometry import obb_penetration_m, quat_from_axis_angle
from clutterbench.sim.shelf import Shelf
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


# -- the JSON form: keys, types and shapes (check_spec_dict) -----------------------------------
def _set(*path_and_value):
    *path, key, value = path_and_value

    def edit(d):
        for p in path:
            d = d[p]
        d[key] = value

    return edit


def _pop(*path_and_key):
    *path, key = path_and_key

    def edit(d):
        for p in path:
            d = d[p]
        del d[key]

    return edit


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (_set("family", "heap"), "family: 'heap' is not one of shelved, stacked"),
        (_set("family", 3), "family: 3 is not one of"),
        (_set("colour", "red"), "unknown key 'colour' (allowed: version, family"),
        (_pop("shelf"), "missing key 'shelf'"),
        (_pop("boxes"), "missing key 'boxes'"),
        (_pop("camera"), "missing key 'camera'"),
        (_pop("version"), "missing key 'version'"),
        (_set("version", 2), "unsupported spec version 2"),
        (_set("boxes", []), "boxes: the list is empty"),
        (_set("boxes", {"0": {}}), "boxes: expected a list of boxes, got an object"),
        (_set("boxes", 1, 7), "box 1: expected an object, got a number (7)"),
        (_set("boxes", 1, "mass", 0.2), "box 1: unknown key 'mass' (allowed: size_m, pose"),
        (_pop("boxes", 2, "pose"), "box 2: missing key 'pose'"),
        (_pop("boxes", 0, "size_m"), "box 0: missing key 'size_m'"),
        (
            lambda d: d["boxes"][1].__setitem__("pose", d["boxes"][1]["pose"][:6]),
            "box 1: pose: expected a list of 7 numbers [x, y, z, qw, qx, qy, qz], got a list of 6",
        ),
        (_set("boxes", 2, "size_m", "0.1"), "box 2: size_m: expected a list of 3 numbers"),
        (
            _set("boxes", 2, "size_m", [0.1, "a", 0.1]),
            "box 2: size_m: expected a list of 3 numbers [depth x, width y, height z] (m), got a "
            "string ('a') in the list",
        ),
        (_set("boxes", 0, "pose", [True] * 7), "box 0: pose: expected a list of 7 numbers"),
        (_set("boxes", 0, "type", "big"), "box 0: type: expected a catalogue index"),
        (_set("boxes", 0, "type", -2), "box 0: type: expected a catalogue index"),
        (_set("boxes", 1, "density_kg_m3", "x"), "box 1: density_kg_m3: expected a number"),
        (_set("meta", [1]), "meta: expected an object, got a list of 1"),
        (_set("shelf", 0.33), "shelf: expected a mapping"),
        (_set("shelf", "depth", 0.3), "shelf.depth: unknown key"),
        (_set("shelf", "width_m", "wide"), "shelf.width_m: expected a number"),
        (_set("shelf", "height_m", -0.3), "shelf.height_m: -0.3 m must be positive"),
        (_set("camera", "image_size", -5), "camera.image_size: -5 is out of range (must be >= 16)"),
        (_set("camera", "image_size", "128"), "camera.image_size: expected an integer"),
        (_set("camera", "zoom", 2), "camera.zoom: unknown key"),
        (_set("camera", [128]), "camera: expected a mapping"),
    ],
)
def test_bad_key_type_or_shape_is_named(edit, message):
    d = stack3()
    edit(d)
    with pytest.raises(ClutterbenchError) as info:
        SceneSpec.from_dict(d)
    assert str(info.value).startswith(f"spec: {message}")
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[1, 2]", "a scene spec must be a JSON object, got a list of 2"),
        ('"stack3"', "a scene spec must be a JSON object, got a string"),
        ("null", "a scene spec must be a JSON object, got null"),
        ("{", "not valid JSON"),
    ],
)
def test_a_json_that_is_no_object_is_named(tmp_path, text, message):
    path = tmp_path / "s.json"
    path.write_text(text)
    with pytest.raises(ClutterbenchError) as info:
        SceneSpec.load(path)
    assert str(info.value).startswith(f"{path}: {message}")


def test_a_directory_or_a_missing_path_is_one_line(tmp_path):
    with pytest.raises(ClutterbenchError) as info:
        SceneSpec.load(tmp_path)
    assert str(info.value) == f"{tmp_path}: is a directory, not a scene spec (.json) file"
    with pytest.raises(ClutterbenchError, match="^scene spec not found: "):
        SceneSpec.load(tmp_path / "nope.json")


def test_every_family_and_optional_key_is_accepted():
    d = stack3()
    for family in (*FAMILY_NAMES, "stack", "custom"):
        d["family"] = family
        assert SceneSpec.from_dict(d).family == family
    for key in ("family", "meta"):
        del d[key]
    d["shelf"], d["camera"] = {}, {}  # every value defaults
    spec = SceneSpec.from_dict(d)
    assert (spec.family, spec.meta) == ("custom", {})
    assert (spec.shelf, spec.camera) == (Shelf(), CameraConfig())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (_set("family", "heap"), "family: 'heap' is not one of"),
        (_pop("shelf"), "missing key 'shelf'"),
        (_set("boxes", []), "boxes: the list is empty"),
        (
            lambda d: d["boxes"][1].__setitem__("pose", d["boxes"][1]["pose"][:6]),
            "box 1: pose: expected a list of 7 numbers",
        ),
        (_set("boxes", 2, "size_m", "0.1"), "box 2: size_m: expected a list of 3 numbers"),
        (_set("camera", "image_size", -5), "camera.image_size: -5 is out of range"),
        (lambda d: [d], "a scene spec must be a JSON object, got a list of 1"),
    ],
)
def test_every_command_refuses_a_bad_spec_with_one_line(tmp_path, monkeypatch, edit, message):
    monkeypatch.chdir(tmp_path)
    d = stack3()
    d = edit(d) or d
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    for args in (
        ["scene", "act", str(bad), "--remove", "0"],
        ["scene", "show", str(bad), "-o", "x.png"],
        ["plan", str(bad), "--target", "0"],
    ):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {bad}: "), lines
        assert message in lines[0]
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("what", ["directory", "missing"])
def test_every_command_refuses_a_directory_or_missing_spec(tmp_path, monkeypatch, what):
    monkeypatch.chdir(tmp_path)
    path = tmp_path if what == "directory" else tmp_path / "nope.json"
    message = "is a directory, not a scene spec" if what == "directory" else "scene spec not found"
    for args in (
        ["scene", "act", str(path), "--remove", "0"],
        ["scene", "show", str(path), "-o", "x.png"],
        ["plan", str(path), "--target", "0"],
    ):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], lines
