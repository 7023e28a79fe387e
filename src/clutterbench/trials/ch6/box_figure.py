"""The figure of the physics-from-depth planner's box estimates (like thesis Fig. 6.8;
reports/trials/box_estimation.png, drawn by stage trials): a few scenes of a trial stream at
their canonical start, each the depth image with the true boxes and the ones fitted to it
projected by the camera. The trials draw it because they hold the scenes; the table of the
estimation errors is the report's (report/box_estimation.py, from the records).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from clutterbench.perception.fitted_scenes import make_estimator
from clutterbench.sim.config import CameraConfig, PhysicsConfig
from clutterbench.sim.pull import SceneState
from clutterbench.trials.ch6.physics_model import estimate_errors


def estimate_panels(
    stream: str,
    stream_cfg: Any,
    seed: int,
    indices: list[int],
    physics: PhysicsConfig,
    camera: CameraConfig,
    max_attempts: int,
    min_pixels: int,
) -> list[dict[str, Any]]:
    """The figure's panels (`estimation_figure`): scenes `indices` of a trial stream at
    their canonical start, the boxes fitted to their first observation beside the true ones."""
    from clutterbench.data.trial_scenes import draw_trial_spec
    from clutterbench.sim.pull import world_at
    from clutterbench.sim.render import observe

    estimator = make_estimator(stream_cfg.catalogue, min_pixels)
    panels = []
    for i in indices:
        spec = draw_trial_spec(stream, stream_cfg, seed, i, physics, camera, max_attempts)
        obs = observe(world_at(spec, SceneState.start(spec), physics, render=True), camera)
        est = estimator(obs)
        errors = estimate_errors(est, spec, np.asarray(spec.poses))
        centre = np.median([b[1] for b in errors["boxes"]]) if errors["boxes"] else float("nan")
        panels.append(
            {
                "depth_m": obs.depth_m,
                "camera": obs.camera,
                "true": (spec.sizes_m, spec.poses),
                "est": (est.sizes_m, est.poses),
                "title": f"{stream} scene {i} ({spec.family})\n{est.n}/{spec.n} boxes "
                f"estimated, median centre error {centre:.1f} mm",
            }
        )
    return panels


def _edges(size: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(12, 2, 3) the edges of a box in the shelf frame."""
    from clutterbench.sim.geometry import quat_to_matrix

    R = quat_to_matrix(pose[3:])
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    corners = pose[:3] + (signs * (np.asarray(size) / 2)) @ R.T
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8) if np.sum(signs[a] != signs[b]) == 1]
    return np.array([[corners[a], corners[b]] for a, b in pairs])


def estimation_figure(panels: Sequence[dict[str, Any]], path: Path) -> None:
    """Each panel: the depth image with the true boxes (pink) and the estimated ones (white,
    dashed) projected by the camera. panel: depth_m, camera (CameraModel), true (sizes,
    poses), est (sizes, poses), title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clutterbench.io import atomic_path

    n = max(1, len(panels))
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.8), squeeze=False)
    for ax, p in zip(axes[0], panels):
        depth = np.where(p["depth_m"] > 0, p["depth_m"], np.nan)
        ax.imshow(depth, cmap="viridis")
        for (sizes, poses), style in (
            (p["true"], {"color": "#ff4fa3", "lw": 1.4}),
            (p["est"], {"color": "white", "lw": 1.0, "ls": "--"}),
        ):
            for size, pose in zip(sizes, poses):
                for a, b in _edges(size, pose):
                    u, v, _ = p["camera"].world_to_pixel(np.stack([a, b]))
                    ax.plot(u - 0.5, v - 0.5, **style)
        h, w = depth.shape
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_title(p["title"], fontsize=8)
        ax.axis("off")
    fig.suptitle("Estimated (white, dashed) and true (pink) boxes", fontsize=9)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=110, metadata={"Software": None})
    plt.close(fig)
