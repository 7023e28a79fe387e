"""Figure like thesis Fig. 6.8: depth images with the true support relations (pink) and the
inferred ones (white) drawn as arrows from supporter to supported box; every box outlined
and numbered with its index, and a legend of both."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from clutterbench.errors import ClutterbenchError  # noqa: E402
from clutterbench.io import atomic_path  # noqa: E402

MAX_PANELS = 6
COLS = 3
TRUE_STYLE = {"color": "#ff1493", "lw": 4.0, "linestyle": "-"}
"""Ground truth: thick deep pink, drawn under the inferred edges (thesis Fig. 6.8: pink)."""
INFERRED_STYLE = {
    "color": "white",
    "lw": 1.5,
    "linestyle": "--",
    "path_effects": [patheffects.withStroke(linewidth=2.5, foreground="black")],
}
"""Inferred: thin white dashed on top, so an edge in both shows white on pink; a dark rim
keeps it visible on near (light) boxes."""
DPI = 80


@dataclasses.dataclass
class SupportPanel:
    """One scene of the figure."""

    depth_m: np.ndarray
    """(H, W) float32 depth in metres (0: no return)."""
    masks: np.ndarray
    """(K, H, W) bool visible box masks."""
    ids: list[int]
    """Box id of each mask."""
    inferred: set[tuple[int, int]]
    """(supporter, supported) box ids the method inferred."""
    true: set[tuple[int, int]]
    """(supporter, supported) box ids of the physics ground truth."""
    label: str
    """Panel title, e.g. the scene index and family."""


def centroids_px(masks: np.ndarray, ids: Sequence[int]) -> dict[int, tuple[float, float]]:
    """Box id -> (x, y) pixel centroid of its mask; boxes with an empty mask are left out."""
    out = {}
    for box, mask in zip(ids, masks):
        ys, xs = np.nonzero(mask)
        if xs.size:
            out[int(box)] = (float(xs.mean()), float(ys.mean()))
    return out


def _arrow(ax, a: tuple[float, float], b: tuple[float, float], style: dict, z: int) -> None:
    ax.annotate(
        "",
        xy=b,
        xytext=a,
        arrowprops={
            "arrowstyle": "-|>",
            "mutation_scale": 12,
            "shrinkA": 4,
            "shrinkB": 4,
            **style,
        },
        zorder=z,
    )


def _draw(ax, panel: SupportPanel) -> None:
    depth, masks = panel.depth_m, panel.masks
    assert depth.ndim == 2 and depth.dtype == np.float32, "depth_m must be (H, W) float32 m"
    assert masks.ndim == 3 and masks.dtype == np.bool_, "masks must be (K, H, W) bool"
    assert masks.shape[1:] == depth.shape and len(panel.ids) == len(masks), "masks match ids"
    valid = depth[depth > 0]
    lo, hi = (float(valid.min()), float(valid.max())) if valid.size else (0.0, 1.0)
    ax.imshow(depth, cmap="gray_r", vmin=lo, vmax=hi, interpolation="nearest")
    colors = plt.get_cmap("tab10")
    for k, mask in enumerate(masks):
        if mask.any():
            ax.contour(mask.astype(np.float32), levels=[0.5], colors=[colors(k % 10)], linewidths=1)
    at = centroids_px(masks, panel.ids)
    hidden = 0
    for edges, style, z in ((panel.true, TRUE_STYLE, 3), (panel.inferred, INFERRED_STYLE, 4)):
        for supporter, supported in sorted(edges):
            if supporter in at and supported in at:
                _arrow(ax, at[supporter], at[supported], style, z)
            elif edges is panel.true:
                hidden += 1
    for box, (x, y) in sorted(at.items()):
        ax.text(
            x,
            y,
            str(box),
            ha="center",
            va="center",
            fontsize=8,
            zorder=5,
            bbox={"boxstyle": "round,pad=0.15", "fc": "black", "ec": "none", "alpha": 0.6},
            color="white",
        )
    true = f"true {len(panel.true)}" + (f" ({hidden} with a hidden box)" if hidden else "")
    both = len(panel.inferred & panel.true)
    ax.set_title(f"{panel.label}\n{true}, inferred {len(panel.inferred)}, both {both}", fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])


def support_figure_fig(panels: Sequence[SupportPanel], title: str) -> Figure:
    """The figure of `support_figure`, not yet written."""
    if not 0 < len(panels) <= MAX_PANELS:
        raise ClutterbenchError(f"support figure: 1 to {MAX_PANELS} panels, got {len(panels)}")
    cols = min(COLS, len(panels))
    rows = math.ceil(len(panels) / COLS)
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.2 * cols, 3.5 * rows + 0.8), squeeze=False, layout="constrained"
    )
    for ax in axes.flat[len(panels) :]:
        ax.axis("off")
    for ax, panel in zip(axes.flat, panels):
        _draw(ax, panel)
    legend = [
        Line2D([], [], **TRUE_STYLE, label="true (physics)"),
        Line2D([], [], **INFERRED_STYLE, label="inferred"),
        Line2D([], [], color=plt.get_cmap("tab10")(0), lw=1, label="box outline"),
        Patch(facecolor="black", alpha=0.6, label="n: box index"),
    ]
    fig.legend(
        handles=legend,
        loc="outside lower center",
        ncol=len(legend),
        fontsize=8,
        facecolor="0.55",
        title="support X -> Y: the arrow points from supporter X to supported Y",
        title_fontsize=8,
    )
    fig.suptitle(title, fontsize=10)
    return fig


def support_figure(panels: Sequence[SupportPanel], out_path: Path, title: str) -> None:
    """Up to six scenes in two rows of three, written atomically as a PNG whose bytes
    depend only on the panels (fixed dpi, no software or time stamp)."""
    fig = support_figure_fig(panels, title)
    with atomic_path(Path(out_path)) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, metadata={"Software": None})
    plt.close(fig)
