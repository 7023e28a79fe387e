"""Fresh pull-consequence scenes drawn and labelled (`clutterbench evaluate-predictor --fresh
N`): which scenes and from which seed streams is data/testset_fresh.py; here they are drawn and
labelled by the code that builds the test set, in the project's worker pool, and written as a
test set.

What is reused, not copied: a dataset source's scenes are drawn and labelled by
data.generate.label_scene (what stage generate runs for the dataset the test set copies), a
benchmark stream's by support.testset_starts.benchmark_start (what stage testset runs for the
ch. 6 streams' starts); the arrays, the deletion replay and the manifest come from
data.testset (labelled_arrays, export_testset), so a fresh set is a test set like the
published one, with the same loader, label kinds and thresholds (the reference set's)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from clutterbench.data.testset_fresh import (
    BENCHMARK,
    allocate,
    check_apart,
    check_camera,
    fresh_name,
    load_reference,
    stream_seed,
)
from clutterbench.errors import ClutterbenchError


def fresh_jobs(setting: Mapping[str, Any], counts: Mapping[str, int], seed: int) -> list[dict]:
    """One job per fresh scene: its source, its index in the source's fresh stream, the seeds;
    `setting`: the configs a job draws with (see fresh_testset)."""
    gen, trials = setting["generate"], setting["trials"]
    jobs = []
    for source, k in counts.items():
        if source.startswith(BENCHMARK):
            stream = source.removeprefix(BENCHMARK)
            if stream not in trials.streams:
                raise ClutterbenchError(f"fresh: the test set's source {source}: no such stream")
            cfg = trials.streams[stream]
        elif source in gen.datasets:
            cfg = gen.datasets[source]
        else:
            raise ClutterbenchError(f"fresh: the test set's source {source}: no such dataset")
        jobs += [
            {"source": source, "index": i, "seed": seed, "cfg": cfg, "setting": setting}
            for i in range(k)
        ]
    return jobs


def label_fresh(job: Mapping[str, Any]) -> tuple[Any, str, int, int]:
    """One fresh scene labelled (in a worker) -> (LabelledScene, source, index, target), as
    data.testset.labelled_arrays takes them."""
    from clutterbench.data.generate import label_scene
    from clutterbench.support.testset_starts import benchmark_start

    setting, source, i = job["setting"], job["source"], job["index"]
    seed = stream_seed(job["seed"])
    trials, sim = setting["trials"], setting["sim"]
    if source.startswith(BENCHMARK):
        name = fresh_name(source.removeprefix(BENCHMARK))
        scene, target = benchmark_start(name, job["cfg"], trials, sim, seed, i)
        return scene, f"{BENCHMARK}{name}", i, target
    pull = (trials.ch6.pull_increment_m, trials.ch6.grasp_lift_m)
    gen = setting["generate"]
    scene = label_scene(fresh_name(source), job["cfg"], sim, seed, i, gen.max_attempts, pull)
    return scene, fresh_name(source), i, -1


def fresh_testset(
    params: Mapping[str, Any],
    trials: Any,
    reference: Path,
    n: int,
    seed: int,
    out: Path,
    workers: int = 1,
) -> dict[str, Any]:
    """N fresh scenes (user seed `seed`) drawn in the proportions of the test set `reference`,
    labelled and written to out/ as a test set (scenes.npz, manifest.json, load_testset.py)
    with the reference's thresholds and visible-box threshold; returns its manifest, whose
    `fresh` entry names the seed, the stream seed and the reference. `trials`: the params'
    `trials` section (trials.config.TrialsConfig: its streams and the trials' pull), parsed
    by the caller: this layer stands below the trials and imports none of them."""
    from clutterbench.config import load_base, load_section
    from clutterbench.data.config import GenerateConfig
    from clutterbench.data.testset import export_testset, labelled_arrays
    from clutterbench.data.testset_load import load
    from clutterbench.io import write_json
    from clutterbench.parallel import iter_in_workers
    from clutterbench.sim.config import SimConfig

    ref = load_reference(reference)
    sim = load_section(SimConfig, "sim", params)
    check_camera(ref, sim.camera, reference)
    setting = {
        "generate": load_section(GenerateConfig, "generate", params),
        "trials": trials,
        "sim": sim,
    }
    counts = allocate(ref["sources"], n)
    names = [s.removeprefix(BENCHMARK) for s in counts]
    check_apart(params, load_base(params).seed, seed, names)
    jobs = fresh_jobs(setting, counts, seed)
    t0 = time.perf_counter()
    label = f"fresh: label {n} scenes"
    scenes = list(iter_in_workers(label, label_fresh, jobs, max(1, workers)))
    t1 = time.perf_counter()
    thresholds = dict(ref["thresholds"])
    manifest = export_testset(
        [labelled_arrays(scenes)], sim.camera, thresholds, ref["min_pixels"], out, sim.physics
    )
    seconds = {"label": t1 - t0, "deletions_and_write": time.perf_counter() - t1}
    manifest["fresh"] = {
        "scenes": n,
        "seed": seed,
        "stream_seed": stream_seed(seed),
        "counts": counts,
        "reference_sha256": ref["sha256"],
        "workers": max(1, workers),
        "seconds": {k: round(v, 2) for k, v in seconds.items()},
    }
    write_json(out / "manifest.json", manifest)  # the loader checks scenes.npz, not this
    load(out)  # the set loads as any test set does (hash, schema)
    return manifest
