"""Named scene streams as the environments draw them: episode i of a stream is the pipeline's
scene i of that stream (the same seed stream, generator and canonical settled start) and its
target (the target stream of data/trial_scenes.py), read from the project's params.yaml.

    source = stream_source("ch6_3_10")            # a stream of trials.streams
    source = stream_source(family="stacked", n_objects=(3, 5), catalogue="various")
    spec, target = source.episode(17)

A stream named by its family, box count and catalogue (no `trials.streams` entry) gets a
seed stream of its own, keyed by that description, so it never repeats a table stream's
scenes."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from clutterbench.config import (
    BaseConfig,
    load_base,
    load_params,
    load_section,
    project_params_path,
)
from clutterbench.errors import ClutterbenchError
from clutterbench.sim.config import CameraConfig, PhysicsConfig, SimConfig
from clutterbench.sim.spec import SceneSpec
from clutterbench.trials.config import SceneStreamConfig, TrialsConfig

if TYPE_CHECKING:
    from clutterbench.data.trial_scenes import StreamStart

DEFAULT_STREAM = "ch6_3_10"
"""The environments' default: Table 6.3's 3-10 box mix."""


@dataclasses.dataclass(frozen=True)
class StreamSource:
    """Where an environment's episodes come from, with every setting the pipeline draws
    them with."""

    name: str
    """The seed stream's name (trials/<name>)."""
    cfg: SceneStreamConfig
    seed: int
    """base.seed of the project."""
    scale: str
    physics: PhysicsConfig
    camera: CameraConfig
    trials: TrialsConfig

    def start(self, index: int) -> StreamStart:
        """Episode `index`'s start on the stream (its scene's and its target's draws)."""
        from clutterbench.data.trial_scenes import StreamStart

        return StreamStart(
            self.name,
            self.cfg,
            self.seed,
            index,
            self.physics,
            self.camera,
            self.trials.max_attempts,
        )

    def spec(self, index: int) -> SceneSpec:
        """Scene `index` of the stream, settled: its canonical start (cached per process)."""
        if not isinstance(index, int) or index < 0:
            raise ClutterbenchError(f"episode {index!r}: an episode index is an integer >= 0")
        key = (self.name, repr(self.cfg), self.seed, self.physics, self.camera, index)
        if key not in _SPECS:
            if len(_SPECS) > 256:
                _SPECS.clear()
            _SPECS[key] = self.start(index).spec()
        return _SPECS[key]

    def episode(self, index: int) -> tuple[SceneSpec, int]:
        """Scene `index` of the stream and its target (the trials' target stream, drawn from
        the canonical start's observation)."""
        from clutterbench.sim.pull import SceneState, world_at
        from clutterbench.sim.render import observe

        spec = self.spec(index)  # the episode's canonical start, as trials.ch6.Extraction's
        obs = observe(world_at(spec, SceneState.start(spec), self.physics, True), self.camera)
        target = self.start(index).target(obs, self.trials.ch6.min_target_pixels, spec)
        return spec, target


_SPECS: dict[Any, SceneSpec] = {}


def stream_source(
    stream: str | None = None,
    family: str | Mapping[str, float] | None = None,
    n_objects: tuple[int, int] | int | None = None,
    catalogue: str | None = None,
    scale: str | None = None,
    params_path: Path | None = None,
) -> StreamSource:
    """The stream `stream` of trials.streams (default ch6_3_10), or, with `family` (a name or
    {family: weight}), `n_objects` ((lo, hi) or one count) and `catalogue`, a stream of those
    scenes; `scale`: the params' scale profile (default base.scale)."""
    params = load_params(params_path or project_params_path())
    if scale is not None:
        params = {**params, "base": {**dict(params.get("base") or {}), "scale": scale}}
    base: BaseConfig = load_base(params)
    trials = load_section(TrialsConfig, "trials", params)
    sim = load_section(SimConfig, "sim", params)
    custom = family is not None or n_objects is not None or catalogue is not None
    if stream is not None and custom:
        raise ClutterbenchError(
            "stream: give a stream name or family/n_objects/catalogue, not both"
        )
    if not custom:
        name = stream or DEFAULT_STREAM
        if name not in trials.streams:
            raise ClutterbenchError(
                f"stream '{name}': not in trials.streams (known: {', '.join(trials.streams)})"
            )
        cfg = trials.streams[name]
    else:
        default = trials.streams.get(DEFAULT_STREAM) or SceneStreamConfig()
        families = {family: 1.0} if isinstance(family, str) else dict(family or default.families)
        if isinstance(n_objects, int):
            n_objects = (n_objects, n_objects)
        lo_hi = tuple(int(v) for v in (n_objects or default.n_objects))
        try:
            cfg = SceneStreamConfig(
                families=families, n_objects=lo_hi, catalogue=catalogue or default.catalogue
            )
        except (ValueError, TypeError) as exc:
            raise ClutterbenchError(f"stream: {exc}") from None
        mix = "+".join(f"{f}:{w:g}" for f, w in sorted(cfg.families.items()))
        name = f"env/{mix}/{cfg.n_objects[0]}-{cfg.n_objects[1]}/{cfg.catalogue}"
    return StreamSource(name, cfg, base.seed, base.scale, sim.physics, sim.camera, trials)
