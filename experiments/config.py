"""Params of the dev-stream commands (section `dev` of experiments/params.yaml): the dev
streams and each recheck.

Imports no SAPIEN and no torch (the checks read configs only).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import yaml

from clutterbench.config import bounded, load_section, parse
from clutterbench.errors import ClutterbenchError
from clutterbench.trials.condition_sets import Sensing
from clutterbench.trials.config import DEV_PREFIX, SceneStreamConfig, TrialsConfig

PARAMS = Path(__file__).resolve().parent / "params.yaml"
"""The rechecks' params (section `dev`); the stages' params.yaml never holds them."""


@dataclasses.dataclass(frozen=True)
class Ch4PilesConfig:
    """The ch. 4 training-pile recheck (`python -m experiments.ch4_piles`)."""

    model: str = "ch4_various"
    """The ch. 4 network retrained on each pile range (a key of train.models)."""
    pile_ranges: tuple[tuple[int, int], ...] = ((6, 6), (5, 10))
    """Candidate box counts per training pile (its dataset's n_objects; all else as params')."""
    streams: tuple[str, ...] = ("dev_ch4_10", "dev_ch4_5")
    """Dev streams the risk planner runs on with each network (keys of dev.streams)."""
    episodes: int = bounded(100, ge=1)
    """Trials per network and stream."""
    oracle: bool = True
    """Also the oracle on the same scenes: the ceiling each network falls below."""

    def __post_init__(self) -> None:
        if len(set(self.pile_ranges)) < 2 or len(set(self.pile_ranges)) < len(self.pile_ranges):
            raise ValueError("ch4_piles.pile_ranges: need two or more different ranges to compare")
        for lo, hi in self.pile_ranges:
            if not 1 <= lo <= hi:
                raise ValueError(f"ch4_piles.pile_ranges: [{lo}, {hi}] is not a range of boxes")
        if not self.streams:
            raise ValueError("ch4_piles.streams: no dev stream to run on")


def check_training(check: str, training: Sequence[str]) -> None:
    """A sensed-training recheck compares two or more different training presets."""
    if len(set(training)) < 2 or len(set(training)) < len(training):
        raise ValueError(f"{check}.training: need two or more different presets")


@dataclasses.dataclass(frozen=True)
class Ch4SensingConfig:
    """The ch. 4 sensed-training recheck (`python -m experiments.ch4_sensing`)."""

    model: str = "ch4_various"
    """The ch. 4 network retrained with each training sensor (a key of train.models)."""
    training: tuple[Sensing, ...] = ("ideal", "d415")
    """Candidate train.sensing presets (ideal: the parametric noise of train.noise); each
    network is trained on the pipeline's dataset, all else as params'."""
    sensing: Sensing = "d415"
    """The sensor of the trials' pictures (trials.ch4_sensed's), masks by region growing."""
    streams: tuple[str, ...] = ()
    """Dev streams the risk planner runs on with each network (keys of dev.streams)."""
    episodes: int = bounded(100, ge=1)
    """Trials per network and stream."""
    oracle: bool = True
    """Also the oracle on the same scenes: the ceiling each network falls below."""

    def __post_init__(self) -> None:
        check_training("ch4_sensing", self.training)


@dataclasses.dataclass(frozen=True)
class DetectorSensingConfig:
    """The detector's sensed-training recheck (`python -m experiments.detector_sensing`)."""

    training: tuple[Sensing, ...] = ("ideal", "d415")
    """Candidate detector.sensing presets (ideal: the parametric noise of detector.noise); the
    first is the one every other is compared with."""
    scored_on: tuple[Sensing, ...] = ("ideal", "d415")
    """The sensors whose returns of the val images each network is scored on."""
    bootstrap: int = bounded(1000, ge=10)
    """Scene bootstrap draws for the interval of each mAP difference."""

    def __post_init__(self) -> None:
        check_training("detector_sensing", self.training)
        if not self.scored_on or len(set(self.scored_on)) < len(self.scored_on):
            raise ValueError("detector_sensing.scored_on: one or more different presets")


@dataclasses.dataclass(frozen=True)
class Ch5SensingConfig:
    """The ch. 5 network's sensed-training recheck (`python -m experiments.ch5_sensing`)."""

    training: tuple[Sensing, ...] = ("ideal", "d415")
    """Candidate train.sensing presets of trials.ch5.model (ideal: the parametric noise of
    train.noise); each network is trained on the pipeline's dataset, all else as params'."""
    sensing: Sensing = "d415"
    """The sensor of the trials' pictures (trials.ch5_sensed's); the planner's clusters come
    from the detector trained on its images (models/detector_<sensing>)."""
    streams: tuple[str, ...] = ()
    """Dev streams of the ch. 5 trial families the planner runs on (keys of dev.streams)."""
    episodes: int = bounded(100, ge=1)
    """Trials per network and stream."""
    oracle: bool = True
    """Also the oracle on the same scenes (the generator's clusters, the world's outcomes)."""

    def __post_init__(self) -> None:
        check_training("ch5_sensing", self.training)
        if self.sensing == "ideal":
            raise ValueError("ch5_sensing.sensing: a sensor preset (the trials' pictures)")


@dataclasses.dataclass(frozen=True)
class Ch6SensingConfig:
    """The ch. 6 CP's sensed-training recheck (`python -m experiments.ch6_sensing`)."""

    training: tuple[Sensing, ...] = ("ideal", "d415")
    """Candidate train.sensing presets of trials.ch6.model, every head (as ch5_sensing's)."""
    sensing: Sensing = "d415"
    """The sensor of the trials' pictures (trials.sensed's), masks by region growing."""
    planners: tuple[str, ...] = ("multi_step_pull", "bimanual_pull")
    """Planners reading the CP alone, beside each one's Table 6.3 baseline (same sensing)."""
    streams: tuple[str, ...] = ()
    """Dev streams of the ch. 6 trial families (keys of dev.streams)."""
    episodes: int = bounded(100, ge=1)
    """Trials per network, planner and stream."""
    oracle: bool = True
    """Also both search oracles on the same scenes (they read the world)."""
    parts: bool = True
    """Also the params' network's planners and baselines under each of ch6_sensing.PARTS."""

    def __post_init__(self) -> None:
        check_training("ch6_sensing", self.training)
        if self.sensing == "ideal":
            raise ValueError("ch6_sensing.sensing: a sensor preset (the trials' pictures)")
        if not self.planners:
            raise ValueError("ch6_sensing.planners: no planner to run")


VARIED = ("blocker_goal", "upright_footprint")
"""The trials.ch5 fields a ch. 5 planner variant may set."""


@dataclasses.dataclass(frozen=True)
class Ch5PlannerConfig:
    """The ch. 5 planner recheck (`python -m experiments.ch5_planner`)."""

    streams: tuple[str, ...] = ()
    """Dev streams of the ch. 5 trial families (keys of dev.streams; params.yaml names them)."""
    variants: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)
    """Name -> trials.ch5 fields it sets (VARIED); every variant is compared with the first."""
    planners: tuple[Literal["replenish", "contact"], ...] = ("replenish",)
    """The planners run under every variant (trials.config.CH5_PLANNERS): the thesis' with
    collapse prediction, and the one that may push what stands in a blocker's way; each is
    compared with the first."""
    perceptions: tuple[Literal["detector", "clusters"], ...] = ("detector", "clusters")
    """The planner's clusters: the trained detector's, the generator's ground truth, or both."""
    episodes: int = bounded(100, ge=1)
    """Trials per variant, arm and stream."""
    oracle: bool = True
    """Also each variant's oracle on the same scenes."""

    def __post_init__(self) -> None:
        from clutterbench.trials.config import Ch5TrialParams

        if self.variants and len(self.variants) < 2:
            raise ValueError("ch5_planner.variants: need two or more variants to compare")
        for name, over in self.variants.items():
            if not isinstance(over, Mapping):
                raise ValueError(f"ch5_planner.variants.{name}: a mapping of trials.ch5 fields")
            for key in over:
                if key not in VARIED:
                    raise ValueError(
                        f"ch5_planner.variants.{name}.{key}: a variant sets only "
                        f"{', '.join(VARIED)}"
                    )
            try:
                parse(Ch5TrialParams, dict(over), f"variants.{name}")
            except ClutterbenchError as exc:
                raise ValueError(str(exc)) from None
        if not self.planners:
            raise ValueError("ch5_planner.planners: no planner to run")
        if not self.perceptions:
            raise ValueError("ch5_planner.perceptions: no perception to run the planner with")


CH6_VARIED = (
    "abort_response",
    "pull_map_meaning",
    "pull_prob_threshold",
    "pull_score_threshold",
    "when_no_plan",
    "idle_hold_share",
    "idle_hold_prob",
    "score_over",
    "pull_watch_m",
    "hold_feared",
    "truth_hold",
    "box_hold",
    "fit_hypotheses",
    "fit_noise_mm",
    "box_contact",
    "box_cp_max",
    "box_edge_precision",
    "abort_release",
    "held_release",
)
"""The trials.ch6 fields a ch. 6 pull-planner variant may set."""


@dataclasses.dataclass(frozen=True)
class Ch6PullConfig:
    """The ch. 6 pull-planner recheck (`python -m experiments.ch6_pull`)."""

    streams: tuple[str, ...] = ()
    """Dev streams of the ch. 6 trial families (keys of dev.streams; params.yaml names them)."""
    variants: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)
    """Name -> trials.ch6 fields it sets (CH6_VARIED); every variant is compared with the first."""
    planners: tuple[str, ...] = ("multi_step_pull_truth", "bimanual_pull_truth")
    """ch. 6 planners run under every variant (names in trials.ch6.PLANNERS)."""
    episodes: int = bounded(100, ge=1)
    """Episodes per variant, planner and stream."""
    oracle: bool = True
    """Also both search oracles on the same scenes (they read no variant): the ceilings."""
    against: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Planner -> the planner it is also compared with, under each variant, episode by
    episode (both in `planners`); with it, one variant is enough."""
    sensing: Sensing = "ideal"
    """The planners' sensor (box head, thresholds: that sensor's); the oracles read the world."""
    perception: Literal["instance", "depth"] = "instance"
    """The planners' masks: the simulator's, or region growing on the (sensed) depth."""

    def __post_init__(self) -> None:
        from clutterbench.trials.config import Ch6TrialParams

        if len(self.variants) < 2 and not (self.variants and self.against):
            raise ValueError(
                "ch6_pull.variants: need two or more variants to compare (or one, with "
                "planners to compare in `against`)"
            )
        for a, b in self.against.items():
            for name in (a, b):
                if name not in self.planners:
                    raise ValueError(f"ch6_pull.against: {name} is not among the planners")
        for name, over in self.variants.items():
            if not isinstance(over, Mapping):
                raise ValueError(f"ch6_pull.variants.{name}: a mapping of trials.ch6 fields")
            for key in over:
                if key not in CH6_VARIED:
                    raise ValueError(
                        f"ch6_pull.variants.{name}.{key}: a variant sets only "
                        f"{', '.join(CH6_VARIED)}"
                    )
            try:
                parse(Ch6TrialParams, dict(over), f"variants.{name}")
            except ClutterbenchError as exc:
                raise ValueError(str(exc)) from None
        if not self.planners:
            raise ValueError("ch6_pull.planners: no planner to run")


@dataclasses.dataclass(frozen=True)
class PerturbedFitConfig:
    """The perturbed-fit recheck (`python -m experiments.perturbed_fit`)."""

    streams: tuple[str, ...] = ()
    """Dev streams whose scenes it draws (params.yaml: dev_ch6_3_10)."""
    seeds: tuple[int, ...] = (101, 102, 103, 104)
    """Seeds of the recheck's own (each draws other scenes of every stream)..."""
    depth_noise_m: tuple[float, ...] = (0.001, 0.002, 0.003, 0.004)
    """... and the depth noise (standard deviation, m) of each seed's run."""
    scenes: int = bounded(160, ge=1)
    """Scenes per stream and seed."""

    def __post_init__(self) -> None:
        if not self.seeds or len(self.seeds) != len(self.depth_noise_m):
            raise ValueError("perturbed_fit: give one depth_noise_m per seed")
        if any(not 0.0 <= s < 0.05 for s in self.depth_noise_m):
            raise ValueError("perturbed_fit.depth_noise_m: each in [0, 0.05) m")


@dataclasses.dataclass(frozen=True)
class DevConfig:
    """Dev streams and the rechecks run on them; no stage reads this section."""

    streams: Mapping[str, SceneStreamConfig] = dataclasses.field(default_factory=dict)
    """Dev stream name (dev_*) -> the scenes it draws, seeded from base.seed and its name."""
    ch4_piles: Ch4PilesConfig = Ch4PilesConfig()
    """The ch. 4 training-pile recheck."""
    ch4_sensing: Ch4SensingConfig = Ch4SensingConfig()
    """The ch. 4 sensed-training recheck (train the network on the sensor's images?)."""
    detector_sensing: DetectorSensingConfig = DetectorSensingConfig()
    """The detector's sensed-training recheck (train the detector on the sensor's images?)."""
    ch5_sensing: Ch5SensingConfig = Ch5SensingConfig()
    """The ch. 5 network's sensed-training recheck (train it on the sensor's images?)."""
    ch6_sensing: Ch6SensingConfig = Ch6SensingConfig()
    """The ch. 6 CP's sensed-training recheck (train it on the sensor's images?)."""
    ch5_planner: Ch5PlannerConfig = Ch5PlannerConfig()
    """The ch. 5 planner recheck (how a blocker is carried)."""
    perturbed_fit: PerturbedFitConfig = PerturbedFitConfig()
    """The perturbed-fit recheck (no box fit raises out of a stage)."""
    ch6_pull: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"block": {}, "learn": {}})
    )
    """The ch. 6 pull-planner recheck (what an abort teaches the graph, what the maps mean)."""
    ch6_pull_thresholds: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"support": {}, "other": {}})
    )
    """The same recheck over the pull-head CP planners' thresholds (python -m
    experiments.ch6_pull ch6_pull_thresholds)."""
    ch6_pull_watch: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"off": {}, "on": {}})
    )
    """The same recheck over the pull-head CP planners' watch of their pull
    (trials.ch6.pull_watch_m; python -m experiments.ch6_pull ch6_pull_watch)."""
    ch6_no_plan: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"give_up": {}, "least_risk": {}})
    )
    """The same recheck over what the pull planners do when their rule rejects every
    candidate (trials.ch6.when_no_plan; python -m experiments.ch6_pull ch6_no_plan)."""
    ch6_no_plan_thresholds: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"support": {}, "other": {}})
    )
    """The pull-head CP planners' thresholds once a decision that rejects every candidate
    pulls the least risky one (python -m experiments.ch6_pull ch6_no_plan_thresholds)."""
    ch6_idle_hold: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"idle": {}, "hold": {}})
    )
    """The bimanual pull planners' idle arm (trials.ch6.idle_hold_share; python -m
    experiments.ch6_pull ch6_idle_hold)."""
    ch6_clear: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"contact": {}, "visible": {}})
    )
    """Whose shares the pull planners' collapse score takes, and clearing around a rejected
    plan (trials.ch6.score_over, when_no_plan clear; python -m experiments.ch6_pull
    ch6_clear)."""
    ch6_hold: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(variants={"leave_out": {}, "simulate": {}})
    )
    """How the bimanual pull planners score and choose a held pull (trials.ch6.truth_hold,
    hold_feared; python -m experiments.ch6_pull ch6_hold)."""
    ch6_vs_pfd: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"current": {}},
            planners=("multi_step_pull", "physics_from_depth"),
            against={"multi_step_pull": "physics_from_depth"},
        )
    )
    """The pull-head CP planners against physics from depth, episode by episode (`against`;
    python -m experiments.ch6_pull ch6_vs_pfd)."""
    ch6_box: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"current": {}},
            planners=("multi_step_box", "physics_from_depth"),
            against={"multi_step_box": "physics_from_depth"},
        )
    )
    """The box-head planners against physics from depth and the pixel pull planners (python
    -m experiments.ch6_pull ch6_box)."""
    ch6_box_physics: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"current": {}},
            planners=("multi_step_box_physics", "physics_from_depth"),
            against={"multi_step_box_physics": "physics_from_depth"},
            oracle=False,
        )
    )
    """The learned-plus-physics planners against physics from depth, episode by episode (a
    section of its own: each decision simulates every pull it asks the box head about; python -m
    experiments.ch6_pull ch6_box_physics)."""
    ch6_box_hold: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"leave_out": {}, "simulate": {"box_hold": "simulate"}},
            planners=("bimanual_box_physics",),
            oracle=False,
        )
    )
    """How the learned-plus-physics bimanual planner scores a held pull (trials.ch6.box_hold;
    python -m experiments.ch6_pull ch6_box_hold)."""
    ch6_fit_hypotheses: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"one": {}, "four": {"fit_hypotheses": 4}},
            planners=("multi_step_box_physics", "bimanual_box_physics"),
            oracle=False,
        )
    )
    """How many scenes the learned-plus-physics planners fit to one observation
    (trials.ch6.fit_hypotheses, fit_noise_mm); each variant's fusion chosen again on the
    support stage's val scenes (python -m experiments.ch6_pull ch6_fit_hypotheses)."""
    ch6_box_contact: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"head": {}, "learned": {"box_contact": "learned"}},
            planners=("multi_step_box_physics", "bimanual_box_physics"),
            oracle=False,
        )
    )
    """The contact in the learned-plus-physics planners' support edges (trials.ch6.box_contact);
    each variant's fusion chosen again on the support stage's val scenes (python -m
    experiments.ch6_pull ch6_box_contact)."""
    ch6_box_cp_max: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"support": {}, "lower": {"box_cp_max": 0.3}},
            planners=("multi_step_box_physics", "bimanual_box_physics"),
            oracle=False,
        )
    )
    """The box planners' cp_max (trials.ch6.box_cp_max): the support stage's outcome
    threshold or lower (python -m experiments.ch6_pull ch6_box_cp_max)."""
    ch6_box_edge: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"support": {}, "precise": {"box_edge_precision": 0.9}},
            planners=("multi_step_box_physics", "bimanual_box_physics"),
            oracle=False,
        )
    )
    """The learned-plus-physics planners' support graph (trials.ch6.box_edge_precision,
    box_contact); each variant's fusion chosen again on the support stage's val scenes
    (python -m experiments.ch6_pull ch6_box_edge)."""
    ch6_release: Ch6PullConfig = dataclasses.field(
        default_factory=lambda: Ch6PullConfig(
            variants={"drop": {}, "lower": {"held_release": "lower"}},
            planners=("oracle_hold", "bimanual_pull"),
            oracle=False,
        )
    )
    """How a pulled box aborted mid-pull and a held box are let go (trials.ch6.abort_release,
    held_release), every planner and the search oracles under each variant alike (python -m
    experiments.ch6_pull ch6_release)."""

    def __post_init__(self) -> None:
        for name in self.streams:
            if not name.startswith(DEV_PREFIX):
                raise ValueError(f"streams.{name}: a dev stream's name starts with '{DEV_PREFIX}'")
        for check in (f.name for f in dataclasses.fields(self) if f.name != "streams"):
            for name in getattr(getattr(self, check), "streams", ()):
                if name not in self.streams:
                    raise ValueError(
                        f"{check}.streams: unknown dev stream '{name}' "
                        f"(known: {', '.join(self.streams) or 'none'})"
                    )


def check_dev_streams(dev: DevConfig, trials: TrialsConfig) -> None:
    """Dev runs and the tables never share scenes: no table stream is named like a dev stream
    (so no table condition, whose stream must be a table stream, runs on one), and no dev
    stream's seed key (trials.scenes.stream_key) is a table stream's."""
    from clutterbench.data.trial_scenes import stream_key

    for name in trials.streams:
        if name.startswith(DEV_PREFIX):
            raise ClutterbenchError(
                f"trials.streams.{name}: a table stream may not be named like a dev stream "
                f"('{DEV_PREFIX}*'); move it to dev.streams or rename it"
            )
    table = {stream_key(name): name for name in trials.streams}
    for name in dev.streams:
        if stream_key(name) in table:
            raise ClutterbenchError(
                f"dev.streams.{name}: draws the scenes of table stream "
                f"trials.streams.{table[stream_key(name)]}"
            )


def with_dev(params: Mapping[str, Any], path: Path = PARAMS) -> dict[str, Any]:
    """`params` (params.yaml's) with the `dev` section of experiments/params.yaml, unless it
    has one already (a test's params)."""
    if "dev" in params:
        return dict(params)
    return {**params, "dev": yaml.safe_load(path.read_text())["dev"]}


def load_dev(params: Mapping[str, Any]) -> DevConfig:
    """The `dev` section at params' scale (base.scale of params.yaml)."""
    return load_section(DevConfig, "dev", with_dev(params))
