"""The robust search oracles: the search oracles of Table 6.3 (trials/ch6/oracle.py), but a
simulated step counts as clean only when it is clean in the table's world and in each of
`noise.robust_draws` perturbed worlds (draws.py, drawn apart from the replays'), so the plan
found does not rest on a knife edge that only a search on the exact simulator can find. The
plan is executed, as every plan is, in the table's world."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from clutterbench.sim.pull import SceneState
from clutterbench.trials.ch6.episodes import run_ch6_episode
from clutterbench.trials.ch6.jobs import Ch6Job
from clutterbench.trials.ch6.oracle import Action, SearchOracle
from clutterbench.trials.ch6.planners import PLANNERS, register_planner
from clutterbench.trials.core.harness import EpisodeResult
from clutterbench.trials.noise.config import NoiseConfig
from clutterbench.trials.noise.draws import SEARCH, Draw, draw

CRITERIA = ("success", "strict_success")


class RobustSearchOracle(SearchOracle):
    """SearchOracle whose every simulated step must also be clean in `draws`."""

    def __init__(self, *args: Any, draws: list[Draw], **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.draws = draws
        self.draw_simulations = 0

    def simulate(
        self, state: SceneState, action: Action, cut_short: bool = True
    ) -> tuple[dict[str, Any], SceneState | None, np.ndarray | None]:
        step, after, disp = super().simulate(state, action, cut_short)
        if not any(step.get(k) for k in CRITERIA):
            return step, after, disp
        spec, physics = self.spec, self.physics
        step = dict(step)
        try:
            for d in self.draws:
                self.spec, self.physics = d.spec(spec, physics), d.physics(physics)
                self.draw_simulations += 1
                other, _, _ = super().simulate(
                    d.start(state, len(state.removed)), action, cut_short
                )
                for k in CRITERIA:
                    step[k] = bool(step.get(k)) and bool(other.get(k))
                if not any(step[k] for k in CRITERIA):
                    break
        finally:
            self.spec, self.physics = spec, physics
        return step, after, disp


def register_robust(cfg: NoiseConfig, seed: int) -> None:
    """Register `<oracle>_robust` for each search oracle the robust conditions mirror, its draws
    seeded by `seed`, the job's stream and episode (again in each worker: RobustEpisode)."""
    for base in sorted(set(cfg.robust.values())):
        declared = PLANNERS[base]
        factory = declared.factory

        def make(job: Ch6Job, spec: Any, factory: Any = factory) -> RobustSearchOracle:
            oracle = factory(job, spec)
            draws = [
                draw(cfg, seed, job.stream, job.index, k, spec.n, SEARCH)
                for k in range(cfg.robust_draws)
            ]
            fields = {
                f: getattr(oracle, f) for f in ("spec", "physics", "camera", "pull", "limits")
            }
            return RobustSearchOracle(
                **fields,
                holding=oracle.holding,
                cf=oracle.cf,
                hold_any_pull=oracle.hold_any_pull,
                draws=draws,
            )

        register_planner(
            f"{base}_robust",
            **{f: getattr(declared, f) for f in ("world", "holds", "role", "cost")},
            oracle=declared.ceiling,
        )(make)


@dataclasses.dataclass(frozen=True, kw_only=True, repr=False)
class RobustEpisode:
    """One robust-oracle episode: the search oracle's job, its planner `<oracle>_robust`."""

    job: Ch6Job
    noise: NoiseConfig

    def __getattr__(self, name: str) -> Any:  # condition, stream, index, seed: job_name's
        job = self.__dict__.get("job")
        if job is None or name.startswith("__"):
            raise AttributeError(name)
        return getattr(job, name)


def robust_episode(base: Ch6Job, condition: str, noise: NoiseConfig) -> RobustEpisode:
    """The robust twin of a search-oracle job: the same episode, the `_robust` planner."""
    job = dataclasses.replace(base, condition=condition, planner=f"{base.planner}_robust")
    return RobustEpisode(job=job, noise=noise)


def run_robust_episode(ep: RobustEpisode) -> EpisodeResult:
    """One robust-oracle episode (registering its planner in this process first)."""
    if ep.job.planner not in PLANNERS:
        register_robust(ep.noise, ep.job.seed)
    return run_ch6_episode(ep.job)
