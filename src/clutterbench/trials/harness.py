"""The trial harness shared by every chapter: episodes in parallel -> records + one MCAP.

A condition is a list of episode jobs and an episode function (a module-level function, so
worker processes can import it). Each worker process keeps one renderer and runs torch on one
thread, so an episode's bits do not depend on how many workers run: the same params and seed
give byte-identical records whatever `trials.workers` is. Results come back in episode
order; the parent writes `records.jsonl` (one JSON record per episode) and `episodes.mcap`
(every episode on one timeline, openable in Foxglove), both atomically.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.logs.mcap_episode import EpisodeWriter
from clutterbench.progress import progress_bar

EPISODE_GAP_S = 1.0
"""Simulated seconds left empty between two episodes on the condition's MCAP timeline."""
EPISODE_TOPIC = "/trial/episode"
DECISION_TOPIC = "/planner/decision"
OUTCOME_TOPIC = "/trial/outcome"


@dataclasses.dataclass
class EpisodeLog:
    """What an episode shows in the MCAP: events at simulated times (s from its start)."""

    events: list[tuple[float, str, Any]] = dataclasses.field(default_factory=list)
    record_images: bool = True

    def observation(self, t_s: float, depth_m: np.ndarray, instance: np.ndarray) -> None:
        if self.record_images:
            self.events.append((t_s, "depth", depth_m))
            self.events.append((t_s, "instance", instance))

    def poses(self, t_s: float, poses: np.ndarray) -> None:
        self.events.append((t_s, "poses", np.asarray(poses, dtype=np.float64)))

    def json(self, t_s: float, topic: str, payload: dict[str, Any]) -> None:
        self.events.append((t_s, topic, payload))

    @property
    def duration_s(self) -> float:
        return max((t for t, _, _ in self.events), default=0.0)


@dataclasses.dataclass
class EpisodeResult:
    record: dict[str, Any]
    """The episode's JSON record (plain JSON types only)."""
    log: EpisodeLog


EpisodeFn = Callable[[dict[str, Any]], EpisodeResult]


def _worker_init(torch_threads: int) -> None:
    from clutterbench.sim.render import ensure_renderer

    ensure_renderer()
    try:
        import torch

        torch.set_num_threads(torch_threads)
    except ImportError:  # pragma: no cover - torch is a dependency
        pass


def _call(args: tuple[EpisodeFn, dict[str, Any]]) -> EpisodeResult:
    fn, job = args
    return fn(job)


def run_episodes(
    label: str, fn: EpisodeFn, jobs: Sequence[dict[str, Any]], workers: int
) -> list[EpisodeResult]:
    """Run `fn` on every job (in worker processes when workers > 1), results in job order."""
    results: list[EpisodeResult] = []
    with progress_bar(label, total=len(jobs)) as advance:
        if workers == 1 or len(jobs) <= 1:
            _worker_init(1)
            for job in jobs:
                results.append(fn(job))
                advance(1)
        else:
            ctx = mp.get_context("spawn")  # fresh processes: one renderer each, no forked GL
            with ctx.Pool(min(workers, len(jobs)), _worker_init, (1,)) as pool:
                for result in pool.imap(_call, [(fn, job) for job in jobs]):
                    results.append(result)
                    advance(1)
    return results


def write_mcap(path: Path, results: Sequence[EpisodeResult], metadata: dict[str, str]) -> None:
    """Every episode on one timeline: episode k starts after episode k-1 ended plus a gap.
    /trial/episode marks each start (its record's header), /trial/outcome each end."""
    t0 = 0.0
    with EpisodeWriter(path, metadata) as ep:
        for res in results:
            head = {k: v for k, v in res.record.items() if not isinstance(v, list | dict)}
            ep.write_json(t0, EPISODE_TOPIC, head)
            for t_s, kind, payload in res.log.events:
                t = t0 + t_s
                if kind == "depth":
                    ep.write_depth(t, payload)
                elif kind == "instance":
                    ep.write_instance(t, payload)
                elif kind == "poses":
                    ep.write_poses(t, [f"box_{k}" for k in range(len(payload))], payload)
                else:
                    ep.write_json(t, kind, payload)
            end = t0 + res.log.duration_s
            ep.write_json(end, OUTCOME_TOPIC, head)
            t0 = end + EPISODE_GAP_S
        ep.set_outcome({"episodes": len(results)})
