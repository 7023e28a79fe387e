"""The perturbed worlds of the task-noise replays and their summary (trials/noise)."""

from __future__ import annotations

import numpy as np

from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.noise.config import NoiseConfig
from clutterbench.trials.noise.draws import REPLAY, SEARCH, Draw, draw
from clutterbench.trials.noise.replay import survival

CFG = NoiseConfig()
BASE = PhysicsConfig()


def _spec(n: int = 4) -> SceneSpec:
    sizes = np.full((n, 3), 0.05)
    poses = np.array([[0.1, 0.06 * k, 0.025, 1.0, 0.0, 0.0, 0.0] for k in range(n)])
    return SceneSpec(sizes_m=sizes, poses=poses)


def test_the_tables_world_is_the_tables_bit_for_bit():
    spec, none = _spec(), Draw.none(4)
    assert none.physics(BASE) == BASE
    assert [none.spec(spec, BASE).density(k, 1.0) for k in range(4)] == [BASE.density_kg_m3] * 4
    state = SceneState(np.asarray(spec.poses), frozenset({1}))
    assert none.start(state, 3) is state


def test_draws_are_seeded_by_stream_episode_draw_and_kind_and_stay_in_their_bounds():
    a = draw(CFG, 0, "ch6_3_10", 5, 0, 4, REPLAY)
    assert np.array_equal(a.mass, draw(CFG, 0, "ch6_3_10", 5, 0, 4, REPLAY).mass)
    for other in (
        draw(CFG, 0, "ch6_3_10", 5, 1, 4, REPLAY),
        draw(CFG, 0, "ch6_3_10", 6, 0, 4, REPLAY),
        draw(CFG, 0, "ch6_10", 5, 0, 4, REPLAY),
        draw(CFG, 0, "ch6_3_10", 5, 0, 4, SEARCH),
        draw(CFG, 1, "ch6_3_10", 5, 0, 4, REPLAY),
    ):
        assert not np.array_equal(a.mass, other.mass)
    for k in range(50):
        d = draw(CFG, 0, "s", k, 0, 4, REPLAY)
        p = d.physics(BASE)
        assert abs(p.static_friction / BASE.static_friction - 1) <= CFG.friction_rel
        assert np.isclose(
            p.dynamic_friction / BASE.dynamic_friction, p.static_friction / BASE.static_friction
        )
        assert abs(p.pull_speed_m_s / BASE.pull_speed_m_s - 1) <= CFG.pull_speed_rel
        assert np.all(np.abs(d.mass - 1) <= CFG.mass_rel)


def test_a_steps_start_is_jittered_within_bounds_never_down_and_not_where_removed():
    spec = _spec()
    d = draw(CFG, 0, "s", 0, 0, 4, REPLAY)
    state = SceneState(np.asarray(spec.poses, dtype=float), frozenset({2}))
    moved = d.start(state, 0).poses - state.poses
    assert np.all(np.abs(moved[:, :2]) <= CFG.jitter_m)
    assert np.all(moved[:, 2] >= 0) and np.all(moved[:, 2] <= CFG.jitter_m)
    assert np.all(moved[2] == 0) and np.all(moved[:, 3:] == 0)
    assert np.any(moved[[0, 1, 3], :3] != 0)
    assert np.array_equal(d.start(state, 0).poses, d.start(state, 0).poses)
    assert not np.array_equal(d.start(state, 0).poses, d.start(state, 1).poses)


def test_survival_counts_each_draw_and_the_tables_successes_kept():
    nominal = [True, True, False]
    draws = [[True, False], [True, True], [False, True]]
    s = survival(nominal, draws)
    assert s["draw_k"] == [2, 2] and s["nominal_k"] == 2 and s["n"] == 3
    assert s["mean_rate"] == 2 / 3 and s["sd_rate"] == 0.0
    assert s["survive"] == 3 / 4  # of the 2 x 2 (success, draw) pairs, 3 succeed
    assert s["all_draws_k"] == 1
