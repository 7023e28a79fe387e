"""The box head and physics from depth fused per box (support/box_fusion.py): the fusion's
inputs, its fit, its fallback, the scene rows and the mapping of fitted boxes to masks."""

from __future__ import annotations

import types

import numpy as np
import pytest

from clutterbench.collapse.box_head import EDGE_HEADS, OUTPUTS
from clutterbench.support import box_fusion as bf


def _scene(rng: np.random.Generator, k: int = 5, informative: bool = True) -> bf.FusionScene:
    """A scene whose truth the simulated pulls give exactly and the head only roughly."""
    truth = rng.random((k, k)) < 0.3
    np.fill_diagonal(truth, False)
    probs = np.zeros((k, k, len(OUTPUTS)), np.float32)
    for kind in EDGE_HEADS:
        noisy = np.clip(truth * 0.6 + rng.random((k, k)) * 0.4, 0.01, 0.99)
        probs[..., OUTPUTS.index(kind)] = noisy
    probs[..., OUTPUTS.index("contact")] = 0.9
    simulated = truth if informative else rng.random((k, k)) < 0.3
    return bf.FusionScene(
        index=0,
        ids=list(range(k)),
        probs=probs,
        simulated={kind: simulated.copy() for kind in EDGE_HEADS},
        known=np.ones(k, bool),
        truth={kind: truth.copy() for kind in EDGE_HEADS},
        contact=np.ones((k, k), bool),
    )


def test_a_pull_not_simulated_gives_no_physics_input():
    x = bf.features(np.array([0.5, 0.9]), np.array([True, True]), np.array([False, True]))
    assert x[0].tolist() == [0.0, 0.0, 0.0]
    assert x[1, 0] == pytest.approx(np.log(9.0))
    assert x[1, 1:].tolist() == [1.0, 0.0]


def test_the_fit_recovers_the_weights_that_made_the_labels():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(20000, 2))
    w = np.array([1.5, -2.0, 0.5])
    y = (rng.random(20000) < 1 / (1 + np.exp(-(x @ w[:2] + w[2])))).astype(float)
    got = bf.fit_logistic(x, y, ridge=0.0)
    assert np.allclose(got, w, atol=0.1)


def test_the_fusion_leans_on_the_simulation_where_it_knows_the_truth():
    rng = np.random.default_rng(1)
    scenes = [_scene(rng) for _ in range(20)]
    chosen = bf.choose_fusion(scenes, "pull")
    assert chosen["weights"][1] > 1.0 and chosen["weights"][2] < -1.0
    fused = bf.graph_scores(
        scenes,
        lambda s: bf.method_probs(s, "pull", "fused", chosen["weights"]),
        "pull",
        chosen["edge"],
    )
    assert fused == (1.0, 1.0)


def test_pairs_of_one_class_leave_the_head_alone():
    rng = np.random.default_rng(2)
    sc = _scene(rng)
    for kind in EDGE_HEADS:
        sc.truth[kind][:] = False
    chosen = bf.choose_fusion([sc], "pull")
    assert chosen["weights"] == list(bf.HEAD_ALONE)
    p = sc.probs[..., OUTPUTS.index("pull")].astype(np.float64)
    np.fill_diagonal(p, 0.0)
    assert np.allclose(bf.method_probs(sc, "pull", "fused", chosen["weights"]), p, atol=1e-3)


def test_physics_from_depth_answers_only_the_pulls_it_simulated():
    rng = np.random.default_rng(3)
    sc = _scene(rng)
    sc.known[2] = False
    p = bf.method_probs(sc, "pull", "physics_from_depth")
    head = sc.probs[..., OUTPUTS.index("pull")]
    assert np.allclose(p[2, [0, 1, 3, 4]], head[2, [0, 1, 3, 4]])
    assert set(np.unique(p[[0, 1, 3, 4]])) <= {0.0, 1.0}
    assert (np.diag(p) == 0).all()


def test_fusion_rows_score_each_kind_against_its_own_truth():
    rng = np.random.default_rng(4)
    sc = _scene(rng)
    sc.truth["pull_collapse"][:] = False
    chosen = {
        k: {"weights": [0.0, 5.0, -5.0, 0.0], "edge": 0.5, "physics_edge": 0.5} for k in EDGE_HEADS
    }
    rows = {r["method"]: r for r in bf.fusion_rows(sc, chosen)}
    assert rows["pull_physics_pull"]["tp"] == rows["pull_box_fused"]["tp"]
    assert rows["pull_box_fused"]["precision"] == 1.0
    assert rows["pull_box_fused"]["recall"] == 1.0
    assert rows["pull_collapse_box_fused"]["n_true"] == 0
    assert rows["pull_collapse_box_fused"]["n_pred"] == rows["pull_box_fused"]["n_pred"] > 0


def test_fitted_boxes_are_mapped_to_their_masks(monkeypatch):
    """The fit keeps masks 0 and 2 (fitted boxes 0 and 1): the pull of fitted box 0 moving
    fitted box 1 marks mask 2 from mask 0; mask 1 was not fitted, so not simulated."""
    from clutterbench.perception import fitted_scenes as fitted
    from clutterbench.sim import labelling

    n = 2
    disp = np.array([[np.nan, 0.05], [0.0, np.nan]])
    outcome = types.SimpleNamespace(
        displacement_m=disp,
        drop_m=np.nan_to_num(disp),
        tilt_deg=np.zeros((n, n)),
        left_shelf=np.zeros((n, n), bool),
    )
    scene = types.SimpleNamespace(spec=types.SimpleNamespace(meta={"ids": [0, 2]}))
    monkeypatch.setattr(fitted, "make_estimator", lambda *a: lambda obs: None)
    monkeypatch.setattr(fitted, "scene_of", lambda *a: scene)
    monkeypatch.setattr(labelling, "pull_outcomes", lambda *a: outcome)
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.config import Ch6TrialParams

    simulate = bf.fitted_pulls(SimConfig(), Ch6TrialParams(), 0.005, (0.01, 15.0), "various", 20)
    masks = np.zeros((3, 8, 8), bool)
    for j in range(3):
        masks[j, j, j] = True
    marked, known = simulate(np.ones((8, 8), np.float32), masks)
    assert known.tolist() == [True, False, True]
    assert np.argwhere(marked["pull"]).tolist() == [[0, 2]]
    assert np.argwhere(marked["pull_collapse"]).tolist() == [[0, 2]]


def test_the_trials_fitted_pull_maps_a_held_box_onto_the_fit(monkeypatch):
    """The fit keeps boxes 0 and 2 of the observation (fitted 0 and 1). A held pull is asked
    of the fit by fitted indices and answered over the visible ids; a held box the fit
    dropped cannot be simulated (None)."""
    from clutterbench.perception import fitted_scenes as fitted
    from clutterbench.sim import pull
    from clutterbench.trials.ch6 import truth_maps
    from clutterbench.trials.ch6.planners import box as planners

    asked = []

    class Fit:
        def __init__(self, *args):
            pass

        def at(self, *args):
            pass

        def moved_by_removing(self, box):
            asked.append((box, None))
            return np.array([False, False])

        def moved_by_held_pull(self, box, hold):
            asked.append((box, hold))
            return np.array([False, True])  # the held box (fitted 1) leaves the shelf

    scene = types.SimpleNamespace(spec=types.SimpleNamespace(meta={"ids": [0, 2]}))
    monkeypatch.setattr(fitted, "make_estimator", lambda *a: lambda obs: None)
    monkeypatch.setattr(fitted, "scene_of", lambda *a: scene)
    monkeypatch.setattr(truth_maps, "TruthCollapseMaps", Fit)
    monkeypatch.setattr(pull, "SceneState", types.SimpleNamespace(start=lambda spec: None))
    from clutterbench.trials.config import Ch6TrialParams

    job = types.SimpleNamespace(
        params=Ch6TrialParams(),
        stream_cfg=types.SimpleNamespace(catalogue="various"),
        camera=None,
        physics=None,
        collapse_free=None,
    )
    spec = types.SimpleNamespace(shelf=None)
    simulate = planners.fitted_pull(job, spec, "pull_collapse")
    obs = types.SimpleNamespace(depth_m=np.ones((4, 4), np.float32))
    assert simulate(obs, [0, 1, 2], 0).tolist() == [False, False, False]
    assert simulate(obs, [0, 1, 2], 0, 2).tolist() == [False, False, True]
    assert asked == [(0, None), (0, 1)]
    assert simulate(obs, [0, 1, 2], 0, 1) is None  # box 1 was not fitted


def test_the_edges_take_the_contact_they_are_given_and_the_head_s_by_default():
    """A recheck may score the graph with another contact (dev box_physics_fusion: the fitted
    scene's, or the truth as a ceiling); the stage's edges keep the head's."""
    from experiments.box_physics_fusion import contact_of

    sc = _scene(np.random.default_rng(4), k=3)
    sc.probs[..., OUTPUTS.index("contact")] = 0.9
    sc.contact = np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]], bool)
    outcome = np.ones((3, 3))
    assert bf.edges(sc, outcome, 0.5) == {(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)}
    truth = contact_of("truth")
    assert bf.edges(sc, outcome, 0.5, truth) == {(0, 1), (1, 0)}
    sc.fitted_contact = np.array([[np.nan, 0.0, 1.0], [0.0, np.nan, np.nan], [1.0, np.nan, np.nan]])
    seen = contact_of("fitted")
    assert bf.edges(sc, outcome, 0.5, seen) == {(0, 2), (2, 0), (1, 2), (2, 1)}
    mean = contact_of("mean")(sc)
    assert mean[0, 1] == pytest.approx(0.45) and mean[1, 2] == pytest.approx(0.9)


def _touching_scenes(
    rng: np.random.Generator, n: int = 40, informative: bool = True
) -> list[bf.FusionScene]:
    """Scenes whose fitted contact is the truth (box 3 never fitted) and whose head says 0.9."""
    scenes = []
    for i in range(n):
        sc = _scene(rng, k=4, informative=informative)
        sc.index = i
        sc.contact = rng.random((4, 4)) < 0.4
        sc.contact = sc.contact | sc.contact.T
        np.fill_diagonal(sc.contact, False)
        sc.fitted_contact = sc.contact.astype(float)
        sc.fitted_contact[3, :] = sc.fitted_contact[:, 3] = np.nan  # box 3 was not fitted
        scenes.append(sc)
    return scenes


def test_the_learned_contact_follows_the_fitted_contact_where_it_tells_the_truth():
    """trials.ch6.box_contact learned: fitted on scenes whose fitted contact is the truth and
    whose head says 0.9 everywhere, it puts touching pairs above the others and falls back on
    the head's logit where no fit holds the pair."""
    from experiments.box_physics_fusion import contact_of

    scenes = _touching_scenes(np.random.default_rng(7))
    w = bf.fit_contact(scenes)
    learned = contact_of("learned", w)
    c = np.stack([learned(sc) for sc in scenes])
    touch = np.stack([sc.contact for sc in scenes])
    known = np.stack([np.isfinite(sc.fitted_contact) for sc in scenes])
    off = ~np.eye(4, dtype=bool)[None]
    assert c[touch & known & off].min() > 0.5 > c[~touch & known & off].max()
    assert np.allclose(c[~known & off], c[0, 0, 3])  # the head alone: one value for them all
    with pytest.raises(ValueError, match="four weights"):
        contact_of("learned")


def test_the_chosen_fusion_carries_its_contact_into_table_6_2s_fused_row():
    """A fusion chosen with the learned contact scores Table 6.2's fused row with it; one
    without contact weights keeps the head's (what the stage does by default)."""
    scenes = _touching_scenes(np.random.default_rng(8))
    w = bf.fit_contact(scenes)
    with_learned = bf.choose_fusion(scenes, "pull", bf.learned_contact(w))
    with_learned["contact_weights"] = list(w)
    head_only = bf.choose_fusion(scenes, "pull")
    assert bf.contact_fn(head_only) is bf.head_contact

    def pooled(chosen: dict, method: str) -> tuple[float, list[dict]]:
        rows = [
            r
            for sc in scenes
            for r in bf.fusion_rows(sc, {k: chosen for k in EDGE_HEADS})
            if r["method"] == method
        ]
        return sum(r["tp"] for r in rows) / sum(r["n_pred"] for r in rows), rows

    learned_precision, _ = pooled(with_learned, "pull_box_fused")
    head_precision, _ = pooled(head_only, "pull_box_fused")
    assert learned_precision > head_precision + 0.1  # it prunes the edges that do not touch
    # physics from depth's row keeps the head's contact either way (repr: NaN recalls)
    alone = [repr(pooled(c, "pull_physics_pull")[1]) for c in (with_learned, head_only)]
    assert alone[0] == alone[1]


def test_the_support_stage_learns_the_contact_only_when_asked(monkeypatch):
    """trials.ch6.box_contact head (the default): box_fusion.json's fusion has the keys it
    always had; learned: the contact's weights too, the edge threshold chosen with it."""
    from clutterbench.support import run

    scenes = _touching_scenes(np.random.default_rng(9), informative=False)
    it = iter(scenes * 2)
    monkeypatch.setattr(run, "answer_scene", lambda sc, maps, sim, contacts=None: next(it))
    val = [types.SimpleNamespace(ids=[0, 1, 2, 3]) for _ in scenes]
    head = run.choose_box_fusion(val, None, None)
    assert {k: set(v) for k, v in head.items()} == {
        k: {"edge", "outcome", "weights", "physics_edge"} for k in EDGE_HEADS
    }
    learned = run.choose_box_fusion(val, None, None, contacts=lambda d, m: None)
    w = bf.fit_contact(scenes)
    for kind in EDGE_HEADS:
        assert learned[kind]["contact_weights"] == pytest.approx(w, abs=1e-6)
        again = bf.choose_fusion(scenes, kind, bf.learned_contact(learned[kind]["contact_weights"]))
        assert learned[kind]["edge"] == again["edge"]
    assert learned["pull"]["edge"] != head["pull"]["edge"]  # here the contact moves it


def test_the_precision_first_point_is_the_most_recall_at_the_precision_asked():
    """The precision-first operating point (trials.ch6.box_edge_precision, dev
    box_physics_fusion): of the thresholds whose mean precision reaches the precision asked,
    the one of the highest recall; where none does, the highest precision; NaN never
    qualifies."""
    from clutterbench.support.box_fusion import precision_first

    curve = [(0.80, 0.99), (0.93, 0.86), (0.91, 0.90), (float("nan"), 0.95), (0.99, 0.10)]
    assert precision_first(curve, 0.90) == 2
    below = [(0.80, 0.99), (0.85, 0.90), (float("nan"), 0.5), (0.84, 0.95)]
    assert precision_first(below, 0.90) == 1
    # ties in recall: the more precise threshold
    assert precision_first([(0.91, 0.80), (0.95, 0.80), (0.97, 0.70)], 0.90) == 1


def test_a_precision_asked_of_the_fused_graph_moves_only_its_edge_threshold():
    """choose_fusion with `precision` (trials.ch6.box_edge_precision): the same weights and
    outcome threshold; the edge threshold of the most recall at that precision on the scenes,
    so a lower precision asked gives more recall and a higher one more precision."""
    rng = np.random.default_rng(5)
    scenes = []
    for _ in range(30):
        sc = _scene(rng, k=6, informative=False)
        truth = sc.truth["pull"]
        weak = np.clip(truth * 0.35 + rng.random(truth.shape) * 0.6, 0.01, 0.99)
        sc.probs[..., OUTPUTS.index("pull")] = weak
        scenes.append(sc)
    f1 = bf.choose_fusion(scenes, "pull")
    scores = {}
    for asked in (0.6, 0.8, 1.0):
        chosen = bf.choose_fusion(scenes, "pull", precision=asked)
        assert chosen["weights"] == f1["weights"] and chosen["outcome"] == f1["outcome"]
        prob = lambda s, w=chosen["weights"]: bf.method_probs(s, "pull", "fused", w)  # noqa: E731
        scores[asked] = bf.graph_scores(scenes, prob, "pull", chosen["edge"])
        assert scores[asked][0] >= asked
    assert scores[0.6][1] > scores[0.8][1] > scores[1.0][1]
    assert scores[0.6][0] < scores[0.8][0] < scores[1.0][0]
