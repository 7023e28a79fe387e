"""The depth-sensor model (sim/sensor.py): each effect on scenes whose answer is known from the
geometry (planes, a box in front of a wall), at every image size, and its seeding."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clutterbench.errors import ClutterbenchError
from clutterbench.observation import CameraModel
from clutterbench.sim.sensor import (
    D415,
    PRESETS,
    RANDOMIZED_FIELDS,
    STRUCTURED_LIGHT,
    correlated,
    observation_rng,
    preset,
    randomized,
    sense,
)

SIZES = (64, 128, 256)
SENSORS = {"structured_light": STRUCTURED_LIGHT, "d415": D415}
Z_BOX, Z_WALL = 0.5, 0.65


def camera(size: int, fovy_deg: float = 42.0) -> CameraModel:
    """The default shelf camera's intrinsics at `size` px (pose: identity)."""
    f = size / 2 / math.tan(math.radians(fovy_deg / 2))
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1.0]])
    return CameraModel(K=K, T_world_from_cam=np.eye(4))


def quiet(cfg, **changes):
    """`cfg` with no random effect left (no noise, quantisation, step pixels or dropout)."""
    clean = dict(subpixel_px=0.0, disparity_step_px=0.0, dropout=0.0)
    return dataclasses.replace(cfg, **{**clean, "step_missing": 0.0, "step_flying": 0.0, **changes})


def box_scene(size: int) -> tuple[np.ndarray, slice, slice]:
    """A fronto-parallel box face at Z_BOX over the middle of a wall at Z_WALL: depth, and the
    box's rows and columns."""
    depth = np.full((size, size), Z_WALL, np.float32)
    rows, cols = slice(size // 4, size // 2), slice(3 * size // 8, 5 * size // 8)
    depth[rows, cols] = Z_BOX
    return depth, rows, cols


def cluttered(size: int) -> np.ndarray:
    """Boxes at 0.45-0.55 m in front of a wall at 0.6 m, with a hole (no return)."""
    depth = np.full((size, size), 0.6, np.float32)
    s = size / 16
    for (r0, r1, c0, c1), z in zip(
        [(2, 6, 1, 5), (3, 9, 6, 10), (9, 14, 3, 8), (10, 13, 11, 15)], [0.5, 0.45, 0.55, 0.52]
    ):
        depth[int(r0 * s) : int(r1 * s), int(c0 * s) : int(c1 * s)] = z
    depth[: int(s), -int(2 * s) :] = 0.0
    return depth


def run_of_zeros(row: np.ndarray, start: int, step: int) -> int:
    """How many consecutive zeros from row[start] going by `step`."""
    n, i = 0, start
    while 0 <= i < row.size and row[i] == 0:
        n, i = n + 1, i + step
    return n


# --- presets ---------------------------------------------------------------------------------


def test_presets_are_ideal_structured_light_and_d415():
    assert list(PRESETS) == ["ideal", "structured_light", "d415"]
    assert preset("ideal") is None
    assert preset("structured_light").kind == "structured_light"
    d415 = preset("d415")
    assert d415.kind == "active_stereo" and d415.baseline_m == 0.055
    assert d415.width_px == 1280 and d415.hfov_deg == pytest.approx(65.0)


def test_an_unknown_preset_is_a_one_line_error_naming_the_known_ones():
    with pytest.raises(ClutterbenchError) as err:
        preset("kinect")
    msg = str(err.value)
    assert "\n" not in msg and "kinect" in msg
    assert all(name in msg for name in PRESETS)


def test_ideal_returns_the_image_unchanged():
    depth = cluttered(128)
    out = sense(depth, camera(128), PRESETS["ideal"], np.random.default_rng(0))
    assert out.dtype == np.float32 and out.tobytes() == depth.tobytes()


# --- seeding ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", SENSORS)
def test_the_same_observation_gets_the_same_noise_and_another_other_noise(name):
    cfg, cam, depth = PRESETS[name], camera(128), cluttered(128)
    a = sense(depth, cam, cfg, observation_rng(3, depth))
    b = sense(depth.copy(), cam, cfg, observation_rng(3, depth.copy()))
    assert a.tobytes() == b.tobytes()
    moved = depth.copy()
    moved[0, 0] += 0.001  # one pixel of a far corner
    c = sense(moved, cam, cfg, observation_rng(3, moved))
    valid = (a > 0) & (c > 0)
    assert np.mean(a[valid] != c[valid]) > 0.5  # not just that pixel: all the noise
    d = sense(depth, cam, cfg, observation_rng(4, depth))
    assert np.mean(a[valid] != d[valid]) > 0.5


def test_observation_rng_hashes_the_shape_too():
    flat = np.zeros((4, 16), np.float32)
    assert observation_rng(0, flat).random() != observation_rng(0, flat.reshape(8, 8)).random()


# --- noise -----------------------------------------------------------------------------------


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SENSORS)
def test_noise_on_planes_is_the_datasheet_formula_and_grows_with_z_squared(name, size):
    """sigma_z = z^2 * sigma_d / (f * b) with the sensor's own f, whatever our image size."""
    cfg = quiet(PRESETS[name], subpixel_px=PRESETS[name].subpixel_px)
    cam, stds = camera(size), {}
    for z in (0.5, 1.0):
        plane = np.full((size, size), z, np.float32)
        out = sense(plane, cam, cfg, np.random.default_rng(size))
        assert np.all(out > 0)
        stds[z] = float(np.std(out.astype(np.float64) - z))
        expected = z**2 * cfg.subpixel_px / (cfg.focal_px * cfg.baseline_m)
        assert stds[z] == pytest.approx(expected, rel=0.04)
    assert stds[1.0] / stds[0.5] == pytest.approx(4.0, rel=0.05)


def test_correlated_noise_has_unit_variance_and_spans_the_window():
    white = np.random.default_rng(0).standard_normal((256, 256))
    assert correlated(white, 0.0) is white
    smooth = correlated(white, 8.0)
    assert np.std(smooth) == pytest.approx(1.0, rel=0.1)
    lag1 = np.corrcoef(smooth[:, :-1].ravel(), smooth[:, 1:].ravel())[0, 1]
    assert lag1 > 0.7
    assert abs(np.corrcoef(white[:, :-1].ravel(), white[:, 1:].ravel())[0, 1]) < 0.02


def test_quantisation_leaves_discrete_disparity_levels():
    cfg = dataclasses.replace(quiet(D415), subpixel_px=D415.subpixel_px)
    ramp = np.tile(np.linspace(0.5, 0.9, 128, dtype=np.float32), (128, 1))
    fb = cfg.focal_px * cfg.baseline_m
    for step, discrete in ((D415.disparity_step_px, True), (0.0, False)):
        c = dataclasses.replace(cfg, disparity_step_px=step)
        out = sense(ramp, camera(128), c, np.random.default_rng(1)).astype(np.float64)
        levels = fb / out / D415.disparity_step_px
        off = np.abs(levels - np.round(levels))
        assert (np.max(off) < 0.01) == discrete
    assert np.mean(off) > 0.1  # continuous: spread over the step


# --- shadows ---------------------------------------------------------------------------------


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SENSORS)
@pytest.mark.parametrize("side", ["+x", "-x"])
def test_a_box_casts_a_shadow_band_of_the_geometric_width_away_from_the_second_view(
    name, size, side
):
    cfg = quiet(PRESETS[name], second_view=side, window_px=0.0)
    depth, rows, cols = box_scene(size)
    out = sense(depth, camera(size), cfg, np.random.default_rng(0))
    f = camera(size).K[0, 0]
    width = f * cfg.baseline_m * (1 / Z_BOX - 1 / Z_WALL)
    row = out[(rows.start + rows.stop) // 2]
    left, right = run_of_zeros(row, cols.start - 1, -1), run_of_zeros(row, cols.stop, 1)
    shadow, lit = (left, right) if side == "+x" else (right, left)
    assert abs(shadow - width) <= 1.0
    assert lit == 0
    assert np.all(out[rows, cols] == pytest.approx(Z_BOX))  # the box itself is seen
    assert np.count_nonzero(out == 0) == pytest.approx(
        width * (rows.stop - rows.start), abs=rows.stop - rows.start
    )


def test_a_slanted_surface_casts_no_shadow_on_itself():
    size = 128
    cam = camera(size)
    x = (np.arange(size) + 0.5 - size / 2) / cam.K[0, 0]
    plane = np.tile((0.7 / (1 - 0.8 * x)).astype(np.float32), (size, 1))  # z = 0.7 + 0.8 X
    for cfg in SENSORS.values():
        for side in ("+x", "-x"):
            out = sense(plane, cam, quiet(cfg, second_view=side), np.random.default_rng(0))
            assert np.all(out > 0)


@pytest.mark.parametrize("side", ["+x", "-x"])
def test_a_surface_the_second_view_sees_stretched_still_hides_what_is_behind_it(side):
    """A slanted face (6 mm deeper per pixel, away from the second view) reprojects with gaps
    between its pixels; the wall behind it must not show through them."""
    size, z_wall = 128, 0.8
    depth = np.full((size, size), z_wall, np.float32)
    depth[40:88, 48:80] = 0.5 + 0.006 * np.arange(32)
    if side == "-x":
        depth = np.ascontiguousarray(depth[:, ::-1])
    out = sense(depth, camera(size), quiet(D415, second_view=side), np.random.default_rng(0))
    width = camera(size).K[0, 0] * D415.baseline_m * (1 / 0.5 - 1 / z_wall)
    for row in out[40:88] if side == "+x" else out[40:88, ::-1]:
        assert abs(run_of_zeros(row, 47, -1) - width) <= 1.0
    assert np.all(out[40:88, 48:80] > 0)


# --- steps: fattening, missing and flying pixels ---------------------------------------------


@pytest.mark.parametrize("size", SIZES)
def test_block_matching_fattens_the_foreground_by_half_its_window(size):
    cam = camera(size)
    f = cam.K[0, 0]
    for radius in (2, 3):
        cfg = quiet(D415, window_px=2 * radius * D415.focal_px / f)  # radius our px
        depth, rows, cols = box_scene(size)
        out = sense(depth, cam, cfg, np.random.default_rng(0))
        row = out[(rows.start + rows.stop) // 2]
        near = np.flatnonzero(np.isclose(row, Z_BOX))
        assert near[-1] + 1 - cols.stop == radius  # the lit side (right: second view at +x)
        column = out[:, cols.stop - 2]
        near = np.flatnonzero(np.isclose(column, Z_BOX))
        assert (rows.start - near[0], near[-1] + 1 - rows.stop) == (radius, radius)


@pytest.mark.parametrize("size", SIZES)
def test_the_presets_fatten_as_their_windows_say(size):
    cam = camera(size)
    for cfg in (D415, STRUCTURED_LIGHT):
        depth, rows, cols = box_scene(size)
        out = sense(depth, cam, quiet(cfg, window_px=cfg.window_px), np.random.default_rng(0))
        near = np.flatnonzero(np.abs(out[(rows.start + rows.stop) // 2] - Z_BOX) < 0.002)
        expected = math.floor(0.5 * cfg.window_px * cam.K[0, 0] / cfg.focal_px + 0.5)
        assert near[-1] + 1 - cols.stop == expected
    assert math.floor(0.5 * D415.window_px * camera(256).K[0, 0] / D415.focal_px + 0.5) == 1
    assert STRUCTURED_LIGHT.window_px == 0


def test_pixels_beside_a_step_go_missing_or_fly_between_its_sides():
    size = 128
    depth, rows, cols = box_scene(size)
    cam, r = camera(size), (rows.start + rows.stop) // 2
    gone = sense(depth, cam, quiet(D415, window_px=0, step_missing=1.0), np.random.default_rng(0))
    assert gone[r, cols.stop - 1] == 0 and gone[r, cols.stop] == 0  # both sides of the step
    assert gone[r, cols.stop - 2] > 0 and gone[r, cols.stop + 1] > 0
    fly = sense(depth, cam, quiet(D415, window_px=0, step_flying=1.0), np.random.default_rng(0))
    edge = fly[r, [cols.stop - 1, cols.stop]]
    assert np.all((edge > Z_BOX) & (edge < Z_WALL))
    assert fly[r, cols.stop + 1] == pytest.approx(Z_WALL)


def test_random_dropout_removes_its_fraction():
    plane = np.full((256, 256), 0.6, np.float32)
    out = sense(plane, camera(256), quiet(D415, dropout=0.2), np.random.default_rng(0))
    assert np.mean(out == 0) == pytest.approx(0.2, abs=0.01)


def test_depth_outside_the_sensor_range_is_no_return():
    near = np.full((64, 64), 0.3, np.float32)
    assert np.all(sense(near, camera(64), D415, np.random.default_rng(0)) == 0)  # Min-Z 0.45
    assert np.mean(sense(near, camera(64), STRUCTURED_LIGHT, np.random.default_rng(0)) > 0) > 0.9


# --- whatever the input ----------------------------------------------------------------------


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SENSORS)
def test_output_is_finite_float32_and_no_return_stays_no_return(name, size):
    depth = cluttered(size)
    out = sense(depth, camera(size), PRESETS[name], observation_rng(0, depth))
    assert out.dtype == np.float32 and out.shape == depth.shape
    assert np.all(np.isfinite(out))
    assert np.all(out[depth == 0] == 0)
    valid = out > 0
    assert 0.5 < valid.mean() < 1.0
    assert np.median(np.abs(out[valid] - depth[valid])) < 0.002


@pytest.mark.parametrize("name", SENSORS)
def test_degenerate_inputs_do_not_raise(name):
    cfg, rng = PRESETS[name], np.random.default_rng(0)
    single = np.zeros((32, 32), np.float32)
    single[16, 16] = 0.6
    nan = np.full((32, 32), 0.6, np.float32)
    nan[3, 3], nan[4, 4] = np.nan, np.inf
    cases = [np.zeros((32, 32), np.float32), np.full((32, 32), 0.6, np.float32), single, nan]
    cases += [np.full((1, 1), 0.6, np.float32), np.zeros((0, 5), np.float32)]
    for depth in cases:
        out = sense(depth, camera(max(depth.shape[0], 1)), cfg, rng)
        assert out.shape == depth.shape and out.dtype == np.float32
        assert np.all(np.isfinite(out)) and np.all(out[~(depth > 0)] == 0)
    assert np.all(sense(cases[0], camera(32), cfg, rng) == 0)


# --- randomization ---------------------------------------------------------------------------


def test_randomized_scales_the_noise_within_the_spread_and_keeps_the_geometry():
    assert randomized(None, np.random.default_rng(0), 0.3) is None
    assert randomized(D415, np.random.default_rng(0), 0.0) == D415
    a = randomized(D415, np.random.default_rng(5), 0.3)
    assert a == randomized(D415, np.random.default_rng(5), 0.3)
    assert a != randomized(D415, np.random.default_rng(6), 0.3)
    for name in RANDOMIZED_FIELDS:
        assert 0.7 * getattr(D415, name) <= getattr(a, name) <= 1.3 * getattr(D415, name)
    geometry = ("kind", "baseline_m", "second_view", "focal_px", "width_px")
    for name in (*geometry, "disparity_step_px", "min_range_m", "max_range_m", "step_m"):
        assert getattr(a, name) == getattr(D415, name)
    sure = dataclasses.replace(D415, step_missing=0.8, step_flying=0.2)
    for seed in range(20):
        b = randomized(sure, np.random.default_rng(seed), 0.9)
        assert b.step_missing + b.step_flying <= 1.0 + 1e-9
    with pytest.raises(ClutterbenchError):
        randomized(D415, np.random.default_rng(0), 1.0)


def _train_config(preset_name: str, noise: bool = True):
    from clutterbench.collapse.config import TrainConfig, TrainSensingConfig
    from clutterbench.config import parse

    model = {"arch": "collapse_map", "dataset": "d", "batch_size": 2, "lr": 1e-3, "epochs": 1}
    model |= {"noise": noise, "net": {"input_size": 64}}
    cfg = parse(TrainConfig, {"models": {"m": model}}, "train")
    return dataclasses.replace(cfg, sensing=TrainSensingConfig(preset=preset_name))


def test_training_augmentation_is_the_noise_unless_a_sensor_is_named():
    from clutterbench.sim.noise import add_depth_noise
    from clutterbench.sim.sensor import SensedAugmentation, focal_px

    depth = np.full((64, 64), 0.6, np.float32)
    depth[20:40, 20:40] = 0.5
    cfg = _train_config("ideal")
    aug = cfg.augmentation("m", 42.0)
    assert aug is cfg.noise
    a = aug.apply(depth, np.random.default_rng(3))
    assert np.array_equal(a, add_depth_noise(depth, cfg.noise, np.random.default_rng(3)))
    assert _train_config("d415", noise=False).augmentation("m", 42.0) is None
    sensed = _train_config("d415").augmentation("m", 42.0)
    assert isinstance(sensed, SensedAugmentation) and sensed.sensor == preset("d415")
    assert sensed.fx_px == pytest.approx(focal_px(64, 42.0))
    assert focal_px(128, 42.0) == pytest.approx(64 / math.tan(math.radians(21.0)))
    one = sensed.apply(depth, np.random.default_rng(5))
    assert np.array_equal(one, sensed.apply(depth, np.random.default_rng(5)))
    assert not np.array_equal(one, sensed.apply(depth, np.random.default_rng(6)))
    assert one.dtype == np.float32 and np.isfinite(one).all()
    assert (one == 0).any() and not np.array_equal(one, depth)  # shadows, steps: sensed


def test_a_network_s_own_training_sensor_overrides_train_s():
    """train.models.<m>.sensing: that network trains on its own sensor, the others on
    train.sensing; a checkpoint of a network without its own keeps its old metadata."""
    from clutterbench.collapse.config import TrainConfig, TrainSensingConfig
    from clutterbench.collapse.train import _checkpoint_meta
    from clutterbench.config import parse
    from clutterbench.sim.sensor import SensedAugmentation

    base = {"arch": "collapse_map", "dataset": "d", "batch_size": 2, "lr": 1e-3, "epochs": 1}
    base |= {"net": {"input_size": 64}}
    own = base | {"sensing": {"preset": "structured_light", "spread": 0.1}}
    cfg = parse(TrainConfig, {"models": {"m": base, "s": own}}, "train")
    assert cfg.augmentation("m", 42.0) is cfg.noise  # train.sensing: ideal
    sensed = cfg.augmentation("s", 42.0)
    assert isinstance(sensed, SensedAugmentation) and sensed.sensor == preset("structured_light")
    assert sensed.spread == 0.1 and cfg.sensing_of("s").preset == "structured_light"
    d415 = dataclasses.replace(cfg, sensing=TrainSensingConfig(preset="d415"))
    assert d415.sensing_of("m").preset == "d415" and d415.sensing_of("s").spread == 0.1
    assert "sensing" not in _checkpoint_meta("m", cfg.models["m"], 0.005, 64, 0, "fp32")["train"]
    meta = _checkpoint_meta("s", cfg.models["s"], 0.005, 64, 0, "fp32")
    assert meta["train"]["sensing"] == {"preset": "structured_light", "spread": 0.1}


def test_a_support_scene_under_a_sensor_keeps_its_masks_and_truth():
    from clutterbench.sim.config import CameraConfig
    from clutterbench.support.evaluate import Scene, sensed_scene

    depth = np.full((64, 64), 0.7, np.float32)
    depth[20:40, 10:30], depth[20:40, 34:54] = 0.55, 0.6
    masks = np.zeros((2, 64, 64), dtype=bool)
    masks[0, 20:40, 10:30] = masks[1, 20:40, 34:54] = True
    eye = np.eye(2, dtype=bool)
    scene = Scene(0, "random", depth, [0, 1], masks, ~eye, eye, 2, gaps_m=np.zeros((2, 2)))
    cam = CameraConfig(image_size=64)
    one, two = sensed_scene(scene, "d415", cam), sensed_scene(scene, "d415", cam)
    assert not np.array_equal(one.depth_m, depth) and np.array_equal(one.depth_m, two.depth_m)
    assert one.masks is scene.masks and one.moved is scene.moved and one.ids == scene.ids
    assert one.gaps_m.shape == (2, 2) and not np.array_equal(one.gaps_m, scene.gaps_m)


def test_the_box_heads_scenes_pass_through_its_sensor():
    """support.box_head.sensing: ideal leaves the scenes as they are; with a preset the val
    and test scenes are the preset's own (as the support stage's sensed rows see them) and
    the train scenes the preset randomised by the spread, seeded by the stage's seed and
    the picture: reruns equal, another seed another draw."""
    from clutterbench.sim.config import CameraConfig, SimConfig
    from clutterbench.sim.noise import TrainSensingConfig
    from clutterbench.support.box_run import as_sensed
    from clutterbench.support.evaluate import Scene, sensed_scene

    depth = np.full((64, 64), 0.7, np.float32)
    depth[20:40, 10:30], depth[20:40, 34:54] = 0.55, 0.6
    masks = np.zeros((2, 64, 64), dtype=bool)
    masks[0, 20:40, 10:30] = masks[1, 20:40, 34:54] = True
    eye = np.eye(2, dtype=bool)
    scenes = [Scene(0, "random", depth, [0, 1], masks, ~eye, eye, 2, gaps_m=np.zeros((2, 2)))]
    sim = SimConfig(camera=CameraConfig(image_size=64))
    assert as_sensed(scenes, TrainSensingConfig(), sim, 3) is scenes
    d415 = TrainSensingConfig(preset="d415", spread=0.5)
    (val,) = as_sensed(scenes, d415, sim, None)
    assert np.array_equal(val.depth_m, sensed_scene(scenes[0], "d415", sim.camera).depth_m)
    (train,), (again,), (other,) = (as_sensed(scenes, d415, sim, s) for s in (3, 3, 4))
    assert np.array_equal(train.depth_m, again.depth_m)
    unspread = sensed_scene(scenes[0], "d415", sim.camera, 0.0, 3)  # same seed, no spread
    for a, b in ((train, val), (train, other), (train, unspread)):
        assert not np.array_equal(a.depth_m, b.depth_m)
    assert train.masks is masks and train.ids == [0, 1]


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SENSORS)
def test_a_steep_slope_is_no_step_at_any_image_size(name, size):
    """A plane seen at a grazing angle, 1.1 cm deeper per pixel of ours at 128 px (more than
    step_m), and a roof fold of two such planes: continuous surfaces, no step for a sensor at
    its own resolution. No pixel goes missing, and block matching fattens nothing."""
    cam = camera(size)
    u = np.arange(size) + 0.5
    per_px = 0.011 * 128 / size  # the same surface at every size
    slope = np.tile((0.5 + per_px * u).astype(np.float32), (size, 1))  # 0.5 .. 1.9 m
    fold = np.tile((0.5 + per_px * np.abs(u - size / 2)).astype(np.float32), (size, 1))
    cfg = quiet(SENSORS[name], step_missing=1.0, baseline_m=1e-4)  # a face of the fold would
    for depth in (slope, fold):  # be in the second view's shadow: steps alone here
        out = sense(depth, cam, cfg, np.random.default_rng(0))
        inner = np.s_[1:-1, 1:-1]  # away from the image's border, whose pairs have one side
        assert np.all(out[inner] > 0), "a pixel of a slope went missing as if at a step"
        fat = sense(
            depth,
            cam,
            dataclasses.replace(cfg, window_px=28.0, step_missing=0.0),
            np.random.default_rng(0),
        )
        assert np.all(fat[inner] == depth[inner])


def test_a_step_beside_a_steep_slope_is_still_a_step():
    """A box face in front of a wall that slopes away steeply: the jump at the box's edge is a
    step (its pixels go missing), the wall's slope beside it is not."""
    size = 128
    depth = np.tile((0.6 + 0.015 * np.arange(size)).astype(np.float32), (size, 1))
    depth[40:80, 40:80] = 0.5
    out = sense(
        depth, camera(size), quiet(D415, window_px=0, step_missing=1.0), np.random.default_rng(0)
    )
    assert np.all(out[41:79, [39, 40, 79, 80]] == 0)  # both sides of each vertical edge
    assert np.all(out[41:79, 82:-2] > 0)  # the slope beyond the box
    assert np.all(out[41:79, 2:30] > 0)  # and before its shadow (columns 31-39)


def _dense_pairs_along(z: np.ndarray, step_m: float) -> np.ndarray:
    """step_pairs' definition along rows, written densely over every pair."""
    valid = z > 0
    both = valid[:, :-1] & valid[:, 1:]
    d = np.where(both, z[:, 1:] - z[:, :-1], np.nan)
    pad = np.pad(d, ((0, 0), (1, 1)), constant_values=np.nan)
    with np.errstate(invalid="ignore"):
        beside = np.fmin(np.abs(d - pad[:, :-2]), np.abs(d - pad[:, 2:]))
        residual = np.where(np.isnan(beside), np.abs(d), beside)
        return both & (np.abs(d) > step_m) & (residual > step_m)


def _dense_steps(z: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """_steps' definition over every pixel: beside a step, and the depth across the largest
    (ties: above, below, left, right)."""
    right, down = _dense_pairs_along(z, step_m), _dense_pairs_along(z.T, step_m).T
    pad = np.pad(z, 1, mode="edge")
    row, col = np.zeros((1, z.shape[1]), bool), np.zeros((z.shape[0], 1), bool)
    biggest, across = np.zeros_like(z), z.copy()
    for nb, step in (
        (pad[:-2, 1:-1], np.vstack([row, down])),
        (pad[2:, 1:-1], np.vstack([down, row])),
        (pad[1:-1, :-2], np.hstack([col, right])),
        (pad[1:-1, 2:], np.hstack([right, col])),
    ):
        diff = np.where(step, np.abs(nb - z), 0.0)
        bigger = diff > biggest
        biggest, across = np.where(bigger, diff, biggest), np.where(bigger, nb, across)
    return biggest > 0, across


def random_clutter(rng: np.random.Generator, size: int) -> np.ndarray:
    """Slanted boxes in front of a wall, a corner whose two steps tie, holes
    and a noisy patch: every kind of pair the step test meets."""
    v, u = np.mgrid[0:size, 0:size] / size
    depth = 0.6 + 0.05 * v
    for _ in range(8):
        r0, c0 = rng.integers(0, size - 4, 2)
        r1, c1 = r0 + rng.integers(2, size // 3), c0 + rng.integers(2, size // 3)
        z0 = rng.choice([0.45, 0.5, 0.5 + 0.02 * rng.random()])
        depth[r0:r1, c0:c1] = z0 + rng.uniform(-0.05, 0.05) * u[r0:r1, c0:c1]
    depth[rng.random((size, size)) < 0.03] = 0.0
    r, c = rng.integers(0, size - 8, 2)  # a corner whose two steps tie (depths exact in
    depth[r : r + 4, c : c + 8] = 0.5  # binary): (r + 4, c + 4) is 1/16 m farther than the
    depth[r + 4 : r + 8, c : c + 4] = 0.625  # pixel above and 1/16 m nearer than the one on
    depth[r + 4 : r + 8, c + 4 : c + 8] = 0.5625  # its left
    patch = slice(size // 2, size // 2 + size // 8)
    depth[patch, patch] += rng.normal(0, 0.01, depth[patch, patch].shape)
    return depth


@pytest.mark.parametrize("size", SIZES)
def test_the_sparse_step_and_shadow_search_equal_their_dense_definition(size):
    from clutterbench.sim import sensor

    rng = np.random.default_rng(size)
    for _ in range(5):
        z = random_clutter(rng, size)
        for step_m in (0.005, 0.01, 0.03):
            right, down = sensor.step_pairs(z, step_m)
            assert np.array_equal(right, _dense_pairs_along(z, step_m))
            assert np.array_equal(down, _dense_pairs_along(z.T, step_m).T)
            at_step, across = sensor._steps(z, step_m)
            want_at, want_across = _dense_steps(z, step_m)
            assert np.array_equal(at_step, want_at) and np.array_equal(across, want_across)
        for cfg in SENSORS.values():
            # the reference z-buffer: every gap column of a joined pair filled, one by one
            fx = camera(size).K[0, 0]
            got = sensor.shadowed(z, fx, cfg.baseline_m, cfg.second_view, cfg.step_m)
            assert got.shape == z.shape and got.any()
            assert np.array_equal(got, _dense_shadowed(z, fx, cfg.baseline_m, cfg.step_m))


def _dense_shadowed(z: np.ndarray, fx: float, baseline_m: float, tol_m: float) -> np.ndarray:
    """`shadowed` for a second view at +x, pixel by pixel and pair by pair."""
    from clutterbench.sim.sensor import _MAX_GAP_PX

    h, w = z.shape
    zbuf = np.full((h, w), np.inf)
    col = np.zeros((h, w), np.int64)
    for i in range(h):
        for j in range(w):
            if z[i, j] > 0:
                col[i, j] = math.floor(j + 0.5 - fx * baseline_m / z[i, j])
                if 0 <= col[i, j] < w:
                    zbuf[i, col[i, j]] = min(zbuf[i, col[i, j]], z[i, j])
    for i in range(h):
        for j in range(w - 1):
            a, b = z[i, j], z[i, j + 1]
            if a > 0 and b > 0 and abs(a - b) <= tol_m:
                lo, hi = sorted((col[i, j], col[i, j + 1]))
                for c in range(lo + 1, min(hi, lo + _MAX_GAP_PX + 1)):
                    if 0 <= c < w:
                        zbuf[i, c] = min(zbuf[i, c], max(a, b))
    seen = np.zeros((h, w), bool)
    for i in range(h):
        for j in range(w):
            c = col[i, j]
            seen[i, j] = z[i, j] > 0 and 0 <= c < w and z[i, j] > zbuf[i, c] + tol_m
    return seen
