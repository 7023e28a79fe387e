"""`python -m clutterbench.bench` (`make bench`): run every part in order -> reports/bench/.

A new part is one line in PARTS: a name and a callable taking no arguments.
"""

from __future__ import annotations

from collections.abc import Callable

from clutterbench.bench.grouped import bench_grouped
from clutterbench.bench.models import bench_models
from clutterbench.bench.sim import bench_replay, bench_sim
from clutterbench.bench.trials import bench_trials


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
]


def main() -> None:
    for _name, part in PARTS:
        part()


if __name__ == "__main__":
    main()
