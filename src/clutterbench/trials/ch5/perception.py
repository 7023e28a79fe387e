"""What the ch. 5 robot sees (thesis 5.2): arrangement clusters from the detector or from the
generator's ground truth, and the collapse map of a cluster to be moved; the networks are
loaded once per worker process."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from clutterbench.observation import Observation
from clutterbench.perception.boxes import detections_from_clusters
from clutterbench.sim.clusters import scene_clusters
from clutterbench.sim.config import PhysicsConfig
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.pull import SceneState
from clutterbench.sim.spec import SceneSpec

if TYPE_CHECKING:
    from clutterbench.trials.ch5.jobs import Ch5Job

_MODELS: dict[str, Any] = {}


def _cached(key: str, make):
    if key not in _MODELS:
        _MODELS[key] = make()
    return _MODELS[key]


# -- perception ----------------------------------------------------------------------------
def true_clusters(spec: SceneSpec, state: SceneState, physics: PhysicsConfig, obs: Observation):
    """The generator's ground-truth clusters of the present state (sim/clusters.py) as
    detections of score 1."""
    poses = state.poses[: spec.n]
    world = BoxWorld.from_state(spec, poses, state.removed, physics)
    world.step(1)
    contacts = world.contact_pairs()
    groups = spec.meta.get("groups", [])
    _, classes, boxes = scene_clusters(spec.sizes_m, poses, groups, contacts, obs.instance)
    return detections_from_clusters(classes, boxes)


def perceive(
    job: Ch5Job,
    spec: SceneSpec,
    state: SceneState,
    obs: Observation,
    perception: str | None = None,
):
    if (perception or job.cond.perception) == "clusters":
        return true_clusters(spec, state, job.physics, obs)
    from clutterbench.collapse.detector import ArrangementDetector

    detector = _cached(
        str(job.detector_path),
        lambda: ArrangementDetector.from_checkpoint(Path(job.detector_path)),
    )
    return detector.detect(obs.depth_m)


def collapse_map_fn(job: Ch5Job):
    """(obs, target mask) -> collapse probabilities, through the ch. 5 network."""
    from clutterbench.collapse.predict import CollapsePredictor

    path = str(job.model_path)
    predictor = _cached(
        path,
        lambda: CollapsePredictor.from_checkpoint(Path(path), image_size=job.camera.image_size),
    )

    def collapse_map(obs: Observation, mask: np.ndarray) -> np.ndarray:
        return predictor(obs.depth_m, mask[None].astype(np.uint8))[0]

    return collapse_map
