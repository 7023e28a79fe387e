"""The one SAPIEN renderer of a process (created on first use, never torn down).

The first picture a process renders compiles shaders (~3-9 s on lavapipe); keeping the
renderer alive makes every later scene cost milliseconds (docs/platform.md). Every world
that renders (sim/render.py for shelves, sim/pile.py for chapter 3's piles) uses this one.
"""

from __future__ import annotations

import sapien

from clutterbench.errors import ClutterbenchError

_RENDERER: sapien.render.SapienRenderer | None = None


def ensure_renderer() -> sapien.render.SapienRenderer:
    """The process-wide renderer (created on first use, never torn down)."""
    global _RENDERER
    if _RENDERER is None:
        try:
            _RENDERER = sapien.render.SapienRenderer()
        except RuntimeError as exc:
            raise ClutterbenchError(
                f"SAPIEN found no Vulkan device ({exc}); install Mesa from bookworm-backports "
                "(scripts/setup_system.sh)"
            ) from None
    return _RENDERER
