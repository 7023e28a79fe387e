"""Stage support: thresholds chosen on val scenes, then Table 6.2's evidence on test scenes."""

from pathlib import Path

import numpy as np
import pandas as pd

from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.criteria import label_thresholds
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.parallel import ParallelConfig
from clutterbench.planning.ch6.support import oracle_heatmaps
from clutterbench.precision import inference_from_params
from clutterbench.progress import progress_bar
from clutterbench.report.support_figure import SupportPanel, support_figure
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.support.config import SupportEvalConfig
from clutterbench.support.evaluate import (
    PULL_HEADS,
    all_scenes,
    choose_all,
    contact_edge_rate,
    evaluate_scene,
    evidence,
    head_prefix,
    method_head,
    predicted_heatmaps,
    split_scenes,
    sweep_all,
    val_metrics_at,
)
from clutterbench.trials.ch6.physics_model import SUPPORT_METHOD, SUPPORT_RULE, PhysicsDepthSupport
from clutterbench.trials.config import TrialsConfig
from clutterbench.trials.core.scenes import stream_key

OUT = Path("reports/support")
SCENES = Path("data/support")


def support(params: dict, base: BaseConfig) -> None:
    cfg = load_section(SupportEvalConfig, "support", params)
    gen = load_section(GenerateConfig, "generate", params)
    sim = load_section(SimConfig, "sim", params)
    parallel = load_section(ParallelConfig, "parallel", params)  # the test scenes' backend
    if cfg.val_dataset not in gen.datasets:
        raise ClutterbenchError(f"support.val_dataset: unknown dataset '{cfg.val_dataset}'")
    model = Path(f"models/{cfg.model}/best.pt")
    precision = inference_from_params(params)
    predictor = CollapsePredictor.from_checkpoint(model, image_size=sim.camera.image_size)
    # Each pull head of the CP gets its own rows, thresholds chosen and scored on its truth.
    heads = [h for h in PULL_HEADS if h in checkpoint_heads(load_checkpoint(model))]
    head_predictors = {
        h: CollapsePredictor.from_checkpoint(model, image_size=sim.camera.image_size, head=h)
        for h in heads
    }
    ch6 = load_section(TrialsConfig, "trials", params).ch6
    read = {"heads": heads, "collapse_free": label_thresholds(params)}

    # 1. thresholds on validation scenes
    val = split_scenes(
        Path("data/generate"),
        Path(f"data/split/{cfg.val_dataset}.json"),
        "val",
        cfg.val_scenes,
        cfg.moved_threshold_m,
        cfg.min_pixels,
        sim.camera,
        **read,
    )
    evidence_of: dict[str, tuple[list, list]] = {h: ([], []) for h in ("deletion", *heads)}
    with progress_bar("support: val heatmaps", total=len(val)) as advance:
        for sc in val:
            for head, (cp_ev, oracle_ev) in evidence_of.items():
                view = sc.view(head)
                cp_ev.append(
                    evidence(view, predicted_heatmaps(view, head_predictors.get(head, predictor)))
                )
                oracle_ev.append(evidence(view, oracle_heatmaps(view.moved, view.masks)))
            advance(1)
    sweep = pd.concat(
        [sweep_all(cp, oracle, cfg, head_prefix(h)) for h, (cp, oracle) in evidence_of.items()],
        ignore_index=True,
    )
    write_text(OUT / "val_sweep.csv", sweep.to_csv(index=False))
    chosen = choose_all(sweep)
    p_edge = contact_edge_rate(val, chosen["coverage"])
    chosen_of = {h: {m: p for m, p in chosen.items() if method_head(m)[0] == h} for h in heads}
    deletion = {m: p for m, p in chosen.items() if method_head(m)[0] == "deletion"}

    # 2. test scenes from their own stream, with every removal simulated
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
        key, test_ds, shards, sim, base.seed, SCENES / "scenes", trial_pull, parallel=parallel
    )

    rows, panels = [], []
    truth: dict[str, dict[str, list]] = {h: {} for h in ("deletion", *heads)}
    rng = np.random.default_rng([base.seed, 62])
    physics_depth = PhysicsDepthSupport(cfg, sim, chosen[SUPPORT_RULE], ch6.physics_depth_settle_s)
    scenes_in = all_scenes(
        SCENES, "scenes", cfg.moved_threshold_m, cfg.min_pixels, sim.camera, **read
    )
    with progress_bar("support: test scenes", total=cfg.test_scenes) as advance:
        for sc in scenes_in:
            heat = predicted_heatmaps(sc, predictor)
            scene_rows, edges = evaluate_scene(sc, heat, deletion, p_edge, rng)
            rows += scene_rows + [physics_depth_row(physics_depth, sc, base.seed)]
            truth["deletion"][str(sc.index)] = sorted(map(list, sc.true_edges))
            for head in heads:  # no random row: rng draws stay the deletion rows'
                view = sc.view(head)
                head_heat = predicted_heatmaps(view, head_predictors[head])
                rows += evaluate_scene(view, head_heat, chosen_of[head], None, rng)[0]
                truth[head][str(sc.index)] = sorted(map(list, view.true_edges))
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
    # edges: removing X moves Y, X and Y touch; <head>_edges: the trials' pull of X marks Y
    # under that head's label kind, X and Y touch
    truths = {f"{head_prefix(h)}edges": edges for h, edges in truth.items()}
    write_json(SCENES / "truth.json", truths | {"moved_threshold_m": cfg.moved_threshold_m})
    scenes = pd.DataFrame(rows)
    write_text(OUT / "scenes.csv", scenes.to_csv(index=False))
    thresholds = {m: as_dict(p) for m, p in chosen.items()} | {"random": {"p_edge": p_edge}}
    thresholds[SUPPORT_METHOD] = as_dict(chosen[SUPPORT_RULE])
    val_at = {m: val_metrics_at(sweep, m, p) for m, p in chosen.items()}
    write_json(
        OUT / "thresholds.json",
        {
            "chosen": thresholds,
            "val": val_at,
            "val_scenes": len(val),
            "network_precision": precision,
        },
    )
    support_figure(panels, OUT / "figure.png", "Inferred (white, dashed) and true (pink) support")
    mean = scenes.groupby("method", sort=False)[["precision", "recall"]].mean()
    for method, r in mean.iterrows():
        print(f"support {method}: precision {r['precision']:.3f} recall {r['recall']:.3f}")


def physics_depth_row(physics_depth: PhysicsDepthSupport, scene, seed: int) -> dict:
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


if __name__ == "__main__":
    run_stage(support)
