"""Chapter 3 (Yamakuzushi) simulation params: the pile of Shogi pieces, the slide, the cameras.

Imports no SAPIEN, so stages that only read configs do not load the simulator. Lengths in
metres, angles as named; the world frame of sim/pile.py (board top at z = 0, board centre at
the origin, z up).
"""

from __future__ import annotations

import dataclasses

from clutterbench.config import bounded


@dataclasses.dataclass(frozen=True)
class PileConfig:
    """How a pile is generated and simulated.

    `timestep_s`, the solver iterations and `persistent_contacts` were chosen by measurement:
    a canonical start must be at rest, i.e. a settled pile rebuilt from its poses and left
    alone for 2 s moves no piece more than 0.5 mm. Piles of seeds 0-99 (first attempt, 9-10
    pieces), share that moved more than 0.5 mm (median / max of the largest move):

    | PhysX step | iterations (pos/vel) | PCM | share moving | median / max | ms a pile |
    |---|---|---|---|---|---|
    | 1/240 s | 10/1 | on  | 19% | 0.13 / 37 mm | 84 |
    | 1/240 s | 30/4 | on  | 13% | 0.08 / 9 mm | |
    | 1/500 s | 10/1 | on  | 8% | 0.08 / 14 mm | 105 |
    | 1/1000 s | 10/1 | on | 12% | 0.04 / 10 mm | |
    | 1/120 s | 10/1 | off | 5% | 0.08 / 3 mm | 39 |
    | 1/240 s | 10/1 | off | 4% | 0.05 / 13 mm | 53 |
    | 1/240 s | 20/4 | off | 10% | 0.09 / 66 mm | 70 |
    | 1/500 s | 10/1 | off | 3% | 0.03 / 7 mm | 118 |

    What moved, with PCM on: a piece leaning on another's edge falls freely for ~20 ms
    (up to 8 mm) because the rebuilt world finds that contact anew with a near-horizontal
    normal, where the settled world's persistent manifold had a supporting one. With PCM off
    what still moves is a piece leaning at 20-33 deg, about the friction angle (atan 0.5 =
    26.6 deg), that slips on a fresh start; smaller steps or more iterations do not cure it.
    Chosen: 1/240 s (1/120 s lets a falling 10 mm tip move ~10 mm a step), 10/1, PCM off;
    `generate_pile` redraws the few piles that still move ("creeping").
    """

    board_size_m: tuple[float, float] = bounded((0.33, 0.36), gt=0.0)
    """Board top (x, y); a Shogi board is ~333 x 364 mm."""
    board_thickness_m: float = bounded(0.1, gt=0.0)
    """The board stands on the floor: a piece pushed off it falls this far."""
    n_pieces: tuple[int, int] = bounded((9, 10), ge=1)
    """Pieces in a pile: (min, max), inclusive; thesis 3.5 plays with 9 and with 10."""
    drop_radius_m: float = bounded(0.05, ge=0.0)
    """Pieces are dropped at uniform random points of a disc this wide around the board
    centre, so they land on one another and form one pile."""
    drop_height_m: tuple[float, float] = bounded((0.005, 0.03), ge=0.0)
    """Gap (min, max) between a dropped piece's lowest point and the top of the pile so far."""
    drop_tilt_deg: float = bounded(90.0, ge=0.0, le=180.0)
    """A dropped piece is tilted from lying flat by up to this (uniform; random axis), after a
    uniform random yaw."""
    timestep_s: float = bounded(1 / 240, gt=0.0, le=0.02)
    """Physics step (s); measured, see the class docstring."""
    solver_position_iterations: int = bounded(10, ge=1, le=255)
    """PhysX position iterations of every piece (measured: more do not help)."""
    solver_velocity_iterations: int = bounded(1, ge=1, le=255)
    """PhysX velocity iterations of every piece."""
    persistent_contacts: bool = False
    """PhysX persistent contact manifolds (PCM, SAPIEN's default). Off: contacts are made anew
    each step (SAT), so a rebuilt pile meets the same contact normals as the settled one."""
    static_friction: float = bounded(0.5, ge=0.0)
    """Static friction of pieces and board (ABS resin on wood)."""
    dynamic_friction: float = bounded(0.4, ge=0.0)
    """Dynamic friction of pieces and board."""
    restitution: float = bounded(0.1, ge=0.0, le=1.0)
    """Coefficient of restitution."""
    settle_max_s: float = bounded(5.0, gt=0.0)
    """Longest a pile may take to come to rest after a drop; longer -> the attempt is redrawn."""
    rest_window_s: float = bounded(0.05, gt=0.0)
    """Rest is checked over windows this long; at rest after two still windows in a row ..."""
    rest_linear_m_s: float = bounded(0.004, gt=0.0)
    """... in which no piece's centre moved faster than this (from poses, not PhysX's
    velocities) ..."""
    rest_angular_rad_s: float = bounded(0.04, gt=0.0)
    """... and no piece turned faster than this."""
    rest_check_s: float = bounded(2.0, gt=0.0)
    """A settled pile, rebuilt from its spec (its canonical start), is left alone this long ..."""
    rest_check_m: float = bounded(0.0005, gt=0.0)
    """... and redrawn when a piece moved more than this: it would creep in every action."""
    max_attempts: int = bounded(20, ge=1)
    """Attempts (each with its own sub-seed) before generation gives up with an error."""

    def __post_init__(self) -> None:
        if self.n_pieces[0] > self.n_pieces[1]:
            raise ValueError(f"n_pieces: min {self.n_pieces[0]} > max {self.n_pieces[1]}")
        if self.drop_height_m[0] > self.drop_height_m[1]:
            raise ValueError("drop_height_m: min > max")


@dataclasses.dataclass(frozen=True)
class SlideConfig:
    """The finger's slide (thesis Fig. 3.9: press the piece, slide it off the board)."""

    speed_m_s: float = bounded(0.1, gt=0.0)
    """Horizontal speed of the pressed piece."""
    moved_threshold_m: float = bounded(0.01, gt=0.0)
    """Another piece whose centre moved more than this is a collapse: the slide failed."""
    exit_margin_m: float = bounded(0.01, ge=0.0)
    """The slide ends when the piece's whole footprint is this far beyond the board edge."""
    settle_max_s: float = bounded(3.0, gt=0.0)
    """Longest the remaining pieces settle after the piece is taken out, before the judge."""


@dataclasses.dataclass(frozen=True)
class PileCameraConfig:
    """The depth cameras: a fixed one above the board, and the arm's movable sensor."""

    image_size: int = bounded(128, ge=16, le=1024)
    """Square image side in pixels."""
    fovy_deg: float = bounded(45.0, gt=1.0, le=150.0)
    """Vertical (= horizontal) field of view; 45 deg frames the 364 mm board from 0.5 m."""
    top_height_m: float = bounded(0.5, gt=0.05)
    """Height of the top camera above the board centre (it looks straight down)."""
    near_m: float = bounded(0.05, gt=0.0)
    """Near clipping plane."""
    far_m: float = bounded(2.0, gt=0.0)
    """Far clipping plane; pixels that see nothing within it get depth 0."""
