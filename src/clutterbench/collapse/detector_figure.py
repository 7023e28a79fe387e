"""Figures of the arrangement detector: labelled boxes on test depth images beside the
ground truth (like thesis Fig. 5.3), and the precision-recall curve of each class."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from clutterbench.collapse.detection_metrics import ClassPR, Dets, Truth  # noqa: E402
from clutterbench.io import atomic_path  # noqa: E402
from clutterbench.perception.boxes import ARRANGEMENT_CLASSES, corners_px  # noqa: E402

CLASS_COLOURS = ("tab:blue", "tab:green", "tab:red", "tab:orange")
"""One colour per class, in ARRANGEMENT_CLASSES order."""


def figure_scenes(classes: Sequence[np.ndarray], n: int) -> list[int]:
    """`n` scene positions to show: first the first scene holding each class (so every class
    appears), then evenly spaced others; sorted."""
    chosen: list[int] = []
    for c in range(len(ARRANGEMENT_CLASSES)):
        hit = next((i for i, cls in enumerate(classes) if c in cls and i not in chosen), None)
        if hit is not None and len(chosen) < n:
            chosen.append(hit)
    for i in np.linspace(0, len(classes) - 1, num=max(n, 1)).round().astype(int):
        if len(chosen) < min(n, len(classes)) and int(i) not in chosen:
            chosen.append(int(i))
    return sorted(chosen)


def _draw(ax, depth_m: np.ndarray, boxes: np.ndarray, classes: np.ndarray, scores) -> None:
    valid = depth_m[depth_m > 0]
    lo, hi = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
    ax.imshow(depth_m, cmap="gray_r", vmin=lo, vmax=hi)
    for k, (x0, y0, x1, y1) in enumerate(corners_px(boxes)):
        colour = CLASS_COLOURS[int(classes[k])]
        # pixel (i, j) is drawn centred on (j, i): box edges sit half a pixel before
        ax.add_patch(
            Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, lw=1.5, ec=colour)
        )
        label = ARRANGEMENT_CLASSES[int(classes[k])]
        if scores is not None:
            label += f" {scores[k]:.2f}"
        ax.text(
            x0 - 0.5,
            y0 - 1.5,
            label,
            color="white",
            fontsize=6,
            va="bottom",
            bbox={"facecolor": colour, "edgecolor": "none", "pad": 0.5},
        )
    ax.set_xticks([])
    ax.set_yticks([])


def detection_figure(
    depth_m: np.ndarray, dets: Sequence[Dets], truth: Sequence[Truth], title: str, path: Path
) -> None:
    """Rows of (prediction, ground truth) pairs, two pairs per row; depth (N, H, W)."""
    n = len(depth_m)
    rows = -(-n // 2)
    fig, axes = plt.subplots(rows, 4, figsize=(9.0, 2.3 * rows + 0.6), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for i in range(n):
        pred_ax, truth_ax = axes[i // 2, 2 * (i % 2)], axes[i // 2, 2 * (i % 2) + 1]
        pred_ax.axis("on")
        truth_ax.axis("on")
        boxes, scores, classes = dets[i]
        _draw(pred_ax, depth_m[i], boxes, classes, scores)
        _draw(truth_ax, depth_m[i], truth[i][0], truth[i][1], None)
        pred_ax.set_title("predicted", fontsize=8)
        truth_ax.set_title("ground truth", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)


def pr_figure(prs: Sequence[ClassPR], title: str, path: Path) -> None:
    """Precision over recall of each class, AP in the legend."""
    fig, ax = plt.subplots(figsize=(4.6, 3.8))
    for name, colour, pr in zip(ARRANGEMENT_CLASSES, CLASS_COLOURS, prs):
        if pr.n_truth == 0:
            continue
        recall = np.concatenate([[0.0], pr.recall])
        precision = np.concatenate([[1.0], pr.precision])
        ax.plot(recall, precision, color=colour, label=f"{name} AP {pr.ap():.3f}")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
