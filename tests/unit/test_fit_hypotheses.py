"""Several scenes fitted to one observation (trials.ch6.fit_hypotheses): the fit of the depth
image, then fits of noisy copies of it; a pull's outcome for a box is the share of the fits
whose pull marks it (trials/ch6/fitted.py fitted_scenes, the support stage's and the
trials' fitted pulls, the fusion's inputs)."""

from __future__ import annotations

import types

import numpy as np
import pytest

from clutterbench.collapse.box_predict import features
from clutterbench.errors import PerceptionError
from clutterbench.perception import fitted_scenes as fitted


def _obs(depth: np.ndarray):
    from clutterbench.observation import Observation

    return Observation(depth_m=depth, instance=np.zeros(depth.shape, np.uint8), camera=None)


def _seen(monkeypatch) -> list[np.ndarray]:
    """The depth images the estimator is handed; scene_of answers each with its depth."""
    seen: list[np.ndarray] = []
    monkeypatch.setattr(fitted, "scene_of", lambda est, *a: est)
    return seen


def _fit(seen: list[np.ndarray], fail: set[int] | None = None):
    def estimate(obs):
        seen.append(obs.depth_m.copy())
        if fail and len(seen) - 1 in fail:
            raise PerceptionError("no model")
        return obs.depth_m

    return estimate


def test_the_first_fit_is_the_image_and_the_others_noisy_copies_where_it_saw_something(
    monkeypatch,
):
    seen = _seen(monkeypatch)
    depth = np.full((6, 6), 0.8, np.float32)
    depth[0] = 0.0  # nothing was hit there
    scenes = fitted.fitted_scenes(_fit(seen), _obs(depth), None, None, None, 0.5, 4, 0.001)
    assert len(scenes) == 4
    assert np.array_equal(seen[0], depth)
    for noisy in seen[1:]:
        assert noisy.dtype == depth.dtype
        assert np.all(noisy[0] == 0.0)
        assert not np.array_equal(noisy[1:], depth[1:])
        assert np.abs(noisy[1:] - 0.8).max() < 0.01
    assert not np.array_equal(seen[1], seen[2])


def test_the_same_observation_gives_the_same_fits_and_one_fit_is_the_image_alone(monkeypatch):
    depth = np.random.default_rng(3).uniform(0.5, 1.0, (8, 8)).astype(np.float32)
    first, again = _seen(monkeypatch), []
    fitted.fitted_scenes(_fit(first), _obs(depth), None, None, None, 0.5, 3, 0.002)
    fitted.fitted_scenes(_fit(again), _obs(depth.copy()), None, None, None, 0.5, 3, 0.002)
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    alone: list[np.ndarray] = []
    fitted.fitted_scenes(_fit(alone), _obs(depth), None, None, None, 0.5, 1, 0.002)
    assert len(alone) == 1 and np.array_equal(alone[0], depth)


def test_a_fit_that_gives_no_model_is_left_out(monkeypatch):
    seen = _seen(monkeypatch)
    depth = np.full((4, 4), 0.7, np.float32)
    scenes = fitted.fitted_scenes(
        _fit(seen, fail={0, 2}), _obs(depth), None, None, None, 0.5, 3, 0.001
    )
    assert len(seen) == 3 and len(scenes) == 1


def test_a_share_of_the_fits_is_a_graded_fusion_input_and_one_fit_the_old_one():
    p = np.array([0.5, 0.9, 0.9])
    share = features(p, np.array([0.25, 0.25, 1.0]), np.array([True, False, True]))
    assert share[0, 1:].tolist() == [0.25, 0.75]
    assert share[1, 1:].tolist() == [0.0, 0.0]  # not simulated
    marked = np.array([True, False, True])
    assert np.array_equal(
        features(p, marked, np.bool_(True)), features(p, marked.astype(float), np.bool_(True))
    )


def _two_scenes(monkeypatch, ids: list[list[int]]):
    scenes = [types.SimpleNamespace(spec=types.SimpleNamespace(meta={"ids": i})) for i in ids]
    monkeypatch.setattr(fitted, "make_estimator", lambda *a: lambda obs: None)
    monkeypatch.setattr(fitted, "fitted_scenes", lambda *a: scenes)
    return scenes


def test_the_support_stage_takes_the_share_of_the_fits_that_pulled_the_box(monkeypatch):
    """Two fits: both keep masks 0 and 1, the second mask 2 too. The first fit's pull of box
    0 moves box 1, the second's does not: a share of 1/2; box 2 was pulled in one fit."""
    from clutterbench.sim import labelling
    from clutterbench.sim.config import SimConfig
    from clutterbench.support import box_fusion as bf
    from clutterbench.trials.config import Ch6TrialParams

    _two_scenes(monkeypatch, [[0, 1], [0, 1, 2]])
    outcomes = iter(
        [
            np.array([[np.nan, 0.05], [0.0, np.nan]]),
            np.array([[np.nan, 0.0, 0.0], [0.0, np.nan, 0.0], [0.05, 0.0, np.nan]]),
        ]
    )

    def pull_outcomes(*a):
        disp = next(outcomes)
        n = len(disp)
        return types.SimpleNamespace(
            displacement_m=disp,
            drop_m=np.nan_to_num(disp),
            tilt_deg=np.zeros((n, n)),
            left_shelf=np.zeros((n, n), bool),
        )

    monkeypatch.setattr(labelling, "pull_outcomes", pull_outcomes)
    simulate = bf.fitted_pulls(SimConfig(), Ch6TrialParams(), 0.005, (0.01, 15.0), "various", 20)
    masks = np.zeros((3, 8, 8), bool)
    for j in range(3):
        masks[j, j, j] = True
    share, known = simulate(np.ones((8, 8), np.float32), masks)
    assert known.tolist() == [True, True, True]
    assert share["pull"][0].tolist() == [0.0, 0.5, 0.0]
    assert share["pull"][2].tolist() == [1.0, 0.0, 0.0]
    assert share["pull"][1].tolist() == [0.0, 0.0, 0.0]


def _trials_fitted_pull(monkeypatch, fit_maps: type):
    """The trials' fitted pull on two fits (`_two_scenes`), each fit's maps a `fit_maps`, and
    an observation to ask it of."""
    from clutterbench.sim import pull
    from clutterbench.trials.ch6 import truth_maps
    from clutterbench.trials.ch6.planners import box as planners
    from clutterbench.trials.config import Ch6TrialParams

    monkeypatch.setattr(truth_maps, "TruthCollapseMaps", fit_maps)
    monkeypatch.setattr(pull, "SceneState", types.SimpleNamespace(start=lambda spec: None))
    job = types.SimpleNamespace(
        params=Ch6TrialParams(fit_hypotheses=2),
        stream_cfg=types.SimpleNamespace(catalogue="various"),
        camera=None,
        physics=None,
        collapse_free=None,
    )
    simulate = planners.fitted_pull(job, types.SimpleNamespace(shelf=None), "pull_collapse")
    return simulate, types.SimpleNamespace(depth_m=np.ones((4, 4), np.float32))


def test_the_trials_fitted_pull_takes_the_share_of_the_fits_that_hold_both_boxes(monkeypatch):
    """Fit A keeps boxes 0 and 1, fit B boxes 0, 1 and 2. The unheld pull of 0 marks 1 in A
    only (1/2); the pull of 0 holding 2 is asked of B alone; box 3 is in no fit (None)."""
    scenes = _two_scenes(monkeypatch, [[0, 1], [0, 1, 2]])
    answers = {id(scenes[0].spec): [False, True], id(scenes[1].spec): [False, False, True]}

    class Fit:
        def __init__(self, spec, *args):
            self.answer = np.array(answers[id(spec)])

        def at(self, *args):
            pass

        def moved_by_removing(self, box):
            return self.answer if len(self.answer) == 2 else np.zeros(3, bool)

        def moved_by_held_pull(self, box, hold):
            return self.answer

    simulate, obs = _trials_fitted_pull(monkeypatch, Fit)
    assert simulate(obs, [0, 1, 2, 3], 0).tolist() == [0.0, 0.5, 0.0, 0.0]
    assert simulate(obs, [0, 1, 2, 3], 0, 2).tolist() == [0.0, 0.0, 1.0, 0.0]
    assert simulate(obs, [0, 1, 2, 3], 3) is None


def test_the_trials_fitted_contacts_are_the_share_of_the_fits_holding_both_boxes(monkeypatch):
    """trials.ch6.box_contact learned: fit A keeps boxes 0 and 1, touching; fit B boxes 0, 1
    and 2, 1 touching 2. Boxes 0 and 1 touch in one of the two fits that hold both (1/2),
    1 and 2 in the one fit that holds both; box 3 is in no fit (NaN); the visible ids may
    come in any order."""
    from clutterbench.sim import labelling

    scenes = _two_scenes(monkeypatch, [[0, 1], [0, 1, 2]])
    touching = {id(scenes[0].spec): [(0, 1)], id(scenes[1].spec): [(1, 2)]}

    class Fit:
        def __init__(self, spec, *args):
            self.spec = spec

        def at(self, *args):
            pass

    asked = []

    def settled(spec, physics):
        asked.append(id(spec))
        return touching[id(spec)]

    monkeypatch.setattr(labelling, "settled_contacts", settled)
    simulate, obs = _trials_fitted_pull(monkeypatch, Fit)
    share = simulate.contacts(obs, [0, 1, 2, 3])
    nan = np.nan
    expected = [[0, 0.5, 0, nan], [0.5, 0, 1, nan], [0, 1, 0, nan], [nan, nan, nan, nan]]
    np.testing.assert_array_equal(share, np.array(expected))
    np.testing.assert_array_equal(simulate.contacts(obs, [2, 1]), [[0, 1], [1, 0]])
    assert len(asked) == 2  # each fit settled once per observation


@pytest.mark.parametrize("bad", [{"fit_hypotheses": 0}, {"fit_noise_mm": 0.0}])
def test_the_fits_are_checked_where_the_params_are_read(bad):
    from clutterbench.config import parse
    from clutterbench.errors import ClutterbenchError
    from clutterbench.trials.config import Ch6TrialParams

    with pytest.raises(ClutterbenchError, match=f"trials.ch6.{next(iter(bad))}"):
        parse(Ch6TrialParams, bad, "trials.ch6")
