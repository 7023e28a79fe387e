"""The benchmark scenes (data/benchmark/, sim/benchmark.py): committed, pinned, complete for
every table of the tiny and default profiles, and what the trials and environments start from."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from clutterbench.cli.benchmark_scenes import scale_jobs, start_of, target_key
from clutterbench.config import load_params
from clutterbench.errors import ClutterbenchError
from clutterbench.sim import benchmark, labelling, pile

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def at_root(monkeypatch):
    """The repository's own artifact, as a stage run in the repository reads it."""
    monkeypatch.chdir(ROOT)
    monkeypatch.delenv(benchmark.ENV, raising=False)
    monkeypatch.setattr(benchmark, "_STORE", None)
    yield benchmark.store()
    benchmark._STORE = None


@pytest.fixture
def no_live_draws(monkeypatch):
    """Every start must come from the artifact: a live draw fails the test."""

    def live(*args, **kwargs):
        raise AssertionError("drawn live: not in the benchmark scenes")

    monkeypatch.setattr(labelling, "_draw_settled_spec", live)
    monkeypatch.setattr(labelling, "_dataset_start", live)
    monkeypatch.setattr(pile, "_generate_pile", live)


def test_the_committed_artifact_is_the_pinned_one(at_root):
    """A regenerated artifact fails here until params.yaml pins its new hash (and nothing
    reads it before)."""
    pin = load_params(ROOT / "params.yaml")["benchmark"]["manifest_sha256"]
    manifest = ROOT / benchmark.DIR / benchmark.MANIFEST
    assert benchmark.file_sha256(manifest) == pin
    files = json.loads(manifest.read_text())["files"]
    assert set(files) == {p.name for p in (ROOT / benchmark.DIR).glob("*.jsonl")}
    assert sum(f["entries"] for f in files.values()) == len(at_root.entries)


@pytest.mark.parametrize("scale", ["tiny", "default"])
def test_every_table_start_and_target_is_in_the_artifact(scale, at_root, no_live_draws):
    jobs = scale_jobs(load_params(ROOT / "params.yaml"), scale)
    kinds = {j["kind"] for j in jobs}
    assert kinds == {"ch6", "ch4", "ch5", "support", "pile"}
    for job in jobs:
        start = start_of(job, target=False)
        if job["kind"] in ("ch6", "ch4"):
            assert target_key(job, start) in at_root.entries, (job["stream"], job["index"])
            assert benchmark.scene_fields(start)["scene_source"] == "benchmark"


def test_a_stage_starts_from_the_artifact_not_from_physics(at_root, monkeypatch):
    """Change a stored start: the trial and the environment start from the change."""
    from clutterbench.trials.core.streams import stream_source

    job = next(
        j
        for j in scale_jobs(load_params(ROOT / "params.yaml"), "tiny")
        if j["kind"] == "ch6" and j["stream"] == "ch6_3_10"
    )
    spec = start_of(job, target=False)
    source = stream_source("ch6_3_10", scale="tiny")
    env_spec, target = source.episode(job["index"])
    assert env_spec.to_json() == spec.to_json()
    assert target == at_root.entries[target_key(job, spec)]["target"]
    key = next(
        k for k, v in at_root.entries.items() if v.get("scene_hash") == benchmark.scene_hash(spec)
    )
    moved = json.loads(json.dumps(at_root.entries[key]))
    moved["spec"]["boxes"][0]["pose"][1] += 0.001  # 1 mm sideways
    monkeypatch.setitem(at_root.entries, key, moved)
    again = start_of(job, target=False)
    assert again.poses[0, 1] == spec.poses[0, 1] + 0.001
    from clutterbench.trials.core import streams

    monkeypatch.setattr(streams, "_SPECS", {})
    assert np.array_equal(source.spec(job["index"]).poses, again.poses)


def test_records_name_a_start_outside_the_artifact_as_drawn(at_root):
    from clutterbench.sim.spec import SceneSpec

    spec = SceneSpec.load(ROOT / "tests/data/stack3.json")
    assert benchmark.scene_fields(spec)["scene_source"] == "drawn"


def copy_project(tmp_path: Path) -> Path:
    root = tmp_path / "project"
    root.mkdir()
    for name in ("params.yaml", "dvc.yaml"):
        shutil.copy(ROOT / name, root / name)
    shutil.copytree(ROOT / benchmark.DIR, root / benchmark.DIR)
    return root


def test_a_changed_pin_or_file_is_one_line(tmp_path):
    root = copy_project(tmp_path)
    assert benchmark.load_store(root).entries
    first = sorted((root / benchmark.DIR).glob("*.jsonl"))[0]
    first.write_text(first.read_text().replace("0", "1", 1))
    with pytest.raises(ClutterbenchError, match=f"{first.name}: missing or not the file"):
        benchmark.load_store(root)
    params = (root / "params.yaml").read_text()
    pin = load_params(root / "params.yaml")["benchmark"]["manifest_sha256"]
    (root / "params.yaml").write_text(params.replace(pin, "f" * 64))
    with pytest.raises(ClutterbenchError, match="commit the new pin"):
        benchmark.load_store(root)
    shutil.rmtree(root / benchmark.DIR)
    with pytest.raises(ClutterbenchError, match="manifest.json missing"):
        benchmark.load_store(root)
    (root / "params.yaml").write_text(params.replace(pin, "0" * 64))
    with pytest.raises(ClutterbenchError, match="is not a sha256"):  # yaml reads it as 0
        benchmark.load_store(root)
    (root / "params.yaml").write_text(params.replace(pin, "null"))
    assert benchmark.load_store(root).entries == {}  # nothing pinned: every start drawn live


def test_off_draws_live(at_root, monkeypatch):
    monkeypatch.setenv(benchmark.ENV, "off")
    key, value = benchmark.lookup("settled", {"any": 1})
    assert value is None and not benchmark.active()
