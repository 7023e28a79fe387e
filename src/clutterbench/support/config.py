"""Params of the support-graph evaluation (the `support` section of params.yaml, Table 6.2).

Imports no SAPIEN and no torch, so that the report stage can read them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

from clutterbench.config import bounded, cores_field
from clutterbench.data.trial_params import SceneStreamConfig
from clutterbench.sim.noise import TrainSensingConfig


@dataclasses.dataclass(frozen=True)
class BoxHeadConfig:
    """The per-box head (collapse/box_head.py): trained on the support model's maps of the val
    dataset's train split, its epoch and thresholds chosen on that dataset's val split, scored
    on test_dataset."""

    test_dataset: str = "ch6_test"
    """Dataset whose every scene scores it (reports/box_head/metrics.json)."""
    train_scenes: int = bounded(2000, ge=1)
    """At most this many scenes of the train split (the first ones) give training pairs."""
    val_scenes: int = bounded(300, ge=1)
    """At most this many scenes of the val split choose the epoch and the thresholds."""
    hidden: int = bounded(64, ge=1)
    """Width of its two hidden layers."""
    epochs: int = bounded(60, ge=1)
    """Passes over the training pairs; the epoch of least val loss is kept."""
    batch_size: int = bounded(256, ge=1)
    lr: float = bounded(0.001, gt=0.0)
    sensing: TrainSensingConfig = TrainSensingConfig()
    """The sensor whose depth it trains on ({preset, spread}; ideal: the exact depth): with a
    preset, every train scene's depth passes through that sensor, its noise randomised by the
    spread, and its val and test scenes' through the preset itself, so its epoch and outcome
    thresholds are chosen, and its scores taken, as that sensor returns the depth."""
    sensed_masks: Literal["instance", "depth", "both"] = "instance"
    """The object masks of a head trained on a sensor (stage box_head_sensed): the simulator's
    (as Table 6.2's sensed rows read theirs), region growing on the sensed depth, each segment
    named by the box its grasp takes (as the trials' rows of `perception: depth` see theirs;
    support/evaluate.py segmented_scene), or both (each scene once with each), in its train,
    val and test scenes alike. The exact-depth head (stage box_head) keeps the simulator's."""


@dataclasses.dataclass(frozen=True)
class SupportEvalConfig:
    """Table 6.2: support relations inferred from one depth image against physics."""

    model: str = "cp_focal"
    """Collapse predictor (a key of train.models): models/<model>/best.pt."""
    val_dataset: str = "ch6"
    """Dataset whose val split chooses every threshold (never the test scenes)."""
    val_scenes: int = bounded(150, ge=1)
    """At most this many val scenes are swept (the first ones of the split)."""
    test: SceneStreamConfig = dataclasses.field(
        default_factory=lambda: SceneStreamConfig(families={"random": 1.0})
    )
    """Test scenes: their own seed stream, family mix and box counts."""
    test_scenes: int = bounded(200, ge=1)
    """Number of test scenes (thesis: 15 real scenes)."""
    moved_threshold_m: float = bounded(0.005, gt=0.0)
    """SUPP(X, Y) needs Y to move more than this when X is removed (thesis 6.2.1: 5 mm)."""
    min_pixels: int = bounded(20, ge=1)
    """A box is an object of the scene when at least this many pixels of it are visible."""
    prob_thresholds: tuple[float, ...] = (0.3, 0.4, 0.5)
    """Swept: R_C is where the heatmap exceeds this."""
    score_thresholds: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5)
    """Swept: an edge when the rule's score exceeds this."""
    bbox_margins_px: tuple[int, ...] = (2, 4)
    """Swept: each object's bounding box is grown by this many pixels (pseudo-direct contact)."""
    adjacency_ious: tuple[float, ...] = (0.0, 0.05)
    """Swept: grown boxes in pseudo-direct contact when their IoU exceeds this."""
    max_gaps_m: tuple[float | None, ...] = (None,)
    """Swept: ... and when their closest visible surface points (back-projected depth) are
    nearer than this; null: no such test (the thesis' rule alone)."""
    figure_scenes: int = bounded(6, ge=1)
    """Test scenes drawn in the figure (thesis Fig. 6.8: six)."""
    workers: int = cores_field(2)
    """Worker processes simulating the test scenes' truth; auto: base.cores."""
    max_attempts: int = bounded(30, ge=1)
    """A test scene is redrawn at most this often."""
    box_head: BoxHeadConfig = dataclasses.field(default_factory=BoxHeadConfig)
    """The per-box head over the support model's maps (stage box_head)."""
    sensing: tuple[Literal["structured_light", "d415"], ...] = ()
    """Depth sensors (sim/sensor.py) under which every method is scored again on the same
    test scenes, their depth images sensed (the masks stay the simulator's): Table 6.2's
    method@<sensor> rows, each sensor with the thresholds and fusion chosen on the val scenes'
    depth as it returns them (Table 6.3's sensed rows under it read the same choice)."""


SENSED_BOX_HEADS = Path("models/box_head_sensed")
"""Stage box_head_sensed: one box head per sensor of support.sensing, <sensor>/best.pt."""
SENSED_BOX_REPORTS = Path("reports/box_head_sensed")
"""Its reports: <sensor>/metrics.json (the outcome thresholds it chose), scores, log."""


def box_head_files(sensing: str) -> tuple[Path, Path]:
    """(checkpoint, metrics.json) of the box head that reads depth as `sensing` returns it:
    stage box_head's for ideal, stage box_head_sensed's, trained on that sensor's depth, for
    a sensor of support.sensing."""
    if sensing == "ideal":
        return Path("models/box_head/best.pt"), Path("reports/box_head/metrics.json")
    return SENSED_BOX_HEADS / sensing / "best.pt", SENSED_BOX_REPORTS / sensing / "metrics.json"
