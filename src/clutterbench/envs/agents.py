"""Agents for `ClutterShelfPlan-v1`: the project's own ch. 6 planners wrapped as gymnasium
policies, and a random agent. An agent factory takes the env and returns a policy: a
callable obs -> action, or an object with `act(obs)`; optional `reset(seed)` (called with the
episode index after each env reset) and `collapse_score(obs, pull, hold)` with `cp_max` (the
env stops a pull whose score exceeds it: Algorithm 1's abort, env.set_monitor).

    clutterbench evaluate-agent clutterbench.envs.agents:multi_step --episodes 200
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.envs.plan import NO_BOX, as_observation
from clutterbench.errors import ClutterbenchError


def agent_planners() -> list[str]:
    """The registered planners that can be agents (Planner.agent: they read only what the
    robot sees, and no network but the collapse predictor and the ch. 4 network)."""
    from clutterbench.trials.ch6.planners import PLANNERS

    return [name for name, p in PLANNERS.items() if p.agent]


def agent_planner(name: str) -> Any:
    """The declaration of planner `name`, one line if it cannot be an agent."""
    from clutterbench.trials.ch6.planners import PLANNERS, declared

    found = declared(name)
    if name not in PLANNERS or not found.agent:
        raise ClutterbenchError(
            f"planner {name!r}: not one that reads only observations "
            f"({', '.join(agent_planners())})"
        )
    return found


class PlannerAgent:
    """A planner of trials.ch6.PLANNERS as an agent: a new planner each episode, made by the
    registry's factory from the job the trials would give it (same network, support rule,
    thresholds chosen on validation scenes by the support stage, cp_max, random stream), so
    on a table's stream it makes the trials' decisions."""

    def __init__(
        self,
        env: Any,
        planner: str,
        rule: str = "coverage_gap",
        support: Any = None,
        cp_max: float | None = None,
        model_path: Path | None = None,
        ch4_model_path: Path | None = None,
    ):
        """`support`, `cp_max`, `model_path`, `ch4_model_path`: instead of the project's
        (the support stage's thresholds, trials.ch6.cp_max, models/<trials.ch6.model>/...)."""
        from clutterbench.trials.ch6.planners import chosen_support

        declared = agent_planner(planner)
        self.env = env.unwrapped
        src = self.env.source
        root = _project_root()
        ch6 = src.trials.ch6
        job = dataclasses.replace(self.env.job(0), planner=planner, rule=rule)
        self.cp_max = np.inf
        if "cp" in declared.networks:
            if support is None:
                thresholds = root / "reports/support/thresholds.json"
                method = declared.support_method(rule, ch6.pull_map_meaning)
                support = chosen_support(thresholds, method)
            if cp_max is None:
                cp_max = ch6.cp_max if ch6.cp_max is not None else support.score_threshold
            self.cp_max = cp_max
            job = dataclasses.replace(
                job,
                support=support,
                cp_max=cp_max,
                model_path=model_path or _require(root / f"models/{ch6.model}/best.pt", ch6.model),
            )
        if "ch4" in declared.networks:
            job = dataclasses.replace(
                job,
                ch4_model_path=ch4_model_path
                or _require(root / f"models/{ch6.ch4_model}/best.pt", ch6.ch4_model),
            )
        self.name, self.job = planner, job
        self.planner: Any = None
        self._seen: tuple[dict[str, Any], Any] | None = None
        self._decision: Any = None
        if not hasattr(self._make(0), "collapse_score"):
            self.collapse_score = None  # nothing to monitor the pulls with

    def _make(self, index: int) -> Any:
        from clutterbench.trials.ch6.planners import make_planner

        self.job = dataclasses.replace(self.job, index=index, stream=self.env.source.name)
        return make_planner(self.job, None)

    def reset(self, seed: int) -> None:
        self.planner = self._make(int(seed))

    def _observation(self, obs: dict[str, Any]) -> Any:
        if self._seen is not None and self._seen[0] is obs:
            return self._seen[1]  # the same Observation object the planner decided on
        return as_observation(obs)

    def act(self, obs: dict[str, Any]) -> tuple[int, int]:
        if self.planner is None:
            self.reset(self.env.episode_index or 0)
        seen = as_observation(obs)
        self._seen = (obs, seen)
        blocked = frozenset(int(k) for k in np.nonzero(obs["blocked"])[0])
        self._decision = None
        try:
            d = self.planner.decide(seen, int(obs["target"]), blocked)
        except ValueError:  # every action its rule allows is rejected: it gives up
            return NO_BOX, NO_BOX
        self._decision = d
        return d.pull, NO_BOX if d.hold is None else d.hold

    def last_decision(self) -> Any:
        """The planner's last Decision (its own abort threshold, a least-risk pull's: the
        env applies it to that step, envs/plan.py set_monitor)."""
        return self._decision

    def collapse_score(self, obs: dict[str, Any], pull: int, hold: int | None) -> float:
        return self.planner.collapse_score(self._observation(obs), pull, hold)


def _project_root() -> Path:
    from clutterbench.trials.core.streams import project_params_path

    return project_params_path().parent


def _require(path: Path, model: str) -> Path:
    if not path.is_file():
        raise ClutterbenchError(f"{path} missing; run `dvc repro train@{model}`")
    return path


def multi_step(env: Any) -> PlannerAgent:
    """Algorithm 1 with one arm (Table 6.3's multi-step row)."""
    return PlannerAgent(env, "multi_step")


def bimanual(env: Any) -> PlannerAgent:
    """Algorithm 1 with the bimanual option (Fig. 6.7)."""
    return PlannerAgent(env, "bimanual")


def single_step(env: Any) -> PlannerAgent:
    """The thesis' previous method (ch. 4 network): pull the target holding its support."""
    return PlannerAgent(env, "single_step")


def pull_target(env: Any) -> PlannerAgent:
    """Pull the target at once, nothing held."""
    return PlannerAgent(env, "pull_target")


def random_planner(env: Any) -> PlannerAgent:
    """The trials' random row (its own random stream per episode)."""
    return PlannerAgent(env, "random")


def random_agent(env: Any):
    """A uniformly random visible box each step (or the target), nothing held."""
    rng = np.random.default_rng(0)

    def act(obs: dict[str, Any]) -> tuple[int, int]:
        seen = obs["instance"][obs["instance"] > 0].astype(int) - 1  # instance k + 1: box k
        boxes = set(np.unique(seen).tolist()) | {int(obs["target"])}
        return int(rng.choice(sorted(boxes))), NO_BOX

    return act
