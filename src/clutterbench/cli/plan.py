"""`clutterbench plan`: the ch. 6 planners on one scene spec (thesis Algorithm 1), optionally
executed and logged."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from clutterbench.cli.common import (
    app,
    check_indices,
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
    from clutterbench.observation import Observation
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.sim.config import PhysicsConfig
    from clutterbench.sim.spec import SceneSpec
    from clutterbench.trials.config import TrialsConfig


@app.command("plan")
def plan(
    spec_path: Annotated[Path, typer.Argument(metavar="SPEC.json", help="Scene spec to plan on.")],
    target: Annotated[int, typer.Option("--target", metavar="K", help="Box to extract.")],
    execute: Annotated[
        bool, typer.Option("--execute", help="Run the plan in simulation and judge it.")
    ] = False,
    planner: Annotated[
        str,
        typer.Option(
            "--planner",
            help="multi_step | bimanual | single_step | pull_target | oracle | oracle_hold | "
            "random (only multi_step and bimanual need the collapse predictor)",
        ),
    ] = "multi_step",
    rule: Annotated[
        str, typer.Option("--rule", help="Support rule: coverage_gap | coverage | iou | iou_gap.")
    ] = "coverage_gap",
    model: Annotated[
        Path | None,
        typer.Option(
            "--model", help="Collapse predictor checkpoint (default: models/cp_focal/best.pt)."
        ),
    ] = None,
    thresholds: Annotated[
        Path | None,
        typer.Option(
            "--thresholds",
            help="Val-chosen thresholds of the support stage "
            "(default: reports/support/thresholds.json).",
        ),
    ] = None,
    mcap: Annotated[
        Path | None, typer.Option("--mcap", help="With --execute: write the episode as MCAP.")
    ] = None,
) -> None:
    """Infer the support graph of one scene (thesis 6.2.2), print it beside the physics truth
    with the extraction order and the bimanual option as JSON; --execute runs the plan."""
    with user_errors():
        from clutterbench.config import load_section
        from clutterbench.sim.spec import SceneSpec
        from clutterbench.trials.config import TrialsConfig

        _check_options(planner, rule, mcap)
        spec = SceneSpec.load(spec_path)
        check_indices(spec.n, target, None, "--target")
        physics = physics_config()
        warn_if_not_at_rest(spec, spec_path, physics)
        params = project_params()
        trials = (
            load_section(TrialsConfig, "trials", params) if "trials" in params else TrialsConfig()
        )
        # The collapse predictor and the support thresholds are needed by the CP planners
        # (and to print the inferred graph); oracle, random and pull_target run without them.
        model_path = default_path(model, f"models/{trials.ch6.model}/best.pt")
        thresholds_path = default_path(thresholds, "reports/support/thresholds.json")
        use_cp = _reads_deletion_maps(planner) or (
            model is not None or (model_path.exists() and thresholds_path.exists())
        )
        obs, out = _observed(spec, physics, trials, target)
        support, cp_max = None, 0.0
        if use_cp:
            inferred, support, cp_max, model_path = _inferred_graph(
                model_path, thresholds_path, rule, trials, spec, obs, target
            )
            out |= inferred
        else:
            out["inferred_edges"] = None  # no collapse predictor: pass --model to infer them
        if execute:
            out["execute"] = _execute(
                spec, spec_path, target, planner, trials, physics, support, cp_max, model_path, mcap
            )
        typer.echo(json.dumps(out))


def _reads_deletion_maps(planner: str) -> bool:
    """Whether the planner plans on the collapse predictor's deletion maps (its declaration)."""
    from clutterbench.trials.ch6.planners import planner_info

    return planner_info(planner).maps == "deletion"


def _check_options(planner: str, rule: str, mcap: Path | None) -> None:
    """--planner a registered planner, --rule a support rule, --mcap a writable file."""
    from clutterbench.trials.ch6.planners import PLANNERS

    if planner not in PLANNERS:  # the registry (built-in planners and registered ones)
        raise ClutterbenchError(f"--planner {planner}: not one of {', '.join(PLANNERS)}")
    if rule not in ("coverage", "iou", "coverage_gap", "iou_gap"):
        raise ClutterbenchError(f"--rule {rule}: not one of coverage, iou, coverage_gap, iou_gap")
    if mcap is not None:
        check_out_file(mcap, "--mcap", "episode.mcap")


def _observed(
    spec: SceneSpec, physics: PhysicsConfig, trials: TrialsConfig, target: int
) -> tuple[Observation, dict[str, Any]]:
    """The scene's observation (the target must be visible) -> it, and the output's target,
    visible boxes and physics-truth support edges."""
    import numpy as np

    from clutterbench.data.trial_scenes import truth_moved_contact
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.render import observe

    obs = observe(BoxWorld.from_spec(spec, physics, render=True), spec.camera)
    if target not in obs.visible_boxes(trials.ch6.min_pixels):
        raise ClutterbenchError(f"--target {target}: the camera does not see that box")
    moved, contact = truth_moved_contact(spec, physics, trials.ch6.moved_threshold_m)
    out: dict[str, Any] = {
        "target": target,
        "visible": obs.visible_boxes(trials.ch6.min_pixels),
        "true_edges": [
            {"supporter": int(a), "supported": int(b)} for a, b in zip(*np.nonzero(moved & contact))
        ],
    }
    return obs, out


def _inferred_graph(
    model_path: Path,
    thresholds_path: Path,
    rule: str,
    trials: TrialsConfig,
    spec: SceneSpec,
    obs: Observation,
    target: int,
) -> tuple[dict[str, Any], SupportParams, float, Path]:
    """The support graph the collapse predictor infers, its extraction order and bimanual
    option -> (those fields, the support thresholds, cp_max, the checkpoint)."""
    from clutterbench.io import read_json
    from clutterbench.planning.ch6.cpg import bimanual_plan, build_cpg, extraction_order
    from clutterbench.planning.ch6.extraction import CollapseGraphPlanner
    from clutterbench.planning.ch6.support import SupportParams
    from clutterbench.trials.core.harness import load_predictor

    model_path = require_file(
        model_path, "--model", "a checkpoint; `dvc repro train@cp_focal` makes the default"
    )
    thresholds_path = require_file(
        thresholds_path, "--thresholds", "`dvc repro support` makes the default"
    )
    chosen = read_json(thresholds_path)
    if not isinstance(chosen, dict) or rule not in chosen.get("chosen", {}):
        raise ClutterbenchError(f"{thresholds_path}: no thresholds for rule '{rule}'")
    support = SupportParams(**chosen["chosen"][rule])
    cp_max = trials.ch6.cp_max if trials.ch6.cp_max is not None else support.score_threshold
    predict = load_predictor(model_path, spec.camera.image_size)
    cp = CollapseGraphPlanner(predict, support, cp_max, trials.ch6.min_pixels)
    edges = cp.support_edges(obs)
    graph = build_cpg(edges, target)
    bim = bimanual_plan(graph, target)
    inferred = {
        "thresholds": chosen["chosen"][rule],
        "inferred_edges": [
            {"supporter": e.supporter, "supported": e.supported, "score": round(e.score, 4)}
            for e in edges
        ],
        "extraction_order": extraction_order(graph, target),
        "bimanual": {
            "hold": bim.hold,
            "pull": bim.pull,
            "steps_to_target": bim.steps_to_target,
        },
    }
    return inferred, support, cp_max, model_path


def _execute(
    spec: SceneSpec,
    spec_path: Path,
    target: int,
    planner: str,
    trials: TrialsConfig,
    physics: PhysicsConfig,
    support: SupportParams | None,
    cp_max: float,
    model_path: Path,
    mcap: Path | None,
) -> dict[str, Any]:
    """The planner run on the scene until the target is out (or the episode ends), the MCAP
    written when asked -> the record's outcome fields."""
    from clutterbench.sim.config import SimConfig
    from clutterbench.trials.ch6.episodes import ch6_jobs, run_extraction
    from clutterbench.trials.config import ConditionConfig
    from clutterbench.trials.core.harness import write_mcap

    cond = ConditionConfig(planner=planner, stream=next(iter(trials.streams), "cli"))
    streams = trials.streams or {}
    job = ch6_jobs(
        "cli",
        cond,
        trials=trials,
        sim=SimConfig(physics=physics, camera=spec.camera),
        seed=0,
        support=support,
        cp_max=cp_max,
        model_path=model_path,
        stream_cfg=streams.get(cond.stream),
    )[0]
    if planner == "single_step":
        job = dataclasses.replace(
            job,
            ch4_model_path=require_file(
                default_path(None, str(job.ch4_model_path)),
                "ch4 model",
                f"`dvc repro train@{trials.ch6.ch4_model}` makes it",
            ),
        )
    result = run_extraction(spec, job, target)
    if mcap is not None:
        write_mcap(mcap, [result], {"spec": spec_path.name, "planner": planner})
    rec = result.record
    return {
        k: rec[k]
        for k in (
            "planner",
            "success",
            "target_extracted",
            "others_still",
            "end",
            "n_disturbed",
            "disturbance_m",
            "aborted_before_motion",
            "aborted_after_motion",
            "steps",
        )
    }
