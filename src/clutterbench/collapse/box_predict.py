"""The box head at inference: one depth image and the visible boxes' masks -> per-box pull
probabilities, support edges and maps, behind the ch. 6 planner's predictor interface
(planning/ch6/extraction.py: a predictor with `box_row` is asked per box, one with
`box_edges` gives the support graph itself, with no pixel rule). Lives in collapse/, below the
planners and the trials that construct it.

`BoxMaps` answers from the network alone. `FusedBoxMaps` is the learned-plus-physics
predictor: each pull it is asked about is also simulated on the boxes fitted to the same
depth image (physics from depth, no training), and per box a logistic regression fuses the
network's logit with the simulated outcome (`fuse`; its weights fitted on validation scenes
by the support stage, support/box_fusion.py). A pull the fit cannot simulate keeps the
network's logit alone.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

from clutterbench.collapse.box_head import (
    OUTPUTS,
    BoxHead,
    BoxHeadMeta,
    edge_probability,
    load_box_head,
    pair_features,
    predict_pairs,
)
from clutterbench.collapse.predict import CollapsePredictor, scene_logits
from clutterbench.observation import Observation
from clutterbench.perception.gaps import camera_points, surface_gaps
from clutterbench.sim.config import CameraConfig

Edge = tuple[int, int, float]
"""(supporter box id, supported box id, probability): one support edge of the box head's graph
(the planner reads it as planning/ch6/support.py's SupportEdge)."""

SimulateFn = Callable[[Observation, list[int], int, int | None], np.ndarray | None]
"""(observation, visible ids, pulled box id, held box id or None) -> (K,) float over the
visible ids: the share of the scenes fitted to the observation in which the pull collapses
(or moves, by the head) the box (0 or 1 with one fit; a bool array is read as one), a held
box held during the pull, let go and settled at its end and judged as the trials judge a
released box; None where the estimate cannot answer (the network's row stays)."""


FittedContactFn = Callable[[Observation, list[int]], np.ndarray]
"""(observation, visible ids) -> (K, K) the share of the scenes fitted to the observation in
which boxes ids[x] and ids[y] touch once settled (NaN where no fit holds both)."""


class BoxMaps:
    """Per-box probabilities of one observation from the box head over the collapse
    predictor's maps; `head` (pull or pull_collapse) is the outcome the planner reads, an
    edge (x, y) where the pull of x marks y and they touch with probability > edge_threshold."""

    needs_all_masks = True
    """The answer for one box depends on every visible box: always pass them all."""

    def __init__(
        self,
        cp: CollapsePredictor,
        model: BoxHead,
        meta: BoxHeadMeta,
        camera: CameraConfig,
        head: str,
        edge_threshold: float,
    ):
        if head not in OUTPUTS or head == "contact":
            raise ValueError(f"head {head!r}: not a pull outcome of the box head {OUTPUTS}")
        self.cp, self.model, self.meta, self.camera = cp, model, meta, camera
        self.head, self.edge_threshold = head, edge_threshold
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.simulated = 0
        """Pulls simulated so far (FusedBoxMaps)."""

    @classmethod
    def from_paths(
        cls,
        cp_path: Path,
        box_path: Path,
        camera: CameraConfig,
        head: str,
        edge_threshold: float,
        **kwargs: object,
    ) -> BoxMaps:
        """From the two checkpoints (the box head refused where it read another network's
        maps); `kwargs` go to the class (FusedBoxMaps: simulate, weights)."""
        model, meta = load_box_head(box_path, cp_model=Path(cp_path).parent.name)
        cp = CollapsePredictor.from_checkpoint(cp_path, image_size=camera.image_size)
        return cls(cp, model, meta, camera, head, edge_threshold, **kwargs)

    def probs(self, depth_m: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(K, K, len(OUTPUTS)) probabilities, x pulled and y marked (diagonal 0); the last
        observation's answer is kept (the decision and its checks ask again)."""
        masks = np.asarray(masks).astype(bool)
        last = self._last
        if last is not None and np.array_equal(last[0], depth_m) and np.array_equal(last[1], masks):
            return last[2]
        k = len(masks)
        if k < 2:
            out = np.zeros((k, k, len(OUTPUTS)), np.float32)
        else:
            probs = cp_probs_of(self.cp, depth_m, masks)
            gaps = surface_gaps(camera_points(depth_m, self.camera), masks)
            out = predict_pairs(self.model, pair_features(probs, masks, depth_m, gaps))
            out[np.eye(k, dtype=bool)] = 0.0
        self._last = (depth_m.copy(), masks.copy(), out)
        return out

    def box_row(self, obs: Observation, ids: list[int], masks: np.ndarray, k: int) -> np.ndarray:
        """(K,) probability that pulling ids[k] marks each visible box (the planner's head)."""
        return self.probs(obs.depth_m, masks)[k, :, OUTPUTS.index(self.head)]

    def box_edges(self, obs: Observation, ids: list[int], masks: np.ndarray) -> list[Edge]:
        """The support graph: (x, y) where the edge's probability exceeds edge_threshold."""
        edge = edge_probability(self.probs(obs.depth_m, masks), self.head)
        return _edges(ids, edge, self.edge_threshold)

    def __call__(self, depth_m: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(K, H, W) maps: map x is each other box's probability on its pixels."""
        masks = np.asarray(masks).astype(bool)
        p = self.probs(depth_m, masks)[..., OUTPUTS.index(self.head)]
        return np.einsum("xy,yhw->xhw", p, masks.astype(np.float32)).astype(np.float32)


class FusedBoxMaps(BoxMaps):
    """BoxMaps fused per box with physics from depth: a row (one pulled box) is simulated on
    the fitted boxes when it is asked for, once per observation, and each box's probability
    is `fuse(weights, ...)` of the network's and the simulated outcome."""

    def __init__(
        self,
        *args,
        simulate: SimulateFn,
        weights: Sequence[float],
        simulate_held: bool = False,
        contact: FittedContactFn | None = None,
        contact_weights: Sequence[float] | None = None,
        **kwargs,
    ):
        if len(weights) != FUSION_INPUTS + 1:
            raise ValueError(f"fusion weights {list(weights)}: not {FUSION_INPUTS} and a bias")
        if (contact is None) != (contact_weights is None):
            raise ValueError("the learned contact needs both the fitted contacts and weights")
        super().__init__(*args, **kwargs)
        self.simulate, self.weights = simulate, tuple(float(w) for w in weights)
        """The fusion's weights (head logit, simulated and marked, simulated and not, bias)."""
        self.contact = contact
        """The fitted scenes' contacts of an observation (trials.ch6.box_contact learned);
        None: the edges take the box head's contact."""
        self.contact_weights = contact_weights
        """The learned contact's weights (head contact logit, fitted and touching, fitted and
        not, bias; the support stage's fit on validation scenes)."""
        self.simulate_held = simulate_held
        """Answer a pull made holding a box (`held_row`) from that very held pull simulated
        on the fitted boxes (trials.ch6.box_hold simulate); False: `held_row` answers None
        and the planner leaves the held box out of the unheld pull's row (Fig. 6.7 (d))."""
        self._rows: dict[tuple[int, int, int], np.ndarray] = {}
        """(observation key, pulled box, held box or -1) -> its fused row, for the last
        observation."""
        self._key: int | None = None

    def box_row(self, obs: Observation, ids: list[int], masks: np.ndarray, k: int) -> np.ndarray:
        """(K,) the fused probability that pulling ids[k] marks each visible box: the
        network's row fused with the pull simulated on the fitted boxes (the network's logit
        alone where the estimate cannot answer)."""
        row = self._fused_row(obs, ids, masks, k, None)
        assert row is not None
        return row

    def held_row(
        self, obs: Observation, ids: list[int], masks: np.ndarray, k: int, hold: int
    ) -> np.ndarray | None:
        """(K,) as box_row for pulling ids[k] while ids[hold] is held, the held box judged
        too: the network's row (it sees no hold) fused with that held pull simulated on the
        fitted boxes, the held box let go at its end. None where the held pull is not
        simulated (simulate_held off, or the fit cannot answer it)."""
        if not self.simulate_held:
            return None
        return self._fused_row(obs, ids, masks, k, hold)

    def _fused_row(
        self, obs: Observation, ids: list[int], masks: np.ndarray, k: int, hold: int | None
    ) -> np.ndarray | None:
        key = hash(obs.depth_m.tobytes())
        if key != self._key:
            self._key, self._rows = key, {}
        slot = (key, k, -1 if hold is None else hold)
        if slot not in self._rows:
            net = super().box_row(obs, ids, masks, k)
            outcome = self.simulate(obs, ids, ids[k], None if hold is None else ids[hold])
            self.simulated += 1
            if outcome is None and hold is not None:
                return None
            known = outcome is not None
            marked = outcome if known else np.zeros(len(ids))
            row = fuse(self.weights, net, marked, np.bool_(known)).astype(np.float32)
            row[k] = 0.0
            self._rows[slot] = row
        return self._rows[slot]

    def box_edges(self, obs: Observation, ids: list[int], masks: np.ndarray) -> list[Edge]:
        """Edges of the fused outcome and the contact: the network's, or learned from it and
        the fitted scenes' contacts (`contact_weights`)."""
        p = np.stack([self.box_row(obs, ids, masks, k) for k in range(len(ids))])
        contact = self.probs(obs.depth_m, masks)[..., OUTPUTS.index("contact")]
        if self.contact is not None:
            assert self.contact_weights is not None
            contact = learned_contact_of(self.contact_weights, contact, self.contact(obs, ids))
        return _edges(ids, p * contact, self.edge_threshold)


FUSION_INPUTS = 3
"""The fusion's inputs per pair (`features`)."""


def features(p: np.ndarray, simulated: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(..., 3) float64 fusion inputs of pairs: the head's logit, simulated and marked,
    simulated and not marked (a pull not simulated: both 0). `simulated` is the share of the
    fitted scenes whose pull marks the box (0 or 1 with one fit; a bool is read as one)."""
    q = np.clip(p.astype(np.float64), 1e-4, 1 - 1e-4)
    sim = np.asarray(simulated, np.float64)
    k = np.broadcast_to(np.asarray(known, bool), sim.shape).astype(np.float64)
    return np.stack([np.log(q / (1 - q)), k * sim, k * (1.0 - sim)], -1)


def fuse(weights: Sequence[float], p: np.ndarray, simulated: np.ndarray, known: np.ndarray):
    """The fused probability of pairs (p, simulated, known broadcast together)."""
    w = np.asarray(weights, np.float64)
    return 1.0 / (1.0 + np.exp(-(features(p, simulated, known) @ w[:-1] + w[-1])))


def contact_inputs(head: np.ndarray, fitted: np.ndarray) -> np.ndarray:
    """(..., 3) float64 inputs of the learned contact of pairs: the box head's contact logit,
    the share of the fitted scenes in which the two boxes touch and its complement (both 0
    where no fit holds the pair: `fitted` NaN), as the pull fusion's `features`."""
    known = np.isfinite(fitted)
    return features(head, np.nan_to_num(fitted), known)


def learned_contact_of(weights: Sequence[float], head: np.ndarray, fitted: np.ndarray):
    """The learned contact probability of pairs (`contact_inputs` under `weights`; chosen on
    validation scenes by the support stage under trials.ch6.box_contact learned)."""
    w = np.asarray(weights, np.float64)
    if len(w) != FUSION_INPUTS + 1:
        raise ValueError(f"contact weights {list(weights)}: not {FUSION_INPUTS} and a bias")
    return 1.0 / (1.0 + np.exp(-(contact_inputs(head, fitted) @ w[:-1] + w[-1])))


def cp_probs_of(predictor: CollapsePredictor, depth_m: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(K, C, H, W) float32: every head of the collapse predictor with each of the K (H, W)
    masks the box pulled."""
    logits = scene_logits(predictor, depth_m.astype(np.float32), masks.astype(np.uint8)[:, None])
    return torch.sigmoid(logits.float()).numpy()


def _edges(ids: list[int], edge: np.ndarray, threshold: float) -> list[Edge]:
    return [
        (ids[x], ids[y], round(float(edge[x, y]), 4))
        for x, y in zip(*np.nonzero(edge > threshold))
        if x != y
    ]
