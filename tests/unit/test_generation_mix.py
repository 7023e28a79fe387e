"""Family and object count are drawn once per scene index: rejections do not bias the mix."""

from __future__ import annotations

import numpy as np
import pytest

from clutterbench.sim import labelling

WEIGHTS = {"shelved": 1.0, "stacked": 1.0, "random": 3.0}
N_RANGE = (5, 10)
SCENES = 400


class Accepted(Exception):
    def __init__(self, family: str, n: int):
        self.family, self.n = family, n


def test_rejections_do_not_change_the_mix(monkeypatch, physics, camera):
    """`random` placements are rejected 60% of the time (as drops off the front are): the
    realized mix must still be what params ask, within 3 standard errors."""

    def fake_place(family, catalogue, n, rng, physics, shelf):
        if family == "random" and rng.random() < 0.6:
            return None, [], "fell"
        raise Accepted(family, n)

    monkeypatch.setattr(labelling, "place_and_settle", fake_place)
    monkeypatch.setattr(labelling._Tally, "add", lambda self, world: world)
    drawn = []
    for index in range(SCENES):
        with pytest.raises(Accepted) as got:
            labelling.generate_labelled_scene(
                seed=0,
                dataset="mix",
                index=index,
                family_weights=WEIGHTS,
                catalogue="various",
                n_objects=N_RANGE,
                pulls=False,
                physics=physics,
                camera=camera,
                max_attempts=50,
            )
        drawn.append((got.value.family, got.value.n))
    total = sum(WEIGHTS.values())
    for family, w in WEIGHTS.items():
        p = w / total
        share = np.mean([f == family for f, _ in drawn])
        assert abs(share - p) < 3 * np.sqrt(p * (1 - p) / SCENES), (family, share, p)
    counts = np.array([n for _, n in drawn])
    k = N_RANGE[1] - N_RANGE[0] + 1
    sd = np.sqrt((k**2 - 1) / 12)  # discrete uniform
    assert abs(counts.mean() - np.mean(N_RANGE)) < 3 * sd / np.sqrt(SCENES)
    assert set(counts) == set(range(N_RANGE[0], N_RANGE[1] + 1))


def test_setup_is_a_function_of_the_scene_index():
    a = labelling.draw_scene_setup(0, "ch6", 17, WEIGHTS, N_RANGE)
    assert a == labelling.draw_scene_setup(0, "ch6", 17, WEIGHTS, N_RANGE)
    others = {labelling.draw_scene_setup(0, "ch6", i, WEIGHTS, N_RANGE) for i in range(30)}
    assert len(others) > 5


def test_a_family_gets_no_more_boxes_than_it_can_arrange():
    """replenish_stacked arranges 7 boxes at most: a 9-10 box draw is capped, other families
    keep the drawn count."""
    cap = labelling.get_family("replenish_stacked").max_objects
    drawn = [
        labelling.draw_scene_setup(0, "mix", i, {"replenish_stacked": 1.0}, (9, 10))
        for i in range(8)
    ]
    assert {n for _, n in drawn} == {cap}
    free = [labelling.draw_scene_setup(0, "mix", i, {"shelved": 1.0}, (9, 10)) for i in range(8)]
    assert {n for _, n in free} <= {9, 10} and max(n for _, n in free) > cap
