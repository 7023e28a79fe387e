"""The ch. 6 pull-planner recheck on dev streams: its params, its jobs (each variant on dev
streams only, its trials.ch6 fields reaching the planner; the oracles once), and the paired
report from records."""

from __future__ import annotations

import json

import pytest

import experiments.ch6_pull as ch6_pull
from clutterbench.config import load_params, load_section, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import SimConfig
from clutterbench.trials.ch6.episodes import make_planner
from clutterbench.trials.config import TrialsConfig
from experiments.ch6_pull import (
    comparisons,
    markdown,
    summary_rows,
    trial_jobs,
    what_it_shows,
)
from experiments.config import Ch6PullConfig, DevConfig, with_dev

STREAM = {"families": {"random": 1}, "n_objects": [3, 5], "catalogue": "various"}
V = {"block": {"abort_response": "block"}, "learn": {"abort_response": "learn"}}


def _dev(**pull):
    return {"streams": {"dev_a": STREAM}, "ch6_pull": {"streams": ["dev_a"]} | pull}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"streams": {"dev_a": STREAM}, "ch6_pull": {"streams": ["dev_b"], "variants": V}},
            "unknown dev stream",
        ),
        (_dev(variants={"block": V["block"]}), "two or more variants"),
        (_dev(variants=V | {"c": {"abort_response": "pray"}}), r"variants\.c\.abort_response"),
        (_dev(variants=V | {"c": {"cp_max": 0.2}}), r"variants\.c\.cp_max: a variant sets"),
        (_dev(variants=V, planners=[]), "no planner"),
        (
            _dev(variants={"now": {}}, planners=["multi_step_pull"], against={"a": "b"}),
            r"against: a is not among the planners",
        ),
    ],
)
def test_bad_ch6_pull_params_are_one_line(data, message):
    with pytest.raises(ClutterbenchError, match=message) as info:
        parse(DevConfig, data, "dev")
    assert "\n" not in str(info.value)


def test_jobs_run_each_variant_on_dev_streams_and_reach_the_planner(root, tmp_path, monkeypatch):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    trials = load_section(TrialsConfig, "trials", params)
    monkeypatch.chdir(tmp_path)
    for model in (trials.ch6.model, trials.ch6.ch4_model):
        (tmp_path / "models" / model).mkdir(parents=True)
        (tmp_path / "models" / model / "best.pt").write_bytes(b"")
    chosen = {"rule": "coverage", "prob_threshold": 0.5, "score_threshold": 0.3}
    chosen |= {"bbox_margin_px": 2, "adjacency_iou": 0.0, "max_gap_m": 0.05}
    pulled = chosen | {"score_threshold": 0.4}
    fell = chosen | {"score_threshold": 0.5}
    thresholds = {"chosen": {"coverage_gap": chosen, "pull_coverage_gap": pulled}}
    thresholds["chosen"]["pull_collapse_coverage_gap"] = fell
    (tmp_path / "t.json").write_text(json.dumps(thresholds))
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", tmp_path / "t.json")
    dev = load_section(DevConfig, "dev", params)
    cfg = dev.ch6_pull
    jobs = trial_jobs(dev, params)
    arms = len(cfg.variants) * len(cfg.planners) + 2 * cfg.oracle
    assert len(jobs) == len(cfg.streams) * arms * cfg.episodes
    seen = set()
    for job in jobs:
        label, stream = job.condition.split("/")
        variant, planner = label.split(":")
        seen.add((variant, planner))
        assert stream in cfg.streams and stream.startswith("dev_") and job.stream == stream
        assert job.stream_cfg == dev.streams[stream] and job.planner == planner
        for key, value in cfg.variants.get(variant, {}).items():
            assert getattr(job.params, key) == value
        pull_head = planner in ("multi_step_pull", "bimanual_pull")
        # a pull planner runs with the thresholds of its meaning's head
        collapse = job.params.pull_map_meaning == "collapse"
        expect = (0.5 if collapse else 0.4) if pull_head else 0.3
        assert job.support.score_threshold == expect
        if variant != "-" and job.index == 0 and not pull_head:  # the variant reaches it
            made = make_planner(job, object())  # truth maps keep the spec only
            assert made.learn_from_aborts == (job.params.abort_response == "learn")
    assert {v for v, _ in seen} == set(cfg.variants) | {"-"}
    assert {p for _, p in seen} == set(cfg.planners) | {"oracle", "oracle_hold"}


def _record(condition: str, episode: int, success: bool) -> dict:
    return {
        "condition": condition,
        "episode": episode,
        "success": success,
        "strict_success": success,
        "end": "target_out" if success else "gave_up",
    }


def test_report_pairs_variants_and_finds_each_planners_oracle():
    records = []
    for e in range(10):
        records += [
            _record("block:bimanual_pull_truth/dev_a", e, e < 3),
            _record("learn:bimanual_pull_truth/dev_a", e, e < 8),
            _record("-:oracle/dev_a", e, e < 5),
            _record("-:oracle_hold/dev_a", e, e < 9),
        ]
    rows = {r["condition"]: r for r in summary_rows(records)}
    learn = rows["learn:bimanual_pull_truth/dev_a"]
    assert learn["success_below_oracle_points"] == pytest.approx(10.0)  # oracle_hold's 90%
    assert rows["block:bimanual_pull_truth/dev_a"]["gave_up"] == 7
    assert rows["-:oracle_hold/dev_a"]["success_below_oracle_points"] is None
    comps = comparisons(records, ["block", "learn"], ["bimanual_pull_truth"], ["dev_a"])
    assert [(c["only_piles"], c["only_against"]) for c in comps] == [(5, 0), (5, 0)]
    shows = what_it_shows(comps)
    assert "learn against block (bimanual_pull_truth), success: 5 episodes won only by it" in shows
    result = {
        "scale": "tiny",
        "config": {"planners": ["bimanual_pull_truth"], "variants": V, "episodes": 10},
        "current": "learn",
        "rows": list(rows.values()),
        "comparisons": comps,
        "shows": shows,
        "n_episodes": len(records),
        "seconds": 60.0,
    }
    text = markdown(result)
    assert "| dev_a | learn | bimanual_pull_truth | " in text and "| 10 / 10 |" in text


def test_one_variant_compares_the_planners_it_is_told_to():
    one = {"now": {}}
    against = {"multi_step_pull": "physics_from_depth"}
    cfg = parse(
        Ch6PullConfig,
        {
            "streams": ["dev_a"],
            "variants": one,
            "planners": [*against.items()][0],
            "against": against,
        },
        "ch6_pull",
    )
    assert cfg.against == against
    records = []
    for e in range(10):
        records += [
            _record("now:multi_step_pull/dev_a", e, e < 6),
            _record("now:physics_from_depth/dev_a", e, 2 <= e < 7),
        ]
    comps = comparisons(records, list(one), cfg.planners, ["dev_a"], cfg.against)
    assert [(c["name"], c["other"], c["only_piles"], c["only_against"]) for c in comps] == [
        ("multi_step_pull", "physics_from_depth", 2, 1)
    ] * 2
    assert "multi_step_pull against physics_from_depth (now), success: 2 episodes won only" in (
        what_it_shows(comps)
    )
    clear = [
        _record(f"now:{p}/dev_a", e, (p == "multi_step_pull") == (e < 18))
        for e in range(20)
        for p in cfg.planners
    ]
    shows = what_it_shows(comparisons(clear, list(one), cfg.planners, ["dev_a"], cfg.against))
    assert "multi_step_pull against physics_from_depth +80.0 points success, now on dev_a" in shows


def test_truth_planners_need_no_network_and_a_cp_planner_names_its_own(root, tmp_path, monkeypatch):
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    monkeypatch.chdir(tmp_path)
    chosen = {"rule": "coverage", "prob_threshold": 0.5, "score_threshold": 0.3}
    chosen |= {"bbox_margin_px": 2, "adjacency_iou": 0.0, "max_gap_m": 0.05}
    (tmp_path / "t.json").write_text(json.dumps({"chosen": {"coverage_gap": chosen}}))
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", tmp_path / "t.json")
    params["dev"]["ch6_pull"]["planners"] = ["multi_step_pull_truth", "bimanual_pull_truth"]
    assert trial_jobs(load_section(DevConfig, "dev", params), params)  # no models/ at all
    params["dev"]["ch6_pull"]["planners"] = ["multi_step_pull_truth", "multi_step_pull"]
    with pytest.raises(ClutterbenchError, match=r"best\.pt missing \(planner multi_step_pull"):
        trial_jobs(load_section(DevConfig, "dev", params), params)


def test_pull_thresholds_reach_only_the_pull_head_planners(root, tmp_path, monkeypatch):
    """trials.ch6.pull_prob_threshold / pull_score_threshold override the support stage's
    choice for the pull-head CP planners alone (support and abort threshold), through the
    stage's condition_jobs and the dev recheck's section alike."""
    import dataclasses

    from clutterbench.trials.ch6.episodes import condition_jobs, planner_support
    from clutterbench.trials.config import ConditionConfig

    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    monkeypatch.chdir(tmp_path)
    trials = load_section(TrialsConfig, "trials", params)
    for model in (trials.ch6.model, trials.ch6.ch4_model):
        (tmp_path / "models" / model).mkdir(parents=True)
        (tmp_path / "models" / model / "best.pt").write_bytes(b"")
    chosen = {"rule": "coverage", "prob_threshold": 0.5, "score_threshold": 0.3}
    chosen |= {"bbox_margin_px": 2, "adjacency_iou": 0.0, "max_gap_m": 0.05}
    thresholds = {f"{h}coverage_gap": chosen for h in ("", "pull_", "pull_collapse_")}
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"chosen": thresholds}))
    over = {"pull_prob_threshold": 0.2, "pull_score_threshold": 0.8}
    ch6 = dataclasses.replace(trials.ch6, **over)
    for planner in ("multi_step_pull", "bimanual_pull", "multi_step", "multi_step_pull_truth"):
        support, cp_max = planner_support(path, planner, "coverage_gap", ch6)
        pulled = planner in ("multi_step_pull", "bimanual_pull")
        assert (support.prob_threshold, support.score_threshold, cp_max) == (
            (0.2, 0.8, 0.8) if pulled else (0.5, 0.3, 0.3)
        ), planner
        assert support.max_gap_m == 0.05  # the rest stays the support stage's choice
    cond = ConditionConfig("bimanual_pull", "ch6_3_10", 1, "coverage_gap")
    staged = dataclasses.replace(trials, ch6=ch6)
    jobs, support, cp_max = condition_jobs(
        "c", cond, trials=staged, sim=SimConfig(physics=None, camera=None), seed=0, thresholds=path
    )
    assert (jobs[0].support.prob_threshold, jobs[0].cp_max, cp_max) == (0.2, 0.8, 0.8)
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", path)
    params["dev"]["ch6_pull_thresholds"] = {
        "streams": list(params["dev"]["ch6_pull"]["streams"]),
        "variants": {"support": {}, "high": over},
        "planners": ["multi_step_pull", "multi_step"],
        "episodes": 1,
        "oracle": False,
    }
    dev = load_section(DevConfig, "dev", params)
    got = {
        j.condition.split("/")[0]: (j.support.prob_threshold, j.cp_max)
        for j in trial_jobs(dev, params, "ch6_pull_thresholds")
    }
    assert got == {
        "support:multi_step_pull": (0.5, 0.3),
        "high:multi_step_pull": (0.2, 0.8),
        "support:multi_step": (0.5, 0.3),
        "high:multi_step": (0.5, 0.3),
    }


def _tiny_with_models(root, tmp_path, monkeypatch) -> dict:
    """The tiny params, run from tmp_path with an empty checkpoint for every network a ch. 6
    box planner job names."""
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    monkeypatch.chdir(tmp_path)
    trials = load_section(TrialsConfig, "trials", params)
    for model in (trials.ch6.model, trials.ch6.ch4_model, "box_head"):
        (tmp_path / "models" / model).mkdir(parents=True)
        (tmp_path / "models" / model / "best.pt").write_bytes(b"")
    return params


def _write_fusion(folder, weight: float, contact: list[float] | None = None):
    """thresholds.json and, beside it, box_fusion.json (head-logit weight `weight`; the learned
    contact's weights where given)."""
    folder.mkdir(parents=True, exist_ok=True)
    fusion = {"edge": 0.3, "outcome": 0.4, "weights": [weight, 1.0, -1.0, 0.0]}
    if contact is not None:
        fusion["contact_weights"] = contact
    chosen = {head: fusion for head in ("pull", "pull_collapse")}
    (folder / "box_fusion.json").write_text(json.dumps({"chosen": chosen}))
    rule = {"rule": "coverage", "prob_threshold": 0.5, "score_threshold": 0.3}
    rule |= {"bbox_margin_px": 2, "adjacency_iou": 0.0, "max_gap_m": 0.05}
    rules = {f"{h}coverage_gap": rule for h in ("", "pull_", "pull_collapse_")}
    (folder / "thresholds.json").write_text(json.dumps({"chosen": rules}))
    return folder / "thresholds.json"


def test_a_variant_that_changes_the_fits_gets_its_own_fusion(root, tmp_path, monkeypatch):
    """dev.<section>: a variant setting trials.ch6.fit_hypotheses reads the fusion chosen again
    for it (variant_thresholds), once; a variant that does not, the support stage's."""
    params = _tiny_with_models(root, tmp_path, monkeypatch)
    write = _write_fusion

    monkeypatch.setattr(ch6_pull, "THRESHOLDS", write(tmp_path / "stage", 0.5))
    asked = []

    def refit(params, variant, ch6, section):
        asked.append((variant, ch6.fit_hypotheses))
        return write(tmp_path / variant, 0.9)

    monkeypatch.setattr(ch6_pull, "variant_thresholds", refit)
    params["dev"]["ch6_fit_hypotheses"]["variants"] = {"one": {}, "four": {"fit_hypotheses": 4}}
    dev = load_section(DevConfig, "dev", params)
    got = {
        j.condition.split("/")[0]: j.box_fusion[0]
        for j in trial_jobs(dev, params, "ch6_fit_hypotheses")
    }
    assert asked == [("four", 4)]
    assert got == {
        "one:multi_step_box_physics": 0.5,
        "one:bimanual_box_physics": 0.5,
        "four:multi_step_box_physics": 0.9,
        "four:bimanual_box_physics": 0.9,
    }


def test_a_learned_contact_variant_reads_the_contact_chosen_for_it(root, tmp_path, monkeypatch):
    """dev ch6_box_contact: the learned variant's fusion is chosen again with the learned
    contact (its weights in the jobs); the head variant's jobs carry none; a fusion without
    contact weights read for a learned contact is one line naming it."""
    params = _tiny_with_models(root, tmp_path, monkeypatch)
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", _write_fusion(tmp_path / "stage", 0.5))
    asked = []

    def refit(params, variant, ch6, section):
        asked.append((variant, ch6.box_contact))
        learned = ch6.box_contact == "learned"
        contact = [0.7, 1.3, -1.3, 0.0] if learned else None
        return _write_fusion(tmp_path / variant, 0.9 if learned else 0.8, contact)

    monkeypatch.setattr(ch6_pull, "variant_thresholds", refit)
    dev = load_section(DevConfig, "dev", params)
    got = {
        j.condition.split("/")[0]: (j.box_fusion[0], j.box_contact)
        for j in trial_jobs(dev, params, "ch6_box_contact")
    }
    # params.yaml's head variant sets box_contact too: chosen again (the stage's fusion, redone)
    assert asked == [("head", "head"), ("learned", "learned")]
    assert got == {
        "head:multi_step_box_physics": (0.8, None),
        "head:bimanual_box_physics": (0.8, None),
        "learned:multi_step_box_physics": (0.9, (0.7, 1.3, -1.3, 0.0)),
        "learned:bimanual_box_physics": (0.9, (0.7, 1.3, -1.3, 0.0)),
    }
    from clutterbench.trials.ch6.planners import box_fusion

    with pytest.raises(ClutterbenchError, match="with the learned contact"):
        box_fusion(tmp_path / "stage" / "thresholds.json", "collapse", "learned")


def test_a_box_cp_max_variant_sets_the_box_planners_cp_max_and_no_other(
    root, tmp_path, monkeypatch
):
    """dev ch6_box_cp_max: trials.ch6.box_cp_max is the box planners' cp_max (null: the
    fusion's val-chosen outcome threshold, 0.4 here); it does not refit the fusion, and a
    planner that is not a box planner keeps its own cp_max."""
    params = _tiny_with_models(root, tmp_path, monkeypatch)
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", _write_fusion(tmp_path / "stage", 0.5))

    def refit(*args):
        raise AssertionError("box_cp_max is no fusion field")

    monkeypatch.setattr(ch6_pull, "variant_thresholds", refit)
    params["dev"]["ch6_box_cp_max"]["variants"] = {"support": {}, "low": {"box_cp_max": 0.15}}
    params["dev"]["ch6_box_cp_max"]["planners"] = ["multi_step_box_physics", "multi_step_pull"]
    dev = load_section(DevConfig, "dev", params)
    got = {j.condition.split("/")[0]: j.cp_max for j in trial_jobs(dev, params, "ch6_box_cp_max")}
    assert got == {
        "support:multi_step_box_physics": 0.4,
        "support:multi_step_pull": 0.3,
        "low:multi_step_box_physics": 0.15,
        "low:multi_step_pull": 0.3,
    }


def test_a_precise_graph_variant_gets_its_fusion_chosen_again_with_that_precision(
    root, tmp_path, monkeypatch
):
    """dev ch6_box_edge: a variant setting trials.ch6.box_edge_precision has its fusion chosen
    again (the edge threshold depends on it); the support variant reads the stage's."""
    params = _tiny_with_models(root, tmp_path, monkeypatch)
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", _write_fusion(tmp_path / "stage", 0.5))
    asked = []

    def refit(params, variant, ch6, section):
        asked.append((variant, ch6.box_contact, ch6.box_edge_precision))
        return _write_fusion(tmp_path / variant, 0.9)

    monkeypatch.setattr(ch6_pull, "variant_thresholds", refit)
    variants = {"support": {}, "precise": {"box_edge_precision": 0.9}}
    params["dev"]["ch6_box_edge"]["variants"] = variants
    dev = load_section(DevConfig, "dev", params)
    got = {
        j.condition.split("/")[0]: j.box_fusion[0] for j in trial_jobs(dev, params, "ch6_box_edge")
    }
    assert asked == [("precise", "head", 0.9)]
    assert got["support:multi_step_box_physics"] == 0.5
    assert got["precise:bimanual_box_physics"] == 0.9


def test_a_sensed_recheck_shows_its_planners_the_sensor_and_the_oracles_the_world(
    root, tmp_path, monkeypatch
):
    """dev.<section>.sensing / perception: the planners see through the sensor with masks from
    depth and read the thresholds chosen for it; the oracles read the world."""
    params = with_dev(load_params(root / "params.yaml"))
    params["base"]["scale"] = "tiny"
    params["dev"]["ch6_pull"] |= {"sensing": "d415", "perception": "depth", "oracle": True}
    params["dev"]["ch6_pull"] |= {"planners": ["multi_step_pull"]}
    trials = load_section(TrialsConfig, "trials", params)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "models" / trials.ch6.model).mkdir(parents=True)
    (tmp_path / "models" / trials.ch6.model / "best.pt").write_bytes(b"")
    chosen = {"rule": "coverage", "prob_threshold": 0.5, "score_threshold": 0.3}
    chosen |= {"bbox_margin_px": 2, "adjacency_iou": 0.0, "max_gap_m": 0.05}
    exact = {rule: chosen for rule in ("pull_coverage_gap", "pull_collapse_coverage_gap")}
    exact["coverage_gap"] = chosen  # the oracles' (read, never used)
    sensed = {rule: chosen | {"score_threshold": 0.7} for rule in exact if "pull" in rule}
    thresholds = {"chosen": exact, "sensed": {"d415": {"chosen": sensed}}}
    (tmp_path / "t.json").write_text(json.dumps(thresholds))
    monkeypatch.setattr(ch6_pull, "THRESHOLDS", tmp_path / "t.json")
    jobs = trial_jobs(load_section(DevConfig, "dev", params), params)
    planners = [j for j in jobs if j.planner == "multi_step_pull"]
    oracles = [j for j in jobs if j.planner.startswith("oracle")]
    assert planners and oracles
    assert {(j.sensing, j.perception, j.cp_max) for j in planners} == {("d415", "depth", 0.7)}
    assert {(j.sensing, j.perception) for j in oracles} == {("ideal", "instance")}
    assert "through the `d415` sensor preset and masks from depth" in ch6_pull.seen_text(
        {"sensing": "d415", "perception": "depth"}
    )
