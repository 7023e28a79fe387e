"""Episode jobs: what one trial episode needs, built by each chapter's `*_jobs` function and
run by its episode function (in this process, a worker process or a Ray worker).

A job is a frozen dataclass (so a misspelt field is a TypeError at construction, and a
copy with changes is `dataclasses.replace`); module-level, so it pickles. `EpisodeJob`
holds the fields every chapter's job has, `ShelfJob` those of the shelf chapters' (4, 5,
6), whose episodes start from a settled scene of a stream; each chapter subclasses one next
to its episode code (trials.ch3.games.Ch3Job, trials.ch4.jobs.Ch4Job, trials.ch5.jobs.Ch5Job,
trials.ch6.jobs.Ch6Job; the episodes modules import them). The records copy some fields:
their values are kept exactly as given (no conversion).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from clutterbench.criteria import CollapseFreeConfig
    from clutterbench.data.trial_scenes import StreamStart
    from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
    from clutterbench.trials.config import SceneStreamConfig, TrialsConfig

NAMING_FIELDS = ("condition", "stream", "planner", "index", "seed")
"""The fields that name a job in its repr (where it has them), in this order."""


@dataclass(frozen=True, kw_only=True, repr=False)
class EpisodeJob:
    """One episode of one condition."""

    condition: str
    """The condition's name (records' `condition`; ch. 3: the game's variant)."""
    index: int
    """The episode's index within its condition (ch. 4-6: the stream's scene; ch. 3: the game)."""
    seed: int
    """The base seed its scene and target streams are drawn from."""
    record_images: bool
    """Whether its MCAP log keeps the images."""
    collapse_free: CollapseFreeConfig
    """The collapse-free criterion's thresholds (trials.collapse_free)."""

    def __repr__(self) -> str:
        named = [f"{k}={getattr(self, k)!r}" for k in NAMING_FIELDS if hasattr(self, k)]
        return f"{type(self).__name__}({', '.join(named)})"


@dataclass(frozen=True, kw_only=True, repr=False)
class ShelfJob(EpisodeJob):
    """An episode on a settled shelf scene of a stream (chapters 4, 5 and 6)."""

    stream_cfg: SceneStreamConfig
    """The stream's scene distribution."""
    physics: PhysicsConfig
    """The simulator's physics."""
    camera: CameraConfig
    """The camera the episode observes with."""
    max_attempts: int
    """How many draws a scene may take to settle before the stream gives up."""

    def start_on(self, stream: str) -> StreamStart:
        """The episode's start: scene `index` of the stream named `stream`, as drawn here."""
        from clutterbench.data.trial_scenes import StreamStart

        return StreamStart(
            stream,
            self.stream_cfg,
            self.seed,
            self.index,
            self.physics,
            self.camera,
            self.max_attempts,
        )


def shelf_fields(
    stream: str, trials: TrialsConfig, sim: SimConfig, seed: int, override: dict[str, Any]
) -> dict[str, Any]:
    """The ShelfJob fields a shelf chapter's jobs take from the configs (stream `stream` of
    trials.streams, trials' max_attempts, mcap_images and collapse_free, sim's physics and
    camera), with `override`'s values in place of any it names (a dev stream's `stream_cfg`,
    `record_images=False`, ...)."""
    fields = {
        "seed": seed,
        "physics": sim.physics,
        "camera": sim.camera,
        "max_attempts": trials.max_attempts,
        "record_images": trials.mcap_images,
        "collapse_free": trials.collapse_free,
    }
    if "stream_cfg" not in override:
        fields["stream_cfg"] = trials.streams[stream]
    return fields | override
