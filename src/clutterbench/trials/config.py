"""Params of the simulated trials (the `trials` section of params.yaml).

Imports no SAPIEN and no torch, so that the report stage can read them. A stream's scenes
(SceneStreamConfig) and the pull heads' names (PULL_MAP_HEADS) are data/trial_params.py's:
the support stage, which stands below the trials, reads them too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, Literal

from clutterbench.config import bounded, cores_field
from clutterbench.criteria import CollapseFreeConfig
from clutterbench.data.trial_params import PULL_MAP_HEADS, SceneStreamConfig  # noqa: F401 (re-exported)
from clutterbench.errors import ClutterbenchError
from clutterbench.maniskill.config import ArmConfig
from clutterbench.trials.ch6_groups import PullExecution, PullLevers, SearchLimits
from clutterbench.trials.condition_sets import OptInRows, SensedRows, Sensing

DEV_PREFIX = "dev_"
"""Every dev stream's name starts with it (experiments/params.yaml), and no table stream's does."""


@dataclasses.dataclass(frozen=True)
class ConditionConfig:
    """One chapter 6 trials condition (run by stage trials with every other)."""

    planner: str
    """Policy: a name registered in trials.ch6.planners (the built-in ones are that package's
    modules; more from trials.planner_modules), checked when the trials stage starts."""
    stream: str
    """Scene stream (a key of trials.streams): conditions on one stream see the same scenes
    and the same targets."""
    episodes: int = bounded(200, ge=1)
    """Number of episodes (absent in params.yaml: trials.ch6.episodes)."""
    rule: Literal["iou", "coverage", "iou_gap", "coverage_gap"] = "coverage_gap"
    """Support rule of the CP-based planners (thresholds chosen on val by the support stage):
    the thesis' IoU rule, the coverage rule of eq. 6.2, or either with the surface-gap test on
    pseudo-direct contact (`_gap`, ours)."""
    perception: Literal["instance", "depth"] = "instance"
    """Where its planner's object masks come from: the simulator's instance image, or region
    growing on the (sensed) depth image, each segment named by the box its grasp takes
    (depth: trials/ch6/seeing.py, docs/sensing.md; planners that read only what a robot sees,
    on the kinematic executor)."""
    sensing: Sensing = "ideal"
    """The depth sensor of its planner's pictures (sim/sensor.py); ideal: the exact depth."""
    executor: Literal["kinematic", "arm"] = "kinematic"
    """Who executes a pull: the box moved kinematically (BoxWorld), or Pandas in a ManiSkill
    scene (trials.arm); the same judge and records either way."""


@dataclasses.dataclass(frozen=True)
class Ch6TrialParams:
    """How an extraction is executed and judged (thesis 6.2.3, Algorithm 1)."""

    episodes: int = bounded(200, ge=1)
    """The episodes of a ch. 6 condition that names none."""

    model: str = "cp_focal"
    """Collapse predictor of the CP-based planners."""
    pull_increment_m: float = bounded(0.02, gt=0.0)
    """The pull toward the camera is cut into increments; the planner re-observes between
    them and aborts when the collapse score exceeds cp_max (Algorithm 1, lines 7-18)."""
    cp_max: float | None = None
    """Abort threshold of the collapse score (eq. 6.2); null: the support rule's score
    threshold chosen on validation scenes (the same evidence that draws an edge)."""
    moved_threshold_m: float = bounded(0.005, gt=0.0)
    """A box other than the pulled one moved when its centre moved more than this."""
    grasp_lift_m: float = bounded(0.003, ge=0.0)
    """The gripper raises the grasped box by this much before pulling it out, so it slides
    clear of what it rests on instead of dragging it (and tipping a tall stack). Below
    moved_threshold_m, so the lift alone never counts as moving a box resting on it."""
    min_target_pixels: int = bounded(40, ge=1)
    """The target is drawn among boxes with at least this many visible pixels."""
    min_pixels: int = bounded(20, ge=1)
    """Planners see a box when at least this many pixels of it are visible."""
    max_steps: int = bounded(14, ge=1)
    """An episode stops (failed) after this many extraction attempts."""
    search_node_budget: int = bounded(40, ge=1)
    """The search oracles expand at most this many states per search (each simulates every
    candidate pull from it); an episode whose search ran out is counted in Table 6.3."""
    search_same_m: float = bounded(1e-6, gt=0.0)
    """The search oracles take two states for one when the same boxes are out and every box
    still in stands within this distance (m) of where it stands in the other (and within
    search_same_deg of its orientation): the next step depends on nothing else. A pile is
    chaotic: states 1 mm apart were seen to differ in whether a clean sequence exists, so
    the tolerance is at the level of float noise, not of what a camera resolves."""
    search_same_deg: float = bounded(1e-3, gt=0.0)
    """The orientation half of that tolerance (degrees, the rotation between the two)."""
    search_cut_m: float = bounded(0.02, gt=0.0)
    """A search oracle's simulated pull stops, judged failed, once another box moved more than
    this (m) mid-pull (well past moved_threshold_m: it does not come back); most pulls in a
    pile fail, so this is most of the search's saving."""
    physics_depth_node_budget: int = bounded(40, ge=1)
    """The physics-from-depth planners' search expands at most this many states of the
    estimated scene per decision (their decision time)."""
    physics_depth_settle_s: float = bounded(0.5, gt=0.0)
    """The estimated scene settles this long before the search; not at rest by then is
    recorded (estimate_not_at_rest)."""
    abort_release: Literal["in_place", "back"] = "in_place"
    """A pull aborted after it moved lets go of its box where it is (in_place: half out, it
    may tip off the shelf), or first puts it back where the pull started (back). Executed
    steps, the search oracles and the truth maps of the pull alike (kinematic executor)."""
    held_release: Literal["drop", "lower"] = "drop"
    """The second arm lets go of the box it held where it holds it (drop: in mid-air when the
    pull took what it rested on), or first sets it down onto what is below it (lower).
    Executed steps, the search oracles and the truth maps of the pull alike."""

    ch4_model: str = "ch4_various"
    """The chapter 4 network (a key of train.models) of the single-step rows: the thesis'
    previous method, extract while supporting (Table 6.3's single-step rows)."""
    ch4_pixel_threshold: float = bounded(0.4, gt=0.0, le=1.0)
    """Its pixel threshold of the risk index (thesis 4.4.1)."""
    abort_response: Literal["block", "learn"] = "learn"
    """What the planners on maps of the pull (`*_pull*`) do after a collapse score
    over cp_max: block skips the box until a step succeeds (Algorithm 1, what the deletion
    planners do); learn also takes the box the score feared for as carried by it, so the
    plan removes that box first or, bimanual, holds it (planning/ch6/extraction.py)."""
    pull_prob_threshold: float | None = bounded(None, gt=0.0, le=1.0)
    """The pull-head CP planners' (maps: pull) collapse area R_C = heatmap > this;
    null: the support stage's choice on validation scenes (the support graph's F-measure
    against pull truth). Chosen on dev streams for the trials' own outcome
    (make dev-ch6-pull, docs/design-choices.md)."""
    pull_score_threshold: float | None = bounded(None, gt=0.0, le=1.0)
    """The same planners' support-edge score threshold, and their abort threshold cp_max
    unless cp_max is set; null: the support stage's choice on validation scenes."""
    pull_watch_m: float | None = bounded(None, gt=0.0)
    """The pull-head CP planners also watch their pull: before each increment, a
    box other than the pulled and held one whose pixels seen at the decision and now moved
    in depth by more than this (median, m) stops the pull like a collapse score over cp_max
    (abort_response learn: that box is then taken as carried by the pulled one). The robot's
    own depth images, no prediction; null: no watch. Chosen on dev streams."""
    when_no_plan: Literal["give_up", "least_risk", "least_risk_unmonitored", "clear"] = "give_up"
    """What the planners on maps of the pull (`*_pull*`) do when their rule
    rejects every candidate: give_up ends the episode (Algorithm 1, what the deletion
    planners do); least_risk pulls the rejected candidate of the lowest collapse score,
    aborting only when the score grows beyond that one; least_risk_unmonitored pulls it
    without abort checks; clear first pulls a box the rule passes from around the rejected
    ones (a contact neighbour of a rejected candidate or of a box its score feared for; the
    lowest score), least_risk when there is none (planning/ch6/extraction.py NO_PLAN_RESPONSES).
    Chosen on dev streams (make dev-ch6-no-plan, make dev-ch6-clear)."""
    score_over: Literal["contact", "visible"] = "contact"
    """Whose shares the collapse score of the planners on maps of the pull (`*_pull*`)
    takes: contact, the objects in pseudo-direct contact with the pulled box (eq. 6.2,
    what the deletion planners do); visible, every visible object, so a pull that drags a
    box it does not touch (through one between) is rejected too. Chosen on dev streams
    (make dev-ch6-clear)."""
    idle_hold_share: float | None = bounded(None, ge=0.0, le=1.0)
    """The bimanual planners on maps of the pull (`bimanual_pull*`): a pull their
    plan makes with the second arm idle holds the pulled box's contact neighbour of the
    largest predicted share (eq. 6.2's, below the edge threshold) above this, one that carries
    nothing in the graph; null: the arm stays idle (thesis Fig. 6.7). Chosen on dev streams
    (make dev-ch6-idle-hold)."""
    hold_feared: Literal["never", "any", "free", "search"] = "never"
    """The bimanual planners on maps of the pull (`bimanual_pull*`): a pull their
    plan makes with the second arm idle whose collapse score exceeds cp_max is tried again
    holding the box that score fears for (the largest share), left out of the score as Fig.
    6.7 (d) leaves out the held child, and taken when it then passes: any, whatever that box
    carries; free, only a box that carries nothing in the graph (what it carries would fall
    when it is let go); search, that box and then every other visible one, the first whose
    held pull passes (differs from any only on maps that know a held pull: truth_hold
    simulate). never: the candidate is rejected (thesis). Chosen on dev streams
    (make dev-ch6-hold)."""
    fit_hypotheses: int = bounded(1, ge=1)
    """How many scenes the learned-plus-physics planners (`*_box_physics`) and Table 6.2's
    fused and physics-from-depth rows fit to one observation: the fit of its depth image,
    then fits of that image with Gaussian noise of fit_noise_mm on every pixel (the same
    observation, the same noise). A pull's outcome for a box is the share of the fits whose
    pull marks it (1: the fit alone, 0 or 1)."""
    fit_noise_mm: float = bounded(1.0, gt=0.0)
    """The depth noise (standard deviation, mm) of the fits after the first (fit_hypotheses)."""
    box_contact: Literal["head", "learned"] = "head"
    """The contact in the support edges of the learned-plus-physics planners (`*_box_physics`):
    head, the box head's contact probability; learned, a logistic regression of the true
    contact on the head's contact logit and the share of the fitted scenes in which the two
    boxes touch once settled (the truth's own rule), its weights and the edge threshold chosen
    on the support stage's val scenes (support/box_fusion.py). Chosen on dev streams (make
    dev-ch6-box-contact)."""
    box_edge_precision: float | None = bounded(None, gt=0.0, le=1.0)
    """The edge threshold of the box head fused with physics from depth (the support graph
    of the learned-plus-physics planners and of Table 6.2's fused rows), chosen by the support
    stage on its val scenes: null, the best F1 of mean precision and recall (Table 6.2's
    criterion); a number, the highest mean recall among the thresholds whose mean precision
    reaches it (a precision-first graph). Rechecked on val: make dev-box-physics-fusion."""
    box_cp_max: float | None = bounded(None, gt=0.0, le=1.0)
    """The box planners' (`*_box`, `*_box_physics`) cp_max: the collapse score (a box's
    predicted probability) over which a candidate is rejected at a decision and a pull is
    stopped; null: the outcome threshold the support stage chose on val pairs (the best F1 of
    the per-box outcome, what draws the graph's edges). Chosen on dev streams (make
    dev-ch6-box-cp-max)."""
    box_hold: Literal["leave_out", "simulate"] = "leave_out"
    """How the learned-plus-physics bimanual planner (`bimanual_box_physics`) scores a pull
    made holding a box: leave_out, the unheld pull's fused row with the held box left out
    (Fig. 6.7 (d): what a network that sees no hold can say; a held box that falls once let
    go goes unseen); simulate, the network's row fused with that very held pull simulated on
    the boxes fitted to the depth image, the held box let go at the end and judged as the
    trials judge a released box (it may settle, it may not leave the shelf). Chosen on dev
    streams (make dev-ch6-box-hold)."""
    truth_hold: Literal["leave_out", "simulate"] = "leave_out"
    """How the truth-map bimanual pull planners (`bimanual_pull_truth`) score a
    pull made holding a box: leave_out, the map of the unheld pull with the held box left
    out (Fig. 6.7 (d), what the CP planners do: the network sees no hold); simulate, the map
    of that very pull by the trials' executor, the held box held, let go and settled, and
    judged as the others (the truth of the executed action). Chosen on dev streams (make
    dev-ch6-hold)."""
    idle_hold_prob: float | None = bounded(None, gt=0.0, le=1.0)
    """The pixel probability threshold of the collapse area idle_hold_share's shares are
    taken of (null: the support rule's, as the edges' and aborts'). Chosen on dev streams."""
    pull_map_meaning: Literal["moved", "collapse"] = "moved"
    """What the maps of the pull mark, truth (`*_pull_truth`) and predicted (`*_pull`, the
    collapse predictor's head of that meaning, PULL_MAP_HEADS): moved, every box the pull
    moves beyond moved_threshold_m or off the shelf (the strict criterion's notion; the pull
    head); collapse, only the boxes that collapse by the collapse-free criterion (off the
    shelf, dropped or tipped beyond trials.collapse_free), the thesis' trial notion (the
    pull_collapse head)."""

    @property
    def pull(self) -> PullExecution:
        """How a pull is executed and judged (executed steps, search oracles, replays)."""
        return PullExecution(
            increment_m=self.pull_increment_m,
            grasp_lift_m=self.grasp_lift_m,
            return_aborted=self.abort_release == "back",
            lower_held=self.held_release == "lower",
            moved_threshold_m=self.moved_threshold_m,
        )

    @property
    def search(self) -> SearchLimits:
        """How far the search oracles search."""
        return SearchLimits(
            node_budget=self.search_node_budget,
            same_m=self.search_same_m,
            same_deg=self.search_same_deg,
            cut_m=self.search_cut_m,
            min_pixels=self.min_pixels,
        )

    @property
    def levers(self) -> PullLevers:
        """The pull planners' choices beyond Algorithm 1 (`*_pull*`, `*_box*` planners)."""
        return PullLevers(
            clear_hold_load=True,
            learn_from_aborts=self.abort_response == "learn",
            watch_m=self.pull_watch_m,
            when_no_plan=self.when_no_plan,
            idle_hold_share=self.idle_hold_share,
            idle_hold_prob=self.idle_hold_prob,
            score_over=self.score_over,
            hold_feared=self.hold_feared,
        )


CH4_PLANNERS = ("risk", "random", "oracle")
"""ch. 4 trial policies: argmin of the risk index r_c over the candidates through a ch. 4
network (eqs. 4.1, 4.2); a uniformly random candidate; every candidate simulated from the
canonical start, the best kept."""


@dataclasses.dataclass(frozen=True)
class Ch4ConditionConfig:
    """One chapter 4 trials condition (stage trials_ch4 runs every one; thesis Table 4.1)."""

    planner: Literal["risk", "random", "oracle"]
    """Policy (trials.config.CH4_PLANNERS)."""
    stream: str
    """Scene stream (a key of trials.streams)."""
    episodes: int = bounded(100, ge=1)
    """Number of trials (absent in params.yaml: trials.ch4.episodes)."""
    mode: Literal["pair", "target"] = "pair"
    """"pair": choose the safest ordered (extract, support) pair (thesis 4.2.3 (1));
    "target": the target is given, choose its support (4.2.3 (2))."""
    model: str | None = None
    """The ch. 4 network of the risk planner (a key of train.models); null for the others."""
    perception: Literal["instance", "depth"] = "instance"
    """Object masks from the simulator's instance image, or from the depth image alone."""
    sensing: Sensing = "ideal"
    """The depth sensor of the planner's picture (sim/sensor.py); ideal: the exact depth."""
    executor: Literal["kinematic", "arm"] = "kinematic"
    """Who executes the pull and holds the support: kinematic, or Pandas (trials.arm)."""

    def __post_init__(self) -> None:
        if (self.planner == "risk") != (self.model is not None):
            raise ValueError(
                f"model: the risk planner needs a ch. 4 network and the {self.planner} "
                "planner takes none"
                if self.planner == "risk"
                else f"model: the {self.planner} planner takes no network (set model: null)"
            )


@dataclasses.dataclass(frozen=True)
class Ch4TrialParams:
    """How a chapter 4 pull is judged (thesis 4.3.3)."""

    episodes: int = bounded(100, ge=1)
    """The episodes of a ch. 4 condition that names none."""

    moved_threshold_m: float = bounded(0.005, gt=0.0)
    """Strict success: no box other than the pulled and the held one moved more than this."""
    min_pixels: int = bounded(20, ge=1)
    """Planners see an object when its mask has at least this many pixels."""
    min_target_pixels: int = bounded(40, ge=1)
    """The predetermined target is drawn among boxes with at least this many visible pixels."""
    pixel_threshold: float = bounded(0.4, gt=0.0, le=1.0)
    """A pixel is in a class's region when its probability exceeds this (thesis 4.4.1)."""
    figure_episode: int = bounded(0, ge=0)
    """Episode drawn as thesis Fig. 4.8 by risk conditions in target mode."""


CH5_PLANNERS = ("replenish", "no_collapse", "contact", "random", "oracle", "oracle_no_contact")
"""ch. 5 trial policies: the thesis' replenishment planner (Fig. 5.2) with collapse
prediction; the same without it (no R_s test and no collapse check of a rearrangement, the
way check kept: the thesis' comparison); beyond the thesis, the planner with collapse
prediction that, where it has no plan, carries a movable blocker although boxes stand in its
way (planning.replenish.ReplenishParams.contact); an action drawn uniformly from the oracle's
action set at every step (floor); every candidate action simulated from the current state, the
first that succeeds kept (ceiling); the same over the actions that move no box into another
(the ceiling of the thesis' planners, which keep that rule)."""


@dataclasses.dataclass(frozen=True)
class Ch5ConditionConfig:
    """One chapter 5 replenishment condition (stage trials_ch5, thesis Table 5.2)."""

    planner: Literal["replenish", "no_collapse", "contact", "random", "oracle", "oracle_no_contact"]
    """Policy (trials.config.CH5_PLANNERS)."""
    stream: str
    """Scene stream (a key of trials.streams)."""
    episodes: int = bounded(100, ge=1)
    """Number of trials (absent in params.yaml: trials.ch5.episodes)."""
    perception: Literal["detector", "clusters"] = "detector"
    """Arrangement clusters from the trained detector (models/detector), or the generator's
    ground-truth clusters (the detector's share of the failures)."""
    sensing: Sensing = "ideal"
    """The depth sensor of the planner's pictures (sim/sensor.py); ideal: the exact depth."""


@dataclasses.dataclass(frozen=True)
class Ch5TrialParams:
    """How a replenishment is planned, executed and judged (thesis 5.2.3, 5.3.2)."""

    episodes: int = bounded(100, ge=1)
    """The episodes of a ch. 5 condition that names none."""

    model: str = "cmn_bs32"
    """Collapse map network of the planner (a key of train.models; thesis 5.2.2)."""
    prob_threshold: float | None = None
    """R_s: pixels whose collapse probability is at least this; null: the threshold chosen on
    the ch. 5 validation split by evaluate@<model>_ch5 (val_chosen_threshold)."""
    iou_threshold: float = bounded(0.1, gt=0.0, le=1.0)
    """th: B_s is movable when IoU(B_j, R_s) < th for every other cluster (thesis 5.2.3)."""
    finger_m: float = bounded(0.012, ge=0.0)
    """g: finger thickness, the margin of every candidate and move (eqs. 5.2-5.9)."""
    moved_threshold_m: float = bounded(0.0064, gt=0.0)
    """A box other than the manipulated ones moved when its centre moved more (thesis 5.2.2)."""
    place_tol_m: float = bounded(0.02, gt=0.0)
    """The new box must rest within this of its planned place (across and up, shelf y-z)."""
    new_boxes: Literal["same", "various", "new"] = "various"
    """Catalogue the box to replenish is drawn from (its size is known to the planner)."""
    max_steps: int = bounded(3, ge=1)
    """Plans per episode (a rearrangement is followed by a new plan); then it gives up."""
    oracle_budget: int = bounded(40, ge=1)
    """The oracle simulates at most this many candidate actions per decision."""
    min_points: int = bounded(3, ge=1)
    """A candidate is occupied when this many depth points of boxes fall inside it."""
    upright_footprint: bool = True
    """A leaning blocker or obstacle is planned with the footprint it has once set upright
    (planning.replenish.carried); false: as its leaning box is seen."""
    blocker_goal: Literal["candidate", "eq_5_6"] = "candidate"
    """Where the planner carries a blocker (planning.replenish.move_goal): aside until it
    clears the candidate it fills, or by eq. (5.6)'s fixed distance."""


@dataclasses.dataclass(frozen=True)
class ArmConditionConfig:
    """One arm-level condition (stage trials_arm): a kinematic condition's planner on the same
    scenes and targets, its pulls executed by Pandas (ManiSkill) instead of kinematically."""

    of: str
    """The condition it repeats: a key of trials.conditions (ch. 6) or trials.ch4_conditions."""
    episodes: int = bounded(50, ge=1)
    """Its first this many episodes (at most that condition's: they are compared one by one)."""


@dataclasses.dataclass(frozen=True)
class TrialsConfig:
    workers: int = cores_field(2)
    """Worker processes per condition, each with its own renderer and one torch thread;
    auto: base.cores."""
    streams: Mapping[str, SceneStreamConfig] = dataclasses.field(default_factory=dict)
    """Scene stream name -> the scenes it draws (seeded from base.seed and its name)."""
    ch6: Ch6TrialParams = Ch6TrialParams()
    """Chapter 6 execution and judging."""
    collapse_free: CollapseFreeConfig = CollapseFreeConfig()
    """Thresholds of the collapse-free criterion, every chapter's (criteria.py)."""
    conditions: Mapping[str, ConditionConfig] = dataclasses.field(default_factory=dict)
    """Condition name -> planner on a stream; stage trials runs them all in one pool."""
    sensed: SensedRows = SensedRows()
    """Conditions run again under a depth sensor with masks from depth (added to conditions)."""
    opt_in: OptInRows = OptInRows()
    """Conditions the trials leave out unless switched on (`make repro-full`)."""
    ch4: Ch4TrialParams = Ch4TrialParams()
    """Chapter 4 judging."""
    ch4_conditions: Mapping[str, Ch4ConditionConfig] = dataclasses.field(default_factory=dict)
    """Condition name -> ch. 4 planner on a stream; stage trials_ch4 runs them all."""
    ch4_sensed: SensedRows = SensedRows()
    """ch. 4 conditions run again under a depth sensor (added to ch4_conditions)."""
    ch5: Ch5TrialParams = Ch5TrialParams()
    """Chapter 5 replenishment planning and judging."""
    ch5_conditions: Mapping[str, Ch5ConditionConfig] = dataclasses.field(default_factory=dict)
    """Condition name -> ch. 5 planner on a stream; stage trials_ch5 runs them all."""
    ch5_sensed: SensedRows = SensedRows()
    """ch. 5 conditions run again under a depth sensor (added to ch5_conditions)."""
    max_attempts: int = bounded(30, ge=1)
    """A trial scene is redrawn at most this often."""
    planner_modules: tuple[str, ...] = ()
    """Python modules the trials stage imports first, so that the planners they register
    (trials.ch6.register_planner) can be named by conditions: a new planner is one module
    plus its entries here and in trials.conditions (docs/extending.md)."""
    mcap_images: bool = True
    """Write depth and instance images of every observation to the condition's MCAP."""
    arm: ArmConfig = ArmConfig()
    """The Pandas of arm-level execution (executor: arm)."""
    arm_conditions: Mapping[str, ArmConditionConfig] = dataclasses.field(default_factory=dict)
    """Condition name -> a kinematic condition repeated arm-level; stage trials_arm runs them
    all and compares each with its kinematic row, episode by episode."""

    @staticmethod
    def prepare_params(data: Mapping[str, Any]) -> Mapping[str, Any]:
        """The raw section with every condition that names no `episodes` given its chapter's
        (trials.ch6/ch4/ch5.episodes, else their defaults), as params.yaml states it once."""
        out = SensedRows.add_to(data)
        for group, chapter in EPISODE_DEFAULTS.items():
            conditions = out.get(group)
            if not isinstance(conditions, Mapping):
                continue
            section = data.get(chapter)
            default = section.get("episodes") if isinstance(section, Mapping) else None
            if default is None:
                default = CHAPTER_PARAMS[chapter]().episodes
            out[group] = {
                name: {"episodes": default, **c} if isinstance(c, Mapping) else c
                for name, c in conditions.items()
            }
        return out

    @property
    def run_conditions(self) -> dict[str, ConditionConfig]:
        """The conditions the trials stage runs: all but the opt-in ones this run leaves out."""
        return {n: c for n, c in self.conditions.items() if n not in self.opt_in.skipped}

    def stage_conditions(self, only: Sequence[str] = ()) -> dict[str, ConditionConfig]:
        """What stage trials runs: the conditions named in `only` (a debugging run; opt-in
        ones too), else run_conditions (the opt-in ones only when trials.opt_in.run)."""
        unknown = [n for n in only if n not in self.conditions]
        if unknown:
            raise ClutterbenchError(
                f"trials.conditions.{unknown[0]}: no such condition "
                f"(known: {', '.join(self.conditions)})"
            )
        return {n: c for n, c in self.conditions.items() if n in only} or self.run_conditions

    def __post_init__(self) -> None:
        if problem := SensedRows.problem_in(self):
            raise ValueError(problem)
        arm_of = {name: arm.of for name, arm in self.arm_conditions.items()}
        if problem := self.opt_in.problem(self.conditions, self.sensed.of, arm_of):
            raise ValueError(problem)
        for group in ("conditions", "ch4_conditions", "ch5_conditions"):
            for name, cond in getattr(self, group).items():
                if cond.stream not in self.streams:
                    raise ValueError(
                        f"{group}.{name}.stream: unknown stream '{cond.stream}' "
                        f"(known: {', '.join(self.streams)})"
                    )
        for name, arm in self.arm_conditions.items():
            of = self.conditions.get(arm.of) or self.ch4_conditions.get(arm.of)
            if of is None:
                known = [*self.conditions, *self.ch4_conditions]
                raise ValueError(
                    f"arm_conditions.{name}.of: unknown condition '{arm.of}' "
                    f"(known: {', '.join(known)})"
                )
            if arm.episodes > of.episodes:
                raise ValueError(
                    f"arm_conditions.{name}.episodes: {arm.episodes} is more than the "
                    f"{of.episodes} episodes of '{arm.of}' it is compared with"
                )
            if arm.of in self.conditions and arm.of in self.ch4_conditions:
                raise ValueError(
                    f"arm_conditions.{name}.of: '{arm.of}' names a ch. 6 and a ch. 4 condition"
                )


EPISODE_DEFAULTS = {"conditions": "ch6", "ch4_conditions": "ch4", "ch5_conditions": "ch5"}
"""A condition group -> the chapter section whose `episodes` its conditions default to."""
CHAPTER_PARAMS = {"ch6": Ch6TrialParams, "ch4": Ch4TrialParams, "ch5": Ch5TrialParams}
