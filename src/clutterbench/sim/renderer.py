"""The one SAPIEN renderer of a process (created on first use, never torn down), and the
depth cameras every world renders with.

Keeping the renderer alive makes every later scene cost milliseconds (docs/platform.md). Every
world that renders (sim/render.py for shelves, sim/pile.py for chapter 3's piles) uses this
one, through `add_depth_camera`: SAPIEN's default shader but for its image-based lighting
(sim/shaders/README.md), whose two textures cost a process's first picture ~5 s on lavapipe.
The pictures the pipeline reads (Position, Segmentation) are the default shader's bit for bit.
"""

from __future__ import annotations

import os
from pathlib import Path

import sapien

from clutterbench.errors import ClutterbenchError

_RENDERER: sapien.render.SapienRenderer | None = None
_RENDERER_PID: int | None = None


def ensure_renderer() -> sapien.render.SapienRenderer:
    """The process-wide renderer (created on first use, never torn down). A process forked
    from one that had rendered cannot render (Vulkan and lavapipe's threads do not survive a
    fork: the child would hang): refused in one line."""
    global _RENDERER, _RENDERER_PID
    if _RENDERER is not None and _RENDERER_PID != os.getpid():
        raise ClutterbenchError(
            "this process was forked from one that had rendered, and SAPIEN's renderer does not "
            "survive a fork: start workers with spawn or forkserver (gym.make_vec: "
            'vector_kwargs={"context": "forkserver"}; docs/environments.md)'
        )
    if _RENDERER is None:
        _RENDERER_PID = os.getpid()
        try:
            _RENDERER = sapien.render.SapienRenderer()
        except RuntimeError as exc:
            raise ClutterbenchError(
                f"SAPIEN found no Vulkan device ({exc}); install Mesa from bookworm-backports "
                "(scripts/setup_system.sh)"
            ) from None
    return _RENDERER


DEPTH_SHADER_DIR = Path(__file__).parent / "shaders" / "depth"
"""The depth cameras' shader directory (sim/shaders/README.md)."""


def add_depth_camera(
    scene: sapien.Scene, name: str, size_px: int, fovy_rad: float, near_m: float, far_m: float
):
    """A square camera on `scene` rendering with DEPTH_SHADER_DIR. SAPIEN's shader directory is
    process-wide and read when a camera is made (ManiSkill's sensors set their own), so it is
    set for this camera and put back."""
    ensure_renderer()
    previous = sapien.render.get_camera_shader_dir()
    sapien.render.set_camera_shader_dir(str(DEPTH_SHADER_DIR))
    try:
        return scene.add_camera(name, size_px, size_px, fovy_rad, near_m, far_m)
    finally:
        sapien.render.set_camera_shader_dir(previous)
