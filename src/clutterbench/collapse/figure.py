"""Figure like thesis Fig. 5.8 / 6.5 (and 4.8): depth, input masks, predicted heatmap,
ground truth."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from clutterbench.io import atomic_path  # noqa: E402


def ground_truth_rgb(masks: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Thesis Fig. 5.8 (d) / 4.8: collapse regions red, target (extracted object) green,
    supported object blue, on black. masks: (H, W) target or (n_masks, H, W)."""
    masks = masks.reshape(-1, *truth.shape)
    rgb = np.zeros((*truth.shape, 3), dtype=np.float32)
    rgb[truth > 0.5, 0] = 1.0
    for channel, mask in zip((1, 2), masks):
        rgb[mask > 0.5, channel] = 1.0
    return rgb


def masks_image(masks: np.ndarray) -> np.ndarray:
    """One mask as a grey image; extraction and support masks as green and blue."""
    if masks.ndim == 2 or len(masks) == 1:
        return masks.reshape(masks.shape[-2:])
    return ground_truth_rgb(masks, np.zeros(masks.shape[-2:]))


def collapse_figure(samples: dict[str, np.ndarray], title: str, path: Path) -> None:
    """One column per sample; rows: depth, input masks, heatmap in [0, 1], ground truth."""
    n = len(samples["depth_m"])
    fig, axes = plt.subplots(4, n, figsize=(1.6 * n + 0.8, 7.4), squeeze=False)
    n_masks = samples["target"].shape[1] if samples["target"].ndim == 4 else 1
    masks = "target mask" if n_masks == 1 else "extract / support"
    rows = ("depth (m)", masks, "collapse map", "ground truth")
    for j in range(n):
        depth = samples["depth_m"][j]
        valid = depth[depth > 0]
        lo, hi = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
        axes[0, j].imshow(depth, cmap="gray_r", vmin=lo, vmax=hi)
        axes[1, j].imshow(masks_image(samples["target"][j]), cmap="gray", vmin=0, vmax=1)
        heat = axes[2, j].imshow(samples["prob"][j], cmap="jet", vmin=0, vmax=1)
        axes[3, j].imshow(ground_truth_rgb(samples["target"][j], samples["truth"][j]))
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    for i, label in enumerate(rows):
        axes[i, 0].set_ylabel(label)
    fig.colorbar(heat, ax=axes[2, :].tolist(), fraction=0.02, pad=0.01, label="P(collapse)")
    legend = [
        Patch(facecolor=(0, 1, 0), label="target (extracted)"),
        *([Patch(facecolor=(0, 0, 1), label="supported (held)")] if n_masks > 1 else []),
        Patch(facecolor=(1, 0, 0), label="collapsing (moved)"),
    ]
    fig.legend(handles=legend, loc="lower center", ncol=len(legend), fontsize=8, frameon=False)
    fig.suptitle(title)
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=80, metadata={"Software": None})
    plt.close(fig)
