"""bench.scaling's arithmetic: per-job costs, efficiency and Ray's overhead from
the cases, and the paper scale costed from them (hand-made cases; no backend runs); and the
bench's workloads (bench.workloads): each a stage's own jobs on the bench's seed, only the
conditions it may run without a trained network (built, never run)."""

from __future__ import annotations

import pytest

from clutterbench.bench import scaling
from clutterbench.bench.scaling import (
    CASES,
    cost_markdown,
    derived,
    paper_cost,
    stage_jobs,
    trials_target,
)
from clutterbench.bench.workloads import SEED, WORKLOADS, scale_params, workload_jobs
from clutterbench.config import load_section
from clutterbench.errors import ClutterbenchError
from clutterbench.trials.ch4.episodes import Ch4Job
from clutterbench.trials.config import TrialsConfig


def _case(workload: str, backend: str, workers: int, wall: float, start: float = 0.0) -> dict:
    job_s_sum, jobs = 8.0, 4
    return {
        "workload": workload,
        "backend": backend,
        "workers": workers,
        "jobs": jobs,
        "units": 8 if workload == "generate" else 4,
        "wall_s": wall,
        "start_s": start,
        "shutdown_s": 1.0 if backend == "ray" else 0.0,
        "job_s_sum": job_s_sum,
        "overhead_per_job_s": (wall - start - (1.0 if backend == "ray" else 0.0)) / jobs
        - job_s_sum / workers / jobs,
        "digest": "same",
    }


WALLS = {("processes", 1): 10.0, ("processes", 2): 6.0, ("ray", 1): 14.0, ("ray", 2): 10.0}


@pytest.fixture
def bench() -> dict:
    cases = [
        _case(w, b, n, WALLS[(b, n)], 3.0 if b == "ray" else 0.0)
        for w in ("generate", "trials")
        for b, n in CASES
    ]
    return {"scale": "default", "cpu_model": "test CPU", "cases": cases, "derived": derived(cases)}


def test_derived_measures(bench):
    d = bench["derived"]["generate"]
    assert d["unit_s"] == 8.0 / 8  # job time per scene, processes x1
    assert d["efficiency"] == {"processes": 10 / 12, "ray": 14 / 20}
    assert d["ray_fixed_s"] == 4.0
    # overhead per job at 2 workers: processes (6 - 4) / 4, ray (10 - 4 - 4) / 4
    assert d["ray_overhead_per_task_s"] == pytest.approx(0.0)
    assert d["same_bytes"]
    bench["cases"][-1]["digest"] = "other"
    assert not derived(bench["cases"])["trials"]["same_bytes"]


def test_paper_cost_is_jobs_times_measured_cost(bench):
    cost = paper_cost(bench)
    jobs = stage_jobs("paper")
    rows = {r["stage"]: r for r in cost["rows"]}
    assert set(rows) == set(jobs)
    gen = rows["generate"]
    assert gen["cpu_hours"] == pytest.approx(jobs["generate"] * 1.0 / 3600)
    assert gen["wall_h_2_cores"] == pytest.approx(jobs["generate"] / (2 * 10 / 12) / 3600)
    assert gen["wall_h_ray_4x16"] == pytest.approx((4.0 + jobs["generate"] / (64 * 0.7)) / 3600)
    assert "cpu_hours" not in rows["slides"]
    lines = cost_markdown(cost)
    assert any(line.startswith("| generate |") for line in lines)
    assert any("not measured by this bench" in line for line in lines)
    target = trials_target(bench)
    assert target["episodes"] == stage_jobs("default")["trials"] and target["fraction"] > 0


def test_the_trials_workload_is_the_stages_mix_of_network_free_planners():
    """The bench's trials jobs cycle through every default condition whose planner needs no
    network (the search oracles, the truth-map planners, physics from depth, random,
    pull_target), so its per-episode cost weighs them as the stage does."""
    from clutterbench.bench.workloads import mix_conditions
    from clutterbench.trials.ch6.planners import planner_info

    trials = load_section(TrialsConfig, "trials", scale_params("default"))
    names = mix_conditions(trials)
    planners = {trials.conditions[n].planner for n in names}
    assert {"oracle", "oracle_hold", "multi_step_pull_truth", "physics_from_depth"} <= planners
    assert not any(planner_info(p).networks for p in planners)
    assert not {"multi_step", "single_step", "multi_step_box", "bimanual_box_physics"} & planners
    _, jobs, units = workload_jobs("trials", "default", 0, 0, len(names) + 2)
    assert units == len(jobs) == len(names) + 2
    got = [j.planner for j in jobs]
    want = [trials.conditions[n].planner for n in names]
    assert got == want + want[:2]  # round-robin over the conditions, in params order


def test_the_ch4_and_slides_workloads_are_the_stages_jobs():
    """trials_ch4: the stage's random and oracle conditions round-robin (the risk planner reads
    a network); slides: one pile per job, as the slides stage fans them out."""
    from clutterbench.bench.workloads import CH4_NETWORK_FREE

    trials = load_section(TrialsConfig, "trials", scale_params("default"))
    names = [k for k, c in trials.ch4_conditions.items() if c.planner in CH4_NETWORK_FREE]
    assert {trials.ch4_conditions[n].planner for n in names} == {"random", "oracle"}
    _, jobs, units = workload_jobs("trials_ch4", "default", 0, 0, len(names) + 1)
    assert units == len(jobs) == len(names) + 1
    assert [j.cond.planner for j in jobs] == [trials.ch4_conditions[n].planner for n in names] + [
        trials.ch4_conditions[names[0]].planner
    ]
    assert all(j.model_path is None for j in jobs)
    _, piles, units = workload_jobs("slides", "default", 3, 0, 0)
    assert units == len(piles) == 3 and len({p["seed"] for p in piles}) == 3


def test_the_ch5_workload_is_the_stages_jobs_of_its_network_free_conditions():
    """trials_ch5: the stage's own jobs (trials.ch5.ch5_jobs) of the conditions that read
    neither the collapse map network nor the detector, on the bench's seed, round-robin;
    their oracles do not also simulate the detector's view (that needs its network)."""
    import dataclasses

    from clutterbench.bench.workloads import ch5_network_free
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch5.episodes import ch5_jobs, run_ch5_episode

    params = scale_params("tiny")
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    names = [k for k, c in trials.ch5_conditions.items() if ch5_network_free(c)]
    conds = [trials.ch5_conditions[n] for n in names]
    assert {c.planner for c in conds} == {"oracle", "oracle_no_contact"}
    assert {c.perception for c in conds} == {"clusters"}
    fn, jobs, units = workload_jobs("trials_ch5", "tiny", 0, 0, len(names) + 1)
    assert fn is run_ch5_episode and units == len(jobs) == len(names) + 1
    assert [j.condition for j in jobs] == [f"bench_{n}" for n in names + names[:1]]
    assert [j.index for j in jobs] == [0] * len(names) + [1]
    first = trials.ch5_conditions[names[0]]
    own = ch5_jobs(
        f"bench_{names[0]}",
        dataclasses.replace(first, episodes=2),
        trials=trials,
        sim=sim,
        seed=SEED,
        prob_threshold=0.5,
        scene_type=first.stream.removeprefix("ch5_"),
        oracle_detector=False,
        record_images=False,
    )
    assert jobs[0] == own[0] and jobs[-1] == own[1]
    assert all(j.seed == SEED and not j.oracle_detector for j in jobs)


def test_the_ch3_workload_is_the_stages_games_without_the_convnet():
    """trials_ch3: the stage's own jobs (trials.ch3.ch3_jobs) of the variants that read no
    ConvNet, game g of each on the pile of the bench's seed stream, round-robin."""
    from clutterbench.bench.workloads import CH3_NETWORK_FREE
    from clutterbench.data.slides import pile_seed
    from clutterbench.trials.ch3.games import run_ch3_game

    fn, jobs, units = workload_jobs("trials_ch3", "tiny", 0, 0, 4)
    assert fn is run_ch3_game and units == len(jobs) == 4
    assert [j.condition for j in jobs] == ["no_convnet", "random", "oracle", "no_convnet"]
    assert set(CH3_NETWORK_FREE) == {"no_convnet", "random", "oracle"}
    assert [j.index for j in jobs] == [0, 0, 0, 1]
    assert [j.seed for j in jobs] == [pile_seed(SEED, "ch3_games", g) for g in (0, 0, 0, 1)]
    assert all(j.model is None and not j.record_images for j in jobs)
    assert jobs[0].cfg.games.variants == ("no_convnet",)


@pytest.fixture
def bare(root, tmp_path, monkeypatch):
    """A working directory with the project's params and no trained network."""
    (tmp_path / "params.yaml").symlink_to(root / "params.yaml")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_arm_workload_runs_the_arm_conditions_whose_network_exists(bare):
    """trials_arm: every arm condition repeats a network planner, so the workload runs those
    whose network is trained (here only ch4_various: various_5_arm), as the stage builds
    them (executor arm, the chapter said), on the bench's seed; none: it cannot run."""
    import importlib.util

    from clutterbench.bench.workloads import unavailable
    from clutterbench.trials.arm.episodes import run_arm_episode

    if importlib.util.find_spec("mani_skill") is None:
        pytest.skip("ManiSkill is not installed (the workload is skipped without it)")
    with pytest.raises(ClutterbenchError, match="no arm condition can run"):
        workload_jobs("trials_arm", "tiny", 0, 0, 2)
    why = unavailable("trials_arm", "tiny")
    assert why is not None and "best.pt missing" in why
    (bare / "models/ch4_various").mkdir(parents=True)
    (bare / "models/ch4_various/best.pt").touch()
    assert unavailable("trials_arm", "tiny") is None
    fn, jobs, units = workload_jobs("trials_arm", "tiny", 0, 0, 2)
    assert fn is run_arm_episode and units == len(jobs) == 2
    assert [j.condition for j in jobs] == ["bench_various_5_arm"] * 2
    assert [j.index for j in jobs] == [0, 1]
    assert all(isinstance(j, Ch4Job) and j.cond.executor == "arm" for j in jobs)
    assert all(j.seed == SEED and j.cond.planner == "risk" for j in jobs)
    # the ch. 6 conditions' network without the support stage's thresholds: still not run
    (bare / "models/cp_focal").mkdir()
    (bare / "models/cp_focal/best.pt").touch()
    _, jobs, _ = workload_jobs("trials_arm", "tiny", 0, 0, 2)
    assert {j.condition for j in jobs} == {"bench_various_5_arm"}


def test_the_bench_skips_a_workload_it_cannot_run_with_a_line(bare, monkeypatch, capsys):
    pytest.importorskip("ray")
    monkeypatch.setattr(scaling, "WORKLOADS", ("trials_arm",))
    result = scaling.bench_ray("tiny", out_dir=bare / "out")
    assert result["cases"] == [] and "trials_arm" in result["skipped"]
    assert "bench ray: trials_arm skipped (" in capsys.readouterr().out
    rows = {r["stage"]: r for r in paper_cost(result)["rows"]}
    assert "cpu_hours" not in rows["trials_arm"] and "skipped" in rows["trials_arm"]
    line = next(x for x in cost_markdown(paper_cost(result)) if x.startswith("| trials_arm |"))
    assert "not measured by this bench (skipped: " in line


def test_the_arm_episodes_flag_is_trials_arms_job_count(monkeypatch):
    calls = []
    monkeypatch.setattr(scaling, "bench_ray", lambda *a: calls.append(a))
    scaling.main(["--episodes", "9", "--arm-episodes", "2"])
    scaling.main([])
    assert [c[3] for c in calls] == [9, 16] and [c[5] for c in calls] == [2, 4]


def test_every_workload_costs_its_stage(bench):
    """With every workload measured, every simulation stage's row is costed, and a job's
    cost says what it is (trials_arm: the conditions the bench ran)."""
    cases = [
        _case(w, b, n, WALLS[(b, n)], 3.0 if b == "ray" else 0.0)
        | {"conditions": ["bench_various_5_arm"] if w == "trials_arm" else []}
        for w in WORKLOADS
        for b, n in CASES
    ]
    full = bench | {"cases": cases, "derived": derived(cases)}
    assert set(full["derived"]) == set(WORKLOADS)
    rows = {r["stage"]: r for r in paper_cost(full)["rows"]}
    assert all("cpu_hours" in r for r in rows.values())
    assert "oracle_no_contact" in rows["trials_ch5"]["cost_of"]
    assert "no_convnet" in rows["trials_ch3"]["cost_of"]
    assert rows["trials_arm"]["cost_of"].startswith("an arm-level episode (Pandas) of various_5")
    assert not any("not measured" in line for line in cost_markdown(paper_cost(full)))


def test_busy_cores_count_the_workers_the_case_waited_for():
    import subprocess
    import sys

    before = scaling.cpu_seconds()
    burn = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass"
    subprocess.run([sys.executable, "-c", burn], check=True)
    assert scaling.cpu_seconds() - before >= 0.3


def test_busy_cores_cell_is_of_the_processes_backend_only():
    case = _case("generate", "processes", 2, 10.0) | {
        "cpu_s": 16.0,
        "busy_cores": 1.6,
        "jobs_per_s": 0.4,
    }
    assert scaling.busy_cell(case) == "1.60 (80%)"
    assert scaling.busy_cell(case | {"backend": "ray"}) == ""
    assert scaling.busy_cell(_case("generate", "processes", 2, 10.0)) == ""  # an older bench
    machine = {"cpu_model": "test CPU", "logical_cpus": 2, "torch_threads": 2, "machine": "x"}
    result = {"scale": "default", **machine, "cases": [case], "derived": {}}
    lines = scaling.ray_markdown(result)
    assert any(line.endswith("| 1.60 (80%) |") for line in lines)
