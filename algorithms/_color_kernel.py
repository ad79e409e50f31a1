"""The per-pixel loop of :func:`algorithms.flow.flow_to_color` (numba; its numpy form was 0.12 s a picture).

Each pixel goes through the float64 operations of the numpy expressions it replaces, in
the same order (``tests/algorithms/test_flow.py`` keeps those expressions and compares the
pixels), with ``atan2`` and ``hypot`` from the same C library numpy calls.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["color_code"]


@numba.njit(cache=True, nogil=True)
def color_code(f, known, scale, wheel, out):  # pragma: no cover - numba
    """f (H, W, 2) float64 flow, known (H, W) bool, scale > 0 (px of full saturation), wheel (n, 3)
    float64 Middlebury colours; out (H, W, 3) uint8 RGB, black where not known.

    Per pixel: r = min(|w| / scale, 1); the direction's position fk on the wheel,
    ((atan2(-v, -u) / pi + 1) / 2 (n - 1)), interpolated between its two colours k0, k1;
    then desaturated towards white by 1 - r: round(255 (1 - r (1 - colour / 255))).
    """
    h, w = known.shape
    n = wheel.shape[0]
    for y in range(h):
        for x in range(w):
            if not known[y, x]:
                out[y, x, 0] = 0
                out[y, x, 1] = 0
                out[y, x, 2] = 0
                continue
            u = f[y, x, 0]
            v = f[y, x, 1]
            r = min(math.hypot(u, v) / scale, 1.0)
            angle = math.atan2(-v, -u) / np.pi
            fk = (angle + 1.0) / 2.0 * (n - 1)
            fl = math.floor(fk)
            k0 = int(fl) % n
            k1 = (k0 + 1) % n
            frac = fk - fl
            for c in range(3):
                col = ((1 - frac) * wheel[k0, c] + frac * wheel[k1, c]) / 255.0
                col = 1.0 - r * (1.0 - col)
                out[y, x, c] = np.uint8(np.rint(255.0 * col))
