"""Figure like thesis Fig. 4.8: one scene, one target, the network's output for several
choices of the box to hold: extracted E (green), supported S (blue), predicted collapse C
(red), and the risk index r_c of each choice (eq. 4.1), the least first."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from clutterbench.io import atomic_path  # noqa: E402
from clutterbench.planning.risk import CLASSES, PIXEL_THRESHOLD  # noqa: E402

COLOURS = {"E": (0.1, 0.8, 0.2), "S": (0.2, 0.4, 1.0), "C": (1.0, 0.1, 0.1)}
"""Thesis Fig. 4.8: green extracted, blue supported, red collapsing region."""
MAX_CHOICES = 4
DPI = 80


def _grey(depth_m: np.ndarray) -> np.ndarray:
    valid = depth_m > 0
    if not valid.any():
        return np.zeros((*depth_m.shape, 3))
    lo, hi = np.percentile(depth_m[valid], [1, 99])
    g = 1.0 - np.clip((depth_m - lo) / max(hi - lo, 1e-6), 0, 1)  # near = light
    g[~valid] = 0.0
    return np.repeat(g[..., None], 3, axis=-1)


def overlay(depth_m: np.ndarray, probs: np.ndarray, threshold: float = PIXEL_THRESHOLD):
    """(H, W, 3) depth in grey with each class region (probability > threshold) tinted; C is
    drawn last, so collapse shows over E and S."""
    img = _grey(depth_m)
    for name in ("E", "S", "C"):
        region = probs[CLASSES.index(name)] > threshold
        img[region] = 0.45 * img[region] + 0.55 * np.array(COLOURS[name])
    return img


def risk_figure(
    out_path: Path,
    depth_m: np.ndarray,
    target_mask: np.ndarray,
    supports: list[str],
    probs: np.ndarray,
    risks: np.ndarray,
    title: str,
    threshold: float = PIXEL_THRESHOLD,
) -> None:
    """Depth with the target outlined, then the MAX_CHOICES choices of least risk.

    supports: one label per candidate; probs (A, 4, H, W) in planning.risk.CLASSES order;
    risks (A,)."""
    assert len(supports) == len(probs) == len(risks), "one label, map and risk per candidate"
    order = np.argsort(risks, kind="stable")[:MAX_CHOICES]
    n = 1 + len(order)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 2.9), squeeze=False)
    ax = axes[0, 0]
    ax.imshow(_grey(depth_m), interpolation="nearest")
    ax.contour(target_mask.astype(float), levels=[0.5], colors=[COLOURS["E"]], linewidths=1.5)
    ax.set_title("depth, target outlined", fontsize=8)
    for i, k in enumerate(order, start=1):
        ax = axes[0, i]
        ax.imshow(overlay(depth_m, probs[k], threshold), interpolation="nearest")
        letter = "abcdefgh"[i - 1]
        ax.set_title(f"({letter}) hold {supports[k]}: r_c = {risks[k]:.3f}", fontsize=8)
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with atomic_path(Path(out_path)) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png", metadata={"Software": None})
    plt.close(fig)
