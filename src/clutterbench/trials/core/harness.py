"""The trial harness shared by every chapter: episodes in parallel -> records + one MCAP.

A condition is a list of episode jobs and an episode function (a module-level function, so
worker processes can import it). Each worker process keeps one renderer and runs torch on one
thread, so an episode's bits do not depend on how many workers run: the same params and seed
give byte-identical records whatever `trials.workers` is, in worker processes or on Ray
(params.yaml `parallel`, clutterbench.parallel). Results come back in episode order; the
parent writes `records.jsonl` (one JSON record per episode) and `episodes.mcap` (every
episode on one timeline, openable in Foxglove: docs/foxglove.md), both atomically.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from clutterbench.logs.mcap_episode import EpisodeWriter
from clutterbench.observation import CameraModel
from clutterbench.parallel import ParallelConfig, map_in_workers
from clutterbench.trials.core.jobs import EpisodeJob

EPISODE_GAP_S = 1.0
"""Simulated seconds left empty between two episodes on the condition's MCAP timeline."""
EPISODE_TOPIC = "/trial/episode"
DECISION_TOPIC = "/planner/decision"
OUTCOME_TOPIC = "/trial/outcome"


_PREDICTORS: dict[str, Any] = {}


def load_predictor(path: Path, image_size: int, head: str = "deletion"):
    """The collapse predictor answering for head `head` of the network (deletion or pull,
    models.checkpoint.checkpoint_heads), loaded once per worker process; returns
    predict(depth, masks)."""
    from clutterbench.collapse.predict import CollapsePredictor

    key = str(path) if head == "deletion" else f"{path}#{head}"
    if key not in _PREDICTORS:
        _PREDICTORS[key] = CollapsePredictor.from_checkpoint(
            Path(path), image_size=image_size, head=head
        )
    return _PREDICTORS[key]


_BOX_HEADS: dict[str, Any] = {}


def load_box_networks(cp_path: Path, box_path: Path, image_size: int) -> tuple[Any, Any, Any]:
    """(the collapse predictor of `cp_path`, the box head of `box_path`, its meta) for the box
    planners, loaded once per worker process (the box head refused where it read another
    network's maps: collapse/box_head.py load_box_head)."""
    from clutterbench.collapse.box_head import load_box_head

    key = f"{box_path}@{Path(cp_path).parent.name}"
    if key not in _BOX_HEADS:
        _BOX_HEADS[key] = load_box_head(Path(box_path), cp_model=Path(cp_path).parent.name)
    return (load_predictor(cp_path, image_size), *_BOX_HEADS[key])


@dataclasses.dataclass(frozen=True)
class SceneInfo:
    """What the MCAP needs to draw an episode's scene: the boxes, the shelf, the camera."""

    sizes_m: np.ndarray
    """(N, 3) full extents of box k along its own x, y, z (SceneSpec.sizes_m), metres."""
    boards: tuple[tuple[str, np.ndarray, np.ndarray], ...]
    """The shelf's boards: (name, half extents, centre) in the world frame (Shelf.boards())."""
    K: np.ndarray
    """(3, 3) camera intrinsics (pixels)."""
    T_world_from_cam: np.ndarray
    """(4, 4) pose of the OpenCV camera frame in the world (shelf) frame."""
    width: int
    height: int


@dataclasses.dataclass
class EpisodeLog:
    """What an episode shows in the MCAP: events at simulated times (s from its start)."""

    events: list[tuple[float, str, Any]] = dataclasses.field(default_factory=list)
    record_images: bool = True

    def scene(
        self,
        t_s: float,
        sizes_m: np.ndarray,
        boards: Sequence[tuple[str, np.ndarray, np.ndarray]],
        camera: CameraModel,
        image_hw: tuple[int, int],
    ) -> None:
        """The episode's boxes, shelf boards and camera (its images are `image_hw` = (H, W)),
        recorded once at its start: /scene, /camera/calibration and /camera/tf."""
        height, width = (int(v) for v in image_hw)
        info = SceneInfo(
            sizes_m=np.array(sizes_m, dtype=np.float64),
            boards=tuple((str(n), np.array(h, float), np.array(c, float)) for n, h, c in boards),
            K=np.array(camera.K, dtype=np.float64),
            T_world_from_cam=np.array(camera.T_world_from_cam, dtype=np.float64),
            width=width,
            height=height,
        )
        self.events.append((t_s, "scene", info))

    def observation(self, t_s: float, depth_m: np.ndarray, instance: np.ndarray) -> None:
        if self.record_images:
            self.events.append((t_s, "depth", depth_m))
            self.events.append((t_s, "instance", instance))

    def heatmap(self, t_s: float, topic: str, probs: np.ndarray) -> None:
        """A (H, W) probability map in [0, 1] (a collapse map), written as mono8 on `topic`."""
        if self.record_images:
            image = np.clip(np.round(np.asarray(probs, dtype=np.float64) * 255), 0, 255)
            self.events.append((t_s, "heatmap", (topic, image.astype(np.uint8))))

    def poses(self, t_s: float, poses: np.ndarray, removed: Iterable[int] | None = None) -> None:
        """Every box's pose [x, y, z, qw, qx, qy, qz]; `removed`: the boxes taken out so far
        (the MCAP takes them off /scene)."""
        self.events.append((t_s, "poses", np.asarray(poses, dtype=np.float64)))
        if removed is not None:
            self.events.append((t_s, "removed", tuple(sorted(int(k) for k in removed))))

    def json(self, t_s: float, topic: str, payload: dict[str, Any]) -> None:
        self.events.append((t_s, topic, payload))

    @property
    def duration_s(self) -> float:
        return max((t for t, _, _ in self.events), default=0.0)


@dataclasses.dataclass
class EpisodeResult:
    record: dict[str, Any]
    """The episode's JSON record (plain JSON types only)."""
    log: EpisodeLog
    wall_s: float | None = None
    """Wall-clock seconds the episode took (the machine's, never written to an output)."""


J = TypeVar("J", bound=EpisodeJob)
"""An episode job type (trials.core.jobs)."""


def run_episodes(
    label: str,
    fn: Callable[[J], EpisodeResult],
    jobs: Sequence[J],
    workers: int,
    parallel: ParallelConfig | None = None,
) -> list[EpisodeResult]:
    """Run `fn` on every job (in worker processes when workers > 1, or on Ray: `parallel`,
    params.yaml's section; None: processes), results in job order."""
    return map_in_workers(label, fn, jobs, workers, parallel)


def write_condition(
    name: str,
    results: Sequence[EpisodeResult],
    about: dict[str, Any],
    reports: Path,
    data: Path,
) -> dict[str, Any]:
    """Condition `name`'s episodes among `results` -> reports/<name>/records.jsonl and
    summary.json (`about` and the aggregate row), data/<name>/episodes.mcap (`about` but its
    `support` as metadata); returns the summary."""
    from clutterbench.io import write_json
    from clutterbench.trials.core.records import write_records
    from clutterbench.trials.core.stats import aggregate

    mine = [r for r in results if r.record["condition"] == name]
    records = [r.record for r in mine]
    write_records(reports / name / "records.jsonl", records)
    write_mcap(
        data / name / "episodes.mcap",
        mine,
        {k: str(v) for k, v in about.items() if k != "support"},
    )
    row = aggregate(records).iloc[0].to_dict()
    summary = about | {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}
    write_json(reports / name / "summary.json", summary)
    return summary


def write_mcap(path: Path, results: Sequence[EpisodeResult], metadata: dict[str, str]) -> None:
    """Every episode on one timeline: episode k starts after episode k-1 ended plus a gap.
    /trial/episode marks each start (its record's header), /trial/outcome each end. An
    episode's scene (boxes and shelf on /scene) replaces the previous one's; the camera
    (/camera/calibration, /camera/tf) is written with it and beside every depth image; a box
    taken out leaves /scene."""
    t0 = 0.0
    with EpisodeWriter(path, metadata) as ep:
        for res in results:
            head = {k: v for k, v in res.record.items() if not isinstance(v, list | dict)}
            ep.write_json(t0, EPISODE_TOPIC, head)
            scene: SceneInfo | None = None
            camera_at: float | None = None
            gone: set[int] = set()
            for t_s, kind, payload in res.log.events:
                t = t0 + t_s
                if kind == "scene":
                    scene, gone = payload, set()
                    ep.write_scene(t, payload.sizes_m, payload.boards)
                    _write_camera(ep, t, payload)
                    camera_at = t
                elif kind == "depth":
                    if scene is not None and camera_at != t:
                        _write_camera(ep, t, scene)
                        camera_at = t
                    ep.write_depth(t, payload)
                elif kind == "instance":
                    ep.write_instance(t, payload)
                elif kind == "heatmap":
                    ep.write_mono8(t, payload[0], payload[1])
                elif kind == "poses":
                    ep.write_poses(t, [f"box_{k}" for k in range(len(payload))], payload)
                elif kind == "removed":
                    new = sorted(set(payload) - gone)
                    if scene is not None and new:
                        ep.delete_scene_entities(t, [f"box_{k}" for k in new])
                    gone |= set(new)
                else:
                    ep.write_json(t, kind, payload)
            end = t0 + res.log.duration_s
            ep.write_json(end, OUTCOME_TOPIC, head)
            t0 = end + EPISODE_GAP_S
        ep.set_outcome({"episodes": len(results)})


def _write_camera(ep: EpisodeWriter, t_s: float, scene: SceneInfo) -> None:
    ep.write_camera(t_s, scene.K, scene.T_world_from_cam, scene.width, scene.height)
