"""Make the benchmark scenes (sim/benchmark.py): the settled start, and the target, of every
episode of every table's test streams, drawn live once and written to data/benchmark/.

    python -m clutterbench.cli.benchmark_scenes                  # the params' base.scale
    python -m clutterbench.cli.benchmark_scenes --scales tiny default

`make benchmark-scenes` runs it for the tiny and default profiles (what the repository
commits). It never runs as a side effect: no stage writes data/benchmark/, and a regenerated
artifact is used only once params.yaml pins its new manifest hash (benchmark.manifest_sha256;
the command prints it). Entries are keyed by every input of their draw, so the scales share
the entries they have in common and an artifact made for more scales still serves each.

What it covers (each stream up to the most episodes any of its conditions runs):
- Table 6.3 and the arm-level rows: the ch. 6 streams' starts and targets;
- Tables 4.1 / arm: the ch. 4 streams' starts and targets;
- Table 5.2: the ch. 5 streams' starts (drawn with their "no free place" test);
- Table 6.2: the support test scenes' starts (trials/support);
- Fig. 3.15: the piles of the ch. 3 games.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

from clutterbench.config import load_base, load_params, load_section, project_params_path
from clutterbench.data.trial_scenes import stream_key
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_text
from clutterbench.sim import benchmark
from clutterbench.sim.config import SimConfig
from clutterbench.support.config import SupportEvalConfig
from clutterbench.trials.config import TrialsConfig


def scale_jobs(params: dict[str, Any], scale: str) -> list[dict[str, Any]]:
    """One job per (chapter, stream, episode) whose start the tables of `scale` read."""
    params = {**params, "base": {**dict(params.get("base") or {}), "scale": scale}}
    base = load_base(params)
    cfg = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    common = {
        "seed": base.seed,
        "physics": sim.physics,
        "camera": sim.camera,
        "max_attempts": cfg.max_attempts,
    }
    episodes: dict[tuple[str, str], int] = defaultdict(int)
    for cond in cfg.conditions.values():
        episodes["ch6", cond.stream] = max(episodes["ch6", cond.stream], cond.episodes)
    for cond in cfg.ch4_conditions.values():
        episodes["ch4", cond.stream] = max(episodes["ch4", cond.stream], cond.episodes)
    for arm in cfg.arm_conditions.values():
        if arm.of in cfg.conditions:
            key = ("ch6", cfg.conditions[arm.of].stream)
        else:
            key = ("ch4", cfg.ch4_conditions[arm.of].stream)
        episodes[key] = max(episodes[key], arm.episodes)
    jobs: list[dict[str, Any]] = []
    for (chapter, stream), n in sorted(episodes.items()):
        min_pixels = cfg.ch6.min_target_pixels if chapter == "ch6" else cfg.ch4.min_target_pixels
        jobs += [
            common
            | {
                "kind": chapter,
                "stream": stream,
                "stream_cfg": cfg.streams[stream],
                "index": i,
                "min_pixels": min_pixels,
            }
            for i in range(n)
        ]
    jobs += ch5_start_jobs(cfg, base.seed, sim)
    support = load_section(SupportEvalConfig, "support", params)
    jobs += [
        common
        | {
            "kind": "support",
            "stream": "support",
            "index": i,
            "support": support,
            "max_attempts": support.max_attempts,
        }
        for i in range(support.test_scenes)
    ]
    jobs += pile_jobs(params, base.seed)
    return jobs


def ch5_start_jobs(cfg: TrialsConfig, seed: int, sim: SimConfig) -> list[dict[str, Any]]:
    """The ch. 5 trials' own jobs (each a start job naming the trials' Ch5Job, "job"), one per
    distinct start (the start depends on the stream and the candidates' geometry, not on the
    planner)."""
    from clutterbench.trials.ch5.episodes import ch5_jobs

    jobs, seen = [], set()
    for name, cond in cfg.ch5_conditions.items():
        for job in ch5_jobs(
            name,
            cond,
            trials=cfg,
            sim=sim,
            seed=seed,
            prob_threshold=0.5,  # the collapse threshold: no start depends on it
            scene_type=cond.stream.removeprefix("ch5_"),
            record_images=False,
        ):
            if (cond.stream, job.index) not in seen:
                seen.add((cond.stream, job.index))
                jobs.append(
                    {
                        "kind": "ch5",
                        "condition": job.condition,
                        "stream": cond.stream,
                        "index": job.index,
                        "seed": job.seed,
                        "job": job,
                    }
                )
    return jobs


def pile_jobs(params: dict[str, Any], seed: int) -> list[dict[str, Any]]:
    from clutterbench.data.slides import pile_seed
    from clutterbench.trials.ch3.config import Ch3Config

    cfg = load_section(Ch3Config, "yamakuzushi", params)
    return [
        {
            "kind": "pile",
            "stream": "ch3_games",
            "index": g,
            "seed": pile_seed(seed, "ch3_games", g),
            "pile": cfg.pile,
        }
        for g in range(cfg.games.n_games)
    ]


def draw_start(job: dict[str, Any]) -> list[dict[str, Any]]:
    """Draw one job's start (and target) live, exactly as its trials stage does -> the
    entries it made."""
    with benchmark.recording() as entries:
        start_of(job, target=True)
    return list(entries)


def start_of(job: dict[str, Any], target: bool) -> Any:
    """One job's start as its trials stage reads it (from the artifact when it holds it, else
    drawn); with `target`, the ch. 4 / ch. 6 target too (from the start's first observation,
    as the episode draws it)."""
    kind = job["kind"]
    if kind in ("ch6", "ch4"):
        from clutterbench.data.trial_scenes import draw_target, draw_trial_spec

        spec = draw_trial_spec(  # the stream's settled scene job["index"], as every trial draws it
            job["stream"],
            job["stream_cfg"],
            job["seed"],
            job["index"],
            job["physics"],
            job["camera"],
            job["max_attempts"],
        )
        if target:
            obs = first_observation(spec, job)
            draw_target(job["seed"], job["stream"], job["index"], obs, job["min_pixels"], spec)
        return spec
    if kind == "ch5":
        from clutterbench.trials.ch5.episodes import draw_start as ch5_start

        return ch5_start(job["job"])[0]
    if kind == "support":
        from clutterbench.sim.labelling import dataset_start
        from clutterbench.sim.shelf import Shelf

        test = job["support"].test
        return dataset_start(
            job["seed"],
            stream_key("support"),
            job["index"],
            dict(test.families),
            test.catalogue,
            test.n_objects,
            job["physics"],
            job["camera"],
            job["max_attempts"],
            Shelf(),
        )[0]
    if kind == "pile":
        from clutterbench.sim.pile import generate_pile

        return generate_pile(job["pile"], job["seed"])
    raise ClutterbenchError(f"benchmark: unknown job kind {kind!r}")


def first_observation(spec: Any, job: dict[str, Any]) -> Any:
    """The observation an episode draws its target from: trials.ch6.Extraction's (the world
    at the canonical start) or trials.ch4.run_ch4_episode's (the world built from the spec)."""
    from clutterbench.sim.render import observe

    if job["kind"] == "ch6":
        from clutterbench.sim.pull import SceneState, world_at

        world = world_at(spec, SceneState.start(spec), job["physics"], render=True)
    else:
        from clutterbench.sim.physics import BoxWorld

        world = BoxWorld.from_spec(spec, job["physics"], render=True)
    return observe(world, job["camera"])


def target_key(job: dict[str, Any], spec: Any) -> str:
    """The artifact's key of a ch. 4 / ch. 6 job's target (trials.scenes.draw_target's)."""
    from clutterbench.data.trial_scenes import target_fields

    fields = target_fields(job["seed"], job["stream"], job["index"], job["min_pixels"], spec)
    return benchmark.entry_key("target", fields)


def check_round_trip(entry: dict[str, Any]) -> None:
    """A stored spec reloads to the very bytes it was drawn as."""
    from clutterbench.sim.spec import SceneSpec

    value = entry["value"]
    if "spec" in value:
        spec = SceneSpec.from_dict(json.loads(json.dumps(value["spec"])))
        if benchmark.scene_hash(spec) != value["scene_hash"]:
            raise ClutterbenchError(
                f"benchmark: {entry['stream']} scene {entry['index']} does not reload bit for bit"
            )


def write_artifact(root: Path, entries: list[dict[str, Any]], scales: list[str]) -> str:
    """data/benchmark/<stream>.jsonl and manifest.json (each written whole, then renamed);
    returns the manifest's sha256."""
    out = root / benchmark.DIR
    out.mkdir(parents=True, exist_ok=True)
    by_file: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)
    for e in entries:
        name = e["stream"].removeprefix("trials/").replace("/", "_") + ".jsonl"
        by_file[name][e["key"]] = e  # the same draw reached twice is one entry
    files = {}
    for name, keyed in sorted(by_file.items()):
        rows = sorted(keyed.values(), key=lambda e: (e["index"], e["kind"], e["key"]))
        text = "".join(json.dumps(e, sort_keys=True) + "\n" for e in rows)
        write_text(out / name, text)
        files[name] = {"sha256": benchmark.file_sha256(out / name), "entries": len(rows)}
    for stale in out.glob("*.jsonl"):
        if stale.name not in files:
            stale.unlink()
    manifest = {
        "about": "settled starts and targets of every table's test streams "
        "(python -m clutterbench.cli.benchmark_scenes)",
        "scales": scales,
        "files": files,
    }
    write_text(out / benchmark.MANIFEST, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return benchmark.file_sha256(out / benchmark.MANIFEST)


def main(argv: list[str] | None = None) -> int:
    from clutterbench.parallel import map_in_workers

    parser = argparse.ArgumentParser(prog="python -m clutterbench.cli.benchmark_scenes")
    parser.add_argument("--scales", nargs="+", help="scale profiles (default: base.scale)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    try:
        path = project_params_path()
        params = load_params(path)
        scales = args.scales or [load_base(params).scale]
        jobs = [j for s in scales for j in scale_jobs(params, s)]
        results = map_in_workers("benchmark scenes", draw_start, jobs, args.workers)
        entries = [e for r in results for e in r]
        for e in entries:
            check_round_trip(e)
        digest = write_artifact(path.parent, entries, scales)
    except ClutterbenchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    pin = (params.get("benchmark") or {}).get("manifest_sha256")
    kinds: dict[str, int] = defaultdict(int)
    for e in entries:
        kinds[e["kind"]] += 1
    print(
        f"benchmark scenes: {len(jobs)} starts for {', '.join(scales)} -> {benchmark.DIR} "
        f"({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})"
    )
    if pin == digest:
        print(f"manifest sha256 {digest}: the same as params.yaml's pin")
    else:
        print(
            f"manifest sha256 {digest}: params.yaml pins {pin}; set benchmark.manifest_sha256 "
            "to the new hash and commit both to use these scenes"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
