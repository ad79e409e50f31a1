"""A plugin the reliability suites import in every worker (``imports: [tests.reliability.rel_plugin]``).

* ``die_once``: a flow method that kills its own worker process with SIGKILL the first
  time it runs while the marker file named by its ``marker`` parameter exists (it removes
  the marker first, so a retry of the task runs normally and returns zero flow).
* A simulated GL failure: creating the renderer for frames :data:`GL_FAIL_WIDTH_PX`
  wide raises :class:`scenes.render.RendererUnavailableError`, as a broken EGL would.
"""

from __future__ import annotations

import os
import signal

import numpy as np

from algorithms.flow import check_frame_pair
from algorithms.registry import FLOW_METHODS, register_flow

GL_FAIL_WIDTH_PX = 72


def die_once(frame0, frame1, *, marker: str = "", always: bool = False):
    """Zero flow; SIGKILL of the own process while ``marker`` exists (removed first unless ``always``)."""
    g0, _ = check_frame_pair(frame0, frame1)
    if marker and os.path.exists(marker):
        if not always:
            os.remove(marker)
        os.kill(os.getpid(), signal.SIGKILL)
    return np.zeros((*g0.shape, 2), np.float32), np.ones(g0.shape, bool)


if "die_once" not in FLOW_METHODS:
    register_flow(die_once)


def _install_gl_failure() -> None:
    from scenes import render

    if getattr(render.get_renderer, "_rel_plugin", False):
        return
    real = render.get_renderer

    def get_renderer(width_px: int, height_px: int):
        if int(width_px) == GL_FAIL_WIDTH_PX:
            raise render.RendererUnavailableError(
                f"simulated GL failure: eglMakeCurrent failed for a {width_px}x{height_px} context")
        return real(width_px, height_px)

    get_renderer._rel_plugin = True
    render.get_renderer = get_renderer


_install_gl_failure()
