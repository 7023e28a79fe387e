"""Labels are a function of the scene: replaying any stored scene's action, through the API
or the CLI, reproduces its stored displacements bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from clutterbench.cli import app
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.io import load_npz
from clutterbench.sim.config import FAMILY_NAMES, SimConfig
from clutterbench.sim.labelling import act_on_spec
from clutterbench.sim.spec import SceneSpec


def stored(out, name: str, ds: DatasetConfig, sim: SimConfig) -> list[dict]:
    gen = GenerateConfig(shard_size=10, workers=1, max_attempts=30, datasets={name: ds})
    manifest = generate_dataset(name, ds, gen, sim, 0, out / name)
    scenes = []
    for shard in manifest["shards"]:
        z = load_npz(out / name / shard)
        for k in range(len(z["scene_index"])):
            scenes.append({key: z[key][k] for key in z if key != "config_hash"})
    return scenes


@pytest.fixture(scope="module")
def shards(tmp_path_factory, camera):
    out = tmp_path_factory.mktemp("replay")
    sim = SimConfig(camera=camera)
    removal = [  # two scenes of every family, each family its own stream
        stored(
            out,
            name,
            DatasetConfig(n_scenes=2, families={name: 1.0}, catalogue="various", n_objects=(5, 8)),
            sim,
        )
        for name in FAMILY_NAMES
    ]
    pulls = DatasetConfig(
        n_scenes=2, families={"pile": 1.0}, catalogue="same", n_objects=(4, 4), pulls=True
    )
    return sim, [s for part in removal for s in part], stored(out, "pulls", pulls, sim)


def test_stored_scenes_of_every_family_replay_exactly(shards):
    sim, scenes, _ = shards
    assert {str(s["family"]) for s in scenes} == set(FAMILY_NAMES)
    for s in scenes:
        spec = SceneSpec.from_json(str(s["spec_json"]))
        n = spec.n
        replayed = np.array([act_on_spec(spec, sim.physics, "remove", x) for x in range(n)])
        assert np.array_equal(replayed, s["removal_m"][:n, :n], equal_nan=True), s["family"]
        assert s["removal_m"][:n, :n].dtype == np.float64


def test_stored_pulls_with_support_replay_exactly(shards):
    sim, _, scenes = shards
    for s in scenes:
        spec = SceneSpec.from_json(str(s["spec_json"]))
        n, n_max = spec.n, s["pull_m"].shape[0]  # (n_max, n_max + 1, n_max)
        for x, sup in [(0, None), (1, 2), (3, 0)]:
            disp = act_on_spec(spec, sim.physics, "pull", x, sup)
            slot = n_max if sup is None else sup
            if sup is not None:
                disp[sup] = np.nan
            assert np.array_equal(disp, s["pull_m"][x, slot, :n], equal_nan=True)


def test_cli_replays_a_stored_label(shards, tmp_path, monkeypatch):
    sim, scenes, _ = shards
    monkeypatch.chdir(tmp_path)  # no params.yaml: physics defaults, as the shards used
    s = next(s for s in scenes if str(s["family"]) == "stacked")
    spec = SceneSpec.from_json(str(s["spec_json"]))
    spec.save(tmp_path / "scene.json")
    for x in range(spec.n):
        result = CliRunner().invoke(app, ["scene", "act", "scene.json", "--remove", str(x)])
        assert result.exit_code == 0, result.output
        got = [o["displacement_m"] for o in json.loads(result.stdout)["objects"]]
        want = s["removal_m"][x, : spec.n]
        assert all(g is None if np.isnan(w) else g == w for g, w in zip(got, want))


def test_stacked_removals_move_something_and_clusters_cover_every_box(shards):
    _, scenes, _ = shards
    for s in scenes:
        n = int(s["n_objects"])
        cluster_of = s["cluster_of"][:n]
        assert np.all(cluster_of >= 0) and np.all(s["cluster_of"][n:] == -1)
        k = int(cluster_of.max()) + 1
        assert np.all(s["cluster_class"][:k] >= 0) and np.all(s["cluster_class"][k:] == -1)
        assert np.all(s["contact"][:n, :n] == s["contact"][:n, :n].T)
        if str(s["family"]) in ("stacked", "pile"):
            # a stack's bottom box carries others: some removal must move a box
            assert np.nanmax(s["removal_m"][:n, :n]) > 0.005, s["family"]


def test_stored_pull_outcomes_replay_as_the_trials_pull(tmp_path, camera):
    """The pull-outcome labels: the stored outcome of pulling each box is what the trials' executor
    does from the stored start, bit for bit; without the trials' pull the stage refuses."""
    from clutterbench.errors import ClutterbenchError
    from clutterbench.sim.pull import SceneState, execute_pull, world_at

    sim = SimConfig(camera=camera)
    ds = DatasetConfig(
        n_scenes=1,
        families={"stacked": 1.0},
        catalogue="various",
        n_objects=(3, 4),
        pull_outcomes=True,
    )
    pull = (0.02, 0.003)
    gen = GenerateConfig(shard_size=10, workers=1, max_attempts=30, datasets={"po": ds})
    manifest = generate_dataset("po", ds, gen, sim, 0, tmp_path / "po", pull)
    z = load_npz(tmp_path / "po" / manifest["shards"][0])
    spec = SceneSpec.from_json(str(z["spec_json"][0]))
    n = spec.n
    for x in range(n):
        result = execute_pull(world_at(spec, SceneState.start(spec), sim.physics), x, None, *pull)
        shift = np.linalg.norm(result.poses_end[:, :3] - result.poses_start[:, :3], axis=1)
        shift[x] = np.nan
        assert np.array_equal(z["pullout_displacement_m"][0, x, :n], shift, equal_nan=True)
        left = ~result.on_shelf
        left[x] = False
        assert np.array_equal(z["pullout_left_shelf"][0, x, :n], left)
    with pytest.raises(ClutterbenchError, match="pull_outcomes needs the trials' pull"):
        generate_dataset("po2", ds, gen, sim, 0, tmp_path / "po2")


def test_the_test_sets_deletions_replay_to_the_labels_and_say_what_collapsed(physics):
    """deletion_outcomes on a three-box stack: each replayed deletion moves the boxes exactly
    as the labels say (removal_matrix), deleting the bottom box drops both others (a
    deletion_collapse), deleting the top one collapses nothing."""
    from clutterbench.data.testset import deletion_outcomes
    from clutterbench.data.testset_load import labels
    from clutterbench.sim.labelling import removal_matrix
    from clutterbench.sim.spec import SceneSpec

    spec = SceneSpec.load(Path(__file__).resolve().parents[1] / "data" / "stack3.json")
    arrays = {
        "n_objects": np.array([3]),
        "sizes_m": spec.sizes_m[None].astype(np.float32),
        "poses": np.asarray(spec.poses)[None],
        "deletion_displacement_m": removal_matrix(
            SceneSpec(sizes_m=spec.sizes_m.astype(np.float32).astype(float), poses=spec.poses),
            physics,
        )[None],
    }
    replay = deletion_outcomes(arrays, physics)
    assert replay == {"displacements_equal": 6, "of": 6}
    ts = arrays | {"manifest": {"thresholds": {"moved_m": 0.005, "drop_m": 0.01, "tilt_deg": 15}}}
    collapse = labels(ts, "deletion_collapse")[0]
    assert collapse[0, 1] and collapse[0, 2] and not collapse[2].any()
    assert arrays["deletion_drop_m"][0, 0, 2] > 0.015
