"""The leaderboard's baseline predictors (stage leaderboard), each a scorecard PredictFn: a
constant 1/2 (no information), the truth of deleting the box (the thesis' labels, asked what
pulling does), the collapse predictor's heads read per box, the box head, and the pull's own
truth (the ceiling)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from clutterbench.collapse.box_head import OUTPUTS
from clutterbench.collapse.box_predict import BoxMaps
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.data.testset_load import labels, visible
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.sim.config import CameraConfig
from clutterbench.support.scorecard import PredictFn


def constant(_depth, masks, _cam, _i) -> np.ndarray:
    return np.full(len(masks), 0.5)


def truth_of(ts: dict, kind: str) -> PredictFn:
    """The labels of `kind` as a predictor (scene found by its depth image)."""
    lab = labels(ts, kind)
    scene_of = {ts["depth_m"][s].astype(np.float32).tobytes(): s for s in range(len(lab))}

    def predict(depth, masks, _cam, i):
        s = scene_of[depth.tobytes()]
        ids = visible(ts, s)
        return lab[s, ids[i], ids].astype(np.float64)

    return predict


def cp_head(model: Path, image_size: int, head: str) -> PredictFn:
    """The collapse predictor's `head` map of pulling the box (read per box by the scorer)."""
    predictor = CollapsePredictor.from_checkpoint(model, image_size=image_size, head=head)

    def predict(depth, masks, _cam, i):
        return predictor(depth, masks[i : i + 1].astype(np.uint8))[0]

    return predict


def box_head(model: Path, box: Path, camera: CameraConfig) -> PredictFn:
    """The box head's probability that pulling the box collapses each other one."""
    maps = BoxMaps.from_paths(model, box, camera, "pull_collapse", 0.5)
    out = OUTPUTS.index("pull_collapse")

    def predict(depth, masks, _cam, i):
        return maps.probs(depth, masks)[i, :, out].astype(np.float64)

    return predict


def baselines(
    ts: dict, model: Path, box: Path, camera: CameraConfig
) -> dict[str, tuple[Callable[[], PredictFn], str]]:
    """name -> (a factory of its PredictFn, what it is)."""
    heads = checkpoint_heads(load_checkpoint(model))
    out: dict[str, tuple[Callable[[], PredictFn], str]] = {
        "constant": (lambda: constant, "1/2 for every box: no information"),
        "deletion_truth": (
            lambda: truth_of(ts, "deletion_moved"),
            "physics truth of deleting the box (the thesis' labels), asked what pulling does",
        ),
    }
    for h in heads:
        out[f"cp_{h}"] = (
            lambda h=h: cp_head(model, camera.image_size, h),
            f"the collapse predictor's {h} head, its mean over each box",
        )
    out["box_head"] = (
        lambda: box_head(model, box, camera),
        "the box head (per box, over the collapse predictor's maps)",
    )
    out["pull_truth"] = (
        lambda: truth_of(ts, "pull_collapse"),
        "physics truth of what the pull collapses: the ceiling",
    )
    return out
