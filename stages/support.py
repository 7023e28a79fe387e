"""Stage support: thresholds chosen on val scenes, then Table 6.2's evidence on test scenes."""

from pathlib import Path

import numpy as np
import pandas as pd

from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.config import BaseConfig, as_dict, load_section
from clutterbench.data.config import DatasetConfig, GenerateConfig
from clutterbench.data.generate import generate_dataset
from clutterbench.errors import ClutterbenchError
from clutterbench.io import write_json, write_text
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.parallel import ParallelConfig
from clutterbench.planning.support import oracle_heatmaps
from clutterbench.precision import inference_from_params
from clutterbench.progress import progress_bar
from clutterbench.report.support_figure import SupportPanel, support_figure
from clutterbench.sim.config import SimConfig
from clutterbench.stage import run_stage
from clutterbench.trials.config import SupportEvalConfig, TrialsConfig
from clutterbench.trials.physics_model import SUPPORT_METHOD, SUPPORT_RULE, PhysicsDepthSupport
from clutterbench.trials.scenes import stream_key
from clutterbench.trials.support_eval import (
    PULL_PREFIX,
    all_scenes,
    choose_all,
    contact_edge_rate,
    evaluate_scene,
    evidence,
    predicted_heatmaps,
    split_scenes,
    sweep_all,
    val_metrics_at,
)

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
    # A CP with a pull head gets its own rows, thresholds chosen and scored on pull truth.
    pull = "pull" in checkpoint_heads(load_checkpoint(model))
    pull_predictor = (
        CollapsePredictor.from_checkpoint(model, image_size=sim.camera.image_size, head="pull")
        if pull
        else None
    )
    ch6 = load_section(TrialsConfig, "trials", params).ch6

    # 1. thresholds on validation scenes
    val = split_scenes(
        Path("data/generate"),
        Path(f"data/split/{cfg.val_dataset}.json"),
        "val",
        cfg.val_scenes,
        cfg.moved_threshold_m,
        cfg.min_pixels,
        sim.camera,
        pull,
    )
    cp_ev, oracle_ev, pull_cp_ev, pull_oracle_ev = [], [], [], []
    with progress_bar("support: val heatmaps", total=len(val)) as advance:
        for sc in val:
            cp_ev.append(evidence(sc, predicted_heatmaps(sc, predictor)))
            oracle_ev.append(evidence(sc, oracle_heatmaps(sc.moved, sc.masks)))
            if pull_predictor is not None:
                pv = sc.pull_view()
                pull_cp_ev.append(evidence(pv, predicted_heatmaps(pv, pull_predictor)))
                pull_oracle_ev.append(evidence(pv, oracle_heatmaps(pv.moved, pv.masks)))
            advance(1)
    sweep = sweep_all(cp_ev, oracle_ev, cfg)
    if pull:
        pull_sweep = sweep_all(pull_cp_ev, pull_oracle_ev, cfg, PULL_PREFIX)
        sweep = pd.concat([sweep, pull_sweep], ignore_index=True)
    write_text(OUT / "val_sweep.csv", sweep.to_csv(index=False))
    chosen = choose_all(sweep)
    p_edge = contact_edge_rate(val, chosen["coverage"])
    deletion = {m: p for m, p in chosen.items() if not m.startswith(PULL_PREFIX)}
    pull_chosen = {m: p for m, p in chosen.items() if m.startswith(PULL_PREFIX)}

    # 2. test scenes from their own stream, with every removal simulated
    test_ds = DatasetConfig(
        n_scenes=cfg.test_scenes,
        families=dict(cfg.test.families),
        catalogue=cfg.test.catalogue,
        n_objects=cfg.test.n_objects,
        moved_threshold_m=cfg.moved_threshold_m,
        pull_outcomes=pull,  # the pull truth: the trials' own pull of every box
    )
    shards = GenerateConfig(shard_size=10, workers=cfg.workers, max_attempts=cfg.max_attempts)
    key = stream_key("support")
    trial_pull = (ch6.pull_increment_m, ch6.grasp_lift_m) if pull else None
    generate_dataset(
        key, test_ds, shards, sim, base.seed, SCENES / "scenes", trial_pull, parallel=parallel
    )

    rows, truth, pull_truth, panels = [], {}, {}, []
    rng = np.random.default_rng([base.seed, 62])
    physics_depth = PhysicsDepthSupport(cfg, sim, chosen[SUPPORT_RULE], ch6.physics_depth_settle_s)
    scenes_in = all_scenes(
        SCENES, "scenes", cfg.moved_threshold_m, cfg.min_pixels, sim.camera, pull
    )
    with progress_bar("support: test scenes", total=cfg.test_scenes) as advance:
        for sc in scenes_in:
            heat = predicted_heatmaps(sc, predictor)
            scene_rows, edges = evaluate_scene(sc, heat, deletion, p_edge, rng)
            rows += scene_rows + [physics_depth_row(physics_depth, sc, base.seed)]
            truth[str(sc.index)] = sorted(map(list, sc.true_edges))
            if pull_predictor is not None:  # no random row: rng draws stay the deletion rows'
                pv = sc.pull_view()
                pull_heat = predicted_heatmaps(pv, pull_predictor)
                rows += evaluate_scene(pv, pull_heat, pull_chosen, None, rng)[0]
                pull_truth[str(sc.index)] = sorted(map(list, pv.true_edges))
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
    truths = {"edges": truth, "moved_threshold_m": cfg.moved_threshold_m}
    if pull:
        truths["pull_edges"] = pull_truth  # pulling X moves Y (or off the shelf), X, Y touch
    write_json(SCENES / "truth.json", truths)
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
