"""The box head: its pair features, training, scores, checkpoint checks, its predictors (the
network alone and learned plus physics) and the CPG planner reading them per box."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from clutterbench.collapse.box_head import (
    OUTPUTS,
    BoxHead,
    BoxHeadMeta,
    edge_probability,
    feature_names,
    load_box_head,
    off_diagonal,
    pair_features,
    save_box_head,
)
from clutterbench.collapse.box_predict import BoxMaps, FusedBoxMaps
from clutterbench.errors import ClutterbenchError
from clutterbench.observation import CameraModel, Observation
from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
from clutterbench.planning.ch6.support import SupportParams
from clutterbench.report.table_6_1_boxes import box_table
from clutterbench.support.box_train import (
    Pairs,
    auroc,
    average_ranks,
    binary_scores,
    choose_threshold,
    score_methods,
    train_box_head,
)
from clutterbench.support.config import BoxHeadConfig

HEADS = ("deletion", "pull", "pull_collapse")


def _masks() -> np.ndarray:
    """Three boxes: 0 and 1 side by side, 2 far right."""
    m = np.zeros((3, 16, 16), bool)
    m[0, 4:12, 1:4] = True  # 24 px; box 1: 32 px
    m[1, 4:12, 4:8] = True
    m[2, 4:12, 12:16] = True
    return m


def test_pair_features_read_each_head_on_the_other_box():
    masks = _masks()
    probs = np.zeros((3, 3, 16, 16), np.float32)
    probs[0, 1][masks[1]] = 0.8  # pulling 0: the pull head marks all of box 1
    probs[0, 1][6, 5] = 1.0
    gaps = np.array([[0.0, 0.01, np.inf], [0.01, 0.0, np.inf], [np.inf, np.inf, 0.0]])
    depth = np.ones((16, 16), np.float32)
    f = pair_features(probs, masks, depth, gaps)
    names = feature_names(HEADS)
    assert f.shape == (3, 3, len(names))
    at = {n: i for i, n in enumerate(names)}
    n = masks[1].sum()
    assert f[0, 1, at["pull_mean"]] == pytest.approx((0.8 * (n - 1) + 1.0) / n)
    assert f[0, 1, at["pull_max"]] == pytest.approx(1.0)
    assert f[0, 1, at["pull_share"]] == pytest.approx(1.0)
    assert f[0, 2, at["pull_mean"]] == 0.0 and f[1, 0, at["pull_mean"]] == 0.0
    assert f[0, 1, at["gap_m"]] == pytest.approx(0.01) and f[0, 2, at["gap_m"]] == pytest.approx(
        0.2
    )
    assert f[0, 1, at["dx"]] > 0 > f[1, 0, at["dx"]]  # box 1 is right of box 0
    assert f[0, 1, at["h_overlap"]] == 0.0 and f[0, 2, at["h_gap"]] == pytest.approx(8 / 16)
    assert f[0, 1, at["above"]] < 0 and f[0, 1, at["below"]] < 0  # side by side, same rows
    assert off_diagonal(f).shape == (6, len(names))


def test_auroc_and_scores_match_their_definitions():
    rng = np.random.default_rng(0)
    p, y = rng.random(200), rng.random(200) < 0.3
    pos, neg = p[y], p[~y]
    brute = ((pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()) / (
        len(pos) * len(neg)
    )
    assert auroc(p, y) == pytest.approx(brute)
    s = binary_scores(np.array([0.9, 0.8, 0.2, 0.1]), np.array([1, 0, 1, 0]), 0.5)
    assert (s["precision"], s["recall"]) == (0.5, 0.5)
    # a threshold that separates the classes is chosen over one that does not
    assert choose_threshold(np.array([0.9, 0.7, 0.3, 0.2]), np.array([1, 1, 0, 0])) <= 0.65


@pytest.mark.parametrize("levels", [None, 3, 100])
def test_average_ranks_are_pandas_ranks_value_for_value(levels):
    rng = np.random.default_rng(levels or 0)
    p = rng.random(500) if levels is None else rng.integers(0, levels, 500) / levels
    p[::7] = -0.0 if levels else p[::7]  # -0.0 ties with 0.0
    expected = pd.Series(p).rank(method="average").to_numpy()
    assert np.array_equal(average_ranks(p), expected)
    y = rng.random(500) < 0.4
    assert auroc(p, y) == float(
        (expected[y].sum() - y.sum() * (y.sum() + 1) / 2) / (y.sum() * (~y).sum())
    )
    p[3] = np.nan  # a NaN among the predictions: pandas' answer, NaN where it is a positive
    y[3] = True
    assert np.isnan(auroc(p, y))


def _pairs(n: int, seed: int) -> Pairs:
    """Separable pairs: outcome j is on where feature j > 0."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, len(feature_names(HEADS)))).astype(np.float32)
    y = (x[:, : len(OUTPUTS)] > 0).astype(np.float32)
    rows = pd.DataFrame({"family": "random", "visible": rng.integers(2, 10, n)})
    return Pairs(x, y, rows)


def test_training_learns_a_separable_problem_and_keeps_its_best_epoch():
    cfg = BoxHeadConfig(epochs=8, hidden=16, batch_size=64, lr=0.01)
    train, val = _pairs(2000, 0), _pairs(500, 1)
    model, log, best = train_box_head(train, val, cfg, seed=0)
    assert list(log["epoch"]) == list(range(1, 9)) and best == int(log["val_loss"].idxmin()) + 1
    with torch.no_grad():
        p = torch.sigmoid(model(torch.from_numpy(val.x))).numpy()
    for j in range(len(OUTPUTS)):
        assert auroc(p[:, j], val.y[:, j]) > 0.97
    scores, chosen = score_methods({"box_head": p}, {"box_head": p}, val, val)
    assert set(chosen["box_head"]) == set(OUTPUTS)
    assert (scores[scores["group"] == "all"]["f1"] > 0.85).all()


def test_a_checkpoint_is_refused_in_one_line_when_wrong(tmp_path):
    meta = BoxHeadMeta("cp_focal", HEADS, feature_names(HEADS), 8, 64)
    path = tmp_path / "best.pt"
    save_box_head(BoxHead(len(meta.features), 8), meta, path)
    model, got = load_box_head(path, cp_model="cp_focal")
    assert got == meta and isinstance(model, BoxHead)
    with pytest.raises(ClutterbenchError, match="trained on cp_focal's maps"):
        load_box_head(path, cp_model="cp_other")
    with pytest.raises(ClutterbenchError, match="no box-head checkpoint"):
        load_box_head(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ClutterbenchError, match="not a box-head checkpoint"):
        load_box_head(tmp_path / "junk.pt")


class _FixedMaps(BoxMaps):
    """BoxMaps with the network's answer given: probs[x, y, output]."""

    def __init__(self, probs: np.ndarray, edge_threshold: float = 0.5, **kwargs):
        self.given = probs
        self.head, self.edge_threshold = "pull_collapse", edge_threshold
        self._last, self.simulated = None, 0
        for k, v in kwargs.items():
            setattr(self, k, v)

    def probs(self, depth_m, masks):
        return self.given


class _FixedFused(FusedBoxMaps, _FixedMaps):
    def __init__(self, probs, simulate, weights, simulate_held=False, contact=None, cw=None):
        _FixedMaps.__init__(self, probs)
        self.simulate, self.weights, self._rows, self._key = simulate, weights, {}, None
        self.simulate_held = simulate_held
        self.contact, self.contact_weights = contact, cw


def _obs() -> Observation:
    masks = _masks()
    inst = np.zeros((16, 16), np.uint8)
    for k, m in enumerate(masks):
        inst[m] = k + 1
    return Observation(np.ones((16, 16), np.float32), inst, CameraModel(np.eye(3), np.eye(4)))


def _probs(collapse: np.ndarray, contact: np.ndarray) -> np.ndarray:
    p = np.zeros((3, 3, len(OUTPUTS)), np.float32)
    p[..., OUTPUTS.index("pull_collapse")] = collapse
    p[..., OUTPUTS.index("pull")] = collapse
    p[..., OUTPUTS.index("contact")] = contact
    return p


def test_box_edges_are_outcome_times_contact_above_the_threshold():
    collapse = np.array([[0, 0.9, 0.9], [0.1, 0, 0], [0, 0, 0]], np.float32)
    contact = np.array([[0, 0.9, 0.1], [0.9, 0, 0], [0.1, 0, 0]], np.float32)
    maps = _FixedMaps(_probs(collapse, contact))
    edges = maps.box_edges(_obs(), [0, 1, 2], _masks())
    assert [(a, b) for a, b, _ in edges] == [(0, 1)]  # 0.81; (0, 2): 0.09
    assert edge_probability(maps.given, "pull_collapse")[0, 1] == pytest.approx(0.81)


def test_the_fused_predictor_fuses_each_simulated_row_once_per_observation():
    collapse = np.array([[0, 0.5, 0.5], [0.02, 0, 0.01], [0, 0.95, 0]], np.float32)
    calls = []

    def simulate(obs, ids, box, hold=None):
        calls.append(box)
        if box == 1:
            return None  # the fit dropped box 1: the network's logit alone
        return np.array([False, False, True])  # the fitted boxes say: box 2 falls

    weights = (1.0, 2.0, -2.0, 0.0)  # logit + 2 when simulated marked, - 2 when not
    maps = _FixedFused(_probs(collapse, np.ones((3, 3))), simulate, weights)
    obs, ids, masks = _obs(), [0, 1, 2], _masks()
    rows = [maps.box_row(obs, ids, masks, k) for k in range(3)]
    assert calls == [0, 1, 2]
    sig = lambda z: 1 / (1 + np.exp(-z))  # noqa: E731
    assert rows[0].tolist() == pytest.approx([0.0, sig(-2.0), sig(2.0)])  # 0.5: logit 0
    assert rows[1].tolist() == pytest.approx([0.02, 0.0, 0.01], abs=1e-6)
    logit = np.log(0.95 / 0.05)
    expected = [sig(-2.0 + np.log(1e-4 / (1 - 1e-4))), sig(logit - 2), 0.0]  # 0 clipped to 1e-4
    assert rows[2].tolist() == pytest.approx(expected, rel=1e-4)
    maps.box_row(obs, ids, masks, 0)  # the same observation: not simulated again
    assert calls == [0, 1, 2] and maps.simulated == 3
    with pytest.raises(ValueError, match="fusion weights"):
        FusedBoxMaps(simulate=simulate, weights=(1.0, 0.0))


def test_the_learned_contact_prunes_an_edge_the_fitted_boxes_do_not_touch():
    """trials.ch6.box_contact learned: the head says every pair touches (0.9); the fitted
    scenes say boxes 0 and 2 do not, 0 and 1 do; the learned contact (weights chosen on val
    by the support stage) keeps (0, 1) and drops (0, 2), which the head's contact keeps."""
    collapse = np.array([[0, 0.9, 0.9], [0, 0, 0], [0, 0, 0]], np.float32)

    def simulate(obs, ids, box, hold=None):
        return np.array([False, True, True]) if box == 0 else np.zeros(3, bool)

    weights = (1.0, 0.0, 0.0, 0.0)  # the network's row alone
    fitted = np.array([[np.nan, 1.0, 0.0], [1.0, np.nan, 0.0], [0.0, 0.0, np.nan]])
    asked = []

    def contact(obs, ids):
        asked.append(list(ids))
        return fitted

    probs = _probs(collapse, np.full((3, 3), 0.9))
    obs, ids, masks = _obs(), [0, 1, 2], _masks()
    head = _FixedFused(probs, simulate, weights)
    assert [(a, b) for a, b, _ in head.box_edges(obs, ids, masks)] == [(0, 1), (0, 2)]
    cw = (0.0, 4.0, -4.0, 0.0)  # touching in the fits: logit + 4; not: - 4
    learned = _FixedFused(probs, simulate, weights, contact=contact, cw=cw)
    assert [(a, b) for a, b, _ in learned.box_edges(obs, ids, masks)] == [(0, 1)]
    assert asked == [[0, 1, 2]]
    with pytest.raises(ValueError, match="both the fitted contacts and weights"):
        FusedBoxMaps(simulate=simulate, weights=weights, contact=contact)


def test_a_held_pull_simulated_on_the_fitted_boxes_judges_the_held_box_too():
    """Pulling 0 collapses 1 (network 0.6). Held, 1 falls once let go in one fit and is
    saved in the other: only the simulated held pull tells them apart; left out (Fig. 6.7
    (d)), the held box is never judged and the held pull always passes."""
    collapse = np.array([[0, 0.6, 0], [0.05, 0, 0], [0, 0, 0]], np.float32)
    weights = (1.0, 2.0, -2.0, 0.0)
    params = SupportParams("coverage", 0.5, 0.5, 2, 0.0)
    asked = []

    def fit(held_falls: bool):
        def simulate(obs, ids, box, hold=None):
            asked.append((box, hold))
            marked = np.zeros(3, bool)
            marked[1] = box == 0 and (hold is None or held_falls)
            return marked

        return simulate

    def score(held_falls: bool, simulate_held: bool) -> float:
        maps = _FixedFused(_probs(collapse, np.ones((3, 3))), fit(held_falls), weights)
        maps.simulate_held = simulate_held
        planner = CollapseGraphPlanner(
            maps, params, cp_max=0.5, min_pixels=1, bimanual=True, score_over="visible"
        )
        return planner.collapse_score(_obs(), 0, hold=1)

    assert score(held_falls=True, simulate_held=False) < 0.01  # box 2 only: 0 clipped
    assert score(held_falls=False, simulate_held=False) < 0.01
    assert asked and all(hold is None for _, hold in asked)
    asked.clear()
    sig = lambda z: 1 / (1 + np.exp(-z))  # noqa: E731
    logit = np.log(0.6 / 0.4)
    assert score(held_falls=True, simulate_held=True) == pytest.approx(sig(logit + 2), rel=1e-5)
    assert score(held_falls=False, simulate_held=True) == pytest.approx(sig(logit - 2), rel=1e-5)
    assert (0, 1) in asked  # the held pull itself was simulated

    def unknown(obs, ids, box, hold=None):
        return None if hold is not None else np.array([False, True, False])

    maps = _FixedFused(_probs(collapse, np.ones((3, 3))), unknown, weights, simulate_held=True)
    assert maps.held_row(_obs(), [0, 1, 2], _masks(), 0, 1) is None  # the fit cannot answer
    planner = CollapseGraphPlanner(maps, params, cp_max=0.5, min_pixels=1, score_over="visible")
    assert planner.collapse_score(_obs(), 0, hold=1) < 0.01  # then the held box is left out


def test_the_planner_reads_a_per_box_predictor_for_its_graph_and_its_scores():
    # pulling 0 collapses 1 (an edge: 0 carries 1); pulling 1 collapses nothing
    collapse = np.array([[0, 0.9, 0], [0.05, 0, 0], [0, 0, 0]], np.float32)
    contact = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]], np.float32)
    maps = _FixedMaps(_probs(collapse, contact))
    params = SupportParams("coverage", 0.5, 0.5, 2, 0.0)
    planner = CollapseGraphPlanner(maps, params, cp_max=0.5, min_pixels=1, score_over="visible")
    obs = _obs()
    assert planner.collapse_score(obs, 0) == pytest.approx(0.9)
    assert planner.collapse_score(obs, 1) == pytest.approx(0.05)
    decision = planner.decide(obs, 0, frozenset())
    assert decision.pull == 1  # the box the target carries comes out first
    assert decision.state["edges"] == [[0, 1, 0.9]]


def test_the_per_box_table_lists_every_method_and_refuses_a_bad_file(tmp_path):
    val = _pairs(300, 2)
    p = np.clip(val.y + 0.1, 0, 1)
    scores, _ = score_methods({"box_head": p}, {"box_head": p}, val, val)
    box_table(scores, tmp_path, "tiny")
    text = (tmp_path / "table_6_1_boxes.md").read_text()
    assert "box head (per box)" in text and "pull collapses the box" in text
    with pytest.raises(ClutterbenchError, match="lack column"):
        box_table(scores.drop(columns=["auroc"]), tmp_path, "tiny")
