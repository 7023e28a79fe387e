"""Chapter 3 target selection (thesis 3.3.3, 3.5.2): which piece to slide, and which way.

Every function sees what a robot sees: the top depth image with its instance masks and camera
model (an `Observation`), and for the ConvNet variant the slide ConvNet; never the simulator.
A target is ranked per piece: the candidates of one piece share its pose, so when the
POMDP (planning.pomdp) finds a piece not worth sliding, the next piece is tried.

- `convnet_targets`: the raster scan (10 x 10 start points x 8 directions = 800), each
  candidate on a piece scored by the ConvNet; each (piece, direction) slide scored by its
  best candidate (thesis: "the one with the highest probability in our ConvNet is
  selected") or their mean (select.score); per piece its best slide; pieces by that score.
- `least_occluded_targets`: without the ConvNet (thesis 3.5.2): pieces by visible area in the
  top view, largest first, slid from the centre of what is seen of them, away from the pile
  (the direction of the raster nearest to the line from the pile's centre through the piece).
- `random_targets`: a uniformly random candidate on a piece (the floor).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from clutterbench.config import bounded
from clutterbench.data.slide_crops import (
    ScanConfig,
    height_image,
    piece_under,
    raster_candidates,
    slide_crops,
    subset,
)
from clutterbench.observation import Observation


@dataclasses.dataclass(frozen=True)
class Target:
    """A slide to try: which piece (as the top view's instance mask names it), from where,
    which way, and the ConvNet's P(success) when it scored it."""

    piece: int
    start_xy: tuple[float, float]
    direction: int
    """Direction index d: the slide runs at d * 2 pi / n_directions."""
    probability: float | None = None

    def angle_rad(self, n_directions: int) -> float:
        return self.direction * 2 * np.pi / n_directions


@dataclasses.dataclass(frozen=True)
class SelectConfig:
    min_probability: float = bounded(0.5, ge=0.0, le=1.0)
    """ConvNet variant: a piece whose best candidate scores below this is not worth sliding
    (no such piece left ends the game)."""
    max_targets: int = bounded(3, ge=1)
    """Pieces offered to the POMDP per step, best first; all refused ends the game."""
    min_visible_px: int = bounded(20, ge=1)
    """A piece with fewer visible top-view pixels is not a target (a sliver)."""
    score: Literal["best", "mean"] = "best"
    """ConvNet variant: a (piece, direction) slide scores its best candidate's probability
    (the thesis: the candidate of highest probability wins) or the mean over its candidates
    (every start point on the piece slides the same piece the same way; the mean is less
    lifted by one lucky crop)."""


@dataclasses.dataclass(frozen=True)
class PomdpConfig:
    """The observe-or-slide POMDP of thesis 3.4 (planning.pomdp)."""

    reward: float = bounded(1.0, gt=0.0)
    """r of eq. (3.6): the value of sliding a piece in a flat state."""
    alpha: float = bounded(0.9, ge=0.0)
    """Weight of the uncertainty reduction V1 in eq. (3.12) (thesis 0.9)."""
    beta: float = bounded(0.1, ge=0.0)
    """Weight of the visibility V2 in eq. (3.12) (thesis 0.1)."""
    e_th_m: float = bounded(0.006, gt=0.0)
    """e_th of eq. (3.5): the ICP fit error at which a state's weight reaches 0."""
    max_observations: int = bounded(3, ge=0)
    """Sensor moves per target at most; then the POMDP must slide or refuse."""
    viewpoint_distances_m: tuple[float, ...] = bounded((0.3,), gt=0.0)
    """Distances of the viewpoint candidates from the target along the polyhedron's face
    normals (thesis Fig. 3.10)."""
    min_elevation_deg: float = bounded(30.0, gt=0.0, le=90.0)
    """Viewpoints lower than this above the board are left out (the arm's reach)."""
    min_flat_share: float = bounded(0.5, ge=0.0, le=1.0)
    """A slide the POMDP chooses is made only when the flat states (S_slide) hold at least
    this share of the belief; otherwise the piece is refused and the next one tried."""
    min_mass: float = bounded(0.005, ge=0.0)
    """Below this belief mass (eq. 3.8) no state fits the piece: e.g. one resting on another
    at a tilt none of the 32 states holds (eq. 3.5 omitted them all) ..."""
    when_no_state_fits: Literal["refuse", "slide"] = "slide"
    """... and the POMDP then refuses the piece (the thesis' rule read literally: no belief on
    the flat states) or leaves the choice to the target selection (slide: the POMDP has no
    evidence either way). Chosen on validation piles (docs/design-choices.md)."""


def _visible_pieces(obs: Observation, min_px: int) -> dict[int, np.ndarray]:
    """piece -> (n, 2) board points (x, y) of its visible top-view pixels."""
    pts = obs.camera.depth_to_points(obs.depth_m)
    out = {}
    for piece in obs.visible_boxes(min_px):
        sel = obs.instance == piece + 1
        out[piece] = pts[sel][:, :2]
    return out


def convnet_targets(model, obs: Observation, scan: ScanConfig, sel: SelectConfig) -> list[Target]:
    """Per visible piece its best raster candidate, pieces by ConvNet probability (highest
    first); only those at or above `min_probability`."""
    from clutterbench.models.slide_convnet import success_probability

    cands = raster_candidates(scan)
    pieces = piece_under(obs, cands.start_xy, scan.edge_margin_px)
    seen = set(obs.visible_boxes(sel.min_visible_px))
    on = np.array([k for k in range(len(cands)) if int(pieces[k]) in seen], dtype=np.int64)
    if not len(on):
        return []
    probs = success_probability(
        model, slide_crops(height_image(obs), obs.camera, subset(cands, on), scan)
    ).numpy()
    by_slide: dict[tuple[int, int], list[int]] = {}
    for i, k in enumerate(on):
        by_slide.setdefault((int(pieces[k]), int(cands.direction[k])), []).append(i)
    best: dict[int, Target] = {}
    for (piece, d), rows in by_slide.items():
        p = probs[rows]
        score = float(p.max() if sel.score == "best" else p.mean())
        if piece not in best or score > best[piece].probability:
            k = on[rows[int(np.argmax(p))]]
            start = (float(cands.start_xy[k, 0]), float(cands.start_xy[k, 1]))
            best[piece] = Target(piece, start, d, score)
    ranked = sorted(best.values(), key=lambda t: (-t.probability, t.piece))
    return [t for t in ranked if t.probability >= sel.min_probability][: sel.max_targets]


def least_occluded_targets(obs: Observation, scan: ScanConfig, sel: SelectConfig) -> list[Target]:
    """Pieces by visible top-view area (largest first), each slid from its visible centroid
    away from the pile's centre."""
    pieces = _visible_pieces(obs, sel.min_visible_px)
    if not pieces:
        return []
    centre = np.concatenate(list(pieces.values())).mean(axis=0)
    step = 2 * np.pi / scan.n_directions
    out = []
    for piece, xy in sorted(pieces.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        start = xy.mean(axis=0)
        away = start - centre
        angle = np.arctan2(away[1], away[0]) if np.hypot(*away) > 1e-6 else 0.0
        d = int(np.round(angle / step)) % scan.n_directions
        out.append(Target(piece, (float(start[0]), float(start[1])), d))
    return out[: sel.max_targets]


def random_targets(
    obs: Observation, scan: ScanConfig, sel: SelectConfig, rng: np.random.Generator
) -> list[Target]:
    """One uniformly random raster candidate on a visible piece (empty when none)."""
    cands = raster_candidates(scan)
    pieces = piece_under(obs, cands.start_xy, scan.edge_margin_px)
    seen = set(obs.visible_boxes(sel.min_visible_px))
    on = [k for k in range(len(cands)) if int(pieces[k]) in seen]
    if not on:
        return []
    k = on[int(rng.integers(len(on)))]
    start = (float(cands.start_xy[k, 0]), float(cands.start_xy[k, 1]))
    return [Target(int(pieces[k]), start, int(cands.direction[k]))]
