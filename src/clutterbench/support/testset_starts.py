"""The ch. 6 table streams' benchmark starts (data/benchmark) for the pull-consequence test set:
each episode's settled start and target, read as the trials read them, rendered and labelled
with what deleting and what pulling each box does (the trials' own pull)."""

from __future__ import annotations

from typing import Any

from clutterbench.progress import progress_bar
from clutterbench.sim.labelling import label_spec
from clutterbench.sim.pull import SceneState, world_at
from clutterbench.sim.render import ensure_renderer, observe


def benchmark_starts(trials: Any, sim: Any, seed: int, streams: dict[str, int]) -> list[tuple]:
    """(LabelledScene, "benchmark:<stream>", episode index, target) for episodes 0..n-1 of
    each stream of `streams` (stream -> n)."""
    from clutterbench.trials.core.scenes import draw_target, draw_trial_spec

    ensure_renderer()
    pull = (trials.ch6.pull_increment_m, trials.ch6.grasp_lift_m)
    out = []
    with progress_bar("testset: benchmark starts", total=sum(streams.values())) as advance:
        for stream, n in streams.items():
            cfg = trials.streams[stream]
            for i in range(n):
                spec = draw_trial_spec(
                    stream, cfg, seed, i, sim.physics, sim.camera, trials.max_attempts
                )
                obs = observe(world_at(spec, SceneState.start(spec), sim.physics, True), sim.camera)
                target = draw_target(seed, stream, i, obs, trials.ch6.min_target_pixels, spec)
                out.append(
                    (
                        label_spec(spec, sim.physics, sim.camera, pull),
                        f"benchmark:{stream}",
                        i,
                        target,
                    )
                )
                advance(1)
    return out
