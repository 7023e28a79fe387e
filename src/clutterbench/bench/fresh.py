"""`make bench`, fresh part: what a trusted score costs -> reports/bench/fresh.{json,md}.

`clutterbench evaluate-predictor docs/examples/example_predictor.py --fresh 200` as a user runs
it (a subprocess: the import, the worker pool's start, the labelling of 200 fresh scenes, the
deletions' replay, the scoring), timed end to end with its phases read from the fresh set's
manifest; and `clutterbench evaluate-agent docs/examples/random_agent.py:make_agent --fresh
200` (200 fresh episodes drawn, settled and run). Target: 200 fresh scenes scored within
5 min on the project's 2 cores. A fixed seed keeps the work the same from run to run; the
outputs go to a temporary folder, never to the leaderboard.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from clutterbench.bench import header, write_result
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json
from clutterbench.platform_info import cpu_description

SCENES = 200
SEED = 1
TARGET_S = 300.0
CLI = [sys.executable, "-m", "clutterbench.cli.__main__"]
PREDICTOR = "docs/examples/example_predictor.py"
AGENT = "docs/examples/random_agent.py:make_agent"


def _timed(args: list[str]) -> dict[str, Any]:
    """Run one command -> its wall time, CPU time of its processes and the load around it."""
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    c0 = os.times()
    out = subprocess.run(args, capture_output=True, text=True)
    c1 = os.times()
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise ClutterbenchError(f"bench fresh: {' '.join(args[3:5])} failed: {last}")
    return {
        "wall_s": time.perf_counter() - t0,
        "cpu_s": (c1.children_user + c1.children_system) - (c0.children_user + c0.children_system),
        "load_average_1min": [load0, os.getloadavg()[0]],
        # the command's headline, without the paths it wrote to (a temporary folder)
        "headline": out.stdout.strip().splitlines()[-1].split(" -> ")[0].split("; wrote")[0],
    }


def bench_fresh(out_dir: Path = Path("reports/bench"), scenes: int = SCENES) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="bench-fresh-") as tmp:
        board, sets = Path(tmp) / "board", Path(tmp) / "fresh"
        common = ["--fresh", str(scenes), "--seed", str(SEED), "--out"]
        predictor = _timed(
            [*CLI, "evaluate-predictor", PREDICTOR, *common, str(board), "--fresh-dir", str(sets)]
        )
        fresh = read_json(sets / str(SEED) / "manifest.json")["fresh"]
        agent = _timed([*CLI, "evaluate-agent", AGENT, *common, str(Path(tmp) / "agents")])
    phases = {k: fresh["seconds"][k] for k in ("label", "deletions_and_write")}
    phases["start_and_score"] = round(predictor["wall_s"] - sum(phases.values()), 2)
    result = {
        **cpu_description(),
        "torch_threads": 1,
        "scenes": scenes,
        "seed": SEED,
        "workers": fresh["workers"],
        "target_s": TARGET_S,
        "predictor": predictor | {"phases_s": phases},
        "agent": agent,
        "predictor_within_target": predictor["wall_s"] <= TARGET_S,
    }
    write_result(out_dir, "fresh", result, _markdown(result))
    print(
        f"fresh {scenes} scenes: {predictor['wall_s']:.1f} s ({phases}); "
        f"agent {agent['wall_s']:.1f} s"
    )
    return result


def _markdown(result: dict[str, Any]) -> list[str]:
    p, a, n = result["predictor"], result["agent"], result["scenes"]
    md = header(f"Trusted scores: {n} fresh scenes labelled and scored", result)
    md += [
        f"`clutterbench evaluate-predictor {PREDICTOR} --fresh {n} --seed {result['seed']}` and "
        f"`clutterbench evaluate-agent {AGENT} --fresh {n}`, each a fresh process, end to end "
        f"({result['workers']} labelling workers); target: {n} scenes scored within "
        f"{result['target_s']:g} s. CPU s: its processes' CPU time; load: the 1-minute load "
        "average before and after (other work on the machine slows the wall time).",
        "",
        "| command | wall (s) | CPU s | load | within target | result |",
        "|---|---|---|---|---|---|",
        f"| evaluate-predictor --fresh {n} | {p['wall_s']:.1f} | {p['cpu_s']:.1f} | "
        f"{_load(p)} | {'yes' if result['predictor_within_target'] else 'no'} | "
        f"{p['headline']} |",
        f"| evaluate-agent --fresh {n} | {a['wall_s']:.1f} | {a['cpu_s']:.1f} | {_load(a)} | — | "
        f"{a['headline']} |",
        "",
        "Where the predictor's time goes (s): "
        + ", ".join(f"{k.replace('_', ' ')} {v:.1f}" for k, v in p["phases_s"].items())
        + " (label: drawing, settling, rendering and simulating every removal and pull of each "
        "scene in the worker pool; deletions and write: the test set's deletion replay, one "
        "process; start and score: import, the reference set's check and the scoring).",
    ]
    return md


def _load(r: dict[str, Any]) -> str:
    return " → ".join(f"{v:.1f}" for v in r["load_average_1min"])
