"""The support stage's work: thresholds chosen on val scenes, then Table 6.2's evidence (rows,
truth, thresholds, figure) on test scenes generated from their own stream."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from clutterbench.collapse.box_head import EDGE_HEADS
from clutterbench.collapse.box_predict import BoxMaps
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.config import as_dict, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.data.trial_scenes import stream_key
from clutterbench.errors import ClutterbenchError
from clutterbench.io import read_json, write_json, write_text
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.parallel import ParallelConfig
from clutterbench.planning.ch6.support import oracle_heatmaps
from clutterbench.precision import Precision, inference_from_params
from clutterbench.progress import progress_bar
from clutterbench.sim.config import SimConfig
from clutterbench.support.box_fusion import (
    FittedContacts,
    SimulatePulls,
    answer_scene,
    choose_fusion,
    fit_contact,
    fitted_contacts,
    fitted_pulls,
    fusion_rows,
    learned_contact,
)
from clutterbench.support.box_run import box_rows, choose_edge_thresholds
from clutterbench.support.config import SupportEvalConfig, box_head_files
from clutterbench.support.evaluate import (
    PULL_HEADS,
    Scene,
    all_scenes,
    choose_all,
    contact_edge_rate,
    evaluate_scene,
    evidence,
    head_prefix,
    method_head,
    predicted_heatmaps,
    sensed_scene,
    split_scenes,
    sweep_all,
    val_metrics_at,
)
from clutterbench.support.figure import SupportPanel, support_figure
from clutterbench.support.physics_depth import SUPPORT_METHOD, SUPPORT_RULE, PhysicsDepthSupport


@dataclass(frozen=True)
class SupportPaths:
    """Where the stage reads (model, val scenes) and writes (reports, test scenes)."""

    model: Path  # the CP checkpoint
    box_head: Path  # the box head's checkpoint (stage box_head)
    box_metrics: Path  # its metrics.json: the outcome thresholds it chose on val pairs
    gen_dir: Path  # generated datasets
    split_file: Path  # the val dataset's split
    out: Path  # val_sweep.csv, scenes.csv, thresholds.json, figure.png
    scenes: Path  # the test scenes and their truth.json

    @classmethod
    def of(cls, cfg: SupportEvalConfig, out: Path, scenes: Path) -> SupportPaths:
        """The pipeline's inputs of `cfg` (models/, data/generate, data/split), these outputs."""
        box_head, box_metrics = box_head_files("ideal")
        return cls(
            model=Path(f"models/{cfg.model}/best.pt"),
            box_head=box_head,
            box_metrics=box_metrics,
            gen_dir=Path("data/generate"),
            split_file=Path(f"data/split/{cfg.val_dataset}.json"),
            out=out,
            scenes=scenes,
        )


@dataclass(frozen=True)
class Predictors:
    """The CP's deletion predictor, its pull heads and one predictor per pull head."""

    deletion: CollapsePredictor
    heads: list[str]
    of_head: dict[str, CollapsePredictor]


def load_predictors(model: Path, image_size: int) -> Predictors:
    predictor = CollapsePredictor.from_checkpoint(model, image_size=image_size)
    # Each pull head of the CP gets its own rows, thresholds chosen and scored on its truth.
    heads = [h for h in PULL_HEADS if h in checkpoint_heads(load_checkpoint(model))]
    head_predictors = {
        h: CollapsePredictor.from_checkpoint(model, image_size=image_size, head=h) for h in heads
    }
    return Predictors(predictor, heads, head_predictors)


@dataclass(frozen=True)
class ValChoice:
    """What the stage chooses on the val scenes as one sensor returns their depth: every
    method's sweep and thresholds, the random row's edge rate, the box head's edge thresholds
    and the box head fused with physics from depth."""

    sweep: pd.DataFrame
    chosen: dict
    p_edge: float
    box: dict[str, dict[str, float]]
    fusion: dict[str, dict[str, Any]]


@dataclass(frozen=True)
class ValInputs:
    """What every choice on val scenes reads besides the scenes themselves."""

    cfg: SupportEvalConfig
    models: Predictors
    box_maps: BoxMaps
    outcome: dict[str, float]  # the box head's outcome thresholds (stage box_head, val pairs)
    simulate: SimulatePulls
    contacts: FittedContacts | None
    edge_precision: float | None  # trials.ch6.box_edge_precision


def run_support(
    params: dict,
    seed: int,
    cfg: SupportEvalConfig,
    sim: SimConfig,
    parallel: ParallelConfig,
    paths: SupportPaths,
    ch6: Any,
) -> pd.DataFrame:
    """Choose thresholds on val scenes, score every method on fresh test scenes and write the
    outputs; returns each method's mean precision and recall over the test scenes. `ch6`: the
    trials' ch. 6 params (the `trials` section's `ch6`: the trials' pull, the fitted scenes,
    the box head's fusion), parsed by the stage: the support stage stands below the trials
    and imports none of them. Each sensor of cfg.sensing gets its own choice, made on the val
    scenes' depth as that sensor returns it, for its rows here and the trials' rows under it."""
    precision = inference_from_params(params)
    models = load_predictors(paths.model, sim.camera.image_size)
    read = {"heads": models.heads, "collapse_free": label_thresholds(params)}

    # 1. thresholds on validation scenes, on exact depth and as each sensor returns it
    val = val_scenes(cfg, sim, paths, read)
    catalogue = load_section(GenerateConfig, "generate", params).datasets[cfg.val_dataset].catalogue
    inputs = ValInputs(
        cfg,
        models,
        BoxMaps.from_paths(paths.model, paths.box_head, sim.camera, "pull", 0.5),
        read_json(paths.box_metrics)["thresholds"]["box_head"],
        fitted_pulls_of(params, cfg, sim, ch6, catalogue),
        fitted_contacts_of(cfg, sim, ch6, catalogue),
        ch6.box_edge_precision,
    )
    sensed_inputs = {s: sensed_box_head(inputs, paths.model, sim, s) for s in cfg.sensing}
    choice = choose_on_val(val, inputs)
    write_text(paths.out / "val_sweep.csv", choice.sweep.to_csv(index=False))
    sensed = {
        s: choose_on_val([sensed_scene(sc, s, sim.camera) for sc in val], sensed_inputs[s], s)
        for s in cfg.sensing
    }
    fusion = {"chosen": choice.fusion, "val_scenes": len(val)}
    if sensed:
        fusion["sensed"] = {s: {"chosen": c.fusion} for s, c in sensed.items()}
    write_json(paths.out / "box_fusion.json", fusion)

    # 2. test scenes from their own stream, with every removal simulated
    generate_test_scenes(cfg, sim, parallel, seed, ch6, models.heads, paths.scenes)
    rng = np.random.default_rng([seed, 62])

    def physics_depth(c: ValChoice) -> PhysicsDepthSupport:  # its contact: the rule's choice
        return PhysicsDepthSupport(cfg, sim, c.chosen[SUPPORT_RULE], ch6.physics_depth_settle_s)

    scenes_in = all_scenes(
        paths.scenes, "scenes", cfg.moved_threshold_m, cfg.min_pixels, sim.camera, **read
    )
    test = TestInputs(
        physics_depth(choice),
        seed,
        inputs.box_maps,
        fitted_pulls_of(params, cfg, sim, ch6, cfg.test.catalogue),
        fitted_contacts_of(cfg, sim, ch6, cfg.test.catalogue),
    )
    rows, panels, truth = score_test_scenes(scenes_in, cfg, models, choice, rng, test)
    sensed_tests = {
        s: dataclasses.replace(
            test, physics_depth=physics_depth(c), box_maps=sensed_inputs[s].box_maps
        )
        for s, c in sensed.items()
    }
    rows += sensed_rows(cfg, sim, paths, read, models, sensed, sensed_tests)
    # edges: removing X moves Y, X and Y touch; <head>_edges: the trials' pull of X marks Y
    # under that head's label kind, X and Y touch
    truths = {f"{head_prefix(h)}edges": edges for h, edges in truth.items()}
    write_json(paths.scenes / "truth.json", truths | {"moved_threshold_m": cfg.moved_threshold_m})
    scenes = pd.DataFrame(rows)
    write_text(paths.out / "scenes.csv", scenes.to_csv(index=False))
    write_thresholds(paths.out, choice, len(val), precision, sensed)
    support_figure(
        panels, paths.out / "figure.png", "Inferred (white, dashed) and true (pink) support"
    )
    return scenes.groupby("method", sort=False)[["precision", "recall"]].mean()


def sensed_box_head(inputs: ValInputs, model: Path, sim: SimConfig, sensing: str) -> ValInputs:
    """`inputs` with the box head trained on `sensing`'s depth (stage box_head_sensed) and
    the outcome thresholds it chose on its val pairs; one line when that stage has not
    trained one for this sensor."""
    head, metrics = box_head_files(sensing)
    if not head.is_file() or not metrics.is_file():
        raise ClutterbenchError(
            f"{head}: no box head trained on {sensing} depth; run stage box_head_sensed "
            "(support.sensing names the sensors it trains for)"
        )
    return dataclasses.replace(
        inputs,
        box_maps=BoxMaps.from_paths(model, head, sim.camera, "pull", 0.5),
        outcome=read_json(metrics)["thresholds"]["box_head"],
    )


def choose_on_val(val: list[Scene], inputs: ValInputs, sensing: str = "ideal") -> ValChoice:
    """Every choice the stage makes on the val scenes `val` (their depth as `sensing`
    returned it): each method's thresholds (Table 6.2's criterion, best f1 of mean precision
    and recall), the box head's edge thresholds and its fusion with physics from depth."""
    sweep = val_sweep(val, inputs.cfg, inputs.models, sensing)
    chosen = choose_all(sweep)
    return ValChoice(
        sweep,
        chosen,
        contact_edge_rate(val, chosen["coverage"]),
        choose_edge_thresholds(val, inputs.box_maps, inputs.outcome),
        choose_box_fusion(
            val, inputs.box_maps, inputs.simulate, inputs.contacts, inputs.edge_precision
        ),
    )


@dataclass(frozen=True)
class TestInputs:
    """What scoring the test scenes reads besides the scenes and the choice on val scenes:
    physics from depth (its own rows), the seed, the box head and the fitted scenes' pulls and
    contacts (None: the head's contact)."""

    physics_depth: PhysicsDepthSupport
    seed: int
    box_maps: BoxMaps
    simulate: SimulatePulls
    contacts: FittedContacts | None


def sensed_rows(
    cfg: SupportEvalConfig,
    sim: SimConfig,
    paths: SupportPaths,
    read: dict[str, Any],
    models: Predictors,
    choices: dict[str, ValChoice],
    tests: dict[str, TestInputs],
) -> list[dict]:
    """Every method's rows on the test scenes again under each sensor of cfg.sensing (their
    depth sensed, support/evaluate.py sensed_scene), named method@<sensor>, each with the
    thresholds and fusion chosen on the val scenes as that sensor returned them (`choices`)
    and physics from depth on that choice's contact thresholds (`tests`)."""
    rows: list[dict] = []
    for k, sensing in enumerate(cfg.sensing):
        scenes = all_scenes(
            paths.scenes, "scenes", cfg.moved_threshold_m, cfg.min_pixels, sim.camera, **read
        )
        sensed = (sensed_scene(sc, sensing, sim.camera) for sc in scenes)
        rng = np.random.default_rng([tests[sensing].seed, 62, k + 1])
        more, _, _ = score_test_scenes(sensed, cfg, models, choices[sensing], rng, tests[sensing])
        rows += [r | {"method": f"{r['method']}@{sensing}"} for r in more]
    return rows


def val_scenes(
    cfg: SupportEvalConfig, sim: SimConfig, paths: SupportPaths, read: dict[str, Any]
) -> list[Scene]:
    """The first cfg.val_scenes scenes of the val dataset's val split."""
    return split_scenes(
        paths.gen_dir,
        paths.split_file,
        "val",
        cfg.val_scenes,
        cfg.moved_threshold_m,
        cfg.min_pixels,
        sim.camera,
        **read,
    )


def val_sweep(
    val: list[Scene], cfg: SupportEvalConfig, models: Predictors, sensing: str = "ideal"
) -> pd.DataFrame:
    """Every method's threshold sweep over the val scenes' evidence."""
    evidence_of: dict[str, tuple[list, list]] = {h: ([], []) for h in ("deletion", *models.heads)}
    label = "support: val heatmaps" + ("" if sensing == "ideal" else f" ({sensing} depth)")
    with progress_bar(label, total=len(val)) as advance:
        for sc in val:
            for head, (cp_ev, oracle_ev) in evidence_of.items():
                view = sc.view(head)
                cp_ev.append(
                    evidence(
                        view, predicted_heatmaps(view, models.of_head.get(head, models.deletion))
                    )
                )
                oracle_ev.append(evidence(view, oracle_heatmaps(view.moved, view.masks)))
            advance(1)
    return pd.concat(
        [sweep_all(cp, oracle, cfg, head_prefix(h)) for h, (cp, oracle) in evidence_of.items()],
        ignore_index=True,
    )


def generate_test_scenes(
    cfg: SupportEvalConfig,
    sim: SimConfig,
    parallel: ParallelConfig,
    seed: int,
    ch6: Any,
    heads: list[str],
    scenes_dir: Path,
) -> None:
    """The test scenes from the support stream, with every removal (and, for a CP with pull
    heads, the trials' pull of every box) simulated."""
    test_ds = DatasetConfig(
        n_scenes=cfg.test_scenes,
        families=dict(cfg.test.families),
        catalogue=cfg.test.catalogue,
        n_objects=cfg.test.n_objects,
        moved_threshold_m=cfg.moved_threshold_m,
        pull_outcomes=bool(heads),  # the pull truth: the trials' own pull of every box
    )
    shards = GenerateConfig(shard_size=10, workers=cfg.workers, max_attempts=cfg.max_attempts)
    key = stream_key("support")
    trial_pull = (ch6.pull_increment_m, ch6.grasp_lift_m) if heads else None
    generate_dataset(
        key, test_ds, shards, sim, seed, scenes_dir / "scenes", trial_pull, parallel=parallel
    )


def score_test_scenes(
    scenes_in: Any,
    cfg: SupportEvalConfig,
    models: Predictors,
    choice: ValChoice,
    rng: np.random.Generator,
    test: TestInputs,
) -> tuple[list[dict], list[SupportPanel], dict[str, dict[str, list]]]:
    """Every method's rows on every test scene, the figure's panels and each head's true edges,
    with the thresholds, box-head edges and fusion of `choice` (chosen on val scenes)."""
    chosen, p_edge = choice.chosen, choice.p_edge
    heads = models.heads
    chosen_of = {h: {m: p for m, p in chosen.items() if method_head(m)[0] == h} for h in heads}
    deletion = {m: p for m, p in chosen.items() if method_head(m)[0] == "deletion"}
    rows, panels = [], []
    truth: dict[str, dict[str, list]] = {h: {} for h in ("deletion", *heads)}
    with progress_bar("support: test scenes", total=cfg.test_scenes) as advance:
        for sc in scenes_in:
            heat = predicted_heatmaps(sc, models.deletion)
            scene_rows, edges = evaluate_scene(sc, heat, deletion, p_edge, rng)
            rows += scene_rows + [physics_depth_row(test.physics_depth, sc, test.seed)]
            truth["deletion"][str(sc.index)] = sorted(map(list, sc.true_edges))
            for head in heads:  # no random row: rng draws stay the deletion rows'
                view = sc.view(head)
                head_heat = predicted_heatmaps(view, models.of_head[head])
                rows += evaluate_scene(view, head_heat, chosen_of[head], None, rng)[0]
                truth[head][str(sc.index)] = sorted(map(list, view.true_edges))
            rows += box_rows(sc, test.box_maps, choice.box)
            answers = answer_scene(sc, test.box_maps, test.simulate, test.contacts)
            fused = fusion_rows(answers, choice.fusion)
            where = {"scene": sc.index, "family": sc.family, "n_objects": sc.n_objects}
            rows += [where | {"visible": len(sc.ids)} | r for r in fused]
            if len(panels) < cfg.figure_scenes:
                panels.append(
                    SupportPanel(
                        sc.depth_m,
                        sc.masks,
                        sc.ids,
                        edges["coverage"],
                        sc.true_edges,
                        f"test scene {sc.index} ({sc.family})",
                    )
                )
            advance(1)
    return rows, panels, truth


def fitted_pulls_of(
    params: dict, cfg: SupportEvalConfig, sim: SimConfig, ch6: Any, catalogue: str
) -> SimulatePulls:
    """Physics from depth's pulls of every visible box (support/box_fusion.py), the boxes
    fitted with `catalogue`'s sizes, marked as the support truth marks them."""
    return fitted_pulls(
        sim, ch6, cfg.moved_threshold_m, label_thresholds(params), catalogue, cfg.min_pixels
    )


def choose_box_fusion(
    val: list[Scene],
    box_maps: BoxMaps,
    simulate: SimulatePulls,
    contacts: FittedContacts | None = None,
    precision: float | None = None,
) -> dict[str, dict[str, Any]]:
    """Per pull head, the box head and physics from depth fused (support/box_fusion.py):
    weights and thresholds chosen on the val scenes; with the fitted scenes' `contacts`
    (trials.ch6.box_contact learned), the learned contact's weights too (`contact_weights`),
    fitted on the same scenes, and the edge threshold chosen with that contact; with
    `precision` (trials.ch6.box_edge_precision), the edge threshold of the most recall at that
    mean precision instead of the best f1."""
    answers = []
    with progress_bar("support: val pulls in the fitted boxes", total=len(val)) as advance:
        for sc in val:
            if len(sc.ids) > 1:
                answers.append(answer_scene(sc, box_maps, simulate, contacts))
            advance(1)
    if contacts is None:
        return {kind: choose_fusion(answers, kind, precision=precision) for kind in EDGE_HEADS}
    w = fit_contact(answers)
    weights = {"contact_weights": [round(float(v), 6) for v in w]}
    contact = learned_contact(weights["contact_weights"])
    return {kind: choose_fusion(answers, kind, contact, precision) | weights for kind in EDGE_HEADS}


def fitted_contacts_of(
    cfg: SupportEvalConfig, sim: SimConfig, ch6: Any, catalogue: str
) -> FittedContacts | None:
    """The fitted scenes' contacts where the edges learn their contact from them
    (trials.ch6.box_contact learned), else None."""
    if ch6.box_contact != "learned":
        return None
    return fitted_contacts(sim, ch6, catalogue, cfg.min_pixels)


def write_thresholds(
    out: Path,
    choice: ValChoice,
    n_val: int,
    precision: Precision,
    sensed: dict[str, ValChoice],
) -> None:
    """thresholds.json: each method's chosen thresholds, its val metrics at them, the box
    head's thresholds per pull head (`box_head`: edge, outcome), the val scene count and the
    network precision the heatmaps were inferred at; under `sensed`, per sensor, the same
    chosen on the val scenes as that sensor returned them."""
    data = threshold_fields(choice) | {"val_scenes": n_val, "network_precision": precision}
    if sensed:
        data["sensed"] = {s: threshold_fields(c) for s, c in sensed.items()}
    write_json(out / "thresholds.json", data)


def threshold_fields(choice: ValChoice) -> dict[str, Any]:
    """A choice's part of thresholds.json: chosen, val (metrics at them), box_head."""
    thresholds = {m: as_dict(p) for m, p in choice.chosen.items()}
    thresholds |= {"random": {"p_edge": choice.p_edge}}
    thresholds[SUPPORT_METHOD] = as_dict(choice.chosen[SUPPORT_RULE])
    val_at = {m: val_metrics_at(choice.sweep, m, p) for m, p in choice.chosen.items()}
    return {"chosen": thresholds, "val": val_at, "box_head": choice.box}


def physics_depth_row(physics_depth: PhysicsDepthSupport, scene: Scene, seed: int) -> dict:
    """The scene's physics-from-depth row: a perception failure is recorded in it
    (PhysicsDepthSupport.row); anything else is a bug, one line naming the scene and seed."""
    try:
        return physics_depth.row(scene)
    except ClutterbenchError as exc:
        raise ClutterbenchError(f"support: test scene {scene.index}, seed {seed}: {exc}") from None
    except Exception as exc:
        raise ClutterbenchError(
            f"support: test scene {scene.index}, seed {seed}: {type(exc).__name__}: {exc}"
        ) from None
