"""The physics-from-depth planner: rebuild the shelf from one depth image, simulate before
acting (Pathak and Muthusamy 2025 do this on real box stacks).

Each step: fit the visible boxes from the observation (`estimate`, e.g.
perception.box_fit.fit_boxes), hand them to a world model (`search`: build a scene from the
boxes, simulate candidate pulls in it and search sequences of them, trials/ch6/physics_model.py
with SAPIEN) and pull the first box of the sequence it finds; re-estimated from a fresh
observation after every executed step. Both are passed in, so this module imports no
simulator and a user can swap in another estimator or another physics model; the planner
gets the `Observation` and nothing else of the world. Estimated boxes map back to the
world's boxes through the instance ids of the masks they were fitted to (`BoxEstimate.ids`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from clutterbench.errors import PerceptionError
from clutterbench.observation import Observation
from clutterbench.perception.box_fit import BoxEstimate
from clutterbench.planning.ch6.extraction import Decision

EstimateFn = Callable[[Observation], BoxEstimate]
SearchFn = Callable[[BoxEstimate, int], tuple["list[tuple[int, int | None]] | None", dict]]
"""(estimate, target's index in it) -> (plan: [(pull, hold)] in the estimate's indices, or
None when no clean sequence was found; JSON-able info: search nodes, rest, ...)."""


class PhysicsFromDepthPlanner:
    """Pull the first box of a clean sequence found by simulation in the estimated scene;
    the target when none is found (or the target is not among the estimated boxes, or the
    observation gave no model: a PerceptionError, recorded in the step)."""

    def __init__(self, estimate: EstimateFn, search: SearchFn, holding: bool):
        self.estimate, self.search, self.holding = estimate, search, holding
        self.steps: list[dict[str, Any]] = []
        """Per decision: the estimate and the search's info (the trial record's)."""
        self.first: BoxEstimate | None = None
        """The estimate of the first observation (scored against the truth by the trials)."""

    @property
    def policy(self) -> str:
        return "physics_from_depth_hold" if self.holding else "physics_from_depth"

    def decide(self, obs: Observation, target: int, blocked: frozenset[int]) -> Decision:
        info: dict[str, Any] = {"policy": self.policy}
        try:
            est = self.estimate(obs)
            if self.first is None:
                self.first = est
            info["estimated"] = list(est.ids)
            t = est.index_of(target)
            if t is None:  # the target is not seen well enough to fit: pull it
                self.steps.append(info | {"target_missing": True})
                return Decision(target, None, info | {"plan": None})
            plan, found = self.search(est, t)
        except PerceptionError as exc:  # this observation gave no model: pull the target
            self.steps.append(info | {"perception_error": str(exc)})
            return Decision(target, None, info | {"plan": None, "perception_error": str(exc)})
        info |= found
        self.steps.append(dict(info))
        if not plan:
            return Decision(target, None, info | {"plan": None})
        mapped = [(est.ids[p], None if h is None else est.ids[h]) for p, h in plan]
        pull, hold = mapped[0]
        if pull in blocked:  # never happens without a monitor; kept safe
            return Decision(target, None, info | {"plan": None})
        return Decision(pull, hold, info | {"plan": [list(a) for a in mapped]})
