"""Where the environments' episodes come from (the ManiSkill tasks' default scene source,
which envs/__init__.py plugs into maniskill/tasks.py, and envs/plan.py): the named streams'
starts drawn exactly as their chapter's trials draw them, so episode i of an environment
starts from the bytes of the table's episode i.

A ch. 6 (or ch. 4) stream's start is scene i drawn and settled (trials/core/streams.py). A
ch. 5 stream's start also depends on the episode's new box: a shelved start with a free place
for it is redrawn (thesis Fig. 5.9; trials/ch5/episodes.py draw_start), so its source draws
as the ch. 5 trials do."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

from clutterbench.sim.config import SimConfig
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import Ch5ConditionConfig
from clutterbench.trials.core.streams import StreamSource
from clutterbench.trials.core.streams import stream_source as shelf_source


@dataclasses.dataclass(frozen=True)
class Ch5StreamSource(StreamSource):
    """A ch. 5 stream: episode i's start as trials_ch5 draws it (with the episode's new box)."""

    cond: Ch5ConditionConfig | None = None
    """A ch. 5 condition on the stream (its start does not depend on the planner)."""

    def spec(self, index: int) -> SceneSpec:
        from clutterbench.trials.ch5.episodes import ch5_jobs, draw_start

        if not isinstance(index, int) or index < 0:
            return super().spec(index)  # its one-line refusal
        sim = SimConfig(physics=self.physics, camera=self.camera)
        cond = dataclasses.replace(self.cond, episodes=index + 1)
        job = ch5_jobs(
            "env",
            cond,
            trials=self.trials,
            sim=sim,
            seed=self.seed,
            prob_threshold=0.5,
            scene_type="env",
        )[index]
        return draw_start(job)[0]


def stream_source(
    stream: str | None = None,
    family: str | Mapping[str, float] | None = None,
    n_objects: tuple[int, int] | int | None = None,
    catalogue: str | None = None,
    scale: str | None = None,
    params_path: Path | None = None,
) -> StreamSource:
    """trials/core/streams.py's stream_source, but a ch. 5 stream's (one a ch. 5 condition
    runs on) draws its starts as the ch. 5 trials do."""
    src = shelf_source(stream, family, n_objects, catalogue, scale, params_path)
    on_it = [c for c in src.trials.ch5_conditions.values() if c.stream == src.name]
    if not on_it:
        return src
    fields = {f.name: getattr(src, f.name) for f in dataclasses.fields(StreamSource)}
    return Ch5StreamSource(**fields, cond=on_it[0])
