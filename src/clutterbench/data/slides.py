"""The chapter 3 ConvNet dataset (thesis 3.3.2, 3.5.1): depth crops of slide candidates,
each labelled by simulating its slide from the pile's canonical start.

The thesis annotated its simulated depth images by hand; here each label is physics: a
candidate (start point, direction) of the raster scan (planning.yamakuzushi) selects the
piece seen at its start point, and that piece is slid in that direction from a fresh world
built from the settled pile (sim.pile.slide): success when it leaves the board and no other
piece moves beyond the threshold. Every candidate on the same piece and direction shares
one simulation; its crops differ by start point. The samples are balanced 50/50 (as the
thesis' 6,000 / 6,000) by keeping every sample of the rarer label and an equal random draw
of the other; piles, not crops, are split into train and validation (90 / 10), so no
validation crop shows a training pile.
"""

from __future__ import annotations

import dataclasses
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.config import as_dict, bounded, cores_field
from clutterbench.data.slide_crops import (
    ScanConfig,
    height_image,
    piece_under,
    raster_candidates,
    slide_crops,
    subset,
)
from clutterbench.errors import ClutterbenchError
from clutterbench.io import load_npz, save_npz, write_json
from clutterbench.parallel import ParallelConfig, map_in_workers
from clutterbench.sim.pile_config import PileCameraConfig, PileConfig, SlideConfig

CROP_DTYPE = np.float16
"""Crops are stored as float16 metres (0.1 mm steps near a piece's height: plenty)."""


@dataclasses.dataclass(frozen=True)
class SlideDataConfig:
    n_piles: int = bounded(150, ge=2)
    """Piles generated for the dataset (seed stream ch3_data)."""
    slides_per_pile: int = bounded(24, ge=1)
    """Distinct (piece, direction) slides simulated per pile (drawn among those the raster
    scan hits); every raster candidate on a simulated slide becomes a sample."""
    n_samples: int = bounded(6000, ge=4)
    """Samples kept after balancing (at most; half success, half failure; thesis 12,000)."""
    val_fraction: float = bounded(0.1, gt=0.0, le=0.5)
    """Fraction of the piles held out for validation (thesis 10%)."""
    workers: int = cores_field(2)
    """Worker processes simulating piles; auto: base.cores."""


def pile_seed(base_seed: int, stream: str, index: int) -> int:
    """The seed of pile `index` of a seed stream (ch3_data, ch3_games, ...)."""
    return zlib.crc32(f"{base_seed}/{stream}/{index}".encode())


def label_pile(job: dict[str, Any]) -> dict[str, np.ndarray]:
    """One pile's samples: crops, labels and what each crop is (run in a worker)."""
    from clutterbench.sim.pile import PileWorld, generate_pile, slide, top_observation

    pile_cfg, slide_cfg, cam = job["pile"], job["slide"], job["camera"]
    scan: ScanConfig = job["scan"]
    spec = generate_pile(pile_cfg, job["seed"])
    world = PileWorld.from_spec(spec, pile_cfg, render=True)
    obs = top_observation(world, cam)
    cands = raster_candidates(scan)
    pieces = piece_under(obs, cands.start_xy, scan.edge_margin_px)
    hit = np.nonzero(pieces >= 0)[0]
    slides = sorted({(int(pieces[k]), int(cands.direction[k])) for k in hit})
    rng = np.random.default_rng(job["seed"])
    chosen = [slides[i] for i in sorted(rng.permutation(len(slides))[: job["slides_per_pile"]])]
    step = 2 * np.pi / scan.n_directions
    outcome = {}
    for piece, d in chosen:
        result = slide(PileWorld.from_spec(spec, pile_cfg), piece, d * step, slide_cfg)
        outcome[(piece, d)] = result.success
    keep = np.array(
        [k for k in hit if (int(pieces[k]), int(cands.direction[k])) in outcome], dtype=np.int64
    )
    crops = slide_crops(height_image(obs), obs.camera, subset(cands, keep), scan)
    labels = [outcome[(int(pieces[k]), int(cands.direction[k]))] for k in keep]
    return {
        "crops": crops.astype(CROP_DTYPE),
        "label": np.array(labels, dtype=np.uint8),
        "candidate": keep,
        "piece": pieces[keep].astype(np.int16),
        "pile": np.full(len(keep), job["index"], dtype=np.int32),
        "slides": np.array(len(outcome), dtype=np.int64),
        "slide_success": np.array(sum(outcome.values()), dtype=np.int64),
    }


def balance(labels: np.ndarray, n_samples: int, seed: int) -> np.ndarray:
    """Sorted indices of at most `n_samples` samples, half of each label (all of the rarer
    label when it has fewer than n_samples / 2)."""
    rng = np.random.default_rng(seed)
    pos, neg = np.nonzero(labels == 1)[0], np.nonzero(labels == 0)[0]
    per = min(len(pos), len(neg), n_samples // 2)
    if per == 0:
        raise ClutterbenchError(
            f"slide dataset: {len(pos)} successes and {len(neg)} failures; both are needed "
            "(more piles: yamakuzushi.data.n_piles)"
        )
    picked = [rng.choice(pos, per, replace=False), rng.choice(neg, per, replace=False)]
    return np.sort(np.concatenate(picked))


def generate_slide_dataset(
    data: SlideDataConfig,
    pile: PileConfig,
    slide_cfg: SlideConfig,
    camera: PileCameraConfig,
    scan: ScanConfig,
    seed: int,
    out_dir: Path,
    parallel: ParallelConfig | None = None,
) -> dict[str, Any]:
    """data/ch3_slides/{samples.npz, manifest.json}; returns the manifest. `parallel`: the
    backend the piles are simulated on (None: worker processes)."""
    jobs = [
        {
            "index": i,
            "seed": pile_seed(seed, "ch3_data", i),
            "pile": pile,
            "slide": slide_cfg,
            "camera": camera,
            "scan": scan,
            "slides_per_pile": data.slides_per_pile,
        }
        for i in range(data.n_piles)
    ]
    parts = map_in_workers("ch3 slide data", label_pile, jobs, data.workers, parallel)
    merged = {
        k: np.concatenate([p[k] for p in parts])
        for k in ("crops", "label", "candidate", "piece", "pile")
    }
    keep = balance(merged["label"], data.n_samples, seed)
    samples = {k: v[keep] for k, v in merged.items()}
    rng = np.random.default_rng(pile_seed(seed, "ch3_split", 0))
    n_val = max(1, int(round(data.val_fraction * data.n_piles)))
    val_piles = np.sort(rng.permutation(data.n_piles)[:n_val])
    samples["val"] = np.isin(samples["pile"], val_piles).astype(np.uint8)
    save_npz(out_dir / "samples.npz", samples)
    n_slides = int(sum(int(p["slides"]) for p in parts))
    manifest = {
        "n_piles": data.n_piles,
        "slides_simulated": n_slides,
        "slides_successful": int(sum(int(p["slide_success"]) for p in parts)),
        "candidates_labelled": int(len(merged["label"])),
        "candidates_successful": int(merged["label"].sum()),
        "n_samples": int(len(keep)),
        "n_success": int(samples["label"].sum()),
        "n_train": int((samples["val"] == 0).sum()),
        "n_val": int(samples["val"].sum()),
        "val_piles": [int(i) for i in val_piles],
        "crop_px": scan.crop_px,
        "config": {
            "data": as_dict(data),
            "pile": as_dict(pile),
            "slide": as_dict(slide_cfg),
            "camera": as_dict(camera),
            "scan": as_dict(scan),
            "seed": seed,
        },
    }
    write_json(out_dir / "manifest.json", manifest)
    return manifest


def load_slide_samples(path: Path) -> dict[str, np.ndarray]:
    """The samples of `generate_slide_dataset` (one-line errors for a missing or corrupt
    file)."""
    return load_npz(path, ["crops", "label", "pile", "val"])
