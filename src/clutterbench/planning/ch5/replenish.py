"""Shelf replenishment (thesis 5.2.3, Fig. 5.2): where a new box of known size can go, and
what must be moved first, from one depth image, the arrangement detections and collapse maps.

Frames. The thesis writes its candidates in the image: x to the right, y down, a cluster
B_i = (x_i, y_i, w_i, h_i) (eq. 5.1). Every cluster here sits at its own depth, so its box is
back-projected at that depth into the *image-aligned metric frame*: the same axes in metres
on the plane through the cluster's front face (x_img = -y_shelf, y_img = -z_shelf, since the
camera looks into the shelf along +x with the shelf's y to its left). The thesis' equations
then hold as printed with w', h', g in metres, and a candidate is a place on the shelf.

Left and right are the image's. Thesis eqs. (5.3) and (5.4) as printed put B^right at
x_i - w_i/2 - ... (the image's left) while eq. (5.6) moves a blocker on B^right further
toward +x, away from B_i only if B^right lies to the right: we take right = +x throughout
(`candidate_rect`), so that both hold.

The planner sees the depth image, the detections and the camera (never the simulator): which
boxes a detection holds is the executor's business (trials/ch5/episodes.py grasps what is
inside it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence, Set
from typing import Any, Literal

import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.boxes import Detection

Side = Literal["top", "left", "right"]
BlockerGoal = Literal["candidate", "eq_5_6"]
SIDES_OF_CLASS: dict[str, tuple[Side, ...]] = {"C^h": ("top",), "C^v": ("left", "right")}
"""Thesis 5.2.3: B^top on a stacked cluster, B^left / B^right beside a shelved one; leaning
clusters (C^r, C^l) offer no place, they are obstacles to move (and set upright)."""
BRANCHES = ("simple", "bimanual", "rearrange", "contact", "none")
"""Thesis Fig. 5.2: simple replenishment, bimanual replenishment, bimanual rearrangement (a
move first, then a new plan), or no plan (the episode gives up); beyond the thesis, with
ReplenishParams.contact: a bimanual replenishment whose blocker pushes what stands in its way
(`ReplenishPlanner`), in place of no plan."""
SURFACE_MARGIN_M = 0.004
"""A depth point within this of the shelf's floor, back or side boards is the shelf, not a
box."""
DROP_M = 0.002
"""A placed box is let go this far above what it will rest on."""
TOP_BAND_M = 0.005
"""A cluster's top surface: its points within this of its highest one."""
SUPPORT_BAND_M = 0.015
"""A candidate off the floor rests on the box points within this under its bottom."""
FRONT_BAND_M = 0.003
"""A cluster's front face: its points within this of its nearest ones (5th percentile)."""
RECT_FILL = 0.9
"""A front face whose convex hull fills this share of its least rotated rectangle is that
rectangle (one box, or boxes flush as one)."""

CollapseMap = Callable[[Observation, np.ndarray], np.ndarray]
"""(observation, (H, W) bool target mask) -> (H, W) float collapse probability."""


@dataclasses.dataclass(frozen=True)
class WorkingSpace:
    """The shelf interior the robot knows (thesis 5.2.3: W330 x D280 x H330 mm)."""

    width_m: float = 0.330
    depth_m: float = 0.280
    height_m: float = 0.330


@dataclasses.dataclass(frozen=True)
class ReplenishParams:
    """How the replenishment planner decides (thesis 5.2.3)."""

    finger_m: float = 0.012
    """g: thickness of the gripper's fingers, the margin around a placement (eqs. 5.2-5.9)."""
    prob_threshold: float = 0.5
    """A pixel of a collapse map is in the collapse region R_s when its probability is at
    least this (thesis: "the predefined probability threshold")."""
    iou_threshold: float = 0.1
    """th: B_s is movable when IoU(B_j, R_s) < th for every other cluster j (eq. 5.5 text)."""
    use_collapse: bool = True
    """False: the thesis' "without collapse prediction" variant (every blocker is movable)."""
    min_points: int = 3
    """A candidate is occupied when at least this many depth points of boxes fall in it."""
    upright_footprint: bool = True
    """A leaning cluster (C^r / C^l) is carried as it will stand once set upright (its front
    face's upright rectangle, `carried`); False: as its leaning box is seen."""
    blocker_goal: BlockerGoal = "candidate"
    """Where a blocker is carried (`move_goal`): "candidate", aside until its near edge
    reaches the candidate's far edge; "eq_5_6", aside by eq. (5.6)'s w'/2 + w_s/2 + g
    wherever it stands (the same when it stands centred on the candidate)."""

    contact: bool = False
    """Beyond the thesis: where it has no plan, carry the first blocker whose only fault is a
    way blocked by other boxes (they are pushed), if it is movable (eq. 5.5, as any blocker);
    False: the thesis' assumption that a moved object touches no other holds in every plan."""

    @property
    def goal_from_candidate(self) -> bool:
        return self.blocker_goal == "candidate"


@dataclasses.dataclass(frozen=True)
class Cluster:
    """A detection placed in the image-aligned metric frame at its own depth."""

    index: int
    cls: str
    box_px: np.ndarray
    """(4,) (x, y, w, h) pixels, thesis eq. (5.1)."""
    rect_m: np.ndarray
    """(4,) (x, y, w, h) metres in the image-aligned frame (x = -y_shelf, y = -z_shelf)."""
    front_x_m: float
    """Shelf x of its front face (median of its visible points)."""
    top_span_m: np.ndarray
    """(2,) image-aligned x extent of its top surface: where B^top can rest (eq. 5.2)."""
    mask: np.ndarray
    """(H, W) bool: the box-surface pixels inside its image box."""


@dataclasses.dataclass(frozen=True)
class Candidate:
    cluster: int
    side: Side
    rect_m: np.ndarray
    """(4,) B_i^side in the image-aligned metric frame, thesis eqs. (5.2)-(5.4)."""
    occupants: tuple[int, ...]
    """Clusters with points inside it, most points first (-1: points of no cluster)."""
    pose: np.ndarray
    """(7,) where the new box is let go: [x, y, z, qw, qx, qy, qz] in the shelf frame."""

    @property
    def free(self) -> bool:
        return not self.occupants


@dataclasses.dataclass(frozen=True)
class Move:
    """Carry every box of a cluster by one rigid motion (thesis eqs. 5.5-5.6, 5.8-5.9)."""

    cluster: int
    box_px: np.ndarray
    """(4,) the cluster's image box: what the robot grasps (the executor's business)."""
    start_m: np.ndarray
    """(2,) p^start in the image-aligned metric frame."""
    goal_m: np.ndarray
    """(2,) p^goal."""
    upright: bool
    """Rotate the cluster upright as it moves (C^r / C^l, thesis 5.2.3)."""

    @classmethod
    def carrying(cls, cluster: Cluster, goal_m: np.ndarray) -> Move:
        """`cluster` carried from where its rectangle stands to `goal_m`, set upright on the
        way if it leans (C^r / C^l)."""
        c = cluster
        return cls(c.index, c.box_px, c.rect_m[:2].copy(), goal_m, c.cls in ("C^r", "C^l"))

    @property
    def translation_m(self) -> np.ndarray:
        """(3,) the motion in the shelf frame."""
        d = self.goal_m - self.start_m
        return np.array([0.0, -d[0], -d[1]])


@dataclasses.dataclass(frozen=True)
class Plan:
    branch: str
    """One of BRANCHES."""
    candidate: Candidate | None
    """Where the new box goes (None: rearrange / none)."""
    move: Move | None
    """bimanual: the blocker carried aside and held while the box is placed; rearrange: the
    cluster carried aside and let go (then the planner looks again)."""
    info: dict[str, Any] = dataclasses.field(default_factory=dict)


def new_box_extent_m(size_m: np.ndarray, side: Side) -> tuple[float, float]:
    """(w', h') of a box of local extents (D, W, H) placed on `side`: lying flat on a stack
    (width across, height up) or standing like a book beside a row (height across, width up)."""
    _, w, h = (float(v) for v in size_m)
    return (w, h) if side == "top" else (h, w)


def candidate_rect(b: np.ndarray, side: Side, w_new: float, h_new: float, g: float) -> np.ndarray:
    """B_i^side = (x, y, w, h) beside cluster box b = (x_i, y_i, w_i, h_i) (y down), thesis
    eqs. (5.2)-(5.4), with right = +x (module docstring)."""
    x, y, w, h = (float(v) for v in b)
    if side == "top":  # eq. (5.2): on the stack, flush with its left edge
        return np.array([x - w / 2 + w_new / 2, y - h / 2 - h_new / 2 - g, w_new + 2 * g, h_new])
    if side == "left":  # eq. (5.4) mirrored: left of the row, resting where it rests
        return np.array([x - w / 2 - w_new / 2 - g, y + h / 2 - h_new / 2, w_new + 2 * g, h_new])
    if side == "right":  # eq. (5.3) mirrored
        return np.array([x + w / 2 + w_new / 2 + g, y + h / 2 - h_new / 2, w_new + 2 * g, h_new])
    raise ValueError(f"unknown side {side!r}")


def move_goal(
    s: np.ndarray,
    side: Side,
    w_new: float,
    h_new: float,
    g: float,
    cand: np.ndarray | None = None,
) -> np.ndarray:
    """p^goal of blocker B_s on candidate `side`, thesis eq. (5.6): aside by w'/2 + w_s/2 + g
    on left / right, which puts B_s's near edge at the candidate's far edge when B_s stands
    centred on the candidate. Given the candidate's rectangle `cand` (eqs. 5.3-5.4), B_s goes
    aside by exactly what puts its near edge there from wherever it stands (a blocker off the
    candidate's centre: no farther than needed, nor short of it). On top the thesis lifts by
    h'/2 + h_s/2 + g; we lift by h' + 2g so that the new box fits under whatever B_s's height:
    B^top starts g above the stack (eq. 5.2) and ends h' higher, and B_s keeps g above that."""
    x, y, w, _ = (float(v) for v in s)
    if side in ("left", "right") and cand is not None:
        cx, cw = float(cand[0]), float(cand[2])
        if side == "right":
            return np.array([max(x, cx + cw / 2 + w / 2), y])
        return np.array([min(x, cx - cw / 2 - w / 2), y])
    if side == "right":
        return np.array([x + w_new / 2 + w / 2 + g, y])
    if side == "left":
        return np.array([x - w_new / 2 - w / 2 - g, y])
    return np.array([x, y - h_new - 2 * g])


def rearrange_goal(
    k: np.ndarray, s: np.ndarray, g: float, s_goal: np.ndarray | None = None
) -> np.ndarray:
    """p^goal of the obstacle B_k of a blocker B_s, thesis eq. (5.9): beside B_s, on B_k's
    side of it. Eq. (5.9) as printed measures from B_s's present place, from which B_s then
    moves by eq. (5.6), into B_k when B_k lies on the side B_s moves to; given `s_goal`
    (B_s's p^goal) B_k goes beside that goal in that case, so that B_s's move has room."""
    xk, yk, wk, _ = (float(v) for v in k)
    xs, _, ws, _ = (float(v) for v in s)
    if s_goal is not None and (xk - xs) * (float(s_goal[0]) - xs) > 0:
        xs = float(s_goal[0])
    if xk < xs:
        return np.array([xs - ws / 2 - wk / 2 - g, yk])
    return np.array([xs + ws / 2 + wk / 2 + g, yk])


def rect_iou_mask(rect_px: np.ndarray, region: np.ndarray) -> float:
    """IoU(B_j, R) of an image box (x, y, w, h) pixels and a (H, W) bool region."""
    box = rect_mask(rect_px, region.shape)
    union = np.logical_or(box, region).sum()
    return float(np.logical_and(box, region).sum() / union) if union else 0.0


def rect_mask(rect_px: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """(H, W) bool: the pixels whose centres lie in the box (x, y, w, h)."""
    x, y, w, h = (float(v) for v in rect_px)
    v, u = np.mgrid[0 : shape[0], 0 : shape[1]] + 0.5
    return (np.abs(u - x) <= w / 2) & (np.abs(v - y) <= h / 2)


def in_working_space(rect_m: np.ndarray, space: WorkingSpace, tol_m: float = 0.001) -> bool:
    """Whether an image-aligned metric rectangle lies inside the shelf's interior face."""
    x, y, w, h = (float(v) for v in rect_m)
    return bool(
        x - w / 2 >= -space.width_m / 2 - tol_m
        and x + w / 2 <= space.width_m / 2 + tol_m
        and -(y + h / 2) >= -tol_m
        and -(y - h / 2) <= space.height_m + tol_m
    )


def box_points(obs: Observation, space: WorkingSpace) -> tuple[np.ndarray, np.ndarray]:
    """((H, W, 3) shelf-frame point of every pixel, (H, W) bool: the point is on a box, not
    on the shelf's boards or beyond)."""
    pts = obs.camera.depth_to_points(obs.depth_m)
    x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]
    m = SURFACE_MARGIN_M
    on_box = (
        np.isfinite(x)
        & (x > -0.05)
        & (x < space.depth_m - m)
        & (np.abs(y) < space.width_m / 2 - m)
        & (z > m)
        & (z < space.height_m - m)
    )
    return pts, on_box


def place_clusters(
    obs: Observation,
    detections: Sequence[Detection],
    space: WorkingSpace,
    points: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[Cluster]:
    """Every detection in the image-aligned metric frame: the extent of the box-surface points
    seen inside its image box (the depth image back-projected), its front face at their
    median depth. Boxes of one cluster stand at different depths, so corners back-projected
    at one depth would put the nearer boxes' bottoms below the floor. A detection with no
    such point is dropped."""
    pts, on_box = points if points is not None else box_points(obs, space)
    out: list[Cluster] = []
    for det in detections:
        inside = rect_mask(det.box, obs.depth_m.shape) & on_box
        if not inside.any():
            continue
        p = pts[inside]
        x_img, y_img = -p[:, 1], -p[:, 2]  # image-aligned: x_img = -y_shelf, y_img = -z_shelf
        x0, x1, y0, y1 = x_img.min(), x_img.max(), y_img.min(), y_img.max()
        rect = np.array([(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0])
        front = float(np.median(p[:, 0]))
        band = p[:, 2] >= p[:, 2].max() - TOP_BAND_M
        span = np.array([x_img[band].min(), x_img[band].max()])
        box = np.asarray(det.box, float)
        out.append(Cluster(len(out), det.cls, box, rect, front, span, inside))
    return out


def new_box_pose(
    rect_m: np.ndarray,
    side: Side,
    size_m: np.ndarray,
    cluster: Cluster,
    space: WorkingSpace,
    g_m: float,
    rest_z_m: float | None = None,
) -> np.ndarray:
    """(7,) the new box let go at the candidate: centred across it, DROP_M above what it will
    rest on (a row's floor: the candidate's bottom; a stack's top surface: g under B^top's
    bottom, eq. 5.2's margin, or `rest_z_m` when given, the surface seen higher); flat on a
    stack or standing (width up, thickness across) beside a row, its front face flush with the
    cluster's (as goods face the aisle; a box lying on a stack may hide the stack's top
    surface from the camera, its front face is what is seen)."""
    d = float(size_m[0])
    _, h_new = new_box_extent_m(size_m, side)
    x = cluster.front_x_m + d / 2
    x = float(np.clip(x, d / 2 + 0.003, space.depth_m - d / 2 - 0.003))
    y = -float(rect_m[0])
    z = -(float(rect_m[1]) + float(rect_m[3]) / 2) + h_new / 2 + DROP_M
    if side == "top":
        z -= g_m
        if rest_z_m is not None:
            z = max(z, rest_z_m + h_new / 2 + DROP_M)
        q = np.array([1.0, 0.0, 0.0, 0.0])
    else:  # standing: local y up, local z across (sim/families/shelved.py STANDING)
        q = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])
    return np.array([x, y, max(z, h_new / 2 + DROP_M), *q])


def owner_map(obs: Observation, clusters: Sequence[Cluster]) -> np.ndarray:
    """(H, W) the cluster each pixel belongs to (-1: none; the first cluster where masks
    overlap)."""
    owner = np.full(obs.depth_m.shape, -1, dtype=np.int64)
    for c in clusters:
        owner[c.mask & (owner < 0)] = c.index
    return owner


def owners_by_count(owner: np.ndarray, n_clusters: int, min_points: int) -> tuple[int, ...]:
    """The clusters (-1: none) with at least `min_points` of the selected pixels' `owner`
    values, most first."""
    counts = np.bincount(owner + 1, minlength=n_clusters + 1)
    found = np.nonzero(counts >= min_points)[0]
    return tuple(int(k) - 1 for k in found[np.argsort(-counts[found], kind="stable")])


def path_blockers(
    points: tuple[np.ndarray, np.ndarray],
    owner: np.ndarray,
    clusters: Sequence[Cluster],
    cluster: Cluster,
    goal_m: np.ndarray,
    min_points: int,
) -> tuple[int, ...]:
    """What stands in the way of carrying `cluster` to `goal_m`: the clusters (-1: points of
    no cluster) with at least min_points depth points in the region its image-aligned
    rectangle sweeps beyond where it stands, no deeper in the shelf than its own deepest
    point, most points first; () when the way is clear. Eq. (5.6) sets the goal beside the
    candidate, not where it is free, and the thesis keeps a moved object off the others
    (5.3.3: objects must not touch while moving). `points`: box_points of the observation,
    `owner`: its owner_map."""
    pts, on_box = points
    x, y, w, h = (float(v) for v in cluster.rect_m)
    gx, gy = (float(v) for v in goal_m)
    shrink = 0.002
    xi, yi = -pts[..., 1], -pts[..., 2]
    swept = (
        (xi >= min(x, gx) - w / 2 + shrink)
        & (xi <= max(x, gx) + w / 2 - shrink)
        & (yi >= min(y, gy) - h / 2 + shrink)
        & (yi <= max(y, gy) + h / 2 - shrink)
    )
    where_it_is = (np.abs(xi - x) <= w / 2) & (np.abs(yi - y) <= h / 2)
    deepest = float(pts[cluster.mask, 0].max()) + 0.01
    hit = on_box & swept & ~where_it_is & (pts[..., 0] <= deepest) & (owner != cluster.index)
    return owners_by_count(owner[hit], len(clusters), min_points)


def carried(cluster: Cluster, points: tuple[np.ndarray, np.ndarray], min_points: int) -> Cluster:
    """`cluster` with the rectangle it will have when carried: a leaning one (C^r / C^l) is
    set upright as it moves (thesis 5.2.3), about its centre, so its image-aligned rectangle
    turns from the leaning box's (wide, low) to the upright one's (its thickness across, its
    length up). Boxes lean about the camera's axis, so the front face stays a rectangle
    facing the camera: the rectangle of least area around the face's depth points
    (cv2.minAreaRect, points within FRONT_BAND_M of its nearest) gives the box's length and
    thickness. A face seen as no clean rectangle (under 4 x min_points points, or its hull
    filling under RECT_FILL of the rectangle: occluded, or a row of leaning boxes) keeps the
    rectangle as seen, the conservative one. Upright, a box is taller than it leant: where
    it would dip below the floor it is raised onto it (the executor lifts it so). Other
    classes: unchanged."""
    import cv2

    if cluster.cls not in ("C^r", "C^l"):
        return cluster
    pts, on_box = points
    p = pts[cluster.mask & on_box]
    if len(p) < 4 * min_points:
        return cluster
    p = p[p[:, 0] <= np.percentile(p[:, 0], 5) + FRONT_BAND_M]
    if len(p) < 4 * min_points:
        return cluster
    mm = (np.stack([-p[:, 1], -p[:, 2]], axis=1) * 1000.0).astype(np.float32)
    (cx, cy), (a, b), _ = cv2.minAreaRect(mm)
    if a * b <= 0 or cv2.contourArea(cv2.convexHull(mm)) < RECT_FILL * a * b:
        return cluster
    across, up = min(a, b), max(a, b)
    cy = min(cy, -up / 2)  # image-aligned y is down, the floor at 0: its bottom on the floor
    return dataclasses.replace(cluster, rect_m=np.array([cx, cy, across, up]) / 1000.0)


def candidates(
    obs: Observation,
    clusters: Sequence[Cluster],
    size_m: np.ndarray,
    params: ReplenishParams,
    space: WorkingSpace,
    points: tuple[np.ndarray, np.ndarray] | None = None,
    owner: np.ndarray | None = None,
) -> list[Candidate]:
    """Every placement candidate inside the working space (thesis 5.2.3), with the clusters
    whose box points fall inside it or in front of it (the 3D region: the candidate's
    rectangle from the shelf's front to the new box's depth behind the cluster's front face:
    the box goes in from the front, and a box seen in front of the place hides what is
    behind it and blocks the way).

    B^top spans the cluster's top surface, not its whole width: eq. (5.2) puts the box flush
    with the cluster's left edge, off the stack where its top box is narrower than the boxes
    under it, and rests on that surface; a free B^top whose surface is narrower than half the
    new box (a tilted box on top shows only a strip within TOP_BAND_M of its highest point)
    is no place: the box's middle would overhang it. A candidate beside a cluster must rest
    on something once its occupants are moved: the floor, or box points other than its
    occupants' just under the middle of its bottom (else a free candidate in mid-air beside a
    box on a stack would be "simple"). `points`, `owner`: box_points and owner_map of the
    observation, if already computed."""
    pts, on_box = points if points is not None else box_points(obs, space)
    owner = owner if owner is not None else owner_map(obs, clusters)
    out: list[Candidate] = []
    g, d_new = params.finger_m, float(size_m[0])
    for c in clusters:
        for side in SIDES_OF_CLASS.get(c.cls, ()):
            w_new, h_new = new_box_extent_m(size_m, side)
            b = c.rect_m
            if side == "top":
                b = np.array([c.top_span_m.mean(), b[1], np.ptp(c.top_span_m), b[3]])
            rect = candidate_rect(b, side, w_new, h_new, g)
            if not in_working_space(rect, space):
                continue
            x, y, w, h = rect
            shrink = 0.001
            across = np.abs(-pts[..., 1] - x)
            inside = (  # the candidate's volume and the insertion path in front of it
                on_box
                & (across <= w / 2 - shrink)
                & (np.abs(-pts[..., 2] - y) <= h / 2 - shrink)
                & (pts[..., 0] <= c.front_x_m + d_new + 0.01)
            )
            occupants = owners_by_count(owner[inside], len(clusters), params.min_points)
            if side == "top" and not occupants and np.ptp(c.top_span_m) < w_new / 2:
                continue  # the new box's middle would overhang the top surface: it tips off
            bottom = y + h / 2
            if side != "top" and -bottom > SUPPORT_BAND_M:  # off the floor: box points under it
                under = (
                    on_box
                    & (across <= w / 2 - g)
                    & (-pts[..., 2] >= bottom - 0.002)
                    & (-pts[..., 2] <= bottom + SUPPORT_BAND_M)
                    & ~np.isin(owner, occupants)
                )
                if under.sum() < params.min_points:
                    continue
            rest_z = None
            if side == "top" and occupants and occupants[0] >= 0:
                # the blocker lies on the stack: its lowest points across B^top show where
                # the stack's top is when the blocker hides it (the stack's own visible top
                # is then too low, and a box let go there would be pushed into the stack)
                on_occ = clusters[occupants[0]].mask & on_box & (across <= w / 2)
                if on_occ.sum() >= params.min_points:
                    rest_z = float(np.percentile(pts[on_occ][:, 2], 5))
            pose = new_box_pose(rect, side, size_m, c, space, g, rest_z)
            out.append(Candidate(c.index, side, rect, occupants, pose))
    return out


class ReplenishPlanner:
    """Thesis Fig. 5.2: simple replenishment if a candidate is free; else bimanual
    replenishment (move the one blocker B_s aside and hold it, if no other cluster's box
    overlaps its collapse region R_s by IoU th or more); else bimanual rearrangement (move the
    cluster B_k that overlaps R_s most aside, if that is safe, then look again); else, with
    params.contact, a contact replenishment (a movable B_s carried although boxes stand in
    its way, the first in candidate order); else no plan.

    `collapse_map` None or params.use_collapse False: the thesis' "without collapse
    prediction" variant, every blocker movable."""

    def __init__(
        self,
        params: ReplenishParams,
        space: WorkingSpace,
        collapse_map: CollapseMap | None = None,
    ):
        self.params, self.space, self.collapse_map = params, space, collapse_map

    def _carried(self, cluster: Cluster, points: tuple[np.ndarray, np.ndarray]) -> Cluster:
        if not self.params.upright_footprint:
            return cluster
        return carried(cluster, points, self.params.min_points)

    def _region(self, obs: Observation, cluster: Cluster) -> np.ndarray | None:
        if self.collapse_map is None or not self.params.use_collapse:
            return None
        return self.collapse_map(obs, cluster.mask) >= self.params.prob_threshold

    def _safe(self, region: np.ndarray | None, clusters: Sequence[Cluster], skip: set[int]) -> bool:
        """IoU(B_j, R) < th for every cluster j not in `skip` (no region: always)."""
        if region is None:
            return True
        return all(
            rect_iou_mask(c.box_px, region) < self.params.iou_threshold
            for c in clusters
            if c.index not in skip
        )

    def _rearrange(
        self,
        obs: Observation,
        seen: tuple[tuple[np.ndarray, np.ndarray], np.ndarray],
        clusters: Sequence[Cluster],
        k: Cluster,
        s: Cluster,
        s_goal: np.ndarray,
        regions: dict[int, np.ndarray | None],
        skip: Set[int] = frozenset(),
    ) -> Plan | None:
        """Bimanual rearrangement (eqs. 5.7-5.9): carry B_k beside B_s's goal and let it go,
        if that is safe (its own collapse region overlaps no cluster but those in `skip`), it
        stays in the working space and its way is clear; else None. `seen`: (box_points,
        owner_map) of the observation."""
        if k.index not in regions:
            regions[k.index] = self._region(obs, k)
        if not self._safe(regions[k.index], clusters, set(skip) | {s.index, k.index}):
            return None
        k = self._carried(k, seen[0])
        goal_k = rearrange_goal(k.rect_m, s.rect_m, self.params.finger_m, s_goal)
        moved_k = np.array([goal_k[0], goal_k[1], k.rect_m[2], k.rect_m[3]])
        if not in_working_space(moved_k, self.space):
            return None
        if path_blockers(*seen, clusters, k, goal_k, self.params.min_points):
            return None
        move_k = Move.carrying(k, goal_k)
        return Plan("rearrange", None, move_k, {"obstacle": k.index})

    def plan(self, obs: Observation, detections: Sequence[Detection], size_m: np.ndarray) -> Plan:
        points = box_points(obs, self.space)  # back-projected once per plan
        clusters = place_clusters(obs, detections, self.space, points)
        owner = owner_map(obs, clusters)
        cands = candidates(
            obs, clusters, np.asarray(size_m, float), self.params, self.space, points, owner
        )
        info = _plan_info(clusters, cands)
        for cand in cands:  # simple replenishment
            if cand.free:
                return Plan("simple", cand, None, info | {"candidate": cands.index(cand)})
        regions: dict[int, np.ndarray | None] = {}
        rearrange: Plan | None = None
        touching: list[tuple[int, Cluster, Move]] = []  # movable but for its way
        g = self.params.finger_m
        why_not = info["why_not"] = ["" for _ in cands]  # why no bimanual plan, per candidate
        seen = (points, owner)
        for n, cand in enumerate(cands):  # bimanual replenishment: one blocker
            if cand.occupants[0] < 0:
                why_not[n] = "filled by no detected cluster"  # nothing to grasp
                continue
            s = self._carried(clusters[cand.occupants[0]], points)  # B_s: filling it most
            if s.index == cand.cluster:
                why_not[n] = "filled by its own cluster"  # nothing to move aside
                continue
            w_new, h_new = new_box_extent_m(np.asarray(size_m, float), cand.side)
            by = cand.rect_m if self.params.goal_from_candidate else None
            goal = move_goal(s.rect_m, cand.side, w_new, h_new, g, by)
            moved = np.array([goal[0], goal[1], s.rect_m[2], s.rect_m[3]])
            if not in_working_space(moved, self.space):
                why_not[n] = "blocker's goal outside the shelf"
                continue
            skip = {s.index, cand.cluster}
            in_way = path_blockers(*seen, clusters, s, goal, self.params.min_points)
            if in_way:  # carrying B_s there would push another box: make way first
                why_not[n] = f"blocker's way blocked by {in_way[0]}"
                if self.params.contact:
                    touching.append((n, s, Move.carrying(s, goal)))
                if rearrange is None and in_way[0] >= 0 and in_way[0] not in skip:
                    k = clusters[in_way[0]]
                    rearrange = self._rearrange(obs, seen, clusters, k, s, goal, regions)
                    if rearrange is not None:
                        rearrange.info.update(info | {"candidate": n, "blocker": s.index})
                continue
            if s.index not in regions:  # its collapse map: only once its way is clear
                regions[s.index] = self._region(obs, s)
            region = regions[s.index]
            move = Move.carrying(s, goal)
            if self._safe(region, clusters, skip):
                return Plan("bimanual", cand, move, info | {"candidate": n, "blocker": s.index})
            why_not[n] = "blocker's collapse region overlaps another cluster"
            if rearrange is None and region is not None:  # eqs. (5.7)-(5.9)
                others = [c for c in clusters if c.index not in skip]
                if not others:
                    continue
                # B_k: the cluster overlapping B_s's collapse region most
                k = max(others, key=lambda c: (rect_iou_mask(c.box_px, region), -c.index))
                rearrange = self._rearrange(obs, seen, clusters, k, s, goal, regions, skip)
                if rearrange is not None:
                    rearrange.info.update(info | {"candidate": n, "blocker": s.index})
        if rearrange is not None:
            return rearrange
        for n, s, move in touching:  # contact: the first movable blocker, its way pushed
            if s.index not in regions:
                regions[s.index] = self._region(obs, s)
            if self._safe(regions[s.index], clusters, {s.index, cands[n].cluster}):
                return Plan("contact", cands[n], move, info | {"candidate": n, "blocker": s.index})
        return Plan("none", None, None, info)


def _r(a: np.ndarray) -> list[float]:
    return [round(float(v), 4) for v in a]


def _plan_info(clusters: Sequence[Cluster], cands: Sequence[Candidate]) -> dict[str, Any]:
    """A plan's record of what it saw: the clusters and the placement candidates."""
    return {
        "clusters": [
            {"cls": c.cls, "box_px": _r(c.box_px), "rect_m": _r(c.rect_m)} for c in clusters
        ],
        "candidates": [
            {
                "cluster": c.cluster,
                "side": c.side,
                "rect_m": _r(c.rect_m),
                "occupants": list(c.occupants),
            }
            for c in cands
        ],
    }
