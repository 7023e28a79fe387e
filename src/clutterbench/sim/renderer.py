"""The one SAPIEN renderer of a process (created on first use, never torn down).

The first picture a process renders compiles shaders (~3-9 s on lavapipe); keeping the
renderer alive makes every later scene cost milliseconds (docs/platform.md). Every world
that renders (sim/render.py for shelves, sim/pile.py for chapter 3's piles) uses this one.
"""

from __future__ import annotations

import os

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
