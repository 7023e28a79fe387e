"""Chapter 6 episode jobs on a toy stream, shared by the tests that run real episodes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from clutterbench.planning.ch6.support import SupportParams
from clutterbench.sim.config import CameraConfig, SimConfig
from clutterbench.trials.ch6.episodes import ch6_jobs
from clutterbench.trials.ch6.planners import planner_info
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


@dataclasses.dataclass(frozen=True)
class ToyNetworks:
    """Untrained checkpoints of every network a ch. 6 planner may read (tests/conftest.py)."""

    cp: Path
    """A collapse predictor with one deletion head."""
    cp_heads: Path
    """... with a deletion and a pull head."""
    cp_three_heads: Path
    """... with a deletion, a pull and a pull_collapse head (the box head's)."""
    box_head: Path
    """A box head over cp_three_heads' maps."""
    ch4: Path
    """A ch. 4 network (single_step)."""


def toy_planner_jobs(
    planner: str,
    stream: SceneStreamConfig,
    camera: CameraConfig,
    networks: ToyNetworks,
    *,
    episodes: int = 1,
):
    """`episodes` jobs of `planner` on the toy stream with the untrained networks it reads:
    the pull head's CP for a planner of the pull, the box head over the three-head CP (with a
    toy edge threshold, cp_max and, fused with physics, a toy fusion) for the box planners."""
    maps = planner_info(planner).maps
    cp = networks.cp_heads if maps == "pull" else networks.cp
    box = {}
    if maps in ("box", "box_physics"):  # the box head over a three-head CP's maps
        cp = networks.cp_three_heads
        box = {"box_head_path": networks.box_head, "box_edge_threshold": 0.5, "cp_max": 0.5}
        if maps == "box_physics":  # the fusion: the head's logit and the simulation
            box["box_fusion"] = (1.0, 2.0, -2.0, 0.0)
    jobs = toy_ch6_jobs("random", stream, camera, episodes=episodes, model_path=cp)
    return [
        dataclasses.replace(j, planner=planner, ch4_model_path=networks.ch4, **box) for j in jobs
    ]
