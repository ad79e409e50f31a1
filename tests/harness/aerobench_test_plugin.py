"""A plugin for the runner tests, imported by suites that list it under ``imports``.

It registers a flow method that fails on purpose on narrow frames, so one scene of
a suite fails and the others do not.
"""

from __future__ import annotations

import numpy as np

from algorithms.flow import as_gray
from algorithms.registry import FLOW_METHODS, register_flow

NARROW_PX = 80


def raise_on_narrow(frame0, frame1):
    """Zero flow, except on frames narrower than 80 px, where it raises (a planned failure)."""
    g = as_gray(frame0)
    if g.shape[1] < NARROW_PX:
        raise RuntimeError(f"planned failure on a narrow frame ({g.shape[1]} px wide)")
    return np.zeros((*g.shape, 2), np.float32), np.ones(g.shape, bool)


if "raise_on_narrow" not in FLOW_METHODS:
    register_flow(raise_on_narrow)
