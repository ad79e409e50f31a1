"""TV-L1 optical flow (Zach, Pock and Bischof 2007; Wedel et al. 2009), scikit-image's solver in numba.

The ``tvl1`` reference method used to call ``skimage.registration.optical_flow_tvl1``,
which spends most of its time on array temporaries and boolean fancy indexing
(about 3 s per 640x480 pair on one core). This module runs *the same* solver, step
for step, as fused loops compiled by numba, so its flow is scikit-image's to float
rounding (``tests/algorithms/test_tvl1.py`` compares both on real pairs) at a
fraction of the cost. The coarse-to-fine frame (pyramid, flow resize) reuses the
public scikit-image and SciPy functions scikit-image's own version calls.

Equations (Zach et al. 2007, sec. 3; the numbering of Wedel et al. 2009, sec. 2.2),
with ``w = (v, u)`` in scikit-image's (row, column) order, ``I1w`` the second frame
warped by the current flow, ``grad = nabla I1w``, ``lambda`` = ``attachment``,
``theta`` = ``tightness``, ``tau = 1/4`` (= 0.5 / ndim):

* linearised residual      rho(w) = I1w - I0 + grad . (w - w0)
* data step (thresholding) w_aux = w - rho grad / |grad|^2   if |rho| <= lambda theta |grad|^2
                           w_aux = w - lambda theta sign(rho) grad   otherwise
* TV step (Chambolle's dual projection, per component, twice per iteration)
                           p <- (p - tau g) / (1 + (tau / theta) |g|),  g = forward differences of w
                           w = w_aux - div p   (backward differences; p = 0 outside)

As in scikit-image: the dual variable ``p`` lives for all warps of a level; a
level stops warping once the squared change of the flow over a warp, summed over
the pixels, is below ``tol * pixels``, where the change is measured from the
first data step of that warp (scikit-image's ``flow_previous`` aliases it); the
warp is bilinear with edge replication (``mode='edge'``); ``np.gradient`` gives
central differences inside and one-sided ones at the border; a zero ``|grad|^2``
counts as 1. Arithmetic is float32 where scikit-image's is (constants rounded to
float32, as NumPy does with Python scalars), the warp interpolates in float64 as
SciPy's ``map_coordinates`` does.

Speed: the kernels use numba's ``error_model="numpy"`` (a division by zero gives inf
instead of raising, which lets the loops over the columns vectorise; no divisor here can
be zero: ``1 + f1 |g| >= 1`` and ``|grad|^2`` is replaced by 1 where it is 0), and one
fixed-point iteration is one sweep down the rows (:func:`_iteration`). Both change no
value: the flow stays scikit-image's bit for bit on the pairs the tests compare.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy import ndimage as ndi
from skimage.transform import pyramid_reduce

__all__ = ["tvl1_vu", "tvl1_level"]

_DOWNSCALE = 2.0
_NLEVEL = 10
_MIN_SIZE = 16


@numba.njit(cache=True, error_model="numpy")
def _warp_gradient(I1, v, u, I1w, gr, gc):  # pragma: no cover - numba
    """``I1w`` = I1 sampled bilinearly at (row + v, col + u), edges replicated; ``gr, gc`` = np.gradient(I1w)."""
    h, w = I1.shape
    for i in range(h):
        for j in range(w):
            # the coordinates in float32, as scikit-image adds the grid to the flow, then float64
            y = np.float64(np.float32(i) + v[i, j])
            x = np.float64(np.float32(j) + u[i, j])
            y0 = math.floor(y)
            x0 = math.floor(x)
            ty = y - y0
            tx = x - x0
            ya = min(max(y0, 0), h - 1)
            yb = min(max(y0 + 1, 0), h - 1)
            xa = min(max(x0, 0), w - 1)
            xb = min(max(x0 + 1, 0), w - 1)
            val = (1.0 - ty) * ((1.0 - tx) * np.float64(I1[ya, xa]) + tx * np.float64(I1[ya, xb])) \
                + ty * ((1.0 - tx) * np.float64(I1[yb, xa]) + tx * np.float64(I1[yb, xb]))
            I1w[i, j] = np.float32(val)
    half = np.float32(0.5)
    for i in range(h):
        for j in range(w):
            if h == 1:
                gr[i, j] = 0
            elif i == 0:
                gr[i, j] = I1w[1, j] - I1w[0, j]
            elif i == h - 1:
                gr[i, j] = I1w[h - 1, j] - I1w[h - 2, j]
            else:
                gr[i, j] = (I1w[i + 1, j] - I1w[i - 1, j]) * half
            if w == 1:
                gc[i, j] = 0
            elif j == 0:
                gc[i, j] = I1w[i, 1] - I1w[i, 0]
            elif j == w - 1:
                gc[i, j] = I1w[i, w - 1] - I1w[i, w - 2]
            else:
                gc[i, j] = (I1w[i, j + 1] - I1w[i, j - 1]) * half


@numba.njit(cache=True, inline="always", error_model="numpy")
def _tv_row(f, aux, p0, p1, i, f1, dt):  # pragma: no cover - numba
    """One dual projection and primal update of row ``i`` of one flow component, in place.

    p <- (p - tau g) / (1 + (tau / theta) |g|), g = forward differences of ``f`` (0 past the
    last row / column); then f = aux - div p (backward differences, p = 0 outside). Row i reads
    ``f`` on rows i and i+1 (not yet updated in this step) and ``p`` on rows i (updated here)
    and i-1 (updated before), which is what the whole-array step computes. The border cases
    are peeled off the loops, so that the loops over the columns vectorise.
    """
    h, w = f.shape
    one = np.float32(1.0)
    zero = np.float32(0.0)
    if i < h - 1:
        for j in range(w - 1):
            g0 = f[i + 1, j] - f[i, j]
            g1 = f[i, j + 1] - f[i, j]
            norm = np.float32(np.sqrt(g0 * g0 + g1 * g1)) * f1 + one
            p0[i, j] = (p0[i, j] - dt * g0) / norm
            p1[i, j] = (p1[i, j] - dt * g1) / norm
        g0 = f[i + 1, w - 1] - f[i, w - 1]
    else:
        for j in range(w - 1):
            g1 = f[i, j + 1] - f[i, j]
            norm = np.float32(np.sqrt(zero * zero + g1 * g1)) * f1 + one
            p0[i, j] = (p0[i, j] - dt * zero) / norm
            p1[i, j] = (p1[i, j] - dt * g1) / norm
        g0 = zero
    norm = np.float32(np.sqrt(g0 * g0 + zero * zero)) * f1 + one
    p0[i, w - 1] = (p0[i, w - 1] - dt * g0) / norm
    p1[i, w - 1] = (p1[i, w - 1] - dt * zero) / norm
    # d = -div p: minus both components, plus the upper and left neighbours' (inside only)
    if i > 0:
        f[i, 0] = aux[i, 0] + (-(p0[i, 0] + p1[i, 0]) + p0[i - 1, 0])
        for j in range(1, w):
            f[i, j] = aux[i, j] + ((-(p0[i, j] + p1[i, j]) + p0[i - 1, j]) + p1[i, j - 1])
    else:
        f[i, 0] = aux[i, 0] + (-(p0[i, 0] + p1[i, 0]))
        for j in range(1, w):
            f[i, j] = aux[i, j] + (-(p0[i, j] + p1[i, j]) + p1[i, j - 1])


@numba.njit(cache=True, inline="always", error_model="numpy")
def _data_row(gr, gc, NI, rho0, f0, v, u, aux_v, aux_u, i):  # pragma: no cover - numba
    """Row ``i`` of the data step: w_aux = w - rho grad / |grad|^2 where |rho| <= lambda theta |grad|^2,
    else w - lambda theta sign(rho) grad; then w = w_aux (the TV step starts from it).

    Both cases are computed and one is selected (the same values, without a branch in the loop).
    """
    w = v.shape[1]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    for j in range(w):
        a, b = gr[i, j], gc[i, j]
        n = NI[i, j]
        rho = rho0[i, j] + (a * v[i, j] + b * u[i, j])
        s = f0 * (one if rho > zero else (-one if rho < zero else zero))
        small = abs(rho) <= f0 * n
        av = v[i, j] - (rho * a / n if small else s * a)
        au = u[i, j] - (rho * b / n if small else s * b)
        aux_v[i, j] = av
        aux_u[i, j] = au
        v[i, j] = av
        u[i, j] = au


@numba.njit(cache=True, error_model="numpy")
def _iteration(gr, gc, NI, rho0, f0, f1, dt, v, u, aux_v, aux_u, pv0, pv1, pu0, pu1):  # pragma: no cover
    """One fixed-point iteration: the data step, then two TV steps of each component, in one sweep.

    The whole-array steps run as a wavefront down the rows, so that the rows they touch are
    still in cache: at step i, the data step of row i+1, the first TV step of row i, the
    second of row i-1. Each reads only what the whole-array order would have given it: the
    first TV step of row i needs the data step of rows i and i+1 (done) and its own p on row
    i-1 (done, and not yet overwritten by the second TV step, which is one row behind); the
    second TV step of row i-1 needs the first TV step's f on rows i-1 and i (done).
    """
    h = v.shape[0]
    _data_row(gr, gc, NI, rho0, f0, v, u, aux_v, aux_u, 0)
    for i in range(h):
        if i + 1 < h:
            _data_row(gr, gc, NI, rho0, f0, v, u, aux_v, aux_u, i + 1)
        _tv_row(v, aux_v, pv0, pv1, i, f1, dt)
        _tv_row(u, aux_u, pu0, pu1, i, f1, dt)
        if i >= 1:
            _tv_row(v, aux_v, pv0, pv1, i - 1, f1, dt)
            _tv_row(u, aux_u, pu0, pu1, i - 1, f1, dt)
    _tv_row(v, aux_v, pv0, pv1, h - 1, f1, dt)
    _tv_row(u, aux_u, pu0, pu1, h - 1, f1, dt)


@numba.njit(cache=True, error_model="numpy")
def _solve_level(I0, I1, v, u, attachment, tightness, num_warp, num_iter, tol):  # pragma: no cover - numba
    """scikit-image's ``_tvl1`` on one level, in place on ``v``, ``u`` (float32, (h, w))."""
    h, w = I0.shape
    dt = np.float32(0.25)  # 0.5 / ndim
    f0 = np.float32(attachment * tightness)
    f1 = np.float32(0.25 / tightness)
    tol_total = tol * h * w
    I1w = np.empty((h, w), np.float32)
    gr = np.empty((h, w), np.float32)
    gc = np.empty((h, w), np.float32)
    NI = np.empty((h, w), np.float32)
    rho0 = np.empty((h, w), np.float32)
    aux_v = np.empty((h, w), np.float32)
    aux_u = np.empty((h, w), np.float32)
    first_v = np.empty((h, w), np.float32)
    first_u = np.empty((h, w), np.float32)
    pv0 = np.zeros((h, w), np.float32)
    pv1 = np.zeros((h, w), np.float32)
    pu0 = np.zeros((h, w), np.float32)
    pu1 = np.zeros((h, w), np.float32)
    for _ in range(num_warp):
        _warp_gradient(I1, v, u, I1w, gr, gc)
        for i in range(h):
            for j in range(w):
                n = gr[i, j] * gr[i, j] + gc[i, j] * gc[i, j]
                NI[i, j] = n if n != 0 else np.float32(1.0)
                rho0[i, j] = I1w[i, j] - I0[i, j] - (gr[i, j] * v[i, j] + gc[i, j] * u[i, j])
        for it in range(num_iter):
            _iteration(gr, gc, NI, rho0, f0, f1, dt, v, u, aux_v, aux_u, pv0, pv1, pu0, pu1)
            if it == 0:  # the data step of the first iteration: what scikit-image's flow_previous holds
                first_v[:, :] = aux_v
                first_u[:, :] = aux_u
        change = 0.0
        for i in range(h):
            for j in range(w):
                dv = np.float64(first_v[i, j] - v[i, j])
                du = np.float64(first_u[i, j] - u[i, j])
                change += dv * dv + du * du
        if change < tol_total:
            break


def tvl1_level(I0: np.ndarray, I1: np.ndarray, flow0: np.ndarray, *, attachment: float, tightness: float,
               num_warp: int, num_iter: int, tol: float) -> np.ndarray:
    """The TV-L1 solver on one pyramid level: ``(2, h, w)`` float32 (v, u) from the initial ``flow0``.

    ``I0``, ``I1``: ``(h, w)`` float32 frames; ``flow0`` is not modified.
    """
    v = np.array(flow0[0], np.float32, order="C")
    u = np.array(flow0[1], np.float32, order="C")
    _solve_level(np.ascontiguousarray(I0, np.float32), np.ascontiguousarray(I1, np.float32), v, u,
                 float(attachment), float(tightness), int(num_warp), int(num_iter), float(tol))
    return np.stack([v, u])


def _pyramid(image: np.ndarray) -> list[np.ndarray]:
    """Coarse-to-fine pyramid: halve (Gaussian + resize) while the smaller side stays above 32 px, at most 10."""
    pyramid = [image]
    size = min(image.shape)
    while len(pyramid) < _NLEVEL and size > _DOWNSCALE * _MIN_SIZE:
        nxt = pyramid_reduce(pyramid[-1], _DOWNSCALE, channel_axis=None)
        pyramid.append(nxt)
        size = min(nxt.shape)
    return pyramid[::-1]


def _resize_flow(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A coarse (v, u) field brought to ``shape``: nearest-neighbour zoom, values scaled by the size ratio."""
    scale = [n / o for n, o in zip(shape, flow.shape[1:])]
    factor = np.array(scale, dtype=flow.dtype)[:, None, None]
    return factor * ndi.zoom(flow, [1, *scale], order=0, mode="nearest", prefilter=False)


def tvl1_vu(image0: np.ndarray, image1: np.ndarray, *, attachment: float = 15.0, tightness: float = 0.3,
            num_warp: int = 5, num_iter: int = 10, tol: float = 1e-4) -> np.ndarray:
    """Coarse-to-fine TV-L1 flow in scikit-image's layout: ``(2, H, W)`` float32, ``[0]`` = v (rows), ``[1]`` = u.

    Parameters
    ----------
    image0, image1 : (H, W) float array
        The frames, intensities in [0, 1] (``attachment`` assumes that range).
    attachment : float
        lambda, weight of the data term (smaller: smoother flow).
    tightness : float
        theta, coupling of the data and TV sub-problems.
    num_warp : int
        Warps (re-linearisations) per pyramid level.
    num_iter : int
        Fixed-point iterations per warp.
    tol : float
        A level stops warping once the squared flow change of a warp, per pixel, is below ``tol``.

    Returns
    -------
    (2, H, W) float32: what ``skimage.registration.optical_flow_tvl1`` returns for the same
    arguments (``prefilter=False``, ``dtype=float32``), to float rounding.
    """
    I0 = np.asarray(image0)
    I1 = np.asarray(image1)
    if I0.ndim != 2 or I0.shape != I1.shape:
        raise ValueError(f"tvl1: expected two (H, W) frames of one shape, got {I0.shape} and {I1.shape}")
    for name, val in (("num_warp", num_warp), ("num_iter", num_iter)):
        if int(val) < 1:
            raise ValueError(f"tvl1: {name} must be at least 1, got {val}")
    if not (attachment > 0 and tightness > 0):
        raise ValueError(f"tvl1: attachment and tightness must be positive, got {attachment}, {tightness}")
    levels = list(zip(_pyramid(I0.astype(np.float32, copy=False)), _pyramid(I1.astype(np.float32, copy=False))))
    kw = {"attachment": attachment, "tightness": tightness, "num_warp": num_warp, "num_iter": num_iter, "tol": tol}
    flow = tvl1_level(*levels[0], np.zeros((2, *levels[0][0].shape), np.float32), **kw)
    for J0, J1 in levels[1:]:
        flow = tvl1_level(J0, J1, _resize_flow(flow, J0.shape), **kw)
    return flow
