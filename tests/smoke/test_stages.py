"""Stage smoke tests: the real stages, through dvc, on the tiny profile."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
import yaml

from clutterbench.collapse.config import EvaluateConfig, TrainConfig
from clutterbench.collapse.evaluate import SplitRef, evaluate_sets
from clutterbench.config import load_params, load_section
from clutterbench.crosscheck import copy_pipeline
from clutterbench.data.config import GenerateConfig
from clutterbench.data.dataset import CollapseDataset
from clutterbench.data.generate import generate_dataset
from clutterbench.logs.mcap_episode import read_episode
from clutterbench.models.checkpoint import load_checkpoint, save_checkpoint
from clutterbench.models.collapse_map import CollapseMapConfig, CollapseMapNet
from clutterbench.models.vgg import VGGConfig
from clutterbench.precision import resolve_precision
from clutterbench.report.config import ReportConfig
from clutterbench.sim.config import SimConfig
from clutterbench.trials.ch3.config import Ch3Config
from clutterbench.trials.ch6.planners import planner_info
from clutterbench.trials.condition_sets import NOT_RUN
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.protocol import EPISODE_ENDS
from clutterbench.trials.core.records import read_records

pytestmark = pytest.mark.slow


def tiny_copy(root: Path, dst: Path, cores: int | None = None) -> Path:
    return copy_pipeline(root, dst, "tiny", cores)


def run(cmd: list[str], cwd: Path, check: bool = True) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "DVC_NO_ANALYTICS": "1",
        "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
    }
    out = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    if check and out.returncode != 0:
        raise AssertionError(f"{cmd} failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    return out


def digest_tree(path: Path) -> dict[str, str]:
    return {
        str(p.relative_to(path)): hashlib.md5(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def repro_twice(root, tmp_path_factory):
    """Two tiny copies reproduced at the same time (most of a tiny stage is one process
    starting up and compiling its renderer's shaders, so two at once use both cores): `a` in
    two goes (generate + split, then the rest), `b` in one. Each at base.cores 1: every `auto`
    worker count and torch's threads are one, so no stage spawns workers that import
    everything again and wait for the core the other copy holds."""
    a = tiny_copy(root, tmp_path_factory.mktemp("a") / "repo", cores=1)
    b = tiny_copy(root, tmp_path_factory.mktemp("b") / "repo", cores=1)
    with ThreadPoolExecutor(1) as pool:
        whole = pool.submit(run, ["dvc", "repro"], b)
        run(["dvc", "repro", "generate", "split"], a)
        run(["dvc", "repro"], a)
        whole.result()
    return a, b


def test_dvc_repro_tiny_end_to_end(repro_twice):
    a, _ = repro_twice
    params = load_params(a / "params.yaml")
    gen = load_section(GenerateConfig, "generate", params)
    for name in gen.datasets:
        assert len(list((a / "data/generate" / name).glob("shard-*.npz"))) >= 1
        assert (a / "data/split" / f"{name}.json").exists()
    assert "ch6" in (a / "reports/tables/datasets.md").read_text()
    auto = resolve_precision("auto")  # bf16 only where this CPU runs it natively
    for name in load_section(TrainConfig, "train", params).models:
        meta = load_checkpoint(a / "models" / name / "best.pt").meta
        assert meta["name"] == name and meta["precision"] == auto
        assert (
            json.loads((a / "reports/train" / name / "summary.json").read_text())["precision"]
            == auto
        )
        episode = read_episode(a / "models" / name / "train.mcap")
        assert episode["topics"]["/train/epoch"] >= 1 and "outcome" in episode["metadata"]
        # wall times live outside dvc's outputs (reports/timing/), not in the train report
        assert "seconds" in (a / "reports/timing" / f"train_{name}.json").read_text()
        assert sorted(p.name for p in (a / "reports/train" / name).iterdir()) == [
            "log.csv",
            "summary.json",
        ]
    for table in ("table_5_1", "table_6_1"):
        frame = pd.read_csv(a / "reports/tables" / f"{table}.csv")
        assert "IoU (thesis)" in frame.columns
        assert not any("sweep" in c for c in frame.columns)  # nothing chosen on the test set
        ours = frame.dropna(subset=["IoU"])
        assert len(ours) >= 2 and ours["IoU"].between(0, 1).all()
        assert ours["IoU at val-chosen threshold"].between(0, 1).all()
        assert ours["val-chosen threshold"].between(0, 0.99).all()
        assert ours["differs from thesis"].str.contains(r"64 px \(thesis").all()
    # the box head's per-box table, and the test set with its leaderboard of baselines
    assert "box head (per box)" in (a / "reports/tables/table_6_1_boxes.md").read_text()
    manifest = json.loads((a / "data/testset/manifest.json").read_text())
    assert {"ch6_test", "benchmark:ch6_3_10"} <= set(manifest["sources"])
    replay = manifest["deletion_replay"]  # the deletions replayed, on the CPU that labelled them
    assert replay["of"] > 0 and replay["displacements_equal"] == replay["of"]
    board = (a / "reports/leaderboard/leaderboard.md").read_text()
    assert all(f"| {name} |" in board for name in ("box_head", "pull_truth", "constant"))
    # task noise: every Table 6.3 condition replayed, the robust oracles beside them
    noise = json.loads((a / "reports/noise/summary.json").read_text())["conditions"]
    assert {"oracle_robust", "oracle_hold_robust", "multi_step_pull"} <= set(noise)
    assert "perturbed worlds" in (a / "reports/tables/table_6_3.md").read_text()
    assert "oracle_hold_robust" in (a / "reports/tables/table_6_3_noise.md").read_text()
    # Table 6.1's row of the CP's pull head, on pull labels
    t61 = pd.read_csv(a / "reports/tables/table_6_1.csv")
    pull_row = t61[t61["network"].astype(str).str.contains("pull head")]
    assert len(pull_row) == 1 and pull_row["IoU"].between(0, 1).all()
    pull_metrics = json.loads(
        (a / "reports/evaluate/cp_focal_pull_ch6_test/metrics.json").read_text()
    )
    assert pull_metrics["head"] == "pull"
    heads = load_checkpoint(a / "models/cp_focal/best.pt").meta["heads"]
    assert heads == ["deletion", "pull", "pull_collapse"]
    collapse_metrics = json.loads(
        (a / "reports/evaluate/cp_focal_pull_collapse_ch6_test/metrics.json").read_text()
    )
    assert collapse_metrics["head"] == "pull_collapse"
    for run_dir in (a / "reports/evaluate").iterdir():
        assert json.loads((run_dir / "metrics.json").read_text())["network_precision"] == auto
        assert (run_dir / "figure.png").stat().st_size > 1000
        assert len((run_dir / "sweep.csv").read_text().splitlines()) == 101
        assert len((run_dir / "val_sweep.csv").read_text().splitlines()) == 101
    trials = load_section(TrialsConfig, "trials", params)
    ch4 = read_records(a / "reports/trials_ch4/records.jsonl")
    assert len(ch4) == sum(c.episodes for c in trials.ch4_conditions.values())
    # every table's episode starts from the committed benchmark scenes, on any CPU
    for records in (
        ch4,
        read_records(a / "reports/trials_ch5/records.jsonl"),
        read_records(a / "reports/trials_ch3/records.jsonl"),
        *(read_records(p) for p in sorted((a / "reports/trials").glob("*/records.jsonl"))),
    ):
        assert records and {r["scene_source"] for r in records} == {"benchmark"}
    for name in trials.ch4_conditions:
        assert (
            read_episode(a / "data/trials_ch4" / name / "episodes.mcap")["topics"]["/trial/outcome"]
            == trials.ch4_conditions[name].episodes
        )
    # the opt-in rows (trials.opt_in) are left out at tiny scale as at default: not run, not
    # replayed, and Table 6.3 says so
    skipped = trials.opt_in.skipped
    assert skipped and not any((a / "reports/trials" / name).exists() for name in skipped)
    assert not set(skipped) & set(noise)
    for name, cond in trials.run_conditions.items():
        records = read_records(a / "reports/trials" / name / "records.jsonl")
        assert len(records) == cond.episodes
        for rec in records:  # the episode protocol's named outcome on every step
            assert rec["end"] in EPISODE_ENDS
            for step in rec["steps"]:
                assert {"executed", "aborted_before_motion", "aborted_after_motion"} <= set(step)
                assert {"extracted", "others_still", "success", "success_held"} <= set(step)
                assert {"judged", "counted", "strict_counted", "collapse_free"} <= set(step)
                assert {"strict_success", "box_motion"} <= set(step)
                assert not (step["executed"] and step["aborted_before_motion"])
            # no step follows a (collapse-free) failed one; an abort that disturbed nothing
            # is no failure; the strict episode is a prefix, so strict implies collapse-free
            assert all(s["success"] is not False for s in rec["steps"][:-1])
            assert rec["success"] or not rec["strict_success"]
        topics = read_episode(a / "data/trials" / name / "episodes.mcap")["topics"]
        assert topics["/trial/outcome"] == cond.episodes
        # Foxglove's 3D panel: the scene as cubes and the camera the images project through
        assert topics.get("/scene", 0) >= cond.episodes, name
        assert topics.get("/camera/calibration", 0) >= cond.episodes, name
    for rec in ch4:
        assert {"executed", "aborted_before_motion", "success_held", "risk_ties"} <= set(rec)
        assert {"judged", "counted", "strict_success", "box_motion"} <= set(rec)
        assert rec["valid"] or not rec["success"]  # an invalid action is never a success
    assert (a / "reports/trials_ch4/fig_4_8.png").stat().st_size > 1000
    rows63 = load_section(ReportConfig, "report", params).table_6_3.values()
    n63 = sum(c not in skipped for c in rows63) + len(set(rows63) & set(trials.sensed.of))
    t63 = (a / "reports/tables/table_6_3.md").read_text().splitlines()
    assert sum(NOT_RUN in line for line in t63 if line.startswith("|")) == len(skipped)
    # Table 4.1: its cells and their sensed twins, then a total per method and sensor
    rows41 = trials.ch4_sensed.table_rows(load_section(ReportConfig, "report", params).table_4_1)
    n41 = len(rows41) + len({(r.split("/")[0], r.count("/")) for r in rows41})
    assert n41 == 24 + 8 + 6 + 2  # as params.yaml has it now: 8 twins of 2 methods
    for table, rows in (("table_4_1", n41), ("table_4_1_target", 3), ("table_6_3", n63)):
        frame = pd.read_csv(a / "reports/tables" / f"{table}.csv")
        assert len(frame) == rows and frame["success_rate"].between(0, 1).all(), table
    # Table 6.3 decomposed: every stream with a CP row, its truth-map row and its oracle,
    # under both criteria; planning (+ what the map predicts, where a pull-truth row ran) +
    # perception = the gap. The opt-in rows left out are the 3-5 and 10-box streams' truth
    # rows: there multi_step and multi_step_pull have no split (with them: 12 and 8 chains)
    chains, pull_chains = 8, 6
    dec = pd.read_csv(a / "reports/tables/table_6_3_decomposition.csv")
    assert len(dec) == 2 * chains and set(dec["key"]) == {"success", "strict_success"}
    parts = dec["planning"] + dec["meaning"].fillna(0.0) + dec["perception"]
    assert ((parts - dec["gap"]).abs() < 1e-9).all()
    pull_chain = dec["planner"].map(lambda p: planner_info(p).of_the_pull)
    # the pull head's and the box head's chains: oracle -> pull truth -> CP (multi_step_pull
    # on each stream with its pull-truth row, bimanual_pull, the four box planners)
    assert pull_chain.sum() == 2 * pull_chains
    assert dec[~pull_chain]["meaning"].notna().all()  # every CP row has its pull-truth row
    assert dec[pull_chain]["meaning"].isna().all()
    head = {"moved": "pull", "collapse": "pull_collapse"}[trials.ch6.pull_map_meaning]
    for name, cond in trials.conditions.items():
        if cond.planner in ("multi_step_pull", "bimanual_pull"):  # maps of that pull head
            recs = read_records(a / "reports/trials" / name / "records.jsonl")
            assert {r["collapse_maps"] for r in recs} == {f"predicted by the {head} head"}, name
            assert {r["support_method"] for r in recs} == {f"{head}_{cond.rule}"}, name
    # the physics-from-depth planner's estimates: one row per stream, and the figure
    est = pd.read_csv(a / "reports/tables/box_estimation.csv")
    assert set(est["stream"]) == {"ch6_3_5", "ch6_10", "ch6_3_10"}
    assert (est["estimated"] + est["missing"] == est["boxes"]).all()
    assert (a / "reports/trials/box_estimation.png").stat().st_size > 1000
    t62 = pd.read_csv(a / "reports/tables/table_6_2.csv")
    assert t62.astype(str).apply(lambda c: c.str.contains("physics from depth")).any().any()
    exact = t62[~t62.iloc[:, 0].str.contains("on d415 depth")]
    assert exact.iloc[:, 0].str.contains("CP pull head").sum() == 1  # against the pull truth
    chosen = json.loads((a / "reports/support/thresholds.json").read_text())["chosen"]
    assert {"pull_coverage_gap", "pull_collapse_coverage_gap"} <= set(chosen)
    # as a robot sees: sensed rows in Tables 6.2 and 6.3, the decomposition's sensing part,
    # the test set's sensed track
    sensed_choice = json.loads((a / "reports/support/thresholds.json").read_text())["sensed"]
    for name in trials.sensed.of:
        recs = read_records(a / "reports/trials" / f"{name}_{trials.sensed.sensing}/records.jsonl")
        assert {(r["sensing"], r["perception"]) for r in recs} == {("d415", "depth")}, name
        summary = json.loads(
            (a / "reports/trials" / f"{name}_{trials.sensed.sensing}/summary.json").read_text()
        )
        assert (summary["sensing"], summary["perception"]) == ("d415", "depth"), name
        # ... with the thresholds chosen on the val scenes as that sensor returned them
        cond = trials.stage_conditions([])[f"{name}_{trials.sensed.sensing}"]
        if planner_info(cond.planner).maps in ("deletion", "pull"):
            method = planner_info(cond.planner).support_method(
                cond.rule, trials.ch6.pull_map_meaning
            )
            assert summary["support"] == sensed_choice["d415"]["chosen"][method], name
    assert "sensing" in dec.columns and dec["sensing"].notna().any()
    assert t62.iloc[:, 0].str.contains("on d415 depth").sum() > 1
    sensed_set = json.loads((a / "data/testset_sensed/d415/manifest.json").read_text())
    assert (
        sensed_set["sensing"] == "d415"
        and sensed_set["sha256"]
        != json.loads((a / "data/testset/manifest.json").read_text())["sha256"]
    )
    t42 = pd.read_csv(a / "reports/tables/table_4_2.csv")
    assert len(t42) == 4
    # chapter 3: every variant's games, one row per slide, one MCAP per variant, Fig. 3.15
    ch3 = load_section(Ch3Config, "yamakuzushi", params)
    games = read_records(a / "reports/trials_ch3/records.jsonl")
    assert len(games) == len(ch3.games.variants) * ch3.games.n_games
    slides = read_records(a / "reports/trials_ch3/slides.jsonl")
    assert len(slides) == sum(len(g["steps"]) for g in games)
    for g in games:  # a game ends at its first failed slide
        assert all(s["success"] for s in g["steps"][:-1])
        assert g["pieces_removed"] == sum(s["success"] for s in g["steps"])
    for variant in ch3.games.variants:
        topics = read_episode(a / "data/trials_ch3" / variant / "episodes.mcap")["topics"]
        assert topics["/trial/outcome"] == ch3.games.n_games
    fig = pd.read_csv(a / "reports/tables/fig_3_15.csv")
    assert len(fig) == len(ch3.games.variants)
    assert (a / "reports/tables/fig_3_15.png").stat().st_size > 1000
    assert (a / "reports/train_slide/candidates.png").stat().st_size > 1000
    # arm-level conditions: the Pandas' records, joint states in the MCAP, the comparison
    trials = load_section(TrialsConfig, "trials", params)
    executed = 0
    for name, arm in trials.arm_conditions.items():
        recs = read_records(a / "reports/trials_arm" / name / "records.jsonl")
        assert len(recs) == arm.episodes and all(r["executor"] == "arm" for r in recs)
        steps = [s for r in recs for s in r.get("steps", [r])]
        assert all("arm_outcome" in s for s in steps), name
        # a tiny network may give up before its first step (no step, no arm motion);
        # otherwise the Pandas moved and their joint states are in the MCAP
        assert steps or all(r["end"] == "gave_up" for r in recs), name
        topics = read_episode(a / "data/trials_arm" / name / "episodes.mcap")["topics"]
        assert (topics.get("/arm/joint_states", 0) > 0) == bool(steps), name
        executed += len(steps)
    assert executed, "no arm-level condition executed a step (the ch. 4 one always pulls)"
    arm_vs = pd.read_csv(a / "reports/tables/arm_vs_kinematic.csv")
    assert list(arm_vs["condition"]) == list(trials.arm_conditions)
    status = run(["dvc", "status"], a).stdout
    assert "changed" not in status


def test_every_stage_leaves_its_wall_time_for_the_record(repro_twice):
    from clutterbench.bench.run_times import collect

    a, _ = repro_twice
    record = collect(a / "reports/timing/stages")
    assert set(record["groups"]) == set(yaml.safe_load((a / "dvc.yaml").read_text())["stages"])
    assert record["scale"] == "tiny" and record["total_minutes"] > 0


def test_same_params_give_byte_identical_data_and_tables(repro_twice):
    a, b = repro_twice
    trees = ("data", "models", "reports/train", "reports/evaluate", "reports/tables")
    more = ("reports/support", "reports/trials", "reports/trials_ch4", "reports/trials_ch3")
    more += ("reports/trials_arm", "reports/noise")
    for tree in (*trees, *more, "reports/train_slide", "reports/slides"):
        assert digest_tree(a / tree) == digest_tree(b / tree), tree


def _split(repo: Path, dataset: str, split: str) -> SplitRef:
    gen = load_section(GenerateConfig, "generate", load_params(repo / "params.yaml"))
    path = repo / "data/split" / f"{dataset}.json"
    return SplitRef(dataset, path, split, gen.datasets[dataset].moved_threshold_m)


@pytest.mark.parametrize("dataset", ["ch5", "ch6_test"])
def test_some_test_pairs_collapse(repro_twice, dataset):
    # Without a collapsing test pair every IoU is 0 or undefined and the tables say nothing.
    a, _ = repro_twice
    ds = _split(a, dataset, "test").load(a / "data/generate")
    assert any(ds[i]["collapse"].sum() > 0 for i in range(len(ds))), dataset


def test_perfect_predictor_scores_one_through_the_evaluation_path(repro_twice):
    a, _ = repro_twice
    cfg = load_section(EvaluateConfig, "evaluate", load_params(a / "params.yaml"))
    run = cfg.runs["cp_focal_ch6_test"]
    test_ds = _split(a, run.dataset, run.split).load(a / "data/generate")
    val_ds = _split(a, run.val_dataset, "val").load(a / "data/generate")
    cfg = dataclasses.replace(cfg, batch_size=4)  # several batches, a short last one

    perfect = evaluate_sets(test_ds, val_ds, lambda batch: batch["collapse"], cfg)
    m = perfect.metrics
    for key in ("pixel_accuracy", "iou", "precision", "recall"):
        assert m[key] == 1.0 and m[f"{key}_at_val_chosen"] == 1.0, key
    assert m["val_iou_at_chosen"] == 1.0
    assert all(row["iou"] == 1.0 for row in perfect.sweep + perfect.val_sweep)
    truth = torch.stack([test_ds[i]["collapse"] for i in range(len(test_ds))])
    assert m["positive_pixel_fraction"] == pytest.approx(float(truth.mean()))  # every pixel
    assert m["pairs"] == len(test_ds) and np.array_equal(
        perfect.samples["prob"], perfect.samples["truth"]
    )

    inverted = evaluate_sets(test_ds, val_ds, lambda batch: 1 - batch["collapse"], cfg)
    assert inverted.metrics["iou"] == 0.0 and inverted.metrics["recall"] == 0.0


def test_dataset_yields_masks(repro_twice):
    a, _ = repro_twice
    ds = CollapseDataset(a / "data/generate", a / "data/split/ch6.json", "train", 0.005)
    assert len(ds) > 0
    for i in range(len(ds)):
        item = ds[i]
        assert item["depth_m"].shape == (1, 64, 64)
        assert item["target"].sum() >= 10  # every target is visible
        assert (item["target"] * item["collapse"]).sum() == 0  # the target never "collapses"


def test_generate_resumes_from_finished_shards(root, tmp_path):
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "tiny"
    gen = load_section(GenerateConfig, "generate", params)
    gen = GenerateConfig(shard_size=2, workers=1, max_attempts=30, datasets=gen.datasets)
    sim = load_section(SimConfig, "sim", params)
    ds = dataclasses.replace(gen.datasets["ch6"], pull_outcomes=False)  # resuming, not labels
    out = tmp_path / "ch6"
    generate_dataset("ch6", ds, gen, sim, 0, out)
    first = digest_tree(out)
    (out / "shard-00001.npz").unlink()
    mtime = (out / "shard-00000.npz").stat().st_mtime_ns
    generate_dataset("ch6", ds, gen, sim, 0, out)
    assert (out / "shard-00000.npz").stat().st_mtime_ns == mtime  # kept, not redone
    assert digest_tree(out) == first


def test_bad_params_stop_the_stage_with_one_line(root, tmp_path):
    repo = tiny_copy(root, tmp_path / "repo")
    params = yaml.safe_load((repo / "params.yaml").read_text())
    params["generate"]["datasets"]["ch6"]["n_objects"] = [5, "ten"]
    (repo / "params.yaml").write_text(yaml.safe_dump(params))
    out = run([sys.executable, "stages/generate.py", "ch6"], repo, check=False)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "generate.datasets.ch6.n_objects[1]" in out.stderr
    assert not (repo / "data/generate/ch6").exists()


def test_checkpoint_from_another_config_is_refused(repro_twice, tmp_path):
    a, _ = repro_twice
    repo = tmp_path / "repo"
    shutil.copytree(a, repo)
    ckpt = repo / "models/cmn_bs32/best.pt"
    model = CollapseMapNet(CollapseMapConfig(input_size=128, encoder=VGGConfig(width=0.125)))
    save_checkpoint(ckpt, "collapse_map", model, {})
    out = run([sys.executable, "stages/evaluate.py", "cmn_bs32_ch5"], repo, check=False)
    assert out.returncode == 2 and out.stderr.strip().count("\n") == 0
    assert "takes 128x128 images but the data are 64x64" in out.stderr
    ckpt.write_bytes(b"truncated")
    out = run([sys.executable, "stages/evaluate.py", "cmn_bs32_ch5"], repo, check=False)
    assert out.returncode == 2 and "unreadable" in out.stderr
    assert out.stderr.strip().count("\n") == 0
    assert not list(repo.glob("reports/evaluate/cmn_bs32_ch5/.*tmp*"))


def test_missing_data_is_one_line(root, tmp_path):
    repo = tiny_copy(root, tmp_path / "repo")
    out = run([sys.executable, "stages/split.py", "ch6"], repo, check=False)
    assert out.returncode == 2 and "missing file" in out.stderr
    assert out.stderr.strip().count("\n") == 0
