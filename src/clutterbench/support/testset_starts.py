"""The ch. 6 table streams' benchmark starts (data/benchmark) for the pull-consequence test set:
each episode's settled start and target, read as the trials read them, rendered and labelled
with what deleting and what pulling each box does (the trials' own pull)."""

from __future__ import annotations

from typing import Any

from clutterbench.progress import progress_bar
from clutterbench.sim.labelling import label_spec
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import observe
from clutterbench.sim.renderer import ensure_renderer


def benchmark_starts(trials: Any, sim: Any, seed: int, streams: dict[str, int]) -> list[tuple]:
    """(LabelledScene, "benchmark:<stream>", episode index, target) for episodes 0..n-1 of
    each stream of `streams` (stream -> n)."""
    ensure_renderer()
    out = []
    with progress_bar("testset: benchmark starts", total=sum(streams.values())) as advance:
        for stream, n in streams.items():
            for i in range(n):
                scene, target = benchmark_start(
                    stream, trials.streams[stream], trials, sim, seed, i
                )
                out.append((scene, f"benchmark:{stream}", i, target))
                advance(1)
    return out


def benchmark_start(
    stream: str, cfg: Any, trials: Any, sim: Any, seed: int, index: int
) -> tuple[Any, int]:
    """(LabelledScene, target) of episode `index` of the seed stream `stream` drawn with `cfg`
    (a SceneStreamConfig): one test-set scene, also what `clutterbench evaluate-predictor
    --fresh` labels on streams of its own (data/testset_fresh.py)."""
    from clutterbench.data.trial_scenes import StreamStart

    pull = (trials.ch6.pull_increment_m, trials.ch6.grasp_lift_m)
    start = StreamStart(stream, cfg, seed, index, sim.physics, sim.camera, trials.max_attempts)
    spec = start.spec()
    obs = observe(world_at(spec, SceneState.start(spec), sim.physics, True), sim.camera)
    target = start.target(obs, trials.ch6.min_target_pixels, spec)
    return label_spec(spec, sim.physics, sim.camera, pull), target
