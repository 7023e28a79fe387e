"""Sharded, parallel, resumable generation of labelled scenes (stage `generate`).

A dataset is `n_scenes` scenes cut into shards of `shard_size`; each shard is one .npz
written atomically, stamped with the hash of everything that determines its content. An
interrupted run continues from the finished shards; a shard made under other params is
regenerated. Same params and seed -> byte-identical shards.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import as_dict
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, save_npz, write_json
from clutterbench.parallel import ParallelConfig, iter_in_workers
from clutterbench.sim.config import REJECT_REASONS, SimConfig
from clutterbench.sim.labelling import LabelledScene, generate_labelled_scene
from clutterbench.sim.renderer import ensure_renderer

FORMAT_VERSION = 3  # 2: canonical-start labels, clusters, contacts, float64 labels; 3: a lone
# leaning box is C^r / C^l, replenish_shelved as thesis Fig. 5.9 (old shards are not reused)


def config_hash(
    dataset: str,
    ds: DatasetConfig,
    sim: SimConfig,
    seed: int,
    pull: tuple[float, float] | None = None,
) -> str:
    ds_fields = {k: v for k, v in as_dict(ds).items() if k != "moved_threshold_m"}
    if not ds.pull_outcomes:  # datasets without them keep their hash (finished shards resume)
        ds_fields.pop("pull_outcomes")
    else:
        ds_fields["pull_outcomes"] = list(pull or ())
    payload = {
        "format": FORMAT_VERSION,
        "dataset": dataset,
        "ds": ds_fields,
        "sim": as_dict(sim),
        "seed": seed,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


def shard_path(out_dir: Path, shard: int) -> Path:
    return out_dir / f"shard-{shard:05d}.npz"


def _shard_is_done(path: Path, digest: str) -> bool:
    if not path.exists():
        return False
    try:
        return str(load_npz(path)["config_hash"]) == digest
    except ClutterbenchError:
        return False  # corrupt (e.g. a crash of an older writer): regenerate it


def label_scene(
    dataset: str,
    ds: DatasetConfig,
    sim: SimConfig,
    seed: int,
    index: int,
    max_attempts: int,
    pull: tuple[float, float] | None = None,
) -> LabelledScene:
    """Scene `index` of a dataset configured by `ds` (regenerable alone); `pull`: the trials'
    (increment_m, lift_m), needed when ds.pull_outcomes."""
    return generate_labelled_scene(
        seed=seed,
        dataset=dataset,
        index=index,
        family_weights=dict(ds.families),
        catalogue=ds.catalogue,
        n_objects=ds.n_objects,
        pulls=ds.pulls,
        physics=sim.physics,
        camera=sim.camera,
        max_attempts=max_attempts,
        pull_outcome=pull if ds.pull_outcomes else None,
    )


def make_shard(job: dict[str, Any]) -> dict[str, Any]:
    """Generate and write one shard (in this process)."""
    arrays = shard_arrays(job)
    save_npz(job["path"], arrays)
    return {"shard": job["shard"], "scenes": len(arrays["scene_index"])}


def shard_arrays(job: dict[str, Any]) -> dict[str, np.ndarray]:
    """One shard's arrays, as its .npz stores them; runs in a worker (a process or a Ray
    task, perhaps on another machine: the caller writes the shard)."""
    ds: DatasetConfig = job["ds"]
    sim: SimConfig = job["sim"]
    ensure_renderer()
    scenes = [
        label_scene(job["dataset"], ds, sim, job["seed"], i, job["max_attempts"], job["pull"])
        for i in job["indices"]
    ]
    n_max = ds.n_objects[1]
    s = len(scenes)
    arrays: dict[str, np.ndarray] = {
        "config_hash": np.array(job["digest"]),
        "scene_index": np.array(job["indices"], dtype=np.int64),
        "n_objects": np.array([sc.spec.n for sc in scenes], dtype=np.int16),
        "family": np.array([sc.spec.family for sc in scenes]),
        "depth_m": np.stack([sc.depth_m for sc in scenes]).astype(np.float32),
        "instance": np.stack([sc.instance for sc in scenes]).astype(np.uint8),
        "sizes_m": np.zeros((s, n_max, 3), np.float32),
        "poses": np.zeros((s, n_max, 7), np.float64),
        "type_id": np.full((s, n_max), -1, np.int8),
        # float64: the displacements exactly as simulated, so a replay can be compared bit
        # for bit (tests/contract/test_replay.py).
        "removal_m": np.full((s, n_max, n_max), np.nan, np.float64),
        "contact": np.zeros((s, n_max, n_max), bool),
        "cluster_of": np.full((s, n_max), -1, np.int16),
        "cluster_class": np.full((s, n_max), -1, np.int8),
        "cluster_bbox_px": np.zeros((s, n_max, 4), np.float32),
        "spec_json": np.array([sc.spec.to_json() for sc in scenes]),
        "rejected": np.array(
            [[sc.rejected[r] for r in REJECT_REASONS] for sc in scenes], dtype=np.int32
        ),
        "steps": np.array([sc.steps for sc in scenes], dtype=np.int64),
    }
    if ds.pulls:
        arrays["pull_m"] = np.full((s, n_max, n_max + 1, n_max), np.nan, np.float64)
    if ds.pull_outcomes:
        for key in ("pullout_displacement_m", "pullout_drop_m", "pullout_tilt_deg"):
            arrays[key] = np.full((s, n_max, n_max), np.nan, np.float64)
        arrays["pullout_left_shelf"] = np.zeros((s, n_max, n_max), bool)
    for k, sc in enumerate(scenes):
        n, c = sc.spec.n, len(sc.cluster_class)
        arrays["sizes_m"][k, :n] = sc.spec.sizes_m
        arrays["poses"][k, :n] = sc.spec.poses
        if sc.spec.type_ids is not None:
            arrays["type_id"][k, :n] = sc.spec.type_ids
        arrays["removal_m"][k, :n, :n] = sc.removal_m
        for a, b in sc.contacts:
            arrays["contact"][k, a, b] = arrays["contact"][k, b, a] = True
        arrays["cluster_of"][k, :n] = sc.cluster_of
        arrays["cluster_class"][k, :c] = sc.cluster_class
        arrays["cluster_bbox_px"][k, :c] = sc.cluster_bbox_px
        if ds.pull_outcomes:
            po = sc.pull_outcome
            arrays["pullout_displacement_m"][k, :n, :n] = po.displacement_m
            arrays["pullout_drop_m"][k, :n, :n] = po.drop_m
            arrays["pullout_tilt_deg"][k, :n, :n] = po.tilt_deg
            arrays["pullout_left_shelf"][k, :n, :n] = po.left_shelf
        if ds.pulls:
            # support slot n (no support) is stored in the last slot, n_max
            arrays["pull_m"][k, :n, :n, :n] = sc.pull_m[:, :n]
            arrays["pull_m"][k, :n, n_max, :n] = sc.pull_m[:, n]
    return arrays


def generate_dataset(
    name: str,
    ds: DatasetConfig,
    gen: GenerateConfig,
    sim: SimConfig,
    seed: int,
    out_dir: Path,
    pull: tuple[float, float] | None = None,
    parallel: ParallelConfig | None = None,
) -> dict[str, Any]:
    """Write (or finish) every shard of dataset `name` under `out_dir`; returns the manifest.
    `pull`: the trials' (increment_m, lift_m), for a dataset with pull_outcomes; `parallel`:
    the backend the shards are made on (None: worker processes). Each shard is written here,
    atomically, as it comes back in shard order."""
    if ds.pull_outcomes and pull is None:
        raise ClutterbenchError(f"generate.datasets.{name}: pull_outcomes needs the trials' pull")
    out_dir.mkdir(parents=True, exist_ok=True)
    digest = config_hash(name, ds, sim, seed, pull)
    n_shards = -(-ds.n_scenes // gen.shard_size)
    for stale in out_dir.glob("shard-*.npz"):  # shards beyond a shrunken dataset
        if int(stale.stem.split("-")[1]) >= n_shards:
            stale.unlink()
    jobs = []
    for shard in range(n_shards):
        path = shard_path(out_dir, shard)
        if _shard_is_done(path, digest):
            continue
        lo, hi = shard * gen.shard_size, min((shard + 1) * gen.shard_size, ds.n_scenes)
        jobs.append(
            {
                "shard": shard,
                "indices": list(range(lo, hi)),
                "path": path,
                "ds": ds,
                "sim": sim,
                "seed": seed,
                "dataset": name,
                "digest": digest,
                "max_attempts": gen.max_attempts,
                "pull": pull,
            }
        )
    sizes = [len(j["indices"]) for j in jobs]
    made = iter_in_workers(
        f"generate {name}",
        shard_arrays,
        jobs,
        gen.workers,
        parallel,
        units=sizes,
        completed=ds.n_scenes - sum(sizes),
    )
    for job, arrays in zip(jobs, made):
        save_npz(job["path"], arrays)
    return write_manifest(name, ds, digest, n_shards, out_dir)


def write_manifest(
    name: str, ds: DatasetConfig, digest: str, n_shards: int, out_dir: Path
) -> dict[str, Any]:
    families: dict[str, int] = {}
    rejected = dict.fromkeys(REJECT_REASONS, 0)
    n_objects, steps = [], 0
    for shard in range(n_shards):
        z = load_npz(shard_path(out_dir, shard))
        for f in z["family"]:
            families[str(f)] = families.get(str(f), 0) + 1
        for r, c in zip(REJECT_REASONS, z["rejected"].sum(axis=0)):
            rejected[r] += int(c)
        n_objects += z["n_objects"].tolist()
        steps += int(z["steps"].sum())
    manifest = {
        "dataset": name,
        "config_hash": digest,
        "n_scenes": ds.n_scenes,
        "n_shards": n_shards,
        "shards": [shard_path(out_dir, s).name for s in range(n_shards)],
        "families": dict(sorted(families.items())),
        "rejected": rejected,
        "n_objects_mean": float(np.mean(n_objects)),
        "physics_steps": steps,
    }
    write_json(out_dir / "manifest.json", manifest)
    return manifest
