"""The collapse predictor's pull head: pull labels (the truth maps' definition),
datasets with a channel per label kind, a two-head network trained, saved and read per
head, the config's one-line errors, and the pull rows' plumbing (support thresholds per
head, the decomposition's pull chain)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from clutterbench.collapse.config import TrainConfig
from clutterbench.collapse.predict import CollapsePredictor, forward_logits
from clutterbench.collapse.train import TrainPaths, train_model
from clutterbench.config import parse
from clutterbench.criteria import CollapseFreeConfig, collapsed
from clutterbench.data.dataset import CollapseDataset, open_pairs
from clutterbench.data.labels import collapse_mask, pull_collapse_matrix, pull_moved_matrix
from clutterbench.data.split import Fractions, split_dataset
from clutterbench.data.synthetic import write_synthetic_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, read_json
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint

SIZE, THRESHOLD = 64, 0.005  # 64: a batch of one still has 2x2 maps at 1/32
NET = {
    "input_size": SIZE,
    "encoder": {"width": 0.0625},
    "mask_channels": [4, 4, 4, 4, 4],
    "decoder_channels": [8, 8, 4, 4, 4],
    "output_stride": 4,
}


def test_pull_labels_count_leaving_the_shelf_and_nan_is_no_move():
    disp = np.array(
        [
            [np.nan, 0.004, 0.006, np.nan],
            [0.001, np.nan, np.nan, 0.0],
            [0.02, 0.0, np.nan, 0.005],
            [np.nan, 0.0, 0.0, np.nan],
        ]
    )
    left = np.zeros((4, 4), bool)
    left[1, 2] = True  # NaN displacement but off the shelf: moved
    left[3, 3] = True  # the pulled box itself never counts
    moved = pull_moved_matrix(disp, left, THRESHOLD)
    expect = np.zeros((4, 4), bool)
    expect[0, 2] = expect[1, 2] = expect[2, 0] = True  # 0.005 is not beyond 5 mm
    assert np.array_equal(moved, expect)


CF = CollapseFreeConfig(drop_m=0.010, tilt_deg=15.0)


def test_pull_collapse_labels_are_what_a_trial_calls_a_collapse():
    """Hand cases, then every entry of random outcomes against criteria.collapsed (the
    function that judges the trials), so both mean the same thing."""
    drop = np.array([[np.nan, 0.011, 0.010], [0.0, np.nan, -0.02], [0.0, 0.002, np.nan]])
    tilt = np.array([[np.nan, 0.0, 15.0], [15.1, np.nan, 0.0], [np.nan, 90.0, np.nan]])
    left = np.zeros((3, 3), bool)
    left[1, 2] = True  # rose, no tilt, but off the shelf
    left[2, 2] = True  # the pulled box itself never counts
    got = pull_collapse_matrix(drop, tilt, left, (CF.drop_m, CF.tilt_deg))
    expect = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], bool)  # 10 mm, 15 deg: not beyond
    assert np.array_equal(got, expect)
    rng = np.random.default_rng(0)
    n = 12
    drop, tilt = rng.uniform(-0.02, 0.03, (n, n)), rng.uniform(0, 40, (n, n))
    left = rng.random((n, n)) < 0.1
    got = pull_collapse_matrix(drop, tilt, left, (CF.drop_m, CF.tilt_deg))
    for x in range(n):
        for y in range(n):
            entry = {
                "held": False,
                "drop_m": drop[x, y],
                "tilt_change_deg": tilt[x, y],
                "left_shelf": bool(left[x, y]),
            }
            assert got[x, y] == (x != y and collapsed(entry, CF)), (x, y)


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pull")
    write_synthetic_dataset(root / "gen", "po", 8, 4, SIZE, (3, 5), pull_outcomes=True)
    write_synthetic_dataset(root / "gen", "plain", 4, 4, SIZE, (3, 5))
    for name in ("po", "plain"):
        split_dataset(name, Fractions(0.5, 0.5, 0.0), 0, root / "gen", root / "split")
    return root


def open_ds(data: Path, name: str = "po", **kw) -> CollapseDataset:
    return CollapseDataset(data / "gen", data / f"split/{name}.json", "train", THRESHOLD, **kw)


def test_the_dataset_gives_one_channel_per_label_kind_in_order(data):
    both = open_ds(data, labels=("deletion", "pull"))
    rev = open_ds(data, labels=("pull", "deletion"))
    deletion = open_ds(data)
    shard = load_npz(data / "gen/po/shard-00000.npz")
    checked = 0
    for i in range(len(both)):
        item, s_x = both[i], both.pairs[i]
        assert item["collapse"].shape == (2, SIZE, SIZE)
        assert torch.equal(item["collapse"][:1], deletion[i]["collapse"])
        assert torch.equal(rev[i]["collapse"], item["collapse"].flip(0))
        scene = int(both.scenes["scene_index"][int(s_x[0])])
        if scene >= len(shard["scene_index"]):
            continue
        n, x = int(shard["n_objects"][scene]), int(s_x[1])
        moved = pull_moved_matrix(
            shard["pullout_displacement_m"][scene, :n, :n],
            shard["pullout_left_shelf"][scene, :n, :n],
            THRESHOLD,
        )[x]
        expect = collapse_mask(shard["instance"][scene], moved)
        assert np.array_equal(item["collapse"][1].numpy(), expect)
        checked += 1
    assert checked > 0
    # the two kinds differ somewhere, else the test could not tell them apart
    assert any(
        not torch.equal(both[i]["collapse"][0], both[i]["collapse"][1]) for i in range(len(both))
    )


def test_the_pull_collapse_channel_marks_what_the_pull_collapses(data):
    three = open_ds(
        data, labels=("deletion", "pull", "pull_collapse"), collapse_free=(CF.drop_m, CF.tilt_deg)
    )
    shard = load_npz(data / "gen/po/shard-00000.npz")
    checked = 0
    for i in range(len(three)):
        item, s_x = three[i], three.pairs[i]
        assert item["collapse"].shape == (3, SIZE, SIZE)
        scene = int(three.scenes["scene_index"][int(s_x[0])])
        if scene >= len(shard["scene_index"]):
            continue
        n, x = int(shard["n_objects"][scene]), int(s_x[1])
        fell = pull_collapse_matrix(
            *(shard[k][scene, :n, :n] for k in ("pullout_drop_m", "pullout_tilt_deg")),
            shard["pullout_left_shelf"][scene, :n, :n],
            (CF.drop_m, CF.tilt_deg),
        )[x]
        expect = collapse_mask(shard["instance"][scene], fell)
        assert np.array_equal(item["collapse"][2].numpy(), expect)
        checked += 1
    assert checked > 0
    assert any(
        not torch.equal(three[i]["collapse"][1], three[i]["collapse"][2]) for i in range(len(three))
    )
    with pytest.raises(ClutterbenchError, match="trials.collapse_free"):
        open_ds(data, labels=("pull_collapse",))


def test_pull_labels_without_pull_outcomes_are_a_one_line_error(data):
    with pytest.raises(ClutterbenchError) as err:
        open_ds(data, "plain", labels=("deletion", "pull"))
    msg = str(err.value)
    assert "\n" not in msg and "'plain'" in msg and "generate.datasets.plain.pull_outcomes" in msg
    with pytest.raises(ClutterbenchError, match="at most once"):
        open_ds(data, labels=("pull", "pull"))
    with pytest.raises(ClutterbenchError, match="own"):
        open_pairs(2, data / "gen", data / "split/po.json", "train", THRESHOLD, labels=("pull",))


def _params(**model) -> dict:
    m = {"arch": "collapse_map", "dataset": "po", "batch_size": 4, "lr": 1e-2, "epochs": 1}
    m |= {"loss": "focal", "net": dict(NET), "labels": ["deletion", "pull"]} | model
    return {"models": {"m": m}, "precision": "fp32", "channels_last": False}


@pytest.mark.parametrize(
    "change, key",
    [
        ({"labels": ["deletion", "push"]}, r"train\.models\.m\.labels: push is no label kind"),
        ({"labels": []}, r"train\.models\.m\.labels: none is no label kind"),
        ({"labels": ["pull", "pull"]}, r"train\.models\.m\.labels: .* twice"),
        ({"loss": "ce"}, r"train\.models\.m\.loss: ce does not fit labels"),
        (
            {"net": NET | {"n_masks": 2, "n_classes": 4}, "loss": "ce"},
            r"train\.models\.m\.labels: .* one input mask",
        ),
        ({"arch": "fcn8s", "net": {"input_size": SIZE}}, r"train\.models\.m\.labels: .* arch"),
        ({"net": NET | {"n_classes": 3}}, r"train\.models\.m\.net\.n_classes: labels"),
    ],
)
def test_bad_heads_are_one_line_errors_naming_the_param(change, key):
    with pytest.raises(ClutterbenchError, match=key) as err:
        parse(TrainConfig, _params(**change), "train")
    assert "\n" not in str(err.value)


def test_the_default_labels_keep_one_deletion_channel():
    cfg = parse(TrainConfig, _params(labels=["deletion"]), "train")
    assert cfg.models["m"].labels == ("deletion",) and cfg.models["m"].net.n_classes == 1
    two = parse(TrainConfig, _params(), "train")
    assert two.models["m"].net.n_classes == 2  # one sigmoid channel per head


def _train(data: Path, tmp_path: Path, **model) -> tuple[dict, Path]:
    cfg = parse(TrainConfig, _params(**model), "train")
    paths = TrainPaths(
        gen_dir=data / "gen",
        split_file=data / "split/po.json",
        model_dir=tmp_path / "models/m",
        report_dir=tmp_path / "reports/m",
        timing_file=tmp_path / "timing.json",
    )
    return train_model("m", cfg, THRESHOLD, 0, paths), paths.model_dir / "best.pt"


def test_a_two_head_network_trains_and_its_checkpoint_loads_per_head(data, tmp_path):
    summary, path = _train(data, tmp_path)
    assert summary["heads"] == ["deletion", "pull"]
    for k in ("val_iou_deletion", "val_iou_pull", "val_loss_deletion", "val_loss_pull"):
        assert k in summary["best"]
    best = summary["best"]  # the summed val loss picks the epoch
    assert best["val_loss"] == pytest.approx(best["val_loss_deletion"] + best["val_loss_pull"])
    log = (tmp_path / "reports/m/log.csv").read_text().splitlines()[0].split(",")
    assert "val_iou_pull" in log and "val_loss_deletion" in log
    ckpt = load_checkpoint(path)
    assert checkpoint_heads(ckpt) == ("deletion", "pull") and ckpt.net.n_classes == 2

    by_head = {
        h: CollapsePredictor.from_checkpoint(path, image_size=SIZE, head=h, precision="fp32")
        for h in ("deletion", "pull")
    }
    ds = open_ds(data)
    depth, mask = ds[0]["depth_m"][0].numpy(), ds[0]["target"].numpy()
    heat = {h: p(depth, mask) for h, p in by_head.items()}
    model = ckpt.model()
    with torch.no_grad():
        logits = forward_logits(model, ds[0]["depth_m"][None], ds[0]["target"][None], False, False)
    for k, h in enumerate(("deletion", "pull")):
        assert heat[h].shape == (1, SIZE, SIZE)
        np.testing.assert_allclose(heat[h][0], torch.sigmoid(logits[0, k]).numpy(), atol=1e-5)
    assert not np.allclose(heat["deletion"], heat["pull"])


def test_a_deletion_network_records_no_heads_and_has_no_pull_head(data, tmp_path):
    summary, path = _train(data, tmp_path, labels=["deletion"])
    ckpt = load_checkpoint(path)
    # as before heads: nothing new in the checkpoint, the summary or the log
    assert "heads" not in ckpt.meta and "labels" not in ckpt.meta["train"]
    assert "heads" not in summary and "val_iou_pull" not in summary["best"]
    assert checkpoint_heads(ckpt) == ("deletion",)
    assert "val_iou_deletion" not in read_json(tmp_path / "reports/m/summary.json")["best"]
    with pytest.raises(ClutterbenchError) as err:
        CollapsePredictor.from_checkpoint(path, image_size=SIZE, head="pull")
    assert "\n" not in str(err.value) and "no 'pull' head" in str(err.value)


def test_pull_planners_read_the_pull_heads_thresholds():
    from clutterbench.trials.ch6.planners import planner_info

    for name in ("multi_step_pull", "bimanual_pull", "multi_step_box", "bimanual_box_physics"):
        planner = planner_info(name)
        assert planner.support_method("coverage_gap") == "pull_coverage_gap"
        assert planner.support_method("coverage", "collapse") == "pull_collapse_coverage"
    for name in ("multi_step", "bimanual", "multi_step_pull_truth"):
        planner = planner_info(name)
        assert planner.support_method("coverage_gap") == "coverage_gap"
        assert planner.support_method("coverage_gap", "collapse") == "coverage_gap"


def test_a_method_name_says_its_head_and_rule():
    from clutterbench.support.evaluate import head_prefix, method_head

    for head in ("deletion", "pull", "pull_collapse"):
        for rule in ("coverage", "oracle_coverage_gap", "random"):
            assert method_head(head_prefix(head) + rule) == (head, rule)


def test_the_decomposition_has_a_pull_chain_beside_the_deletion_chain():
    from clutterbench.report.decomposition import decompose

    def records(planner: str, wins: int, n: int = 10) -> list[dict]:
        return [
            {"planner": planner, "stream": "s", "episode": e, "success": e < wins} for e in range(n)
        ]

    by_condition = {
        name: records(name, wins)
        for name, wins in (
            ("multi_step", 3),
            ("multi_step_truth", 4),
            ("multi_step_pull_truth", 7),
            ("multi_step_pull", 5),
            ("oracle", 8),
        )
    }
    rows = {r["planner"]: r for r in decompose(by_condition)}
    pull = rows["multi_step_pull"]
    assert pull["planning"] == pytest.approx(10.0)  # oracle - pull truth
    assert pull["perception"] == pytest.approx(20.0)  # pull truth - pull CP
    assert pull["pull_truth_condition"] == "multi_step_pull_truth" and pull["truth_pct"] is None
    assert "meaning" not in pull and rows["multi_step"]["meaning"] == pytest.approx(30.0)


def test_support_scenes_carry_the_pull_truth_and_pull_rows_draw_no_random_edges():
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.support.evaluate import evaluate_scene, scene_from_arrays

    instance = np.zeros((1, 16, 16), np.uint8)
    instance[0, 8:16, 0:6], instance[0, 8:16, 6:12], instance[0, 0:8, 0:12] = 1, 2, 3
    nan = np.nan
    arrays = {
        "scene_index": np.array([7]),
        "n_objects": np.array([3]),
        "family": np.array(["stacked"]),
        "depth_m": np.full((1, 16, 16), 0.6, np.float32),
        "instance": instance,
        "removal_m": np.array([[[nan, 0.0, 0.02], [0.0, nan, 0.0], [0.0, 0.0, nan]]]),
        "contact": np.ones((1, 3, 3), bool),
        # pulling box 1 drags box 2 (it rests on it) and pushes box 0 off the shelf
        "pullout_displacement_m": np.array([[[nan, 0.0, 0.02], [nan, nan, 0.03], [0, 0, nan]]]),
        "pullout_left_shelf": np.array([[[0, 0, 0], [1, 0, 0], [0, 0, 0]]], bool),
        # ... and of those, box 2 slides level (no collapse); pulling 0 tips box 2
        "pullout_drop_m": np.array([[[nan, 0.0, 0.0], [nan, nan, 0.001], [0, 0, nan]]]),
        "pullout_tilt_deg": np.array([[[nan, 0.0, 40.0], [nan, nan, 2.0], [0, 0, nan]]]),
    }
    heads = ("pull", "pull_collapse")
    scene = scene_from_arrays(arrays, 0, THRESHOLD, 5, heads=heads, collapse_free=(0.01, 15.0))
    assert scene.true_edges == {(0, 2)}  # deletion: only removing box 0 moves box 2
    pull = scene.view("pull")
    assert pull.true_edges == {(0, 2), (1, 0), (1, 2)}
    assert scene.view("pull_collapse").true_edges == {(0, 2), (1, 0)}
    assert scene.view("deletion") is scene
    assert scene_from_arrays(arrays, 0, THRESHOLD, 5).moved_by == {}
    params = SupportParams("coverage", 0.5, 0.1, 2, 0.0)
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    heat = np.zeros((3, 16, 16), np.float32)
    rows, edges = evaluate_scene(pull, heat, {"pull_oracle_coverage": params}, None, rng)
    assert [r["method"] for r in rows] == ["pull_oracle_coverage"] and "random" not in edges
    assert rows[0]["n_true"] == 3 and rng.bit_generator.state == state


def test_an_evaluate_run_names_a_known_head():
    from clutterbench.collapse.config import EvaluateConfig

    run = {"model": "m", "dataset": "d", "val_dataset": "d"}
    cfg = parse(EvaluateConfig, {"threshold": 0.5, "runs": {"r": run | {"head": "pull"}}}, "e")
    assert (
        cfg.runs["r"].head == "pull"
        and parse(EvaluateConfig, {"threshold": 0.5, "runs": {"r": run}}, "e").runs["r"].head
        == "deletion"
    )
    with pytest.raises(ClutterbenchError, match=r"e\.runs\.r: head: 'push'") as err:
        parse(EvaluateConfig, {"threshold": 0.5, "runs": {"r": run | {"head": "push"}}}, "e")
    assert "\n" not in str(err.value)
