"""The sim_profile part's markdown (bench/sim_profile.py): a summary table of the stages,
then per stage its categories, its groups with their extrapolation and its top functions."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from clutterbench.bench import header
from clutterbench.bench.sim_profile_attribution import CATEGORIES, PHYSX, RENDER
from clutterbench.bench.sim_profile_setup import plural


def pct(share: float | None) -> str:
    return "n/a" if share is None else f"{100 * share:.1f} %"


def minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"


def leading(stage: Mapping[str, Any], key: str = "stage_share", n: int = 2) -> str:
    """The stage's `n` largest categories by `key` with their shares."""
    cats = sorted(stage["categories"].items(), key=lambda kv: -kv[1][key])[:n]
    return "; ".join(f"{k} {pct(v[key])}" for k, v in cats)


INTRO = (
    "Each simulation stage's work, a small sample of it run in one fresh process on one "
    "core (one torch thread), under cProfile: the stage's own job constructors and job "
    "functions, params.yaml at default scale, the stage's own seed and first scenes / "
    "episodes / games (bench/sim_profile_stages.py). Networks are not trained on this "
    "machine: where a planner reads one, a randomly initialised network of the default "
    "config stands in (the same forward-pass cost, other decisions: the column 'steps: "
    "sample / committed run' compares the steps of the sampled episodes with the committed "
    "run's records of the same episodes; where the sample took fewer, e.g. an untrained "
    "detector that sees no cluster, that group's extrapolation is low). There is no separate "
    "render stage: generate and every trials stage render their own pictures."
)
HOW = (
    "How the time is attributed: the start-up phase (imports, configs, the jobs built, "
    "the renderer's first picture) counts whole as start-up. "
    "In each group every function's self time goes to the category of its outermost "
    "categorised caller, else its own, else 'Python around the step' (a function's time "
    "split over its callers by the time each caller edge took; categories by file and "
    "function name, sim_profile_attribution.RULES): a planner's search, its PhysX steps "
    "included, is planner time; PhysX and render time inside other categories are listed "
    "beside them. "
    "Inter-process transfer: each job and result pickled and unpickled once, as a worker "
    "pool does (estimate; the sample itself runs in one process). cProfile adds its "
    "overhead to Python calls (measured per call in each process); shares include it."
)
EXTRAPOLATION = (
    "Extrapolated whole stage (an extrapolation, not a measurement): start-up once, plus "
    "per group its once-per-process start-up once and the rest of its time (less the "
    "profiler's measured per-call overhead) per unit times the group's units at default "
    "scale; single core, no parallel workers."
)


def markdown(result: Mapping[str, Any]) -> list[str]:
    lines = header("Where each simulation stage's wall time goes (one core)", result)
    lines += [INTRO, "", HOW, "", EXTRAPOLATION, ""]
    code = result.get("code") or {}
    if code.get("commit"):
        lines += [
            f"Code measured: commit {code['commit']} with {code['changed_src_files']} files "
            "under src/ changed in the working tree (work in progress).",
            "",
        ]
    lines += [
        "| stage | sample (s) | top categories: sample | top categories: extrapolated stage "
        "| default-scale units | extrapolated stage (single core) | other processes' CPU share |",
        "|---|---|---|---|---|---|---|",
    ]
    for s in result["stages"]:
        if "error" in s:
            lines.append(f"| {s['stage']} | not run: {s['error']} | | | | | |")
            continue
        units = ", ".join(plural(n, u) for u, n in _units(s).items())
        lines.append(
            f"| {s['stage']} | {s['sample_s']:.1f} | {leading(s, 'share')} | {leading(s)} | "
            f"{units} | {minutes(s['extrapolated_s'])} | {pct(s.get('others'))} |"
        )
    for s in result["stages"]:
        if "error" not in s:
            lines += ["", *stage_section(s)]
    return lines


def _units(stage: Mapping[str, Any]) -> dict[str, int]:
    """The stage's units at default scale by kind (a group that is another phase of work on
    the units before it not counted again)."""
    out: dict[str, int] = {}
    for g in stage["groups"]:
        if not g.get("phase"):
            out[g["unit"]] = out.get(g["unit"], 0) + g["full_units"]
    return out


def stage_section(s: Mapping[str, Any]) -> list[str]:
    """One stage: its sample, categories, groups and top functions."""
    n = sum(g["units"] for g in s["groups"])
    lines = [
        f"## {s['stage']}",
        "",
        f"Sample: {plural(n, 'unit')} in {plural(len(s['groups']), 'group')}, "
        f"{s['sample_s']:.1f} s profiled "
        f"(start-up {s['startup_s']:.1f} s; upstream input made outside the profile "
        f"{s['upstream_s']:.1f} s). Other processes used {pct(s.get('others'))} of the CPUs "
        f"meanwhile (/proc/stat less this sample's process; attempt {s.get('attempts')}, the "
        f"least disturbed kept). cProfile overhead {1e9 * s['overhead_per_call_s']:.0f} ns "
        "per call.",
        *[f"- {note}" for note in s["notes"]],
        "",
        "| category | sample s | sample share | of which PhysX / render (s) "
        "| extrapolated stage | its share |",
        "|---|---|---|---|---|---|",
    ]
    inside = _inside(s)
    for k in CATEGORIES:
        v = s["categories"][k]
        lines.append(
            f"| {k} | {v['seconds']:.2f} | {pct(v['share'])} | {inside.get(k, '')} | "
            f"{minutes(v['stage_seconds'])} | {pct(v['stage_share'])} |"
        )
    lines += [
        "",
        "| group | conditions | sample units | steps: sample / committed run | s | s / unit "
        "| default-scale units | extrapolated |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for g in s["groups"]:
        steps = " / ".join(map(str, g["steps"])) if "steps" in g else ""
        lines.append(
            f"| {g['name']} | {g['about']} | {plural(g['units'], g['unit'])} | {steps} | "
            f"{g['wall_s']:.2f} | {g['per_unit_s']:.3f} | {g['full_units']} | "
            f"{minutes(g['extrapolated_s'])} |"
        )
    transfer = sum(g["transfer_bytes"] for g in s["groups"])
    count = sum(g["transfers"] for g in s["groups"])
    lines += [
        f"| **whole stage** | | | | | | | **{minutes(s['extrapolated_s'])}** |",
        "",
        f"Pickled: {count} jobs and results, {transfer / 1e6:.2f} MB "
        f"({transfer / max(count, 1) / 1e3:.1f} kB each).",
        "",
        "| function (top 10 by self time) | category | calls | self s | cumulative s |",
        "|---|---|---|---|---|",
    ]
    for t in s["top"]:
        fn = t["function"].replace("|", "\\|")
        lines.append(
            f"| `{fn}` | {t['category']} | {t['calls']} | {t['self_s']:.2f} | "
            f"{t['cumulative_s']:.2f} |"
        )
    return lines


def _inside(s: Mapping[str, Any]) -> dict[str, str]:
    """Per category other than PhysX and render: the PhysX and render seconds in it."""
    sums: dict[str, list[float]] = {}
    for g in s["groups"]:
        for k, own in g["inside"].items():
            if k in (PHYSX, RENDER):
                continue
            row = sums.setdefault(k, [0.0, 0.0])
            row[0] += own.get(PHYSX, 0.0)
            row[1] += own.get(RENDER, 0.0)
    return {k: f"{p:.2f} / {r:.2f}" for k, (p, r) in sums.items() if p or r}
