"""The numba kernels of :func:`algorithms.flow.target_points` (where each pixel's flow points, and inside).

A module of its own so that importing :mod:`algorithms.flow` (which ``scenes`` does) does not
import numba; ``target_points`` imports it on first use. Compiled kernels are cached on disk.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["target_points_kernel", "target_inside_kernel"]


# Row by row over flat rows (u, v, u, v, ...) with x from a float32 arange: the compiler vectorises
# these loops (4-5x faster than indexing f[i, j, c] with x converted from j in the loop).
@numba.njit(cache=True, inline="always")
def _target(xs, r, yi, j, xmax, ymax):  # pragma: no cover - numba
    """Where pixel ``j`` of a row (y = ``yi``, flat flow row ``r``) points, and whether that is inside."""
    x = xs[j] + r[2 * j]
    y = yi + r[2 * j + 1]
    zero = np.float32(0.0)
    return x, y, (x >= zero) & (x <= xmax) & (y >= zero) & (y <= ymax)


@numba.njit(cache=True)
def target_points_kernel(f, map_x, map_y, inside) -> None:
    h, w = inside.shape
    xmax, ymax = np.float32(w - 1), np.float32(h - 1)
    xs = np.arange(w).astype(np.float32)
    rows = f.reshape(h, 2 * w)
    for i in range(h):
        yi = np.float32(i)
        r, mx, my, o = rows[i], map_x[i], map_y[i], inside[i]
        for j in range(w):
            mx[j], my[j], o[j] = _target(xs, r, yi, j, xmax, ymax)


@numba.njit(cache=True)
def target_inside_kernel(f, inside) -> None:
    h, w = inside.shape
    xmax, ymax = np.float32(w - 1), np.float32(h - 1)
    xs = np.arange(w).astype(np.float32)
    rows = f.reshape(h, 2 * w)
    for i in range(h):
        yi = np.float32(i)
        r, o = rows[i], inside[i]
        for j in range(w):
            o[j] = _target(xs, r, yi, j, xmax, ymax)[2]
