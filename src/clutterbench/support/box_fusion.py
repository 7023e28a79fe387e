"""The box head and physics from depth, fused per box: for a pulled box x and another box y,
a logistic regression on the box head's logit that the pull of x marks y and on what the
trials' pull of x does to y among the boxes fitted to the same depth image (physics from
depth, no training). Its weights, edge and outcome thresholds are chosen on validation
scenes (the support stage); Table 6.2 scores its support graph (method `<head>_box_fused`).

A pull physics from depth cannot simulate (a box the fit dropped, a fit that failed) keeps
the box head's answer alone: both physics inputs are 0 there.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from clutterbench.collapse.box_head import EDGE_HEADS, OUTPUTS, off_diagonal
from clutterbench.collapse.box_predict import (
    contact_inputs,
    features,
    fuse,
    learned_contact_of,
)
from clutterbench.planning.ch6.support import edge_precision_recall
from clutterbench.support.box_train import THRESHOLDS, choose_threshold

RIDGE = 1e-3
"""L2 weight of the fusion's logistic regression, per pair (its bias left free)."""
HEAD_ALONE = (1.0, 0.0, 0.0, 0.0)
"""Fusion weights that give the box head's probability unchanged."""
SimulatePulls = Callable[[np.ndarray, np.ndarray], tuple[dict[str, np.ndarray], np.ndarray]]
"""(depth_m, masks (K, H, W)) -> (label kind -> (K, K) float: the share of the fitted scenes
whose simulated pull of x marks y (0 or 1 with one fit), (K,) bool: box x's pull was
simulated)."""


@dataclass
class FusionScene:
    """One scene's answers, in the order of its visible boxes (K)."""

    index: int
    ids: list[int]
    probs: np.ndarray
    """(K, K, len(OUTPUTS)) the box head's probabilities."""
    simulated: dict[str, np.ndarray]
    """label kind -> (K, K) float: physics from depth's outcome (the share of the fitted
    scenes whose pull of x marks y; 0 or 1 with one fit)."""
    known: np.ndarray
    """(K,) bool: box x was fitted, so its pull was simulated."""
    truth: dict[str, np.ndarray]
    """label kind -> (K, K) bool: the physics truth of the trials' pull."""
    contact: np.ndarray
    """(K, K) bool: x and y touch in the settled scene."""
    fitted_contact: np.ndarray | None = None
    """(K, K) the share of the scenes fitted to the image in which x and y touch once settled
    (NaN where no fit holds both); None where not asked for (`answer_scene`)."""


def fit_logistic(x: np.ndarray, y: np.ndarray, ridge: float = RIDGE, steps: int = 50) -> np.ndarray:
    """(F + 1,) weights (the last the bias) of an L2-regularised logistic regression of y on
    x (N, F), by Newton's method: deterministic, no learning rate."""
    a = np.concatenate([x, np.ones((len(x), 1))], 1)
    w = np.zeros(a.shape[1])
    reg = np.full(a.shape[1], ridge * len(x))
    reg[-1] = 0.0
    for _ in range(steps):
        p = 1.0 / (1.0 + np.exp(-(a @ w)))
        grad = a.T @ (p - y) + reg * w
        hess = (a * (p * (1 - p))[:, None]).T @ a + np.diag(reg) + 1e-9 * np.eye(a.shape[1])
        step = np.linalg.solve(hess, grad)
        w = w - step
        if np.abs(step).max() < 1e-10:
            break
    return w


def method_probs(sc: FusionScene, kind: str, method: str, weights=None) -> np.ndarray:
    """(K, K) probability that pulling x marks y under `kind`: the box head's (`box_head`),
    physics from depth's where it simulated and the head's elsewhere (`physics_from_depth`),
    or the fusion with `weights` (`fused`); diagonal 0."""
    p = sc.probs[..., OUTPUTS.index(kind)].astype(np.float64)
    if method == "box_head":
        out = p.copy()
    elif method == "physics_from_depth":
        out = np.where(sc.known[:, None], sc.simulated[kind].astype(np.float64), p)
    elif method == "fused":
        assert weights is not None, "the fusion needs its weights"
        out = fuse(weights, p, sc.simulated[kind], sc.known[:, None])
    else:
        raise ValueError(f"unknown method {method!r}")
    np.fill_diagonal(out, 0.0)
    return out


def pairs(scenes: Sequence[FusionScene], kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Off-diagonal pairs of the scenes: (fusion features (n, 3), truth (n,) float)."""
    x = [
        off_diagonal(
            features(sc.probs[..., OUTPUTS.index(kind)], sc.simulated[kind], sc.known[:, None])
        )
        for sc in scenes
    ]
    y = [off_diagonal(sc.truth[kind]) for sc in scenes]
    return np.concatenate(x), np.concatenate(y).astype(np.float64)


ContactFn = Callable[[FusionScene], np.ndarray]
"""scene -> (K, K) probability that x and y touch (the edges' contact)."""


def head_contact(sc: FusionScene) -> np.ndarray:
    """The box head's contact probability (trials.ch6.box_contact head, the default)."""
    return sc.probs[..., OUTPUTS.index("contact")]


def fit_contact(scenes: Sequence[FusionScene]) -> np.ndarray:
    """(4,) weights of the learned contact (trials.ch6.box_contact learned): a logistic
    regression of the true contact on `contact_inputs` over the scenes' off-diagonal pairs
    (their fitted_contact filled in by `answer_scene`)."""
    assert all(sc.fitted_contact is not None for sc in scenes), "scenes without fitted contacts"
    x = [off_diagonal(contact_inputs(head_contact(sc), sc.fitted_contact)) for sc in scenes]
    y = [off_diagonal(sc.contact) for sc in scenes]
    if not scenes:
        return np.array(HEAD_ALONE)
    y_all = np.concatenate(y).astype(np.float64)
    if y_all.min() == y_all.max():  # one class only (a tiny profile's few scenes): the head
        return np.array(HEAD_ALONE)
    return fit_logistic(np.concatenate(x), y_all)


def learned_contact(weights: Sequence[float]) -> ContactFn:
    """ContactFn of the learned contact with `weights` (`fit_contact`)."""

    def contact(sc: FusionScene) -> np.ndarray:
        assert sc.fitted_contact is not None, "the learned contact needs the fitted contacts"
        return learned_contact_of(weights, head_contact(sc), sc.fitted_contact)

    return contact


def contact_fn(chosen: Mapping[str, Any]) -> ContactFn:
    """The edges' contact of a chosen fusion: learned where it carries contact weights (the
    support stage's choice under trials.ch6.box_contact learned), else the head's."""
    weights = chosen.get("contact_weights")
    return head_contact if weights is None else learned_contact(weights)


def edges(
    sc: FusionScene, outcome: np.ndarray, threshold: float, contact: ContactFn = head_contact
) -> set[tuple[int, int]]:
    """Support edges (x, y) whose outcome x contact probability exceeds threshold."""
    edge = outcome * contact(sc)
    return {(sc.ids[x], sc.ids[y]) for x, y in zip(*np.nonzero(edge > threshold)) if x != y}


def true_edges(sc: FusionScene, kind: str) -> set[tuple[int, int]]:
    a, b = np.nonzero(sc.truth[kind] & sc.contact)
    return {(sc.ids[i], sc.ids[j]) for i, j in zip(a, b) if i != j}


def graph_scores(
    scenes: Sequence[FusionScene],
    prob: Callable[[FusionScene], np.ndarray],
    kind: str,
    t: float,
    contact: ContactFn = head_contact,
) -> tuple[float, float]:
    """Mean precision and recall over the scenes (each where defined: Table 6.2's means) of
    the edges at threshold t against `kind`'s truth edges."""
    pr = np.array(
        [
            edge_precision_recall(edges(sc, prob(sc), t, contact), true_edges(sc, kind))
            for sc in scenes
        ],
        dtype=float,
    ).reshape(-1, 2)
    mean = [float(np.nanmean(v)) if np.isfinite(v).any() else float("nan") for v in pr.T]
    return mean[0], mean[1]


def precision_first(curve: Sequence[tuple[float, float]], precision: float) -> int:
    """The index of the precision-first operating point of `curve` ((mean precision, mean
    recall) at each threshold): of the thresholds whose precision reaches `precision`, the
    one of the highest recall (ties: the higher precision, then the first); where none does,
    the highest precision. NaN never qualifies."""
    ok = [i for i, (pr, _) in enumerate(curve) if np.isfinite(pr) and pr >= precision]
    if ok:
        return max(ok, key=lambda i: (np.nan_to_num(curve[i][1], nan=-1.0), curve[i][0], -i))
    return max(range(len(curve)), key=lambda i: (np.nan_to_num(curve[i][0], nan=-1.0), -i))


def choose_edge_threshold(
    scenes: Sequence[FusionScene],
    prob: Callable[[FusionScene], np.ndarray],
    kind: str,
    contact: ContactFn = head_contact,
    precision: float | None = None,
) -> float:
    """The threshold of THRESHOLDS with the best f1 of mean precision and recall (Table
    6.2's criterion, as the box head's edge threshold is chosen); with `precision`, the
    precision-first one (precision_first: the most recall at that mean precision)."""
    if precision is not None:
        curve = [graph_scores(scenes, prob, kind, float(t), contact) for t in THRESHOLDS]
        return float(THRESHOLDS[precision_first(curve, precision)])
    best, best_f1 = float(THRESHOLDS[len(THRESHOLDS) // 2]), -1.0
    for t in THRESHOLDS:
        precision, recall = graph_scores(scenes, prob, kind, float(t), contact)
        f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else -1.0
        if np.isfinite(f1) and f1 > best_f1:
            best, best_f1 = float(t), f1
    return best


def choose_fusion(
    scenes: Sequence[FusionScene],
    kind: str,
    contact: ContactFn = head_contact,
    precision: float | None = None,
) -> dict[str, Any]:
    """The fusion of label kind `kind` chosen on (validation) scenes: its weights (head
    logit, simulated and marked, simulated and not, bias), the outcome threshold of the best
    f1 on their pairs and the edge threshold of the best graph f1 with `contact` in the
    edges, or with `precision` the precision-first one (trials.ch6.box_edge_precision;
    physics from depth alone: always the best f1 with the head's contact)."""
    x, y = pairs(scenes, kind) if scenes else (np.zeros((0, 3)), np.zeros(0))
    # Pairs of one class only (a tiny profile's few scenes) teach no weights: the head alone.
    w = fit_logistic(x, y) if len(y) and y.min() < y.max() else np.array(HEAD_ALONE)
    p = 1.0 / (1.0 + np.exp(-(x @ w[:-1] + w[-1])))
    outcome = choose_threshold(p, y)
    edge = choose_edge_threshold(
        scenes, lambda sc: method_probs(sc, kind, "fused", w), kind, contact, precision
    )
    alone = choose_edge_threshold(
        scenes, lambda sc: method_probs(sc, kind, "physics_from_depth"), kind
    )
    return {
        "edge": edge,
        "outcome": outcome,
        "weights": [round(float(v), 6) for v in w],
        "physics_edge": alone,
    }


def fusion_rows(sc: FusionScene, chosen: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The scene's Table 6.2 rows, per label kind against its truth (scenes.csv's columns):
    the fused support graph (method `<head>_box_fused`) and physics from depth's pulls alone
    with the box head's contact (`<head>_physics_pull`)."""
    rows = []
    for kind in EDGE_HEADS:
        c = chosen[kind]
        truth = true_edges(sc, kind)
        for method, weights, t, name, contact in (
            ("fused", c["weights"], c["edge"], f"{kind}_box_fused", contact_fn(c)),
            ("physics_from_depth", None, c["physics_edge"], f"{kind}_physics_pull", head_contact),
        ):
            pred = set()
            if len(sc.ids) > 1:
                pred = edges(sc, method_probs(sc, kind, method, weights), t, contact)
            precision, recall = edge_precision_recall(pred, truth)
            rows.append(
                {
                    "method": name,
                    "n_true": len(truth),
                    "n_pred": len(pred),
                    "tp": len(pred & truth),
                    "precision": precision,
                    "recall": recall,
                }
            )
    return rows


FittedContacts = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(depth_m, masks (K, H, W)) -> (K, K) share of the fitted scenes in which x and y touch
(NaN where no fit holds both): `fitted_contacts`."""


def answer_scene(
    sc: Any, maps: Any, simulate: SimulatePulls, contacts: FittedContacts | None = None
) -> FusionScene:
    """The box head's and physics from depth's answers for one support scene
    (support/evaluate.py Scene, read with the truth of every pull head), with `contacts` the
    fitted scenes' contacts too; a scene with one visible box has no pair, and nothing is
    simulated."""
    k = len(sc.ids)
    fitted_contact = None
    if k > 1:
        simulated, known = simulate(sc.depth_m, sc.masks)
        if contacts is not None:
            fitted_contact = contacts(sc.depth_m, sc.masks)
    else:
        simulated, known = {h: np.zeros((k, k), bool) for h in EDGE_HEADS}, np.zeros(k, bool)
        if contacts is not None:
            fitted_contact = np.full((k, k), np.nan)
    return FusionScene(
        index=sc.index,
        ids=list(sc.ids),
        probs=maps.probs(sc.depth_m, sc.masks),
        simulated=simulated,
        known=known,
        truth={k: sc.moved_by[k].astype(bool) for k in EDGE_HEADS},
        contact=sc.contact.astype(bool),
        fitted_contact=fitted_contact,
    )


def scenes_fitted_to(
    sim: Any, ch6: Any, catalogue: str, min_pixels: int
) -> Callable[[np.ndarray, np.ndarray], list[Any]]:
    """(depth_m, masks (K, H, W)) -> the settled scenes fitted to that image with `catalogue`'s
    sizes (perception/fitted_scenes.py fitted_scenes: ch6.fit_hypotheses of them), mask j
    seen as box j; a fitted scene's box a is mask `spec.meta["ids"][a]`."""
    from clutterbench.observation import Observation
    from clutterbench.perception.fitted_scenes import fitted_scenes, make_estimator
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import camera_model
    from clutterbench.sim.shelf import Shelf

    shelf = Shelf()
    camera = camera_model(BoxWorld(shelf, sim.physics, render=True), sim.camera)
    estimate = make_estimator(catalogue, min_pixels)

    def fit(depth: np.ndarray, masks: np.ndarray) -> list[Any]:
        instance = np.zeros(depth.shape, dtype=np.uint8)
        for j, m in enumerate(masks):
            instance[m] = j + 1
        return fitted_scenes(
            estimate,
            Observation(depth_m=depth, instance=instance, camera=camera),
            shelf,
            sim.camera,
            sim.physics,
            ch6.physics_depth_settle_s,
            ch6.fit_hypotheses,
            ch6.fit_noise_mm / 1000.0,
        )

    return fit


def fitted_contacts(sim: Any, ch6: Any, catalogue: str, min_pixels: int) -> FittedContacts:
    """(depth_m, masks (K, H, W)) -> (K, K): the share of the scenes fitted to the image
    (`scenes_fitted_to`) in which boxes x and y touch, by the truth's own rule
    (sim.labelling.settled_contacts); NaN where no fit holds both."""
    from clutterbench.perception.fitted_scenes import contact_share
    from clutterbench.sim.labelling import settled_contacts

    fit = scenes_fitted_to(sim, ch6, catalogue, min_pixels)

    def touching(depth: np.ndarray, masks: np.ndarray) -> np.ndarray:
        fits = [
            ([int(b) for b in s.spec.meta["ids"]], settled_contacts(s.spec, sim.physics))
            for s in fit(depth, masks)
        ]
        return contact_share(len(masks), fits)

    return touching


def fitted_pulls(
    sim: Any,
    ch6: Any,
    moved_m: float,
    collapse_free: tuple[float, float],
    catalogue: str,
    min_pixels: int,
) -> SimulatePulls:
    """Every visible box pulled out of the boxes fitted to the depth image and masks, settled
    (perception/fitted_scenes.py, the physics-from-depth planners' model) by the trials'
    executor (sim.labelling.pull_outcomes, the labels' own code path), each other box marked
    by each pull label kind's own rule (data/labels.py label_matrix); with
    ch6.fit_hypotheses > 1, in each of the scenes fitted to the image and its noisy copies
    (scenes_fitted_to), each pair's outcome the share of the fits that pulled x and marked y."""
    from clutterbench.data.labels import LABEL_ARRAYS, label_matrix
    from clutterbench.sim.labelling import pull_outcomes

    fit = scenes_fitted_to(sim, ch6, catalogue, min_pixels)
    pull = (ch6.pull_increment_m, ch6.grasp_lift_m)

    def simulate(depth: np.ndarray, masks: np.ndarray):
        k = len(masks)
        marks = {kind: np.zeros((k, k)) for kind in EDGE_HEADS}
        fits = np.zeros(k)  # the fits in which box x was pulled
        for scene in fit(depth, masks):
            po = pull_outcomes(scene.spec, sim.physics, pull)
            arrays = {
                "pullout_displacement_m": po.displacement_m,
                "pullout_drop_m": po.drop_m,
                "pullout_tilt_deg": po.tilt_deg,
                "pullout_left_shelf": po.left_shelf,
            }
            at = [int(b) for b in scene.spec.meta["ids"]]  # fitted box a is mask at[a]
            for kind in EDGE_HEADS:
                assert set(LABEL_ARRAYS[kind]) <= set(arrays), kind
                m = label_matrix(kind, arrays.__getitem__, len(at), moved_m, collapse_free)
                for a, x in enumerate(at):
                    for b, y in enumerate(at):
                        if a != b and x < k and y < k and m[a, b]:
                            marks[kind][x, y] += 1.0
            fits[[x for x in at if x < k]] += 1.0
        known = fits > 0
        share = {kind: marks[kind] / np.maximum(fits, 1.0)[:, None] for kind in EDGE_HEADS}
        return share, known

    return simulate
