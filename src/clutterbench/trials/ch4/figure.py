"""Figure like thesis Fig. 4.8: one scene, one target, the network's output for several
choices of the box to hold: extracted E (green), supported S (blue), predicted collapse C
(red), and the risk index r_c of each choice (eq. 4.1), the least first. A legend names the
colours; given the boxes' masks, every panel numbers the boxes as the planner names them.

Stage trials_ch4 draws it (reports/trials_ch4/fig_4_8.png) by re-running one decision of a
risk condition, so it lives with the ch. 4 trials: no stage but report imports report/."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from clutterbench.io import atomic_path  # noqa: E402
from clutterbench.planning.ch4.risk import CLASSES, PIXEL_THRESHOLD  # noqa: E402

COLOURS = {"E": (0.1, 0.8, 0.2), "S": (0.2, 0.4, 1.0), "C": (1.0, 0.1, 0.1)}
"""Thesis Fig. 4.8: green extracted, blue supported, red collapsing region."""
LEGEND = {"E": "E: extracted", "S": "S: supported (held)", "C": "C: predicted collapse"}
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


def _number_boxes(ax, masks: np.ndarray, labels: Sequence[str]) -> None:
    """Each box's label at the centroid of its visible mask."""
    for mask, label in zip(masks, labels):
        ys, xs = np.nonzero(mask)
        if xs.size:
            ax.text(
                float(xs.mean()),
                float(ys.mean()),
                label,
                ha="center",
                va="center",
                fontsize=7,
                color="white",
                bbox={"boxstyle": "round,pad=0.12", "fc": "black", "ec": "none", "alpha": 0.6},
            )


def risk_figure_fig(
    depth_m: np.ndarray,
    target_mask: np.ndarray,
    supports: list[str],
    probs: np.ndarray,
    risks: np.ndarray,
    title: str,
    threshold: float = PIXEL_THRESHOLD,
    box_masks: np.ndarray | None = None,
    box_labels: Sequence[str] | None = None,
) -> Figure:
    """The figure of `risk_figure`, not yet written (see there)."""
    assert len(supports) == len(probs) == len(risks), "one label, map and risk per candidate"
    if box_masks is not None:
        assert box_labels is not None and len(box_labels) == len(box_masks), "a label per mask"
    order = np.argsort(risks, kind="stable")[:MAX_CHOICES]
    n = 1 + len(order)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 3.3), squeeze=False)
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
        if box_masks is not None:
            _number_boxes(ax, box_masks, box_labels)
        ax.set_axis_off()
    handles = [
        Line2D([], [], color=COLOURS["E"], lw=1.5, label="target outline"),
        *(Patch(facecolor=COLOURS[c], label=LEGEND[c]) for c in ("E", "S", "C")),
    ]
    if box_masks is not None:
        handles.append(Patch(facecolor="black", alpha=0.6, label="n: box index"))
    fig.legend(
        handles=handles,
        loc="lower center",
        ncol=len(handles),
        fontsize=7,
        frameon=False,
        title=f"class regions: probability > {threshold:g}",
        title_fontsize=7,
    )
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    return fig


def risk_figure(
    out_path: Path,
    depth_m: np.ndarray,
    target_mask: np.ndarray,
    supports: list[str],
    probs: np.ndarray,
    risks: np.ndarray,
    title: str,
    threshold: float = PIXEL_THRESHOLD,
    box_masks: np.ndarray | None = None,
    box_labels: Sequence[str] | None = None,
) -> None:
    """Depth with the target outlined, then the MAX_CHOICES choices of least risk, with a
    legend of the colours; written as a PNG whose bytes depend only on the inputs.

    supports: one label per candidate; probs (A, 4, H, W) in planning.risk.CLASSES order;
    risks (A,). box_masks (K, H, W) with box_labels (K,): each box's number on every panel
    (the names `supports` uses, e.g. the box index)."""
    fig = risk_figure_fig(
        depth_m, target_mask, supports, probs, risks, title, threshold, box_masks, box_labels
    )
    with atomic_path(Path(out_path)) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png", metadata={"Software": None})
    plt.close(fig)


def draw_figure(job: Any, out_path: Path) -> None:
    """Thesis Fig. 4.8 from one episode of a risk condition in target mode: its scene, its
    target, the network's E / S / C for the supports of least risk (run in this process).
    The simulator and the trials' helpers load only when it is called: drawing a figure of
    given maps (`risk_figure`) loads no SAPIEN."""
    from clutterbench.errors import ClutterbenchError
    from clutterbench.planning.ch4.risk_planner import plan_risk
    from clutterbench.sim.physics import BoxWorld
    from clutterbench.sim.renderer import ensure_renderer
    from clutterbench.trials.ch4.episodes import observe_and_segment, target_segment
    from clutterbench.trials.core.harness import load_predictor

    cond, params = job.cond, job.params
    ensure_renderer()
    start = job.start
    spec = start.spec()
    world = BoxWorld.from_spec(spec, job.physics, render=True)
    obs, seg, _, _ = observe_and_segment(world, spec, job)
    box = start.target(obs, params.min_target_pixels, spec)
    k = target_segment(seg, obs.instance, box)
    if k is None or len(seg.ids) < 2:
        raise ClutterbenchError(f"figure: episode {job.index} has no target segment to draw")
    predictor = load_predictor(job.model_path, job.camera.image_size)
    _, pairs, risks, probs = plan_risk(predictor, obs, seg, k, params.pixel_threshold)
    labels = [
        f"segment {s}" if cond.perception == "depth" else f"box {seg.ids[s]}" for _, s in pairs
    ]
    risk_figure(
        out_path,
        obs.depth_m,
        seg.masks[k],
        labels,
        probs,
        risks,
        f"{job.condition}, episode {job.index}: extract box {box} (model {cond.model})",
        params.pixel_threshold,
        box_masks=seg.masks,
        box_labels=[str(s) for s in range(len(seg.ids))]
        if cond.perception == "depth"
        else [str(b) for b in seg.ids],
    )
