"""Recheck: does the box head learn more from more scenes, from scenes the collapse predictor
never trained on, or with more width? Chosen on the val scenes the box_head stage validates on.

    python -m experiments.box_head_data     # make dev-box-head-data (after box_head)

The box head (collapse/box_head.py) learns from the collapse predictor's maps of the val
dataset's train split: scenes that network was trained on, where its maps are surer than on
scenes it never saw. This recheck collects the pairs of every train-split scene and every
val-split scene once, then trains the head as the stage does (support.box_head: epochs,
batch, lr, seed; the epoch of least val loss) on:
- `stage`: the first support.box_head.train_scenes train scenes (what the stage trains on);
- `all_train`: every train scene;
- `unseen_val`: the val scenes after the first support.box_head.val_scenes (maps of scenes
  the collapse predictor never trained on; the stage never reads them);
- `stage_and_unseen_val`: the two together;
- `stage`, 2x and 4x support.box_head.hidden wide;
- `stage` with the collapse predictor's own last decoder features beside the map statistics:
  the input of its 1x1 output conv (with box x pulled) averaged over box y's pixels, and over
  box x's own (`stage + decoder (other box)`, `stage + decoder (both boxes)`): does the
  network know more than its three maps say?
Each is scored on the first support.box_head.val_scenes val scenes (the stage's val pairs):
val loss, and per output the AUROC and the F1 at its best threshold on those pairs. Never on
the test dataset. Writes experiments/reports/box_head_data.{json,md}; not a dvc stage.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from clutterbench.collapse.box_head import EDGE_HEADS, OUTPUTS, off_diagonal, predict_pairs
from clutterbench.support.box_train import (
    Pairs,
    binary_scores,
    choose_threshold,
    train_box_head,
)
from clutterbench.support.config import BoxHeadConfig
from experiments.command import OUT, run_command, save

NAME = "box_head_data"


def _subset(p: Pairs, keep: np.ndarray) -> Pairs:
    return Pairs(p.x[keep], p.y[keep], p.rows[keep].reset_index(drop=True))


def _join(parts: list[Pairs]) -> Pairs:
    """The pairs of `parts`, one after another."""
    return Pairs(
        np.concatenate([p.x for p in parts]),
        np.concatenate([p.y for p in parts]),
        pd.concat([p.rows for p in parts], ignore_index=True),
    )


def _first_scenes(p: Pairs, n: int) -> np.ndarray:
    """Rows of the pairs' first `n` scenes (in the order the pairs hold them)."""
    first = list(dict.fromkeys(p.rows["scene"]))[:n]
    return p.rows["scene"].isin(first).to_numpy()


def variants(
    train: Pairs, val: Pairs, cfg: BoxHeadConfig
) -> tuple[dict[str, tuple[Pairs, BoxHeadConfig]], Pairs]:
    """name -> (training pairs, head config) of each variant (module docstring), and the
    val pairs every variant is scored on (the stage's: the first cfg.val_scenes)."""
    in_val = _first_scenes(val, cfg.val_scenes)
    stage = _subset(train, _first_scenes(train, cfg.train_scenes))
    unseen = _subset(val, ~in_val)
    wide = {
        f"stage, hidden {k * cfg.hidden}": (stage, dataclasses.replace(cfg, hidden=k * cfg.hidden))
        for k in (2, 4)
    }
    named = {
        "stage": (stage, cfg),
        "all_train": (train, cfg),
        "unseen_val": (unseen, cfg),
        "stage_and_unseen_val": (_join([stage, unseen]), cfg),
    } | wide
    return {k: v for k, v in named.items() if len(v[0])}, _subset(val, in_val)


def decoder_pair_features(feats: torch.Tensor, masks: np.ndarray) -> np.ndarray:
    """(K * (K - 1), 2C) float32, off-diagonal rows as the pairs hold them: the decoder features
    (K, C, h, w) of each pulled box x averaged over box y's pixels, then over x's own; masks
    (K, H, W) bool, pooled to (h, w) by area."""
    k, c, h, w = feats.shape
    m = torch.from_numpy(masks.astype(np.float32))[:, None]
    m = torch.nn.functional.adaptive_avg_pool2d(m, (h, w))[:, 0]
    area = m.flatten(1).sum(1).clamp_min(1e-3)
    pooled = torch.einsum("xchw,yhw->xyc", feats.float(), m) / area[None, :, None]
    own = pooled[torch.arange(k), torch.arange(k)][:, None].expand(k, k, c)
    return off_diagonal(torch.cat([pooled, own], -1).numpy()).astype(np.float32)


def with_decoder(
    train: Pairs, val: Pairs, dec_train: np.ndarray, dec_val: np.ndarray, cfg: BoxHeadConfig
) -> dict[str, tuple[Pairs, Pairs, BoxHeadConfig]]:
    """name -> (training pairs, val pairs, head config) of the decoder variants: the stage's
    train and val pairs, their features widened by the decoder's (other box; both boxes)."""
    keep_tr = _first_scenes(train, cfg.train_scenes)
    keep_va = _first_scenes(val, cfg.val_scenes)
    c = dec_train.shape[1] // 2
    out = {}
    for name, cols in (("other box", slice(0, c)), ("both boxes", slice(0, 2 * c))):
        tr = Pairs(np.concatenate([train.x, dec_train[:, cols]], 1), train.y, train.rows)
        va = Pairs(np.concatenate([val.x, dec_val[:, cols]], 1), val.y, val.rows)
        out[f"stage + decoder ({name})"] = (_subset(tr, keep_tr), _subset(va, keep_va), cfg)
    return out


def score(train: Pairs, val: Pairs, cfg: BoxHeadConfig, seed: int) -> dict[str, Any]:
    """Train as the stage does; val loss and, per output, AUROC and best-threshold F1."""
    model, log, best_epoch = train_box_head(train, val, cfg, seed)
    p = predict_pairs(model, val.x)
    row: dict[str, Any] = {
        "train_scenes": int(train.rows["scene"].nunique()),
        "train_pairs": len(train),
        "hidden": cfg.hidden,
        "best_epoch": best_epoch,
        "val_loss": float(log["val_loss"].min()),
    }
    for j, out in enumerate(OUTPUTS):
        s = binary_scores(p[:, j], val.y[:, j], choose_threshold(p[:, j], val.y[:, j]))
        row[f"{out}_auroc"], row[f"{out}_f1"] = s["auroc"], s["f1"]
    return row


def _collect_with_decoder(
    scenes: Any, predictor: Any, label: str, total: int
) -> tuple[Pairs, np.ndarray]:
    """support.box_train.collect, and each pair's decoder features (the input of the
    predictor's output conv, caught by a forward hook)."""
    from clutterbench.progress import progress_bar
    from clutterbench.support.box_train import cp_probs, scene_pairs

    caught: list[torch.Tensor] = []
    hook = predictor.model.head.register_forward_hook(lambda m, i, o: caught.append(i[0]))
    parts, dec = [], []
    try:
        with progress_bar(label, total=total) as advance:
            for scene in scenes:
                if len(scene.ids) > 1:
                    caught.clear()
                    parts.append(scene_pairs(scene, cp_probs(predictor, scene)))
                    dec.append(decoder_pair_features(torch.cat(caught), scene.masks))
                advance(1)
    finally:
        hook.remove()
    return _join(parts), np.concatenate(dec)


def _collect(
    params: Mapping[str, Any],
) -> tuple[Pairs, Pairs, np.ndarray, np.ndarray, BoxHeadConfig, int]:
    from clutterbench.collapse.predict import CollapsePredictor
    from clutterbench.config import load_base, load_section
    from clutterbench.criteria import label_thresholds
    from clutterbench.data.shards import load_split
    from clutterbench.precision import inference_from_params
    from clutterbench.sim.config import SimConfig
    from clutterbench.support.config import SupportEvalConfig
    from clutterbench.support.evaluate import split_scenes

    cfg = load_section(SupportEvalConfig, "support", params)
    sim = load_section(SimConfig, "sim", params)
    inference_from_params(params)
    gen, split_file = Path("data/generate"), Path(f"data/split/{cfg.val_dataset}.json")
    predictor = CollapsePredictor.from_checkpoint(
        Path(f"models/{cfg.model}/best.pt"), image_size=sim.camera.image_size
    )
    record = load_split(split_file, gen)
    read: dict[str, Any] = {
        "threshold_m": cfg.moved_threshold_m,
        "min_pixels": cfg.min_pixels,
        "camera": sim.camera,
        "heads": EDGE_HEADS,
        "collapse_free": label_thresholds(params),
    }
    got = []
    for split in ("train", "val"):
        scenes = split_scenes(gen, split_file, split, len(record[split]), **read)
        label = f"box_head_data: {split} scenes"
        got.append(_collect_with_decoder(scenes, predictor, label, len(scenes)))
    (train, dec_train), (val, dec_val) = got
    return train, val, dec_train, dec_val, cfg.box_head, load_base(params).seed


def recheck(params: Mapping[str, Any], out_dir: Path = OUT) -> dict[str, Any]:
    started = time.perf_counter()
    train, val, dec_train, dec_val, cfg, seed = _collect(params)
    named, val_pairs = variants(train, val, cfg)
    rows = {name: score(tr, val_pairs, c, seed) for name, (tr, c) in named.items()}
    for name, (tr, va, c) in with_decoder(train, val, dec_train, dec_val, cfg).items():
        rows[name] = score(tr, va, c, seed)
    stage = rows["stage"]["pull_collapse_auroc"]
    best = max(rows, key=lambda k: rows[k]["pull_collapse_auroc"])
    result = {
        "val_scenes": int(val_pairs.rows["scene"].nunique()),
        "val_pairs": len(val_pairs),
        "rows": rows,
        "shows": (
            f"box_head_data: pull_collapse val AUROC {stage:.4f} as the stage trains; best "
            f"{best} {rows[best]['pull_collapse_auroc']:.4f} "
            f"({rows[best]['pull_collapse_auroc'] - stage:+.4f})"
        ),
    }
    return save(result, started, out_dir, NAME, markdown)


def markdown(result: Mapping[str, Any]) -> str:
    lines = [
        "# What the box head learns from: scenes and width",
        "",
        f"`python -m experiments.box_head_data` (module docstring: what each row trains "
        f"on). Every row scored on the stage's val pairs: {result['val_pairs']} pairs of "
        f"{result['val_scenes']} val scenes; never the test dataset. "
        f"{result['seconds'] / 60:.1f} min.",
        "",
        "| trained on | scenes | pairs | hidden | best epoch | val loss | "
        + " | ".join(f"{o} AUROC | {o} F1" for o in OUTPUTS)
        + " |",
        "|---|---|---|---|---|---|" + "---|---|" * len(OUTPUTS),
    ]
    for name, r in result["rows"].items():
        cells = " | ".join(f"{r[f'{o}_auroc']:.4f} | {r[f'{o}_f1']:.4f}" for o in OUTPUTS)
        lines.append(
            f"| {name} | {r['train_scenes']} | {r['train_pairs']} | {r['hidden']} | "
            f"{r['best_epoch']} | {r['val_loss']:.4f} | {cells} |"
        )
    lines += ["", result["shows"]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    run_command(recheck, NAME)
