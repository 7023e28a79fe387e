"""Region growing (perception/region_growing.py) on synthetic depth: boxes ray-cast into an empty
shelf seen as the trials' camera sees it, exact and with sensor noise, holes and flying pixels.
Counts and masks where depth can tell the boxes apart; no exception on degenerate images."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from clutterbench.observation import CameraModel, Observation
from clutterbench.perception.depth_segmentation import ShelfROI
from clutterbench.perception.region_growing import (
    RegionGrowingParams,
    fit_planes,
    segment_regions,
    window_side,
)
from clutterbench.perception.sensor_marks import lag_noise

ROI = ShelfROI(-0.28, 0.28, -0.165, 0.165, 0.0, 0.33)
"""The default shelf's interior (sim/shelf.py: 330 wide, 280 deep, 330 high)."""
PARAMS = RegionGrowingParams()
MIN_PIXELS = 20


@dataclasses.dataclass(frozen=True)
class Box:
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    """(x depth, y width, z height), metres, axis-aligned but for `yaw_deg` about z."""
    yaw_deg: float = 0.0


def camera(size: int) -> CameraModel:
    """The trials' camera: 0.5 m in front of the opening at mid height, looking into the shelf
    (OpenCV frame: x to world -y, y to world -z, z to world +x), 42 deg vertical field of view."""
    f = size / 2 / np.tan(np.deg2rad(21.0))
    K = np.array([[f, 0.0, size / 2], [0.0, f, size / 2], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    T[:3, 3] = [-0.5, 0.0, 0.165]
    return CameraModel(K=K, T_world_from_cam=T)


def render(boxes: list[Box], size: int = 128) -> Observation:
    """Exact depth (along the optical axis) and instance ids of `boxes` in the empty shelf:
    each pixel's ray against every box (slabs) and the shelf's boards (planes)."""
    cam = camera(size)
    v, u = np.mgrid[0:size, 0:size] + 0.5
    K = cam.K
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    d = d_cam @ cam.T_world_from_cam[:3, :3].T  # t along d is the depth
    o = cam.T_world_from_cam[:3, 3]
    depth, inst = np.full(u.shape, np.inf), np.zeros(u.shape, dtype=np.uint8)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value in ((0, 0.28), (1, -0.165), (1, 0.165), (2, 0.0), (2, 0.33)):
            t = (value - o[axis]) / d[..., axis]
            depth = np.where((t > 0) & (t < depth), t, depth)
        for k, box in enumerate(boxes):
            c, s = np.cos(np.deg2rad(box.yaw_deg)), np.sin(np.deg2rad(box.yaw_deg))
            R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # box -> world
            ob, db = R.T @ (o - np.array(box.centre)), d @ R
            half = np.array(box.size) / 2
            t1, t2 = (-half - ob) / db, (half - ob) / db
            near = np.nanmax(np.minimum(t1, t2), axis=-1)
            far = np.nanmin(np.maximum(t1, t2), axis=-1)
            hit = (near <= far) & (near > 0) & (near < depth)
            depth, inst = np.where(hit, near, depth), np.where(hit, k + 1, inst)
    depth[~np.isfinite(depth)] = 0.0
    return Observation(depth.astype(np.float32), inst.astype(np.uint8), cam)


def noisy(obs: Observation, sigma_m: float, per_m2: float, dropout: float, seed: int = 0):
    """`obs` with Gaussian depth noise sigma_m + per_m2 d^2 and `dropout` of returns lost."""
    rng = np.random.default_rng(seed)
    d = obs.depth_m.astype(np.float64)
    out = d + rng.standard_normal(d.shape) * (sigma_m + per_m2 * d**2)
    out[(rng.random(d.shape) < dropout) | (d <= 0)] = 0.0
    return dataclasses.replace(obs, depth_m=out.astype(np.float32))


TRAINING = (0.001, 0.002, 0.005)
"""sim/noise.py's defaults: 1 mm + 0.002 d^2, 0.5% dropout."""
STEREO = (0.002, 0.004, 0.02)
"""A stereo-like sensor: 2 mm + 0.004 d^2, 2% dropout."""

TALL = (0.10, 0.08, 0.12)
APART = [Box((0.14, 0.07, 0.06), TALL), Box((0.14, -0.07, 0.06), TALL)]
"""Two boxes standing on the floor 60 mm apart."""
IN_FRONT = [
    Box((0.16, 0.03, 0.08), (0.10, 0.12, 0.16)),
    Box((0.04, -0.03, 0.04), (0.08, 0.10, 0.08)),
]
"""A short box standing 40 mm in front of a tall one, overlapping it in the image: only the
depth step parts them."""
RESTING = [Box((0.14, 0.0, 0.025), (0.12, 0.14, 0.05)), Box((0.16, 0.0, 0.075), (0.08, 0.10, 0.05))]
"""A box resting on another, set 30 mm back: the lower one's top folds concavely into the upper
one's front, with no depth step."""
STEP = [Box((0.14, 0.04, 0.06), TALL), Box((0.148, -0.04, 0.06), TALL)]
"""Two boxes side by side, touching, one 8 mm behind the other: a step of about two footprints,
with faces parallel (only the jump parts them)."""
LOW = [Box((0.14, 0.0, 0.02), (0.20, 0.14, 0.04))]
"""One low box: its front and its top face (10 px deep at 128 px) are in view: a convex fold."""


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def matched(labels: np.ndarray, obs: Observation) -> list[float]:
    """Each box's best IoU with a segment."""
    boxes = obs.visible_boxes(MIN_PIXELS)
    segs = [labels == k for k in range(1, labels.max() + 1)]
    return [max((iou(s, obs.instance == b + 1) for s in segs), default=0.0) for b in boxes]


def segments(obs: Observation) -> np.ndarray:
    labels = segment_regions(obs, ROI, PARAMS, MIN_PIXELS)
    assert labels.dtype == np.int32 and labels.shape == obs.depth_m.shape
    assert labels.min() >= 0 and set(np.unique(labels)) == set(range(labels.max() + 1))
    return labels


def assert_one_per_box(labels: np.ndarray, obs: Observation, min_iou: float) -> None:
    """Each box has its own segment (IoU > min_iou), no segment holds a fifth of two boxes, and
    the segments matching no box (a noisy fold's sliver) hold under 10% of the boxes' pixels."""
    assert min(matched(labels, obs)) > min_iou
    boxes = obs.visible_boxes(MIN_PIXELS)
    stray = 0
    for k in range(1, labels.max() + 1):
        seg = labels == k
        shares = [
            (seg & (obs.instance == b + 1)).sum() / (obs.instance == b + 1).sum() for b in boxes
        ]
        assert sum(x >= 0.2 for x in shares) <= 1, f"segment {k} holds two boxes"
        if max(iou(seg, obs.instance == b + 1) for b in boxes) <= min_iou:
            stray += seg.sum()
    assert stray < 0.1 * (obs.instance > 0).sum()


def test_the_synthetic_scenes_show_every_box():
    for boxes in (APART, IN_FRONT, RESTING, LOW):
        assert len(render(boxes).visible_boxes(MIN_PIXELS)) == len(boxes)


@pytest.mark.parametrize(
    "boxes", [APART, IN_FRONT, RESTING, LOW], ids=["apart", "in_front", "resting", "low"]
)
@pytest.mark.parametrize("noise", [None, TRAINING, STEREO], ids=["exact", "training", "stereo"])
def test_one_segment_per_box(boxes, noise):
    """Two boxes apart, one in front of another (a depth step), one resting on another (a
    concave fold), one box's front and top faces (a convex fold: one segment)."""
    obs = render(boxes)
    labels = segments(obs if noise is None else noisy(obs, *noise))
    if noise is None:
        assert labels.max() == len(boxes)
    assert_one_per_box(labels, obs, 0.7)


@pytest.mark.parametrize("seed", range(4))
def test_noisy_counts_hold_for_other_draws(seed):
    for boxes in (IN_FRONT, RESTING, LOW):
        obs = render(boxes)
        assert_one_per_box(segments(noisy(obs, *STEREO, seed=seed + 10)), obs, 0.6)


@pytest.mark.parametrize("size", [64, 256])
def test_one_setting_serves_other_image_sizes(size):
    for boxes in (APART, IN_FRONT, LOW):
        obs = render(boxes, size)
        assert_one_per_box(segments(noisy(obs, *TRAINING)), obs, 0.7)


def test_an_image_full_of_holes():
    """30% of returns missing: the planes fill them; the boxes still part."""
    obs = render(IN_FRONT)
    assert_one_per_box(segments(noisy(obs, *TRAINING[:2], dropout=0.3)), obs, 0.6)


def test_flying_pixels_at_edges_join_no_box():
    """Pixels beside a depth step return a depth between the two sides (flying pixels)."""
    obs = render(IN_FRONT)
    d = obs.depth_m.astype(np.float64)
    rng = np.random.default_rng(3)
    step = np.zeros(d.shape, dtype=bool)
    step[:, :-1] |= np.abs(np.diff(d, axis=1)) > 0.01
    step[:-1] |= np.abs(np.diff(d, axis=0)) > 0.01
    across = np.maximum(np.roll(d, -1, axis=1), np.roll(d, -1, axis=0))
    flying = step & (rng.random(d.shape) < 0.5)
    d[flying] += rng.random(flying.sum()) * (across[flying] - d[flying])
    labels = segments(noisy(dataclasses.replace(obs, depth_m=d.astype(np.float32)), *TRAINING))
    assert_one_per_box(labels, obs, 0.7)


def test_degenerate_images_raise_nothing():
    obs = render(APART)
    for depth in (
        np.zeros((128, 128), np.float32),  # no return at all
        np.full((128, 128), np.nan, np.float32),
        np.full((1, 1), 0.6, np.float32),
        np.full((2, 3), 0.6, np.float32),
    ):
        small = dataclasses.replace(obs, depth_m=depth, instance=np.zeros(depth.shape, np.uint8))
        assert segment_regions(small, ROI, PARAMS, MIN_PIXELS).max() == 0
    # One plane across the whole view, 0.1 m into the shelf: one object, the part in the ROI.
    wall = dataclasses.replace(obs, depth_m=np.full((128, 128), 0.6, np.float32))
    assert segments(wall).max() == 1


def test_the_noise_is_measured_and_sets_the_window():
    obs = render(APART)
    inv = np.where(obs.depth_m > 0, 1.0 / np.maximum(obs.depth_m, 1e-9), 0.0)
    assert lag_noise(inv, obs.depth_m > 0, 1) < 1e-5  # planes: no second difference
    sigma = 0.002  # depth noise at z ~ 0.6 m: 1 / z noise of sigma / z^2
    noisy_obs = noisy(obs, sigma, 0.0, 0.0)
    valid = noisy_obs.depth_m > 0
    inv = np.where(valid, 1.0 / np.where(valid, noisy_obs.depth_m, 1.0), 0.0)
    expected = sigma / np.median(obs.depth_m[valid]) ** 2
    assert lag_noise(inv, valid, 1) == pytest.approx(expected, rel=0.3)
    # More noise, a wider window; the window bounded; its normals' error as asked.
    sides = [
        window_side(n, PARAMS.max_window_px, PARAMS.normal_noise_deg)[0]
        for n in (0.1, 0.5, 1.0, 100.0)
    ]
    assert sides == sorted(sides) and sides[0] == 3 and sides[-1] == PARAMS.max_window_px
    assert (
        window_side(0.5, PARAMS.max_window_px, PARAMS.normal_noise_deg)[1]
        <= PARAMS.normal_noise_deg
    )
    assert fit_planes(noisy_obs, PARAMS).window > fit_planes(obs, PARAMS).window


def test_fitted_planes_smooth_the_noise_but_keep_the_edges():
    obs = render(IN_FRONT)
    fit = fit_planes(noisy(obs, *STEREO), PARAMS)
    truth = fit_planes(obs, PARAMS)
    face = (obs.instance == 1) | (obs.instance == 2)
    err = np.abs(fit.points[..., 2] - obs.depth_m)[face & (obs.depth_m > 0)]
    raw = STEREO[0] + STEREO[1] * 0.6**2
    assert np.nanmedian(err) < raw / 3  # smoothed
    cos = np.sum(fit.normals * truth.normals, axis=-1)[face]
    assert np.nanmedian(cos) > np.cos(np.deg2rad(5.0))
    # At the step between the two boxes the fit takes each pixel's own side.
    edge = face & (np.abs(np.diff(obs.depth_m, axis=1, append=0.0)) > 0.02)
    assert np.nanmedian(np.abs(fit.points[..., 2] - obs.depth_m)[edge & face]) < 0.01


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("noise", [None, TRAINING, STEREO], ids=["exact", "training", "stereo"])
def test_a_box_front_and_top_stay_one_segment(noise, seed):
    """The convex fold between a box's front and its top joins them; a concave one (a box
    resting on another) does not."""
    for boxes in (LOW, RESTING):
        obs = render(boxes)
        labels = segments(obs if noise is None else noisy(obs, *noise, seed=seed))
        assert labels.max() == len(boxes)
        assert min(matched(labels, obs)) > 0.8


@pytest.mark.parametrize("noise", [None, TRAINING], ids=["exact", "training"])
def test_a_small_depth_step_parts_touching_boxes(noise):
    """Depth cannot part them once noise hides the step (a stereo-like sensor's 3 mm)."""
    obs = render(STEP)
    assert_one_per_box(segments(obs if noise is None else noisy(obs, *noise)), obs, 0.7)


# A real sensor's marks (perception/sensor_marks.py): holes, flying pixels, correlated noise.


def sensed(obs: Observation, name: str, seed: int) -> Observation:
    """`obs` as sim/sensor.py's preset `name` returns it: shadows, holes and flying pixels at
    depth steps, fattening, disparity noise (correlated over the block-matching window)."""
    from clutterbench.sim import sensor

    rng = np.random.default_rng(seed)
    depth = sensor.sense(obs.depth_m, obs.camera, sensor.preset(name), rng)
    return dataclasses.replace(obs, depth_m=depth)


OLD = dataclasses.replace(PARAMS, hole_weight=1.0, corr_ratio=1e9)
"""Region growing without the sensor marks: filled holes count as returns, noise is white."""


@pytest.mark.parametrize("size", [64, 128, 256])
def test_exact_depth_is_segmented_as_without_the_sensor_marks(size):
    """Exact depth has no hole inside the shelf and no noise: neither step changes a pixel."""
    for boxes in (APART, IN_FRONT, RESTING, STEP, LOW):
        obs = render(boxes, size)
        assert np.array_equal(segments(obs), segment_regions(obs, ROI, OLD, MIN_PIXELS))


def test_a_segment_of_filled_holes_is_no_object():
    """A small box (a segment of 32 px) whose returns are half missing: the plane fit fills
    them, but its 16 measured pixels (plus a quarter of the 16 filled) are under MIN_PIXELS;
    counted as returns, the filled holes would make it a segment."""
    obs = render([Box((0.14, 0.0, 0.015), (0.02, 0.015, 0.03))])
    box = obs.instance == 1
    assert box.sum() == 36 and (segments(obs) == 1).sum() == 32
    holes = box & (np.add.outer(np.arange(128), np.arange(128)) % 2 == 0)  # a checkerboard
    holed = dataclasses.replace(obs, depth_m=np.where(holes, 0.0, obs.depth_m).astype(np.float32))
    assert segments(obs).max() == 1  # whole, the box is a segment
    assert segment_regions(holed, ROI, OLD, MIN_PIXELS).max() == 1
    assert segments(holed).max() == 0


@pytest.mark.xfail(
    strict=True,
    reason="d415 at 128 px since steps are discontinuities (no holes on the grazing floor): the "
    "lag-1 median of the image's quantised disparity (1/32 px) snaps a level below the noise's "
    "rms, and the thresholds it scales split these boxes (~4 strays an image); an unbiased "
    "estimate (clipped rms) splits dev scenes more, so the thresholds need choosing again",
)
def test_holes_and_flying_pixels_at_depth_steps_make_fewer_strays():
    """The d415 preset at 128 px: half the pixels beside each step return nothing, a fifth a
    depth between the two sides; the plane fit fills the holes, whose slivers were segments."""
    strays = {"now": 0, "old": 0}
    for seed in range(6):
        obs = sensed(render(APART), "d415", seed)
        for key, params in (("now", PARAMS), ("old", OLD)):
            labels = segment_regions(obs, ROI, params, MIN_PIXELS)
            assert min(matched(labels, obs)) > 0.7
            strays[key] += labels.max() - len(APART)
    assert strays["now"] <= 8 < 2 * strays["now"] <= strays["old"]


@pytest.mark.parametrize("boxes", [APART, STEP], ids=["apart", "step"])
def test_noise_correlated_over_pixels_is_measured_at_its_span(boxes):
    """The d415 preset at 256 px: block matching correlates the disparity noise over ~2 px, which
    adjacent pixels' differences miss (they move together); measured at its span, the noise
    asks for a wider window and the boxes come out whole, one segment each."""
    obs = render(boxes, 256)
    noisy = sensed(obs, "d415", 1)
    assert fit_planes(noisy, PARAMS).window > fit_planes(noisy, OLD).window
    labels = segments(noisy)
    assert labels.max() == len(boxes)
    assert min(matched(labels, obs)) > 0.8
    assert segment_regions(noisy, ROI, OLD, MIN_PIXELS).max() > 10 * len(boxes)
