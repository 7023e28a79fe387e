"""Chapter 6 episode jobs on a toy stream, shared by the tests that run real episodes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from clutterbench.planning.ch6.support import SupportParams
from clutterbench.sim.config import CameraConfig, SimConfig
from clutterbench.trials.ch6.episodes import ch6_jobs
from clutterbench.trials.config import ConditionConfig, SceneStreamConfig, TrialsConfig

TOY_SUPPORT = SupportParams("coverage", 0.5, 0.3, 2, 0.0)
"""A support rule for jobs whose planner reads none (or a toy network's maps)."""


def toy_ch6_jobs(
    planner: str,
    stream: SceneStreamConfig,
    camera: CameraConfig,
    *,
    episodes: int = 1,
    model_path: Path | None = None,
    trials: TrialsConfig | None = None,
):
    """`episodes` jobs of condition `c` on stream `s` (= `stream`), seed 0, cp_max 0.3;
    `trials`: the trials params the stream is put into (None: their defaults)."""
    cfg = dataclasses.replace(trials or TrialsConfig(), streams={"s": stream})
    cond = ConditionConfig(planner=planner, stream="s", episodes=episodes)
    return ch6_jobs(
        "c",
        cond,
        trials=cfg,
        sim=SimConfig(camera=camera),
        seed=0,
        support=TOY_SUPPORT,
        cp_max=0.3,
        model_path=model_path,
    )
