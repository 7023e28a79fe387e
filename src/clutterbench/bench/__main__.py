"""`python -m clutterbench.bench` (`make bench`): run every part in order -> reports/bench/.
`python -m clutterbench.bench ch3` runs the named parts only.

A new part is one line in PARTS: a name and a callable taking no arguments.
"""

from __future__ import annotations

from collections.abc import Callable

from clutterbench.bench.arm import bench_arm
from clutterbench.bench.box_planners import bench_box_planners
from clutterbench.bench.dvc_overhead import bench_dvc
from clutterbench.bench.envs import bench_envs
from clutterbench.bench.fresh import bench_fresh
from clutterbench.bench.grouped import bench_grouped
from clutterbench.bench.models import bench_models
from clutterbench.bench.physics_depth import bench_physics_depth
from clutterbench.bench.replenish import bench_ch5
from clutterbench.bench.scaling import bench_ray
from clutterbench.bench.sensor import bench_sensor
from clutterbench.bench.sim import bench_replay, bench_sim
from clutterbench.bench.sim_profile import bench_sim_profile
from clutterbench.bench.train_profile import bench_train_profile
from clutterbench.bench.train_rate import bench_train_rate
from clutterbench.bench.trials import bench_trials
from clutterbench.bench.trials_rate import bench_trials_rate
from clutterbench.bench.yamakuzushi import bench_ch3


def _sim() -> dict:
    res = bench_sim()
    for k, v in res.items():
        print(f"{k}: {v}")
    return res


PARTS: list[tuple[str, Callable[[], object]]] = [
    ("sim", _sim),  # sim.json, sim.md
    ("replay", bench_replay),  # replay.json (needs data/generate)
    ("models", bench_models),  # models.json, models.md (with the memory part)
    ("grouped", bench_grouped),  # grouped.json, grouped.md (needs data and trained models)
    ("trials", bench_trials),  # trials.json, trials.md (needs trained models)
    ("trials_rate", bench_trials_rate),  # trials_rate.json, .md (per condition; after support)
    ("ch3", bench_ch3),  # ch3.json, ch3.md (the ConvNet line needs models/slide_convnet)
    ("ch5", bench_ch5),  # ch5.json, ch5.md (needs the detector and the ch. 5 network)
    ("arm", bench_arm),  # arm.json, arm.md (ManiSkill Pandas vs the kinematic pull)
    ("physics_depth", bench_physics_depth),  # physics_depth.json, .md (no network needed)
    ("sensor", bench_sensor),  # sensor.json, .md (the depth-sensor model per image; no data)
    ("box_planners", bench_box_planners),  # box_planners.json, .md (needs the box head)
    ("envs", bench_envs),  # envs.json, envs.md (every registered env: make, reset, 5 steps)
    ("ray", bench_ray),  # ray.json, ray.md (both parallel backends, 1 and 2 workers; needs ray)
    ("train_rate", bench_train_rate),  # train_rate.json, .md (training FLOP/s vs matmul; no data)
    ("train_profile", bench_train_profile),  # train_profile.json, .md (a cp_focal epoch's slice)
    ("sim_profile", bench_sim_profile),  # sim_profile.json, .md (each sim stage's time, by kind)
    ("dvc", bench_dvc),  # dvc.json, dvc.md (dvc's own YAML work per stage; no data needed)
    ("fresh", bench_fresh),  # fresh.json, .md (200 fresh scenes labelled and scored; no data)
]


def main(names: list[str] | None = None) -> None:
    known = dict(PARTS)
    for name in names or list(known):
        if name not in known:
            raise SystemExit(f"error: no bench part {name!r} (parts: {', '.join(known)})")
        known[name]()


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
