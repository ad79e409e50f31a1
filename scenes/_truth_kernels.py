"""The numba kernels of the pinhole ground truth (:class:`scenes.ground_truth.GroundTruth`).

Each kernel is one pass over the pixels doing what a chain of whole-image numpy
operations did before, with the same float32 operations in the same order (no
fast-math, so no fused multiply-add): the arrays they give are bit for bit those of
the numpy chain (tests/scenes/test_ground_truth.py compares both). A ray component
``a xn + b yn + c`` is affine in the pixel, so it arrives split into a per-column
part ``ax[x] = a xn`` and a per-row part ``ay[y] = b yn + c`` (float32 each) and is
summed per pixel, as numpy's broadcast sum did.

Division follows numpy (``error_model="numpy"``): x / 0 is +-inf or NaN, never an exception.
A module of its own so that ``import scenes`` does not import numba; the truth
imports it on first use. Compiled kernels are cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["surface_depth", "vehicle_window", "project_static", "valid_and_shift"]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def surface_depth(D, gx, gy, Cz, rel, abs_m, Z):  # pragma: no cover - numba
    """Depth of the seen point: the ground plane's where the render agrees with it, else the render's.

    D : (H, W) float32 rendered depth (0 = nothing); gx (W,), gy (H,) float32: the ray's
    component along the world's down, ``g . d = gx[x] + gy[y]``; Cz, rel, abs_m float32:
    camera height and the agreement tolerance ``|D - Zg| <= rel D + abs_m``.
    Out: Z (H, W) float32, inf where nothing was rendered.
    """
    h, w = D.shape
    inf = np.float32(np.inf)
    for y in range(h):
        gyy = gy[y]
        for x in range(w):
            d = D[y, x]
            if d <= 0:
                Z[y, x] = inf
                continue
            gd = gx[x] + gyy
            # ground z = 0: Zg = C_z / (g . d), only where the ray goes down
            zg = Cz / gd if gd > 0 else inf
            tol = d * rel
            tol += abs_m
            Z[y, x] = zg if abs(d - zg) <= tol else d


@numba.njit(cache=True, nogil=True, error_model="numpy")
def project_static(Z, ax, ay, b, fx, fy, cx, cy, xs, ys, x1, y1, Z1, flow_cam):  # pragma: no cover - numba
    """Where each pixel's point lands in frame t+1 if it is static: ``X1 = A (Z d) + b``, projected.

    Z : (H, W) float32 depth (inf = sky, projected as depth 1 and zeroed by the caller's valid pass);
    ax : (3, W), ay : (3, H) float32, row k of A split into ``ax[k, x] + ay[k, y]``; b : (3,) float32;
    fx, fy, cx, cy float32; xs (W,), ys (H,) float32 pixel coordinates.
    Out: x1, y1, Z1 (H, W) float32 (pixel and depth in t+1); flow_cam (H, W, 2) float32, the
    camera-induced flow ``(x1 - x, y1 - y)``. The selects are branch-free and the interleaved
    flow is written in a second pass over the row, so that the first pass vectorises (2x faster).
    """
    h, w = Z.shape
    one = np.float32(1.0)
    inf = np.float32(np.inf)
    b0, b1, b2 = b[0], b[1], b[2]
    for y in range(h):
        ay0, ay1, ay2 = ay[0, y], ay[1, y], ay[2, y]
        for x in range(w):
            z = Z[y, x]
            z = one if z == inf else z
            X = ax[0, x] + ay0
            Y = ax[1, x] + ay1
            W = ax[2, x] + ay2
            X *= z
            X += b0
            Y *= z
            Y += b1
            W *= z
            W += b2
            inv = one / W
            # x1 = fx X1_x / X1_z + cx, y1 = fy X1_y / X1_z + cy
            X *= inv
            X *= fx
            X += cx
            Y *= inv
            Y *= fy
            Y += cy
            x1[y, x] = X
            y1[y, x] = Y
            Z1[y, x] = W
        yy = ys[y]
        for x in range(w):
            flow_cam[y, x, 0] = x1[y, x] - xs[x]
            flow_cam[y, x, 1] = y1[y, x] - yy


@numba.njit(cache=True, nogil=True, error_model="numpy")
def valid_and_shift(Z0, x1, y1, Z1, D1, instances, xmax, ymax, rel1, abs_m, flow, flow_cam, valid,
                    sums):  # pragma: no cover - numba
    """Valid mask, sky zeroed, and the sums of the camera flow over valid static pixels.

    Z0 : (H, W) float32 depth at t (inf = sky); x1, y1, Z1 : where each point lands in t+1;
    D1 : (H, W) float32 the depth of t+1 sampled there; instances (H, W) uint16;
    xmax, ymax: the last pixel centre; rel1 = 1 + relative tolerance, abs_m float32.
    A pixel is valid when it lands in the image in front of the camera and is not behind
    what t+1 rendered there: ``Z1 <= D1 rel1 + abs_m``. Flow and flow_cam of sky pixels are
    set to 0. Out: valid (H, W) bool; sums (3,) float64: sum of u, sum of v, count over the
    valid static pixels, accumulated in pixel order.
    """
    h, w = Z0.shape
    su = 0.0
    sv = 0.0
    n = 0
    zero = np.float32(0.0)
    for y in range(h):
        for x in range(w):
            if Z0[y, x] == np.float32(np.inf):
                valid[y, x] = False
                flow[y, x, 0] = zero
                flow[y, x, 1] = zero
                flow_cam[y, x, 0] = zero
                flow_cam[y, x, 1] = zero
                continue
            xx, yy, zz, d = x1[y, x], y1[y, x], Z1[y, x], D1[y, x]
            limit = d * rel1
            limit += abs_m
            ok = (xx >= 0) and (xx <= xmax) and (yy >= 0) and (yy <= ymax) and (zz > 0) and (d > 0) and (zz <= limit)
            valid[y, x] = ok
            if ok and instances[y, x] == 0:
                su += flow_cam[y, x, 0]
                sv += flow_cam[y, x, 1]
                n += 1
    sums[0] = su
    sums[1] = sv
    sums[2] = n


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _np_min(a, b):  # pragma: no cover - numba
    """numpy.minimum of two floats: NaN if either is NaN."""
    if a != a or b != b:
        return a + b
    return a if a <= b else b


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _np_max(a, b):  # pragma: no cover - numba
    """numpy.maximum of two floats: NaN if either is NaN."""
    if a != a or b != b:
        return a + b
    return a if a >= b else b


@numba.njit(cache=True, nogil=True, error_model="numpy")
def vehicle_window(D, r0, c0, xn, yn, A, o, lo, hi, rel, abs_m, Zv, err, hit):  # pragma: no cover - numba
    """Ray-box depth of a vehicle over a window of pixels, and which pixels show it.

    Slab method, float64, per pixel ray ``d = (xn, yn, 1)`` in camera axes turned into the
    vehicle's axes ``r = A d`` from its origin ``o``: for each box (``lo``, ``hi`` (B, 3) its
    corners), ``t`` enters the slab k between ``(lo_k - o_k) / r_k`` and ``(hi_k - o_k) / r_k``;
    a hit is ``t_near <= t_far`` and ``t_near > 0``, the nearest hit over the boxes wins.

    D : (H, W) float32 rendered depth; the window is rows ``r0 ..`` and columns ``c0 ..`` of the
    sizes of ``Zv``; xn (w,), yn (h,) float64 the window's ray components; rel, abs_m float32.
    Out (h, w): Zv float32 the box depth (inf: no hit), err float32 ``|D - Zv|``, hit bool
    ``err <= rel D + abs_m`` and ``D > 0``. Returns the number of hits.
    """
    h, w = Zv.shape
    inf = np.inf
    count = 0
    for i in range(h):
        for j in range(w):
            r_0 = A[0, 0] * xn[j] + A[0, 1] * yn[i] + A[0, 2]
            r_1 = A[1, 0] * xn[j] + A[1, 1] * yn[i] + A[1, 2]
            r_2 = A[2, 0] * xn[j] + A[2, 1] * yn[i] + A[2, 2]
            best = inf
            for k in range(lo.shape[0]):
                t_near = -inf
                t_far = inf
                for a in range(3):
                    r = r_0 if a == 0 else (r_1 if a == 1 else r_2)
                    ta = (lo[k, a] - o[a]) / r
                    tb = (hi[k, a] - o[a]) / r
                    t_near = _np_max(t_near, _np_min(ta, tb))
                    t_far = _np_min(t_far, _np_max(ta, tb))
                if t_near <= t_far and t_near > 0 and t_near < best:
                    best = t_near
            z = np.float32(best)
            d = D[r0 + i, c0 + j]
            e = abs(d - z)
            ok = (e <= d * rel + abs_m) and d > 0
            Zv[i, j] = z
            err[i, j] = e
            hit[i, j] = ok
            count += ok
    return count

