"""The ch. 6 planner registry: one declaration per planner, read by every consumer.

A planner's module registers it with `register_planner(name, ...)`, declaring what it reads
(its collapse maps, its networks, how much of the world), whether it holds a box, its label,
its ceiling and its cost class. The trials build its job from that declaration, the report
labels its row and picks its oracle and truth rows, the decomposition and the paired table
pair it, the bench sorts it, the environments decide whether it can be an agent: nobody
tests a planner's name for a capability. Imports neither SAPIEN nor torch."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Literal

from clutterbench.data.trial_params import PULL_MAP_HEADS
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.ch6.jobs import Ch6Job

Factory = Callable[["Ch6Job", "SceneSpec"], Any]
Maps = Literal["deletion", "pull", "box", "box_physics", "truth", "pull_truth"]
NETWORKS = ("cp", "ch4", "box_head")
"""The checkpoints a planner may load: the collapse predictor (trials.ch6.model), the ch. 4
risk network (trials.ch6.ch4_model), the box head (stage box_head)."""

MAPS_TEXT = {
    "truth": "physics truth",
    "pull_truth": "physics truth of the pull",
}
"""How a trial record names truth maps (`collapse_maps`); predicted maps: Planner.maps_text."""


@dataclasses.dataclass(frozen=True)
class Planner:
    """What a ch. 6 planner is, as everything but its own factory needs to know it."""

    name: str
    """Its name in the registry: what a condition's `planner` says."""
    factory: Factory
    """factory(job, spec) -> an object with `decide(obs, target, blocked)` (docs/extending.md)."""
    label: str | None = None
    """How its row reads in Table 6.3 and its companions (None: its name)."""
    maps: Maps | None = None
    """The collapse maps it plans on by Algorithm 1 (a support rule and cp_max), None for a
    planner of another kind: the collapse predictor's deletion or pull head, the box head per
    box, the box head fused with each pull simulated on fitted boxes, or physics-truth maps of
    deleting a box or of the trials' pull."""
    networks: frozenset[str] = frozenset()
    """The checkpoints it loads (of NETWORKS)."""
    world: Literal["seen", "truth", "fitted"] = "seen"
    """How much of the world it reads: the observation only; the true scene (oracles and truth
    maps: not what a robot sees, so never an agent, never on the arm executor); boxes fitted to
    the observation, simulated (physics from depth, the fused box maps)."""
    holds: bool = False
    """Whether a second arm may hold a box during a pull: its ceiling is the holding search."""
    oracle: str | None = None
    """The search oracle its success is measured against (None: `oracle_hold` if it holds,
    else `oracle`)."""
    role: Literal["planner", "oracle", "floor"] = "planner"
    """A planner, a ceiling (a search oracle: what other rows are measured against) or a floor."""
    cost: Literal["instant", "network", "search"] = "instant"
    """Its cost class: no inference, network inference per step, or physics simulation per
    step (a search; the bench and the run-time docs group planners by it)."""
    truth: str | None = None
    """The same planner on physics-truth maps of what its maps mean (the decomposition's
    perception term), if one is registered."""
    pull_truth: str | None = None
    """The same planner on physics-truth maps of the trials' pull, where `truth` is of deletion
    (the decomposition's map-meaning term)."""
    baseline: str | None = None
    """The training-free planner it is paired against (Table 6.3's paired comparison)."""

    def __post_init__(self) -> None:
        unknown = set(self.networks) - set(NETWORKS)
        if unknown:
            raise ClutterbenchError(
                f"planner '{self.name}': unknown networks {sorted(unknown)} (known: "
                f"{', '.join(NETWORKS)})"
            )

    @property
    def row_label(self) -> str:
        return self.label or self.name

    @property
    def ceiling(self) -> str:
        """The search oracle it is measured against."""
        return self.oracle or ("oracle_hold" if self.holds else "oracle")

    @property
    def algorithm1(self) -> bool:
        """Plans by Algorithm 1 on collapse maps: it takes a support rule and cp_max."""
        return self.maps is not None

    @property
    def reads_truth_maps(self) -> bool:
        return self.maps in ("truth", "pull_truth")

    @property
    def reads_box_head(self) -> bool:
        return self.maps in ("box", "box_physics")

    @property
    def of_the_pull(self) -> bool:
        """Its maps mean the trials' pull (the pull head, per pixel or per box through the box
        head): its support thresholds are those chosen for that head."""
        return self.maps in ("pull", "box", "box_physics")

    @property
    def agent(self) -> bool:
        """Can run as an environment agent: it reads only the observation, and no network
        but the collapse predictor's and the ch. 4 network's."""
        return self.world == "seen" and "box_head" not in self.networks

    def support_method(self, rule: str, meaning: str = "moved") -> str:
        """The support stage's method (reports/support/thresholds.json `chosen`) whose
        thresholds it runs with: its rule, chosen on the deletion maps, or for a planner of
        the pull on the maps of the head of pull_map_meaning `meaning` (`pull_<rule>`,
        `pull_collapse_<rule>`)."""
        return f"{PULL_MAP_HEADS[meaning]}_{rule}" if self.of_the_pull else rule

    def maps_text(self, meaning: str) -> str | None:
        """How its record names its collapse maps (None: it plans on none)."""
        if self.maps is None:
            return None
        if self.maps in MAPS_TEXT:
            return MAPS_TEXT[self.maps]
        if self.maps == "deletion":
            return "predicted"
        text = f"predicted by the {PULL_MAP_HEADS[meaning]} head"
        if self.reads_box_head:
            text += " per box (box head)"
        if self.maps == "box_physics":
            text += ", fused with each pull simulated on the fitted boxes"
        return text


PLANNERS: dict[str, Planner] = {}
"""ch. 6 planner name -> its declaration: the registry the conditions' `planner` names."""


def register_planner(name: str, **declared: Any) -> Callable[[Factory], Factory]:
    """Register a ch. 6 planner factory under `name` with its declaration (the fields of
    Planner but name and factory; every one has a default, so `register_planner("x")` is a
    planner that reads only the observation, holds nothing and runs no network)."""

    def wrap(factory: Factory) -> Factory:
        PLANNERS[name] = Planner(name, factory, **declared)
        return factory

    return wrap


def planner_info(name: str) -> Planner:
    """The declaration of planner `name` (one line naming the known ones if none)."""
    try:
        return PLANNERS[name]
    except KeyError:
        raise ClutterbenchError(
            f"planner '{name}': not registered (known: {', '.join(PLANNERS)}; a module "
            "registering more goes in trials.planner_modules)"
        ) from None


def declared(name: str) -> Planner:
    """The declaration of planner `name`; for a name no module registered (an agent driving
    an environment, a record of another run's planner read by the report) the default one:
    it reads only the observation, holds nothing, has no label, no truth row, no baseline."""
    return PLANNERS.get(name) or Planner(name, _unregistered)


def _unregistered(job: Ch6Job, spec: SceneSpec | None) -> Any:
    raise ClutterbenchError(f"planner '{job.planner}': not registered")


def load_planners(modules: Sequence[str], names: Sequence[str]) -> None:
    """Import the modules that register extra planners, then check that every planner a
    condition names is registered (one line naming the first that is not)."""
    import importlib

    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ClutterbenchError(
                f"trials.planner_modules: cannot import {module} ({exc})"
            ) from None
    for name in names:
        planner_info(name)


def make_planner(job: Ch6Job, spec: SceneSpec | None) -> Any:
    """The planner of `job` for one episode on `spec`."""
    return planner_info(job.planner).factory(job, spec)
