"""bench.scaling's arithmetic (issue 52): per-job costs, efficiency and Ray's overhead from
the cases, and the paper scale costed from them (hand-made cases; no backend runs)."""

from __future__ import annotations

import pytest

from clutterbench.bench.scaling import (
    CASES,
    cost_markdown,
    derived,
    paper_cost,
    stage_jobs,
    trials_target,
)


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
    from clutterbench.bench.scaling import NETWORK_PLANNERS, _params, mix_conditions, workload_jobs
    from clutterbench.config import load_section
    from clutterbench.trials.config import TrialsConfig

    trials = load_section(TrialsConfig, "trials", _params("default"))
    names = mix_conditions(trials)
    planners = {trials.conditions[n].planner for n in names}
    assert {"oracle", "oracle_hold", "multi_step_pull_truth", "physics_from_depth"} <= planners
    assert not planners & set(NETWORK_PLANNERS)
    _, jobs, units = workload_jobs("trials", "default", 0, 0, len(names) + 2)
    assert units == len(jobs) == len(names) + 2
    got = [j["planner"] for j in jobs]
    want = [trials.conditions[n].planner for n in names]
    assert got == want + want[:2]  # round-robin over the conditions, in params order


def test_the_ch4_and_slides_workloads_are_the_stages_jobs():
    """trials_ch4: the stage's random and oracle conditions round-robin (the risk planner reads
    a network); slides: one pile per job, as the slides stage fans them out."""
    from clutterbench.bench.scaling import CH4_NETWORK_FREE, _params, workload_jobs
    from clutterbench.config import load_section
    from clutterbench.trials.config import TrialsConfig

    trials = load_section(TrialsConfig, "trials", _params("default"))
    names = [k for k, c in trials.ch4_conditions.items() if c.planner in CH4_NETWORK_FREE]
    assert {trials.ch4_conditions[n].planner for n in names} == {"random", "oracle"}
    _, jobs, units = workload_jobs("trials_ch4", "default", 0, 0, len(names) + 1)
    assert units == len(jobs) == len(names) + 1
    assert [j["cond"].planner for j in jobs] == [
        trials.ch4_conditions[n].planner for n in names
    ] + [trials.ch4_conditions[names[0]].planner]
    assert all(j["model_path"] is None for j in jobs)
    _, piles, units = workload_jobs("slides", "default", 3, 0, 0)
    assert units == len(piles) == 3 and len({p["seed"] for p in piles}) == 3
