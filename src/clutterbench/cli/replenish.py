"""`clutterbench replenish`: the ch. 5 replenishment planner on one scene spec, optionally
executed and logged."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from clutterbench.cli.common import (
    app,
    check_out_file,
    default_path,
    physics_config,
    project_params,
    require_file,
    user_errors,
    warn_if_not_at_rest,
)
from clutterbench.errors import ClutterbenchError

if TYPE_CHECKING:
    from clutterbench.sim.config import PhysicsConfig
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.ch5.jobs import Ch5Job
    from clutterbench.trials.config import TrialsConfig


@app.command("replenish")
def replenish(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to fill.")],
    box: Annotated[
        str, typer.Option("--box", metavar="W,D,H", help="New box: width, depth, height in mm.")
    ],
    execute: Annotated[
        bool, typer.Option("--execute", help="Run the plan in simulation and judge it.")
    ] = False,
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            help="replenish (with collapse prediction) | no_collapse | contact | random | oracle",
        ),
    ] = "replenish",
    perception: Annotated[
        str,
        typer.Option(
            "--perception",
            help="clusters (the generator's ground truth) | detector (models/detector)",
        ),
    ] = "clusters",
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Collapse map network (default: models/cmn_bs32/best.pt)."),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="With --execute: write the episode as MCAP.")
    ] = None,
) -> None:
    """Plan the replenishment of one scene with a box of known size (thesis 5.2.3): print the
    clusters, the candidates, the branch taken and its move as JSON; --execute runs it and
    prints the judged outcome."""
    with user_errors():
        import numpy as np

        import clutterbench.trials.ch5.episodes as ch5
        import clutterbench.trials.ch5.perception as ch5_perception
        from clutterbench.config import load_section
        from clutterbench.planning.ch5.replenish import ReplenishPlanner
        from clutterbench.sim.physics import BoxWorld
        from clutterbench.sim.pull import SceneState
        from clutterbench.sim.render import observe
        from clutterbench.sim.spec import SceneSpec
        from clutterbench.trials.config import TrialsConfig
        from clutterbench.trials.core.harness import write_mcap

        w, d, h = _box_m(box)
        _check_options(planner, perception, mcap)
        size_m = np.array([d, w, h])
        spec = SceneSpec.load(spec_path)
        physics = physics_config()
        warn_if_not_at_rest(spec, spec_path, physics)
        params = project_params()
        trials = (
            load_section(TrialsConfig, "trials", params) if "trials" in params else TrialsConfig()
        )
        job = _cli_job(trials, planner, perception, model, physics, spec, mcap)
        state = SceneState.start(spec)
        obs = observe(BoxWorld.from_spec(spec, physics, render=True), spec.camera)
        dets = ch5_perception.perceive(job, spec, state, obs)
        out: dict[str, Any] = {"box_mm": [w * 1000, d * 1000, h * 1000], "planner": planner}
        if planner in ch5.PLANNERS:
            cmap = ch5_perception.collapse_map_fn(job) if planner in ch5.COLLAPSE_PLANNERS else None
            plan = ReplenishPlanner(ch5.planner_params(job), ch5.space_of(spec), cmap).plan(
                obs, dets, size_m
            )
            out["plan"] = ch5.plan_json(plan) | {"clusters": plan.info["clusters"]}
        if execute:
            result = ch5.replenish(spec, job, size_m)
            if mcap is not None:
                write_mcap(mcap, [result], {"spec": spec_path.name, "planner": planner})
            rec = result.record
            out["execute"] = {
                k: rec[k]
                for k in ("success", "end", "branch", "n_disturbed", "disturbance_m", "steps")
            }
        typer.echo(json.dumps(out))


def _box_m(box: str) -> tuple[float, float, float]:
    """--box W,D,H in mm -> (w, d, h) in m, each positive."""
    try:
        w, d, h = (float(v) / 1000.0 for v in box.split(","))
    except ValueError:
        raise ClutterbenchError(f"--box {box}: expected W,D,H in mm, e.g. 100,120,30") from None
    if min(w, d, h) <= 0:
        raise ClutterbenchError(f"--box {box}: sizes must be positive")
    return w, d, h


def _check_options(planner: str, perception: str, mcap: Path | None) -> None:
    """--planner a ch. 5 planner, --perception clusters or detector, --mcap a writable file."""
    from clutterbench.trials.config import CH5_PLANNERS

    if planner not in CH5_PLANNERS:
        raise ClutterbenchError(f"--planner {planner}: not one of {', '.join(CH5_PLANNERS)}")
    if perception not in ("clusters", "detector"):
        raise ClutterbenchError(f"--perception {perception}: not clusters or detector")
    if mcap is not None:
        check_out_file(mcap, "--mcap", "episode.mcap")


def _cli_job(
    trials: TrialsConfig,
    planner: str,
    perception: str,
    model: Path | None,
    physics: PhysicsConfig,
    spec: SceneSpec,
    mcap: Path | None,
) -> Ch5Job:
    """The episode job of the command line: its networks checked for, the collapse threshold
    of trials.ch5 (else the evaluate stage's choice, else 0.5)."""
    import clutterbench.trials.ch5.episodes as ch5
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.config import Ch5ConditionConfig, SceneStreamConfig

    model_path = default_path(model, f"models/{trials.ch5.model}/best.pt")
    if planner in ch5.COLLAPSE_PLANNERS:
        require_file(model_path, "--model", f"`dvc repro train@{trials.ch5.model}` makes it")
    detector = default_path(None, "models/detector/best.pt")
    if perception == "detector":
        require_file(detector, "detector", "`dvc repro detector` makes it")
    prob = trials.ch5.prob_threshold
    if prob is None:
        metrics = default_path(None, f"reports/evaluate/{trials.ch5.model}_ch5/metrics.json")
        prob = (
            float(json.loads(metrics.read_text())["val_chosen_threshold"])
            if metrics.exists()
            else 0.5
        )
    cond = Ch5ConditionConfig(planner=planner, stream="cli", perception=perception)
    job = ch5.ch5_jobs(
        "cli",
        cond,
        trials=trials,
        sim=SimConfig(physics=physics, camera=spec.camera),
        seed=0,
        prob_threshold=prob,
        scene_type="cli",
        stream_cfg=SceneStreamConfig(families={"shelved": 1.0}),
        record_images=mcap is not None,
    )[0]
    return dataclasses.replace(job, model_path=model_path, detector_path=detector)
