"""The box_head stage's work: pairs from the val dataset's train and val splits and from the
test dataset, the head trained and scored, its checkpoint, log, scores and figure written."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.collapse.box_head import (
    EDGE_HEADS,
    OUTPUTS,
    BoxHeadMeta,
    edge_probability,
    feature_names,
    save_box_head,
)
from clutterbench.collapse.predict import CollapsePredictor
from clutterbench.criteria import label_thresholds
from clutterbench.errors import ClutterbenchError
from clutterbench.io import atomic_path, write_json, write_text
from clutterbench.models.checkpoint import checkpoint_heads, load_checkpoint
from clutterbench.planning.ch6.support import edge_precision_recall
from clutterbench.precision import inference_from_params
from clutterbench.progress import progress_bar
from clutterbench.sim.config import SimConfig
from clutterbench.sim.noise import TrainSensingConfig
from clutterbench.support.box_train import (
    THRESHOLDS,
    Pairs,
    calibration,
    collect,
    predictors_of,
    score_methods,
    train_box_head,
)
from clutterbench.support.config import BoxHeadConfig, SupportEvalConfig
from clutterbench.support.evaluate import (
    Scene,
    all_scenes,
    segmented_scene,
    sensed_scene,
    split_scenes,
)


@dataclass(frozen=True)
class BoxHeadPaths:
    cp_model: Path  # the collapse predictor whose maps it reads
    gen_dir: Path
    split_file: Path  # the val dataset's split
    model_dir: Path  # best.pt
    out: Path  # metrics.json, scores.csv, log.csv, calibration.png

    @classmethod
    def of(cls, cfg: SupportEvalConfig, model_dir: Path, out: Path) -> BoxHeadPaths:
        """The pipeline's inputs of `cfg` (models/, data/generate, data/split), these outputs."""
        return cls(
            cp_model=Path(f"models/{cfg.model}/best.pt"),
            gen_dir=Path("data/generate"),
            split_file=Path(f"data/split/{cfg.val_dataset}.json"),
            model_dir=model_dir,
            out=out,
        )


def check_datasets(cfg: SupportEvalConfig, params: dict) -> None:
    """One line when the val or the test dataset of the box head is not generated."""
    from clutterbench.config import load_section
    from clutterbench.data.config import GenerateConfig

    datasets = load_section(GenerateConfig, "generate", params).datasets
    for key, name in (
        ("val_dataset", cfg.val_dataset),
        ("box_head.test_dataset", cfg.box_head.test_dataset),
    ):
        if name not in datasets:
            raise ClutterbenchError(f"support.{key}: unknown dataset '{name}'")


def run_box_head(
    params: dict, seed: int, cfg: SupportEvalConfig, sim: SimConfig, paths: BoxHeadPaths
) -> dict[str, dict[str, float]]:
    """Train, choose, score and write; returns the box head's test scores per output."""
    inference_from_params(params)
    ckpt = load_checkpoint(paths.cp_model)
    heads = checkpoint_heads(ckpt)
    if not set(EDGE_HEADS) <= set(heads):
        raise ClutterbenchError(
            f"{paths.cp_model}: the box head reads the pull heads {', '.join(EDGE_HEADS)}; the "
            f"support model has {', '.join(heads)} (train it with those labels)"
        )
    predictor = CollapsePredictor.from_checkpoint(paths.cp_model, image_size=sim.camera.image_size)
    bh = cfg.box_head
    read: dict[str, Any] = {
        "threshold_m": cfg.moved_threshold_m,
        "min_pixels": cfg.min_pixels,
        "camera": sim.camera,
        "heads": EDGE_HEADS,
        "collapse_free": label_thresholds(params),
    }
    pairs: dict[str, Pairs] = {}
    for split, limit in (("train", bh.train_scenes), ("val", bh.val_scenes)):
        scenes = split_scenes(paths.gen_dir, paths.split_file, split, limit, **read)
        scenes = as_sensed(scenes, bh.sensing, sim, seed if split == "train" else None)
        scenes = as_seen(scenes, bh, sim, cfg.min_pixels, split)
        pairs[split] = collect(scenes, predictor, f"box_head: {split} scenes", len(scenes))
    test_scenes = list(all_scenes(paths.gen_dir, bh.test_dataset, **read))
    test_scenes = as_seen(as_sensed(test_scenes, bh.sensing, sim, None), bh, sim, cfg.min_pixels)
    pairs["test"] = collect(test_scenes, predictor, "box_head: test scenes", len(test_scenes))
    for split, p in pairs.items():
        if not len(p):
            raise ClutterbenchError(f"box_head: the {split} scenes hold no pair of visible boxes")

    model, log, best_epoch = train_box_head(pairs["train"], pairs["val"], bh, seed)
    meta = BoxHeadMeta(
        cp_model=paths.cp_model.parent.name,
        heads=tuple(heads),
        features=feature_names(heads),
        hidden=bh.hidden,
        image_size=sim.camera.image_size,
    )
    test_methods = predictors_of(model, pairs["test"], heads)
    val_methods = predictors_of(model, pairs["val"], heads)
    scores, chosen = score_methods(test_methods, val_methods, pairs["test"], pairs["val"])
    paths.model_dir.mkdir(parents=True, exist_ok=True)
    save_box_head(model, meta, paths.model_dir / "best.pt")
    write_text(paths.out / "log.csv", log.to_csv(index=False))
    write_text(paths.out / "scores.csv", scores.to_csv(index=False, float_format="%.6g"))
    overall = scores[scores["group"] == "all"]
    summary = {
        r["output"]: {k: r[k] for k in ("precision", "recall", "f1", "auroc", "ece", "brier")}
        for _, r in overall[overall["method"] == "box_head"].iterrows()
    }
    write_json(
        paths.out / "metrics.json",
        {
            "best_epoch": best_epoch,
            "pairs": {k: len(v) for k, v in pairs.items()},
            "positives": {
                k: dict(zip(OUTPUTS, v.y.sum(0).astype(int).tolist())) for k, v in pairs.items()
            },
            "thresholds": chosen,
            **_sensing_field(bh.sensing),
            "test": {
                m: {
                    r["output"]: {
                        k: _round(r[k]) for k in ("precision", "recall", "f1", "auroc", "ece")
                    }
                    for _, r in overall[overall["method"] == m].iterrows()
                }
                for m in dict.fromkeys(overall["method"])
            },
        },
    )
    calibration_figure(test_methods, pairs["test"], paths.out / "calibration.png")
    return summary


def as_sensed(
    scenes: list[Scene], sensing: TrainSensingConfig, sim: SimConfig, train_seed: int | None
) -> list[Scene]:
    """The scenes as the box head's sensor (support.box_head.sensing) returns their depth:
    unchanged for ideal; the train scenes (`train_seed` given) with the preset's noise
    randomised by its spread, seeded by `train_seed` and each picture; the val and test
    scenes through the preset itself, as the support stage's sensed rows see them."""
    if sensing.preset == "ideal":
        return scenes
    if train_seed is None:
        return [sensed_scene(sc, sensing.preset, sim.camera) for sc in scenes]
    return [
        sensed_scene(sc, sensing.preset, sim.camera, sensing.spread, train_seed) for sc in scenes
    ]


def as_seen(
    scenes: list[Scene], bh: BoxHeadConfig, sim: SimConfig, min_pixels: int, split: str = "test"
) -> list[Scene]:
    """The scenes with the masks a sensed head trains on (support.box_head.sensed_masks):
    unchanged for the simulator's or on exact depth; for depth, each scene's sensed depth
    segmented by region growing (support/evaluate.py segmented_scene); for both, the scenes
    with the simulator's masks and then again with those."""
    if bh.sensing.preset == "ideal" or bh.sensed_masks == "instance":
        return scenes
    out = []
    with progress_bar(f"box_head: {split} scenes' masks from depth", len(scenes)) as advance:
        for sc in scenes:
            out.append(segmented_scene(sc, sim.camera, min_pixels))
            advance(1)
    return scenes + out if bh.sensed_masks == "both" else out


def _sensing_field(sensing: TrainSensingConfig) -> dict[str, Any]:
    """metrics.json's record of the sensor it trained on; none for ideal (as before)."""
    if sensing.preset == "ideal":
        return {}
    return {"sensing": {"preset": sensing.preset, "spread": sensing.spread}}


def _round(v: float) -> float | None:
    return None if not np.isfinite(v) else round(float(v), 4)


def calibration_figure(methods: dict[str, np.ndarray], test: Pairs, out: Path) -> None:
    """Reliability diagrams on the test pairs: the box head and each pixel head read per box,
    one panel per output."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(OUTPUTS), figsize=(4 * len(OUTPUTS), 4), dpi=80)
    for ax, (j, name) in zip(axes, enumerate(OUTPUTS)):
        ax.plot([0, 1], [0, 1], color="grey", lw=1, ls=":")
        for method, probs in methods.items():
            if np.isnan(probs[:, j]).all():
                continue
            cal = calibration(probs[:, j], test.y[:, j])
            ax.plot(cal["predicted"], cal["observed"], marker="o", label=method)
        ax.set(
            title=f"{name} ({int(test.y[:, j].sum())} of {len(test)} pairs)",
            xlabel="predicted",
            ylabel="observed",
        )
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    plt.close(fig)


def box_probs_of(maps: Any, scene: Scene) -> np.ndarray:
    """(K, K, len(OUTPUTS)) box-head probabilities of one support scene."""
    return maps.probs(scene.depth_m, scene.masks)


def _edges(scene: Scene, probs: np.ndarray, head: str, threshold: float) -> set[tuple[int, int]]:
    edge = edge_probability(probs, head)
    return {(scene.ids[x], scene.ids[y]) for x, y in zip(*np.nonzero(edge > threshold)) if x != y}


def choose_edge_thresholds(
    val: Sequence[Scene], maps: Any, outcome: dict[str, float]
) -> dict[str, dict[str, float]]:
    """Per pull head: the edge threshold of the best f1 of mean precision and recall on the
    val scenes (Table 6.2's criterion, support.evaluate.choose_all), and the outcome
    threshold the box_head stage chose on val pairs (`outcome`)."""
    probs = [box_probs_of(maps, sc) for sc in val]
    chosen = {}
    for head in EDGE_HEADS:
        best, best_f1 = float(THRESHOLDS[len(THRESHOLDS) // 2]), -1.0
        for t in THRESHOLDS:
            pr = np.array(
                [
                    edge_precision_recall(_edges(sc, p, head, float(t)), sc.view(head).true_edges)
                    for sc, p in zip(val, probs)
                ],
                dtype=float,
            ).reshape(-1, 2)
            precision, recall = (_nanmean(pr[:, i]) for i in (0, 1))
            f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else -1.0
            if np.isfinite(f1) and f1 > best_f1:
                best, best_f1 = float(t), f1
        chosen[head] = {"edge": best, "outcome": float(outcome[head])}
    return chosen


def _nanmean(v: np.ndarray) -> float:
    """The mean of the defined values (NaN: none defined), as Table 6.2 averages scenes."""
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def box_rows(scene: Scene, maps: Any, chosen: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
    """The scene's rows of scenes.csv for the box head's support graph, one per pull head
    (method `<head>_box`), against that head's truth."""
    probs = box_probs_of(maps, scene) if len(scene.ids) > 1 else None
    rows = []
    for head in EDGE_HEADS:
        view = scene.view(head)
        truth = view.true_edges
        pred = set() if probs is None else _edges(scene, probs, head, chosen[head]["edge"])
        precision, recall = edge_precision_recall(pred, truth)
        rows.append(
            {
                "scene": scene.index,
                "family": scene.family,
                "n_objects": scene.n_objects,
                "visible": len(scene.ids),
                "method": f"{head}_box",
                "n_true": len(truth),
                "n_pred": len(pred),
                "tp": len(pred & truth),
                "precision": precision,
                "recall": recall,
            }
        )
    return rows
