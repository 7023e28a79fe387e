"""The settled scenes of the boxes fitted to one depth image: the fit (box_fit.py, sizes from
a stream catalogue's nearest type) rebuilt as a valid, settled scene (sim/estimated.py), K such
scenes from the image and noisy copies of it, and the share of them in which two boxes touch.

The physics model a robot can build from what it sees: the physics-from-depth planners
(trials/ch6/) and the support stage's physics-from-depth rows and baseline (support/) simulate
in it, so it stands below both. It reads the observation, never the world's state.
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from clutterbench.errors import ClutterbenchError, PerceptionError
from clutterbench.observation import Observation
from clutterbench.perception.box_fit import BoxEstimate, fit_boxes
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.estimated import EstimatedScene, estimated_scene
from clutterbench.sim.shelf import Shelf


def scene_of(
    est: BoxEstimate, shelf: Shelf, camera: CameraConfig, physics: PhysicsConfig, settle_s: float
) -> EstimatedScene:
    """The estimate as a settled scene (sim/estimated.py, whose repair is total); anything a
    world still refuses is this observation's PerceptionError, never the stage's end."""
    try:
        return estimated_scene(est.sizes_m, est.poses, est.ids, shelf, camera, physics, settle_s)
    except PerceptionError:
        raise
    except ClutterbenchError as exc:
        raise PerceptionError(f"estimated scene: {exc}") from None


def fitted_scenes(
    estimate: Any,
    obs: Observation,
    shelf: Shelf,
    camera: CameraConfig,
    physics: PhysicsConfig,
    settle_s: float,
    hypotheses: int = 1,
    noise_m: float = 0.0,
) -> list[EstimatedScene]:
    """The settled scenes fitted to one observation (`scene_of`): the fit of its depth image,
    then `hypotheses - 1` fits of that image with Gaussian noise of `noise_m` on every pixel
    that saw something, as a depth sensor's error could make them. The noise is seeded by
    the image's bytes: the same observation gives the same scenes, in any process. A fit the
    observation gives no model for (a PerceptionError) is left out, so the list may be
    empty."""
    scenes = []
    seed = zlib.crc32(np.ascontiguousarray(obs.depth_m).tobytes())
    for h in range(hypotheses):
        seen = obs
        if h > 0:
            noise = np.random.default_rng([seed, h]).normal(0.0, noise_m, obs.depth_m.shape)
            depth = np.where(obs.depth_m > 0, obs.depth_m + noise, obs.depth_m)
            seen = dataclasses.replace(obs, depth_m=depth.astype(obs.depth_m.dtype))
        try:
            scenes.append(scene_of(estimate(seen), shelf, camera, physics, settle_s))
        except PerceptionError:
            continue
    return scenes


def contact_share(k: int, fits: Sequence[tuple[Sequence[int], Sequence[tuple[int, int]]]]):
    """(K, K) the share of the fitted scenes in which boxes x and y touch; `fits`: per fitted
    scene, where its boxes are (fitted box a is box at[a]; a negative: none of the K) and its
    touching pairs of fitted boxes (sim.labelling.settled_contacts). NaN where no fit holds
    both boxes."""
    touch, both = np.zeros((k, k)), np.zeros((k, k))
    for at, pairs in fits:
        held = [x for x in at if 0 <= x < k]
        both[np.ix_(held, held)] += 1.0
        for a, b in pairs:
            x, y = at[a], at[b]
            if 0 <= x < k and 0 <= y < k:
                touch[x, y] += 1.0
                touch[y, x] += 1.0
    return np.where(both > 0, touch / np.maximum(both, 1.0), np.nan)


def catalogue_of(stream_catalogue: str) -> np.ndarray:
    from clutterbench.sim.catalog import box_extents_m

    return box_extents_m(stream_catalogue)


def make_estimator(catalogue: str, min_pixels: int):
    extents = catalogue_of(catalogue)
    return lambda obs: fit_boxes(obs, extents, min_pixels)
