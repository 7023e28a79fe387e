"""Figures of the chapter 3 slide ConvNet: its calibration on the validation piles, and the
candidate slides of a few validation piles coloured by probability (thesis Fig. 3.12)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from clutterbench.io import atomic_path  # noqa: E402

BANDS = (
    (0.99, 1.01, "red", "> 99%"),
    (0.80, 0.99, "gold", "80-98%"),
    (0.5, 0.80, "grey", "50-79%"),
)
"""Thesis Fig. 3.12's colour bands of P(success) (display only)."""
LINE_M = 0.025
"""Length of a drawn candidate line on the board."""


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)


def calibration_figure(val: Mapping[str, Any], path: Path) -> None:
    """Simulated success rate against the ConvNet's predicted probability, per bin, with the
    bin counts."""
    rows = [r for r in val["calibration"] if r[2]]
    fig, ax = plt.subplots(figsize=(4.2, 3.8))
    ax.plot([0, 1], [0, 1], color="lightgrey", lw=1, label="perfect calibration")
    if rows:
        pred = [r[3] for r in rows]
        rate = [r[4] for r in rows]
        ax.plot(pred, rate, "o-", color="tab:blue", label="ConvNet (validation piles)")
        for p, r, row in zip(pred, rate, rows):
            ax.annotate(str(row[2]), (p, r), fontsize=7, xytext=(3, -9), textcoords="offset points")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("predicted P(success)")
    ax.set_ylabel("simulated success rate")
    ax.set_title(
        f"slide ConvNet calibration, accuracy {val['accuracy']:.3f} (n {val['n']})", fontsize=9
    )
    ax.legend(loc="upper left", fontsize=7)
    _save(fig, path)


def draw_candidates(ax, obs, cands, probs: np.ndarray, n_directions: int) -> None:
    """The top height image, every candidate's start point, and a line along each candidate
    whose probability falls in a band of `BANDS`."""
    from clutterbench.data.slide_crops import height_image

    ax.imshow(height_image(obs), cmap="gray", vmin=0, vmax=0.05)
    u, v, _ = obs.camera.world_to_pixel(np.column_stack([cands.start_xy, np.zeros(len(cands))]))
    ax.plot(u - 0.5, v - 0.5, ".", color="tab:cyan", ms=1.5)
    for lo, hi, colour, _ in reversed(BANDS):
        for k in np.nonzero((probs >= lo) & (probs < hi))[0]:
            theta = cands.direction[k] * 2 * np.pi / n_directions
            end = cands.start_xy[k] + LINE_M * np.array([np.cos(theta), np.sin(theta)])
            pts = np.array([[*cands.start_xy[k], 0.0], [*end, 0.0]])
            pu, pv, _ = obs.camera.world_to_pixel(pts)
            ax.plot(pu - 0.5, pv - 0.5, color=colour, lw=1.0)
    ax.set_xticks([])
    ax.set_yticks([])


def candidates_figure(model, seeds: Sequence[int], pile, camera, scan, path: Path) -> None:
    """Thesis Fig. 3.12 on simulated piles: the candidates of each pile's raster scan,
    coloured by the ConvNet's probability (`pile`, `camera`, `scan`: the yamakuzushi
    params)."""
    from clutterbench.data.slide_crops import (
        height_image,
        piece_under,
        raster_candidates,
        slide_crops,
        subset,
    )
    from clutterbench.models.slide_convnet import success_probability
    from clutterbench.sim.pile import PileWorld, generate_pile, top_observation

    fig, axes = plt.subplots(1, len(seeds), figsize=(3.0 * len(seeds), 3.3), squeeze=False)
    for ax, seed in zip(axes[0], seeds):
        world = PileWorld.from_spec(generate_pile(pile, seed), pile, render=True)
        obs = top_observation(world, camera)
        cands = raster_candidates(scan)
        on = np.nonzero(piece_under(obs, cands.start_xy, scan.edge_margin_px) >= 0)[0]
        crops = slide_crops(height_image(obs), obs.camera, subset(cands, on), scan)
        probs = np.zeros(len(cands))
        probs[on] = success_probability(model, crops).numpy()
        draw_candidates(ax, obs, cands, probs, scan.n_directions)
        ax.set_title(f"pile seed {seed}: best {probs.max():.2f}", fontsize=8)
    handles = [plt.Line2D([], [], color=c, label=lab) for _, _, c, lab in BANDS]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7)
    fig.subplots_adjust(bottom=0.12)
    _save(fig, path)
