"""The sim_profile benchmark's pure pieces: each function's own category from its file and
name, the attribution of self times to the outermost categorised caller over a fake cProfile
call graph, the extrapolation of a stage and its markdown."""

from __future__ import annotations

import pytest

from clutterbench.bench.sim_profile_attribution import (
    BUILD,
    CATEGORIES,
    JUDGE,
    ONCE,
    PHYSX,
    PLANNER,
    PYTHON,
    RENDER,
    TRANSFER,
    attribute,
    classify,
    extrapolate,
    stage_categories,
)
from clutterbench.bench.sim_profile_md import markdown

SRC = "/repo/src/clutterbench"
SITE = "/repo/.venv/lib/python3.11/site-packages"
STEP = ("~", 0, "<built-in method sapien.pysapien.step>")
PICTURE = ("~", 0, "<built-in method sapien.pysapien.render.take_picture>")


@pytest.mark.parametrize(
    "key, category",
    [
        (STEP, PHYSX),
        (("~", 0, "<method 'step' of 'sapien.pysapien.physx.PhysxCpuSystem' objects>"), PHYSX),
        (PICTURE, RENDER),
        (("~", 0, "<built-in method _pickle.dumps>"), TRANSFER),
        ((f"{SRC}/sim/physics.py", 189, "step"), PHYSX),
        ((f"{SRC}/sim/physics.py", 216, "settle"), None),  # the Python loop around the steps
        ((f"{SRC}/sim/physics.py", 65, "__init__"), BUILD),
        ((f"{SRC}/sim/render.py", 62, "observe"), RENDER),
        ((f"{SITE}/sapien/wrapper/scene.py", 131, "step"), PHYSX),
        ((f"{SITE}/mani_skill/envs/scene.py", 379, "step"), PHYSX),
        ((f"{SITE}/mani_skill/envs/sapien_env.py", 1042, "step"), None),
        ((f"{SRC}/trials/ch6/oracle.py", 197, "decide"), PLANNER),
        ((f"{SRC}/trials/ch6/planners/random_order.py", 9, "decide"), PLANNER),
        ((f"{SRC}/planning/ch6/cpg.py", 10, "build_cpg"), PLANNER),
        ((f"{SITE}/torch/nn/modules/module.py", 1, "_call_impl"), PLANNER),
        ((f"{SRC}/trials/core/protocol.py", 50, "judge_pull"), JUDGE),
        ((f"{SRC}/trials/ch6/episodes.py", 180, "_judge"), JUDGE),
        ((f"{SRC}/trials/core/harness.py", 36, "load_predictor"), ONCE),
        ((f"{SRC}/trials/ch3/games.py", 55, "_convnet"), ONCE),
        ((f"{SRC}/models/collapse_map.py", 166, "_split_conv"), PLANNER),
        (("<frozen importlib._bootstrap>", 1165, "_find_and_load"), ONCE),
        ((f"{SRC}/bench/sim_profile_attribution.py", 1, "transfer"), TRANSFER),
        ((f"{SRC}/trials/ch6/episodes.py", 260, "run_ch6_episode"), None),
        ((f"{SITE}/numpy/linalg/linalg.py", 2383, "norm"), None),
    ],
)
def test_classify(key, category):
    assert classify(key) == category


def row(tottime: float, callers: dict | None = None) -> tuple:
    """A pstats row: (primitive calls, calls, tottime, cumtime, callers) (cumtime unused)."""
    return (1, 1, tottime, 0.0, callers or {})


def edge(cumtime: float) -> tuple:
    return (1, 1, 0.0, cumtime)


EPISODE = (f"{SRC}/trials/ch6/episodes.py", 260, "run_ch6_episode")
DECIDE = (f"{SRC}/trials/ch6/oracle.py", 197, "decide")
SEARCH = (f"{SRC}/trials/ch6/oracle.py", 114, "search")
OBSERVE = (f"{SRC}/sim/render.py", 62, "observe")
NORM = (f"{SITE}/numpy/linalg/linalg.py", 2383, "norm")


def fake_stats() -> dict:
    """An episode (1.0 s self) that decides (oracle: 0.5 s self, searching 0.3 s more whose
    steps take 0.6 s), steps itself (0.4 s of steps), observes (0.2 s self, 0.8 s picture)
    and calls norm from its own code (0.1 s) and from the search (0.1 s)."""
    return {
        EPISODE: row(1.0),
        DECIDE: row(0.5, {EPISODE: edge(2.0)}),
        SEARCH: row(0.3, {DECIDE: edge(1.0)}),
        STEP: row(1.0, {SEARCH: edge(0.6), EPISODE: edge(0.4)}),
        OBSERVE: row(0.2, {EPISODE: edge(1.0)}),
        PICTURE: row(0.8, {OBSERVE: edge(0.8)}),
        NORM: row(0.2, {EPISODE: edge(0.1), SEARCH: edge(0.1)}),
    }


def test_attribute_gives_self_time_to_the_outermost_categorised_caller():
    seconds, inside = attribute(fake_stats())
    assert set(seconds) == set(CATEGORIES)
    assert seconds[PLANNER] == pytest.approx(0.5 + 0.3 + 0.6 + 0.1)  # the search's steps
    assert seconds[PHYSX] == pytest.approx(0.4)  # the episode's own steps only
    assert seconds[RENDER] == pytest.approx(0.2 + 0.8)
    assert seconds[PYTHON] == pytest.approx(1.0 + 0.1)  # the episode and its own norm
    assert sum(seconds.values()) == pytest.approx(sum(r[2] for r in fake_stats().values()))
    assert inside[PLANNER][PHYSX] == pytest.approx(0.6)
    assert inside[PLANNER][PYTHON] == pytest.approx(0.1)
    assert inside[RENDER][RENDER] == pytest.approx(1.0)


def test_attribute_splits_by_calls_where_no_edge_took_time_and_survives_recursion():
    a = (f"{SRC}/sim/spec.py", 1, "a")
    stats = {
        EPISODE: row(0.0),
        DECIDE: row(0.0, {EPISODE: (1, 1, 0.0, 0.0)}),
        a: row(1.0, {EPISODE: (3, 3, 0.0, 0.0), DECIDE: (1, 1, 0.0, 0.0), a: (2, 2, 0.0, 0.0)}),
    }
    seconds, _ = attribute(stats)
    assert seconds[PLANNER] == pytest.approx(0.25)
    assert seconds[PYTHON] == pytest.approx(0.75)


def stage_result() -> dict:
    group = {
        "name": "oracle",
        "about": "oracle",
        "unit": "episode",
        "units": 2,
        "full_units": 100,
        "wall_s": 4.0,
        "calls": 1000,
        "categories": dict.fromkeys(CATEGORIES, 0.0) | {PLANNER: 2.0, PHYSX: 1.0, ONCE: 1.0},
        "inside": {PLANNER: {PHYSX: 1.5}},
        "transfer_bytes": 4000,
        "transfers": 4,
        "steps": [3, 4],
    }
    return {
        "stage": "trials",
        "startup_s": 6.0,
        "upstream_s": 0.5,
        "groups": [group],
        "notes": ["a note"],
        "overhead_per_call_s": 1e-3,
        "top": [
            {
                "function": "<built-in method sapien.pysapien.step>",
                "category": PHYSX,
                "calls": 10,
                "self_s": 1.0,
                "cumulative_s": 1.0,
            }
        ],
        "others": 0.25,
        "attempts": 2,
    }


def test_extrapolate_counts_start_up_once_and_the_rest_per_unit():
    stage = stage_result()
    out = extrapolate(stage)
    g = stage["groups"][0]
    assert g["per_unit_s"] == pytest.approx((4.0 - 1.0 - 1000 * 1e-3) / 2)
    assert g["extrapolated_s"] == pytest.approx(1.0 + 1.0 * 100)
    assert out == pytest.approx({"sample_s": 10.0, "extrapolated_s": 6.0 + 101.0})
    cats = stage_categories(stage)
    assert cats[ONCE]["seconds"] == pytest.approx(6.0 + 1.0)
    assert sum(v["share"] for v in cats.values()) == pytest.approx(1.0)
    # the whole stage: start-up once; planner and PhysX (2 : 1) share the 1.0 s per unit
    assert cats[ONCE]["stage_seconds"] == pytest.approx(7.0)
    assert cats[PLANNER]["stage_seconds"] == pytest.approx(100 * 1.0 * 2 / 3)
    assert cats[PHYSX]["stage_seconds"] == pytest.approx(100 * 1.0 / 3)
    assert sum(v["stage_share"] for v in cats.values()) == pytest.approx(1.0)


def test_markdown_has_a_table_per_stage_with_the_others_share():
    stage = stage_result()
    again = stage["groups"][0] | {"name": "scored", "phase": True}  # the same episodes again
    stage["groups"].append(again)
    stage |= extrapolate(stage)
    stage["categories"] = stage_categories(stage)
    result = {
        "stages": [stage, {"stage": "trials_arm", "error": "no ManiSkill"}],
        "cpu_model": "AMD EPYC",
        "logical_cpus": 2,
        "torch_threads": 1,
        "machine": "x86_64",
    }
    text = "\n".join(markdown(result))
    assert "## trials" in text
    assert f"| {PLANNER} | 4.00 | 28.6 % | 3.00 / 0.00 | 2.2 min | 64.1 % |" in text
    assert f"| trials | 14.0 | {ONCE} 57.1 %; {PLANNER} 28.6 % | {PLANNER} 64.1 %; " in text
    assert "| 100 episodes | 3.5 min | 25.0 % |" in text  # the phase's episodes counted once
    assert "| oracle | oracle | 2 episodes | 3 / 4 | 4.00 | 1.000 | 100 | 1.7 min |" in text
    assert "| trials_arm | not run: no ManiSkill |" in text
