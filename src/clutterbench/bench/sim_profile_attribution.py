"""The sim_profile part's attribution (bench/sim_profile.py): the categories of a stage's
wall time, each function's own category from its file and name (`classify`, RULES), every
function's self time given to the category of its outermost categorised caller over
cProfile's caller edges (`attribute`), the pickle round trips that estimate the
inter-process transfer (`transfer`, `each`), and a stage's extrapolation and shares."""

from __future__ import annotations

import pickle
import re
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

PHYSX = "PhysX step"
RENDER = "render"
PLANNER = "planner"
JUDGE = "judge"
ONCE = "start-up: imports, models, renderer"
BUILD = "start-up: building scenes and worlds"
TRANSFER = "inter-process transfer (pickling)"
PYTHON = "Python around the step"
CATEGORIES = (PHYSX, RENDER, PLANNER, JUDGE, ONCE, BUILD, TRANSFER, PYTHON)

TOP = 10

BUILTIN_RULES: tuple[tuple[str, tuple[str, ...]], ...] = (
    (PHYSX, (".pysapien.step>", ".physx.step>", "'step' of 'sapien.")),
    (RENDER, (".take_picture>", ".get_picture>", ".update_render>")),
    (TRANSFER, ("_pickle.dumps>", "_pickle.loads>")),
    (ONCE, ("_imp.create_dynamic>", "_imp.exec_dynamic>")),
)
"""C functions (cProfile's file "~"): a category and fragments of the function's name."""
ANY = ()
RULES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    (TRANSFER, "clutterbench/bench/sim_profile_attribution.py", ("transfer",)),
    (ONCE, "<frozen importlib", ANY),
    (ONCE, "clutterbench/sim/renderer.py", ANY),
    (ONCE, "clutterbench/parallel.py", ("worker_init",)),
    (ONCE, "clutterbench/trials/core/harness.py", ("load_predictor",)),
    (ONCE, "clutterbench/models/", ("load_checkpoint", "load_model_file", "load_torch_file")),
    (ONCE, "clutterbench/models/", ("load_slide_convnet", "load_detector")),
    (ONCE, "clutterbench/trials/ch3/games.py", ("_convnet",)),
    (ONCE, "clutterbench/collapse/", ("from_checkpoint", "from_paths", "load_box_head")),
    (ONCE, "torch/serialization.py", ("load",)),
    (ONCE, "gymnasium/envs/registration.py", ("make",)),
    (BUILD, "mani_skill/envs/sapien_env.py", ("_reconfigure", "_load_scene", "_load_agent")),
    (BUILD, "clutterbench/sim/physics.py", ("__init__", "from_spec", "from_state", "add_box")),
    (BUILD, "clutterbench/sim/pile.py", ("__init__", "from_poses", "from_spec", "add_piece")),
    (BUILD, "clutterbench/sim/benchmark.py", ANY),
    (PHYSX, "clutterbench/sim/physics.py", ("step",)),
    (PHYSX, "clutterbench/sim/pile.py", ("step",)),
    (PHYSX, "sapien/wrapper/scene.py", ("step",)),
    (PHYSX, "mani_skill/envs/scene.py", ("step",)),
    (RENDER, "clutterbench/sim/render.py", ANY),
    (RENDER, "clutterbench/sim/pile.py", ("_observe", "top_observation", "view_observation")),
    (JUDGE, "clutterbench/trials/core/judge.py", ANY),
    (JUDGE, "clutterbench/trials/core/protocol.py", ANY),
    (JUDGE, "clutterbench/criteria.py", ANY),
    (PLANNER, "clutterbench/planning/", ANY),
    (PLANNER, "clutterbench/perception/", ANY),
    (PLANNER, "clutterbench/models/", ANY),
    (PLANNER, "clutterbench/collapse/predict.py", ANY),
    (PLANNER, "clutterbench/collapse/box_predict.py", ANY),
    (PLANNER, "clutterbench/collapse/detector.py", ANY),
    (PLANNER, "clutterbench/trials/ch6/oracle.py", ANY),
    (PLANNER, "clutterbench/trials/ch6/truth_maps.py", ANY),
    (PLANNER, "clutterbench/trials/ch6/physics_model.py", ANY),
    (PLANNER, "clutterbench/trials/ch5/oracle.py", ANY),
    (PLANNER, "clutterbench/trials/ch5/perception.py", ANY),
    (PLANNER, "clutterbench/trials/noise/robust.py", ("simulate",)),
    (PLANNER, "clutterbench/trials/ch3/games.py", ("_choose", "run_pomdp", "_oracle_choice")),
    (PLANNER, "clutterbench/trials/ch4/episodes.py", ("_choose",)),
    (PLANNER, "clutterbench/support/baselines.py", ("predict", "answer_all")),
    (PLANNER, "torch/nn/modules/module.py", ("_call_impl",)),
    (PLANNER, "clutterbench/", ("decide", "collapse_score")),
)
"""Python functions: a category, a fragment of the file's path ("clutterbench/" any of the
package) and the function names (ANY: every function of that file); the first match wins."""
JUDGE_PREFIXES = ("judge", "_judge")
"""A clutterbench function named judge... or _judge... is the judge's, wherever it is."""

Key = tuple[str, int, str]
"""A function as pstats names it: (file, first line, name)."""


def classify(key: Key) -> str | None:
    """The category of one function by its own file and name (None: none of its own)."""
    file, _, name = key
    file = file.replace("\\", "/")
    if file == "~":
        for category, fragments in BUILTIN_RULES:
            if any(f in name for f in fragments):
                return category
        return None
    if "clutterbench/" in file and name.startswith(JUDGE_PREFIXES):
        return JUDGE
    for category, where, names in RULES:
        if where in file and (not names or name in names):
            return category
    return None


def attribute(
    stats: Mapping[Key, tuple], rule: Callable[[Key], str | None] = classify
) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """(seconds per category, {category: {own category: seconds}}) of cProfile stats
    ({function: (calls, primitive calls, tottime, cumtime, {caller: (.., .., tt, ct)})}): each
    function's tottime goes to its outermost categorised caller's category, else its own,
    else PYTHON, split over its callers by the cumulative time of each edge (by calls where
    none took time); the second dict: what the functions' own categories were within each."""
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 20_000))
    memo: dict[Key, dict[str | None, float]] = {}

    def outer(f: Key, visiting: frozenset[Key]) -> dict[str | None, float]:
        if f in memo:
            return memo[f]
        own = rule(f)
        callers = stats[f][4] if f in stats else {}
        edges = [(c, e) for c, e in callers.items() if c in stats and c != f and c not in visiting]
        weights = [e[3] for _, e in edges]
        if sum(weights) <= 0:
            weights = [e[0] for _, e in edges]
        total = sum(weights)
        if total <= 0:
            out: dict[str | None, float] = {own: 1.0}
        else:
            out = {}
            for (c, _), w in zip(edges, weights, strict=True):
                for k, v in outer(c, visiting | {f}).items():
                    k = own if k is None else k
                    out[k] = out.get(k, 0.0) + v * w / total
        memo[f] = out
        return out

    seconds = dict.fromkeys(CATEGORIES, 0.0)
    inside: dict[str, dict[str, float]] = {c: {} for c in CATEGORIES}
    for f, row in stats.items():
        leaf = rule(f) or PYTHON
        for k, v in outer(f, frozenset()).items():
            k = k or PYTHON
            seconds[k] += row[2] * v
            inside[k][leaf] = inside[k].get(leaf, 0.0) + row[2] * v
    return seconds, inside


def top_functions(stats: Mapping[Key, tuple], n: int = TOP) -> list[dict[str, Any]]:
    """The `n` functions of most self time: where, calls, self and cumulative seconds."""
    rows = sorted(stats.items(), key=lambda kv: -kv[1][2])[:n]
    return [
        {
            "function": name if file == "~" else f"{_short(file)}:{line}({name})",
            "category": classify((file, line, name)) or "",
            "calls": int(row[1]),
            "self_s": float(row[2]),
            "cumulative_s": float(row[3]),
        }
        for (file, line, name), row in rows
    ]


def _short(file: str) -> str:
    """A function's file from its package root (site-packages, src, the standard library)."""
    for root in ("site-packages/", "/src/"):
        if root in file:
            return file.split(root, 1)[1]
    return re.sub(r"^.*/lib/python3\.\d+/", "", file)


# --- the inter-process transfer estimate ----------------------------------------------------

TRANSFERS: list[tuple[int, float]] = []
"""(bytes, seconds) of every pickle round trip of the group being run."""


def transfer(obj: Any) -> Any:
    """`obj` pickled and unpickled, as a worker pool sends a job or a result (its size and
    time kept in TRANSFERS); the copy is returned and used."""
    t0 = time.perf_counter()
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    out = pickle.loads(data)
    TRANSFERS.append((len(data), time.perf_counter() - t0))
    return out


def each(fn: Callable[[Any], Any], jobs: list[Any]) -> list[Any]:
    """fn over jobs as a pool runs them: each job and each result through `transfer`."""
    return [transfer(fn(transfer(job))) for job in jobs]


# --- a stage's totals --------------------------------------------------------------------------


def extrapolate(stage: Mapping[str, Any]) -> dict[str, float]:
    """The stage's single-core seconds at default scale, extrapolated from its sample: the
    start-up phase once, each group's once-per-process start-up once and the rest of it
    (less the profiler's overhead) per unit times the group's full units."""
    total = stage["startup_s"]
    sample = stage["startup_s"]
    for g in stage["groups"]:
        once = g["categories"][ONCE]
        rest = max(0.0, g["wall_s"] - once - g["calls"] * stage["overhead_per_call_s"])
        g["per_unit_s"] = rest / g["units"] if g["units"] else 0.0
        g["extrapolated_s"] = once + g["per_unit_s"] * g["full_units"]
        total += g["extrapolated_s"]
        sample += g["wall_s"]
    return {"sample_s": sample, "extrapolated_s": total}


def stage_categories(stage: Mapping[str, Any]) -> dict[str, dict[str, float]]:
    """Per category: the sample's seconds and share of its whole wall time (the start-up
    phase as start-up, each group's time as attributed, scaled to the group's wall time so
    that the shares add up to 1), and the extrapolated whole stage's (`stage_seconds`,
    `stage_share`: start-up once, each group's other categories per unit, less the
    profiler's overhead, times its units at default scale). After `extrapolate`."""
    seconds = dict.fromkeys(CATEGORIES, 0.0)
    whole = dict.fromkeys(CATEGORIES, 0.0)
    seconds[ONCE] += stage["startup_s"]
    whole[ONCE] += stage["startup_s"]
    for g in stage["groups"]:
        attributed = sum(g["categories"].values())
        scale = g["wall_s"] / attributed if attributed > 0 else 0.0
        rest = sum(v for k, v in g["categories"].items() if k != ONCE) * scale
        per_unit = g["per_unit_s"] * g["units"] / rest if rest > 0 else 0.0
        for k, v in g["categories"].items():
            seconds[k] += v * scale
            whole[k] += (
                v * scale if k == ONCE else v * scale * per_unit * g["full_units"] / g["units"]
            )
    wall, total = sum(seconds.values()), sum(whole.values())
    return {
        k: {
            "seconds": seconds[k],
            "share": seconds[k] / wall if wall else 0.0,
            "stage_seconds": whole[k],
            "stage_share": whole[k] / total if total else 0.0,
        }
        for k in CATEGORIES
    }
