"""The CPG planner's one decision rule: it never picks a box its own abort test rejects."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.observation import CameraModel, Observation
from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
from clutterbench.planning.ch6.support import SupportParams

PARAMS = SupportParams("coverage", 0.5, 0.3, 2, 0.0)


def _scene(extra_leaf: bool) -> tuple[Observation, dict[int, np.ndarray]]:
    """Boxes 0 and 1 side by side (in pseudo-contact); optionally box 2 on top of box 1."""
    inst = np.zeros((24, 24), np.uint8)
    inst[8:20, 2:8] = 1
    inst[8:20, 8:14] = 2
    if extra_leaf:
        inst[2:8, 8:14] = 3
    obs = Observation(np.ones((24, 24), np.float32), inst, CameraModel(np.eye(3), np.eye(4)))
    return obs, {k: inst == k + 1 for k in range(3)}


def _predictor(boxes: dict[int, np.ndarray]):
    """Removing 0 collapses all of 1; removing 1 collapses 60% of 0 (a mutual pair whose
    weaker edge the graph drops); removing 2 collapses nothing."""

    def predict(depth, masks):
        out = np.zeros(masks.shape, np.float32)
        for k, m in enumerate(masks.astype(bool)):
            if (m & boxes[0]).any():
                out[k] = boxes[1]
            elif (m & boxes[1]).any():
                rows = np.nonzero(boxes[0].any(axis=1))[0]
                cut = rows[0] + int(round(0.6 * len(rows)))
                out[k, rows[0] : cut] = boxes[0][rows[0] : cut]
        return out

    return predict


def test_a_box_whose_collapse_score_exceeds_cp_max_is_never_picked():
    obs, boxes = _scene(extra_leaf=False)
    planner = CollapseGraphPlanner(_predictor(boxes), PARAMS, cp_max=0.5, min_pixels=1)
    # The graph keeps 0 -> 1, so box 1 is the only leaf; its own abort test (0.6 of box 0
    # in its collapse area) rejects it before any motion: the planner gives up instead.
    assert planner.collapse_score(obs, 1) == pytest.approx(0.6, abs=0.1)
    with pytest.raises(ValueError):
        planner.decide(obs, 0, frozenset())


@pytest.mark.parametrize(
    ("response", "limit"), [("least_risk", 0.6), ("least_risk_unmonitored", float("inf"))]
)
def test_with_no_plan_left_the_least_risk_rejected_pull_is_taken(response, limit):
    obs, boxes = _scene(extra_leaf=False)
    planner = CollapseGraphPlanner(
        _predictor(boxes), PARAMS, cp_max=0.5, min_pixels=1, when_no_plan=response
    )
    # The same scene as above: box 1, the only leaf, is rejected (0.6 > 0.5); instead of
    # giving up the planner pulls it, aborting only beyond its own score (or never).
    decision = planner.decide(obs, 0, frozenset())
    assert decision.pull == 1 and decision.state["no_plan"] == response
    assert [r[0] for r in decision.state["rejected"]] == [1]
    assert decision.cp_max == pytest.approx(limit, abs=0.1)
    # Nothing was rejected at all (every candidate blocked by earlier aborts): it gives up.
    with pytest.raises(ValueError):
        planner.decide(obs, 0, frozenset({0, 1}))


def test_an_unknown_no_plan_response_is_refused():
    obs, boxes = _scene(extra_leaf=False)
    with pytest.raises(ValueError, match="when_no_plan"):
        CollapseGraphPlanner(_predictor(boxes), PARAMS, 0.5, 1, when_no_plan="retry")


def test_the_next_candidate_is_taken_when_one_is_rejected():
    obs, boxes = _scene(extra_leaf=False)
    lenient = CollapseGraphPlanner(_predictor(boxes), PARAMS, cp_max=0.9, min_pixels=1)
    decision = lenient.decide(obs, 0, frozenset())
    assert decision.pull == 1 and decision.state["rejected"] == []
    assert decision.state["cp"] <= 0.9


def _dragging_predictor(boxes: dict[int, np.ndarray], phase: dict[str, bool]):
    """At the decision nothing collapses; mid-pull (phase["mid"]) pulling box 0 threatens
    all of box 1 (the pull drags it, which the decision's map missed)."""

    def predict(depth, masks):
        out = np.zeros(masks.shape, np.float32)
        for k, m in enumerate(masks.astype(bool)):
            if phase["mid"] and (m & boxes[0]).any():
                out[k] = boxes[1]
        return out

    return predict


@pytest.mark.parametrize("bimanual", [False, True])
def test_after_an_abort_the_feared_box_is_removed_or_held_not_given_up(bimanual):
    obs, boxes = _scene(extra_leaf=False)
    phase = {"mid": False}
    kwargs = dict(cp_max=0.5, min_pixels=1, bimanual=bimanual)
    learner = CollapseGraphPlanner(
        _dragging_predictor(boxes, phase), PARAMS, learn_from_aborts=True, **kwargs
    )
    blocker = CollapseGraphPlanner(_dragging_predictor(boxes, phase), PARAMS, **kwargs)
    mid = Observation(obs.depth_m.copy(), obs.instance.copy(), obs.camera)
    for planner in (learner, blocker):
        phase["mid"] = False
        assert planner.decide(obs, 0, frozenset()).pull == 0  # the target is a leaf
        phase["mid"] = True  # the monitor, mid-pull: box 1 is feared for -> abort
        assert planner.collapse_score(mid, 0) > 0.5
        phase["mid"] = False
    # Algorithm 1 skips the aborted target: nothing is left, the planner gives up
    with pytest.raises(ValueError):
        blocker.decide(obs, 0, frozenset({0}))
    decision = learner.decide(obs, 0, frozenset({0}))
    assert decision.state["learned"] == [[0, 1, 1.0]]
    if bimanual:  # Fig. 6.7 (d) on the learned edge: hold box 1, pull the target
        assert (decision.pull, decision.hold) == (0, 1)
    else:  # box 1 now rests on the target in the graph: it goes first
        assert (decision.pull, decision.hold) == (1, None)


def test_a_learned_edge_leaves_with_its_box():
    obs, boxes = _scene(extra_leaf=False)
    phase = {"mid": True}
    planner = CollapseGraphPlanner(
        _dragging_predictor(boxes, phase), PARAMS, 0.5, 1, learn_from_aborts=True
    )
    planner.collapse_score(obs, 0)
    phase["mid"] = False
    assert planner.decide(obs, 0, frozenset({0})).pull == 1
    # box 1 is out: its edge is gone, the target is a leaf again
    gone = Observation(obs.depth_m, np.where(obs.instance == 2, 0, obs.instance), obs.camera)
    assert planner.decide(gone, 0, frozenset()).pull == 0


def test_a_watched_pull_stops_when_a_neighbour_moves_in_depth():
    """pull_watch_m: box 1 comes 6 mm closer on its pixels seen in both images (box 0, the
    pulled one, hides part of it: occlusion alone is no motion) -> the pull stops, naming
    box 1; 2 mm of motion, or no watch, leaves the prediction (nothing) alone."""
    from clutterbench.planning.ch6.extraction import depth_changes

    obs, boxes = _scene(extra_leaf=False)
    phase = {"mid": False}  # the prediction never fears anything here

    def moved(by_m: float) -> Observation:
        depth, inst = obs.depth_m.copy(), obs.instance.copy()
        depth[boxes[1]] -= by_m
        inst[8:20, 8:10] = 1  # the pulled box 0, closer, now covers part of box 1
        depth[8:20, 8:10] = 0.5
        return Observation(depth, inst, obs.camera)

    assert depth_changes(obs, moved(0.006), 1)[1] == pytest.approx(0.006, abs=1e-6)
    assert depth_changes(obs, moved(0.0), 1) == {0: 0.0, 1: 0.0}  # box 0's own pixels too
    for watch, by_m, stops in [(0.004, 0.006, True), (0.004, 0.002, False), (None, 0.006, False)]:
        planner = CollapseGraphPlanner(
            _dragging_predictor(boxes, phase),
            PARAMS,
            0.5,
            1,
            learn_from_aborts=True,
            watch_m=watch,
        )
        assert planner.decide(obs, 0, frozenset()).pull == 0
        assert planner.collapse_score(obs, 0) == 0.0  # the decision's image: nothing moved
        cp = planner.collapse_score(moved(by_m), 0)
        assert (cp > 0.5) == stops, (watch, by_m)
        if stops:
            assert cp == pytest.approx(1.006, abs=1e-6) and planner._threat == (0, 1, cp)


def _grazing_predictor(boxes: dict[int, np.ndarray], share: float):
    """Removing box 0 collapses the top `share` of box 1 (below any edge threshold used)."""

    def predict(depth, masks):
        out = np.zeros(masks.shape, np.float32)
        rows = np.nonzero(boxes[1].any(axis=1))[0]
        cut = rows[0] + int(round(share * len(rows)))
        for k, m in enumerate(masks.astype(bool)):
            if (m & boxes[0]).any():
                out[k, rows[0] : cut] = boxes[1][rows[0] : cut]
        return out

    return predict


@pytest.mark.parametrize(("idle_hold_share", "hold"), [(None, None), (0.1, 1), (0.4, None)])
def test_the_idle_arm_holds_the_neighbour_of_the_largest_share_above_its_threshold(
    idle_hold_share, hold
):
    obs, boxes = _scene(extra_leaf=False)
    planner = CollapseGraphPlanner(
        _grazing_predictor(boxes, 0.25),
        PARAMS,
        cp_max=0.5,
        min_pixels=1,
        bimanual=True,
        idle_hold_share=idle_hold_share,
    )
    # 0.25 of box 1 is below the edge threshold: no edge, the plan pulls the target with the
    # second arm idle; with idle_hold_share below 0.25 that arm holds box 1.
    decision = planner.decide(obs, 0, frozenset())
    assert decision.pull == 0 and decision.hold == hold
    assert ("idle_hold" in decision.state) == (hold is not None)
    if hold is not None:
        assert decision.state["cp"] == 0.0  # the held box cannot collapse
    one_arm = CollapseGraphPlanner(
        _grazing_predictor(boxes, 0.25), PARAMS, 0.5, 1, idle_hold_share=idle_hold_share
    )
    assert one_arm.decide(obs, 0, frozenset()).hold is None  # one arm: nothing to hold with


@pytest.mark.parametrize(("idle_hold_prob", "hold"), [(None, None), (0.1, 1), (0.3, None)])
def test_the_idle_hold_reads_the_map_at_its_own_pixel_threshold(idle_hold_prob, hold):
    obs, boxes = _scene(extra_leaf=False)

    def faint(depth, masks):  # removing box 0 puts all of box 1 at probability 0.2
        out = np.zeros(masks.shape, np.float32)
        for k, m in enumerate(masks.astype(bool)):
            if (m & boxes[0]).any():
                out[k][boxes[1]] = 0.2
        return out

    planner = CollapseGraphPlanner(
        faint, PARAMS, 0.5, 1, bimanual=True, idle_hold_share=0.0, idle_hold_prob=idle_hold_prob
    )
    assert planner.decide(obs, 0, frozenset()).hold == hold


def test_a_visible_score_sees_a_collapse_of_a_box_the_pulled_one_does_not_touch():
    """score_over: the target's pull collapses box 2, far from it (no pseudo-contact):
    eq. 6.2 over the contact objects sees nothing and pulls; over every visible object the
    pull is rejected (Algorithm 1 then gives up)."""
    obs, _ = _scene(extra_leaf=False)
    inst = obs.instance.copy()
    inst[8:20, 18:23] = 3  # box 2: four pixels right of box 1, none of them box 0's
    obs = Observation(obs.depth_m, inst, obs.camera)

    def predict(depth, masks):
        out = np.zeros(masks.shape, np.float32)
        for k, m in enumerate(masks.astype(bool)):
            if (m & (inst == 1)).any():
                out[k] = inst == 3
        return out

    contact = CollapseGraphPlanner(predict, PARAMS, 0.5, 1)
    assert contact.collapse_score(obs, 0) == 0.0
    assert contact.decide(obs, 0, frozenset()).pull == 0
    visible = CollapseGraphPlanner(predict, PARAMS, 0.5, 1, score_over="visible")
    assert visible.collapse_score(obs, 0) == 1.0
    with pytest.raises(ValueError):
        visible.decide(obs, 0, frozenset())
    with pytest.raises(ValueError, match="score_over"):
        CollapseGraphPlanner(predict, PARAMS, 0.5, 1, score_over="everything")


def test_with_no_plan_left_clear_pulls_a_safe_neighbour_of_the_rejected_first():
    """when_no_plan clear: box 1, the only leaf of target 0's graph, is rejected (0.6 >
    0.5); box 2 lies on box 1 and its pull collapses nothing, so it goes first (a pull of
    the rule's own limit). With no such neighbour, the least-risk pull."""
    obs, boxes = _scene(extra_leaf=True)
    planner = CollapseGraphPlanner(_predictor(boxes), PARAMS, 0.5, 1, when_no_plan="clear")
    decision = planner.decide(obs, 0, frozenset())
    assert (decision.pull, decision.hold, decision.cp_max) == (2, None, None)
    assert decision.state["no_plan"] == "clear" and decision.state["cp"] == 0.0
    assert [r[0] for r in decision.state["rejected"]] == [1]
    least = CollapseGraphPlanner(_predictor(boxes), PARAMS, 0.5, 1, when_no_plan="least_risk")
    assert least.decide(obs, 0, frozenset()).pull == 1
    bare, boxes = _scene(extra_leaf=False)
    planner = CollapseGraphPlanner(_predictor(boxes), PARAMS, 0.5, 1, when_no_plan="clear")
    decision = planner.decide(bare, 0, frozenset())
    assert decision.pull == 1 and decision.state["no_plan"] == "least_risk"
    assert decision.cp_max == pytest.approx(0.6, abs=0.1)


def _carrier_scene():
    """Target 0 under boxes 1 and 2, box 3 on box 2, box 4 on box 1. Removing 0 collapses 1
    and 2, removing 2 collapses 3; box 1's pull grazes a quarter of box 2 and an eighth of
    box 4 (below the edge threshold)."""
    inst = np.zeros((30, 30), np.uint8)
    inst[20:28, 2:26] = 1  # box 0, the target, under 1 and 2
    inst[12:20, 2:10] = 2  # box 1
    inst[12:20, 10:18] = 3  # box 2
    inst[4:12, 12:18] = 4  # box 3, on box 2
    inst[4:12, 2:10] = 5  # box 4, on box 1
    obs = Observation(np.ones((30, 30), np.float32), inst, CameraModel(np.eye(3), np.eye(4)))

    def predict(depth, masks):
        out = np.zeros(masks.shape, np.float32)
        for k, m in enumerate(masks.astype(bool)):
            box = int(np.bincount(inst[m]).argmax()) - 1
            if box == 0:
                out[k] = (inst == 2) | (inst == 3)
            elif box == 2:
                out[k] = inst == 4
            elif box == 1:
                out[k, 12:14] = inst[12:14] == 3  # a quarter of box 2
                out[k, 4:5] = inst[4:5] == 5  # an eighth of box 4
        return out

    return obs, predict


def test_the_idle_arm_never_holds_a_box_that_carries_another_in_the_graph():
    """Target 0 carries boxes 1 and 2, box 2 carries box 3: the bimanual plan keeps 2 (the
    larger subtree) and pulls 1 first with the second arm idle. Box 1's pull grazes box 2
    (a quarter) and box 4 (an eighth), both below the edge threshold: the idle arm would hold
    box 2, the larger share, but box 2 carries box 3, so it holds box 4."""
    obs, predict = _carrier_scene()

    planner = CollapseGraphPlanner(predict, PARAMS, 0.5, 1, bimanual=True, idle_hold_share=0.0)
    decision = planner.decide(obs, 0, frozenset())
    assert (decision.pull, decision.hold) == (1, 4)
    assert decision.state["idle_hold"] == 4


@pytest.mark.parametrize(("hold_feared", "hold"), [("never", None), ("any", 1), ("free", 1)])
def test_a_rejected_idle_arm_pull_is_saved_by_holding_the_box_it_fears_for(hold_feared, hold):
    """Pulling target 0 collapses a quarter of box 1: below the edge threshold (no edge, the
    plan pulls the target with the second arm idle) but above cp_max 0.2. hold_feared never
    rejects that pull (no plan left: the planner gives up); any / free hold box 1, which the
    score then leaves out."""
    obs, boxes = _scene(extra_leaf=False)
    planner = CollapseGraphPlanner(
        _grazing_predictor(boxes, 0.25), PARAMS, 0.2, 1, bimanual=True, hold_feared=hold_feared
    )
    if hold is None:
        with pytest.raises(ValueError):
            planner.decide(obs, 0, frozenset())
        return
    decision = planner.decide(obs, 0, frozenset())
    assert (decision.pull, decision.hold) == (0, hold)
    assert decision.state["feared_hold"] == hold and decision.state["cp"] == 0.0
    one_arm = CollapseGraphPlanner(
        _grazing_predictor(boxes, 0.25), PARAMS, 0.2, 1, hold_feared=hold_feared
    )
    with pytest.raises(ValueError):  # one arm: nothing to hold with
        one_arm.decide(obs, 0, frozenset())
    with pytest.raises(ValueError, match="hold_feared"):
        CollapseGraphPlanner(_grazing_predictor(boxes, 0.25), PARAMS, 0.2, 1, hold_feared="all")


def test_a_free_feared_hold_never_holds_a_box_that_carries_another():
    """The scene of the test above, cp_max 0.2: box 1's pull (first of the plan, the second
    arm idle) fears for box 2 (a quarter, the largest share), which carries box 3. any holds
    box 2 (box 4's eighth then passes); free does not, and box 1 is not pulled."""
    obs, predict = _carrier_scene()

    def decide(hold_feared: str):
        planner = CollapseGraphPlanner(predict, PARAMS, 0.2, 1, True, hold_feared=hold_feared)
        try:
            return planner.decide(obs, 0, frozenset())
        except ValueError:
            return None

    saved = decide("any")
    assert (saved.pull, saved.hold, saved.state["feared_hold"]) == (1, 2, 2)
    free = decide("free")
    assert free is None or free.pull != 1


def test_a_held_pull_is_scored_on_its_own_map_where_the_maps_know_it():
    """Target 0 carries box 1 (removing 0 collapses all of 1): the bimanual plan pulls 0
    holding 1 (Fig. 6.7 (d)), scored without the held box: 0. With predict_held, the score
    reads the held pull's own map, the held box judged too: where it falls once let go the
    pull is rejected (and box 1, the only other leaf, is rejected as well: no plan)."""
    obs, boxes = _scene(extra_leaf=False)
    falls = CollapseGraphPlanner(
        _predictor(boxes), PARAMS, 0.5, 1, True, predict_held=lambda d, m, h: h.astype(np.float32)
    )
    assert falls.collapse_score(obs, 0, hold=1) == 1.0
    with pytest.raises(ValueError):
        falls.decide(obs, 0, frozenset())
    for predict_held in (None, lambda d, m, h: np.zeros(m.shape, np.float32)):
        planner = CollapseGraphPlanner(
            _predictor(boxes), PARAMS, 0.5, 1, True, predict_held=predict_held
        )
        decision = planner.decide(obs, 0, frozenset())
        assert (decision.pull, decision.hold, decision.state["cp"]) == (0, 1, 0.0)


def test_the_idle_arm_holds_nothing_where_the_held_pull_s_own_map_fails():
    """The idle-hold scene above (the arm would hold box 1): where the held pull's own map
    says box 1 falls once let go, the target is pulled with the arm idle."""
    obs, boxes = _scene(extra_leaf=False)

    def decide(predict_held):
        planner = CollapseGraphPlanner(
            _grazing_predictor(boxes, 0.25),
            PARAMS,
            0.5,
            1,
            True,
            idle_hold_share=0.1,
            predict_held=predict_held,
        )
        return planner.decide(obs, 0, frozenset())

    assert decide(lambda d, m, h: np.zeros(m.shape, np.float32)).hold == 1
    idle = decide(lambda d, m, h: h.astype(np.float32))
    assert (idle.pull, idle.hold) == (0, None) and "idle_hold" not in idle.state


def test_a_search_for_a_hold_tries_every_visible_box_after_the_feared_one():
    """hold_feared search: target 0's pull fears for box 1 (a quarter, over cp_max 0.2);
    on maps that know a held pull, holding box 1 still fails (it falls once let go) and
    holding box 2 passes: search holds box 2, any gives up."""
    obs, boxes = _scene(extra_leaf=True)
    box1 = obs.instance == 2

    def predict_held(depth, mask, held_mask):
        fails = not (held_mask.astype(bool) & (obs.instance == 3)).any()
        return box1.astype(np.float32) if fails else np.zeros(mask.shape, np.float32)

    def planner(hold_feared):
        return CollapseGraphPlanner(
            _grazing_predictor(boxes, 0.25),
            PARAMS,
            0.2,
            1,
            True,
            hold_feared=hold_feared,
            predict_held=predict_held,
        )

    decision = planner("search").decide(obs, 0, frozenset())
    assert (decision.pull, decision.hold, decision.state["feared_hold"]) == (0, 2, 2)
    with pytest.raises(ValueError):
        planner("any").decide(obs, 0, frozenset())
