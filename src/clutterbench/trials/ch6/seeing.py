"""What a ch. 6 planner sees of the world: every picture through the condition's sensor
(`sensing`, sim/sensor.py), and its object masks (`perception`): the simulator's instance image,
or segments of the sensed depth named by the box a grasp of them takes (perception/seen.py).

The harness holds the world; this is the one place its pictures become what the planner reads,
and where what the planner chose becomes the box the robot's grasp takes."""

from __future__ import annotations

from typing import Any

from clutterbench.observation import Observation
from clutterbench.perception.depth_segmentation import shelf_roi
from clutterbench.perception.seen import SeenSegments, pointed_segment, see_segments
from clutterbench.sim.physics import BoxWorld
from clutterbench.sim.render import observe
from clutterbench.sim.spec import SceneSpec

PERCEPTIONS = ("instance", "depth")
"""The object masks a ch. 6 planner may get: the simulator's, or segments of the depth image."""


class Eyes:
    """The pictures of one episode as its planner gets them."""

    def __init__(self, job: Any, spec: SceneSpec):
        self.camera, self.sensing, self.perception = job.camera, job.sensing, job.perception
        assert self.perception in PERCEPTIONS, f"unknown perception {self.perception!r}"
        self.roi, self.n_boxes, self.min_pixels = (
            shelf_roi(spec.shelf),
            spec.n,
            job.params.min_pixels,
        )
        self.truth: Observation | None = None
        """The last picture with the simulator's instance image (the harness', never the
        planner's)."""
        self.seen: SeenSegments | None = None
        """The last picture's segments (depth perception), None otherwise."""
        self.failures = 0
        """Pictures whose depth image defeated the segmentation (no segments)."""
        self.unpointed = 0
        """Decisions at which no segment covered any of the target's visible pixels."""

    def look(self, world: BoxWorld) -> Observation:
        """The picture the planner gets of `world` now."""
        self.truth = observe(world, self.camera, self.sensing)
        if self.perception == "instance":
            return self.truth
        self.seen = see_segments(self.truth, self.roi, self.n_boxes, self.min_pixels)
        self.failures += self.seen.failure is not None
        return self.seen.obs

    def pointed(self, box: int) -> int:
        """The id under which the planner is told to extract `box` (pointed at by its true
        visible mask in the last picture; the box's own id where no segment covers it)."""
        if self.seen is None or self.truth is None:
            return box
        seen_id = pointed_segment(self.seen, self.truth.instance == box + 1)
        if seen_id is None:
            self.unpointed += 1
            return box
        return seen_id

    def grasped(self, seen_id: int | None) -> int | None:
        """The box a grasp of what the planner calls `seen_id` takes in the last decision's
        picture (None: nothing, or no id)."""
        if seen_id is None or self.seen is None:
            return seen_id
        return self.seen.box_of(seen_id)

    def record_fields(self) -> dict[str, Any]:
        """The episode record's perception fields (instance masks: none beyond `perception`)."""
        if self.perception == "instance":
            return {}
        return {"perception_failures": self.failures, "target_unpointed": self.unpointed}
