"""TV-L1 optical flow, coarse-to-fine with warping: our own, from the papers.

Papers
------
* [Z] C. Zach, T. Pock, H. Bischof, "A Duality Based Approach for Realtime TV-L1
  Optical Flow", DAGM 2007: the energy, its convex relaxation with the
  auxiliary field v, the pointwise thresholding step for v and Chambolle's dual
  projection for u.
* [W] A. Wedel, T. Pock, C. Zach, H. Bischof, D. Cremers, "An Improved
  Algorithm for TV-L1 Optical Flow", 2009: a median filter of the flow inside
  the warping scheme.
* [S] J. Sanchez Perez, E. Meinhardt-Llopis, G. Facciolo, "TV-L1 Optical Flow
  Estimation", IPOL 2013: the discretisation (central differences for the image
  gradient, forward differences for grad u, their adjoint for div p), the
  parameter values lambda = 0.15 on a 0..255 intensity scale, tau = 0.25,
  theta = 0.3, zoom factor 0.5, 5 warps, the stopping rule on the change of u,
  and a Gaussian anti-alias blur before each reduction of the pyramid.

The model ([Z] sec. 2-3, [S] sec. 2)
------------------------------------
The energy of the flow u = (u1, u2) is

    E(u) = sum_d |grad u_d| + lambda |rho(u)|,
    rho(u) = I1(x + u0) + grad I1(x + u0) . (u - u0) - I0(x)       (linearised about u0)

relaxed with an auxiliary field v close to u:

    E(u, v) = sum_d |grad u_d| + 1 / (2 theta) |u - v|^2 + lambda |rho(v)|

and minimised alternately:

1. u fixed, v pointwise ([Z] sec. 3, the thresholding step):

       v = u + lambda theta grad I1          if rho(u) < -lambda theta |grad I1|^2
       v = u - lambda theta grad I1          if rho(u) >  lambda theta |grad I1|^2
       v = u - rho(u) grad I1 / |grad I1|^2   otherwise

   i.e. v = u - clip(rho(u) / |grad I1|^2, -lambda theta, lambda theta) grad I1,
   which is how the kernel computes it (no branch).

2. v fixed, each u_d solves a ROF problem ([Z] sec. 3, Chambolle's 2004 dual
   projection, in the sign convention of [S]):

       u_d = v_d + theta div p_d
       p_d <- (p_d + tau / theta grad u_d) / (1 + tau / theta |grad u_d|)

   tau <= 1/8 is Chambolle's proven bound; tau = 1/4 is what [Z] and [S] use.

Where the warp samples outside frame t+1, or grad I1 vanishes, the data term is
dropped (our choice: grad I1 = 0, rho = 0, so v = u): the smoothness term fills
those pixels in, as in our Horn-Schunck. One pass over the rows fuses both steps: row i gets its new u
(which needs p of rows i and i - 1, not yet updated), then row i - 1 gets its
new p (which needs the new u of rows i - 1 and i). So one iteration reads and
writes each array once; without the stopping rule, all iterations of a warp
run in one sweep down the rows, iteration k + 1 one row behind iteration k
(``_iterate_wavefront``), the same operations on every element in the same
order as iteration after iteration.

The kernels are compiled with ``fastmath``: LLVM may fuse a * b + c into one
multiply-add, reassociate sums and replace a division by a reciprocal estimate
in vector code, so the last bits of a result depend on how the compiler sees
the whole loop, not on the source line alone. The wavefront still accumulates
the change of u that only the stopping rule needs, because the row-by-row loop
does: dropping it changed the last bits of u (measured). Then both paths agree
bit for bit, except on rows of 9 to 16 px, where their compiled loops split
vector and scalar code differently (within 1e-6 px; tests compare both).
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.pyramid import target_inside
from algorithms.registry import register_flow

__all__ = ["tv_l1", "tv_l1_iterate", "tv_l1_pyramid"]

# [S]: grad I1 below this squared norm (0..255 scale, per px^2) carries no usable data term
_MIN_GRAD2 = np.float32(1e-6)
# coarsest level: at least this many px on the shorter side
_MIN_SIDE_PX = 16


# error_model="numpy": no ZeroDivisionError branch in the loops, so that they vectorise
@numba.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _primal_row(a, b, rho0, inv_g2, u1, u2, p11, p12, p21, p22, p12_up, p22_up, lt, th) -> float:
    """Steps 1 and 2 on one row (1-D views; ``p*_up``: the row above, zeros on the first row).

    Updates ``u1, u2`` in place and returns the sum of their squared changes.
    div p = p_x(j) - p_x(j-1) + p_y(i) - p_y(i-1), the terms outside the image 0:
    the negative adjoint of the forward differences ([S]).
    """
    w = u1.shape[0]
    change = np.float32(0.0)
    for j in range(w):
        x1 = u1[j]
        x2 = u2[j]
        ga = a[j]
        gb = b[j]
        # step 1, [Z] thresholding: v = u - clip(rho(u) / |grad I1|^2, -lambda theta, lambda theta) grad I1
        k = min(max((rho0[j] + ga * x1 + gb * x2) * inv_g2[j], -lt), lt)
        div1 = p11[j] + p12[j] - p12_up[j]
        div2 = p21[j] + p22[j] - p22_up[j]
        if j > 0:
            div1 -= p11[j - 1]
            div2 -= p21[j - 1]
        # step 2, [Z] ROF step: u = v + theta div p
        n1 = x1 - k * ga + th * div1
        n2 = x2 - k * gb + th * div2
        change += (n1 - x1) * (n1 - x1) + (n2 - x2) * (n2 - x2)
        u1[j] = n1
        u2[j] = n2
    return change


@numba.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _dual_row(u1, u2, u1_dn, u2_dn, p11, p12, p21, p22, tau_theta, has_next) -> None:
    """Chambolle's update of one row's dual fields from the new u of the row and the row below.

    p_d <- (p_d + tau/theta grad u_d) / (1 + tau/theta |grad u_d|), grad by forward
    differences that are 0 across the last column, and across the last row
    (``has_next`` 0) ([S], Chambolle 2004).
    """
    w = u1.shape[0]
    one = np.float32(1.0)
    for j in range(w - 1):
        u1x = u1[j + 1] - u1[j]
        u2x = u2[j + 1] - u2[j]
        u1y = (u1_dn[j] - u1[j]) * has_next
        u2y = (u2_dn[j] - u2[j]) * has_next
        d1 = one / (one + tau_theta * np.sqrt(u1x * u1x + u1y * u1y))
        d2 = one / (one + tau_theta * np.sqrt(u2x * u2x + u2y * u2y))
        p11[j] = (p11[j] + tau_theta * u1x) * d1
        p12[j] = (p12[j] + tau_theta * u1y) * d1
        p21[j] = (p21[j] + tau_theta * u2x) * d2
        p22[j] = (p22[j] + tau_theta * u2y) * d2
    j = w - 1
    u1y = (u1_dn[j] - u1[j]) * has_next
    u2y = (u2_dn[j] - u2[j]) * has_next
    d1 = one / (one + tau_theta * abs(u1y))
    d2 = one / (one + tau_theta * abs(u2y))
    p11[j] = p11[j] * d1
    p12[j] = (p12[j] + tau_theta * u1y) * d1
    p21[j] = p21[j] * d2
    p22[j] = (p22[j] + tau_theta * u2y) * d2


@numba.njit(cache=True, fastmath=True, error_model="numpy")
def tv_l1_iterate(a: np.ndarray, b: np.ndarray, rho0: np.ndarray, inv_g2: np.ndarray, u1: np.ndarray,
                  u2: np.ndarray, p11: np.ndarray, p12: np.ndarray, p21: np.ndarray, p22: np.ndarray,
                  lambda_: float, theta: float, tau: float, n_iter: int, epsilon: float) -> int:
    """Run the thresholding and dual-projection iterations of one warp, in place on u and p.

    Parameters
    ----------
    a, b : ndarray, (H, W) float32
        grad I1 = (I1x, I1y) at x + u0, fixed during a warp (0 where there is no data term).
    rho0 : ndarray, (H, W) float32
        ``I1(x + u0) - grad I1 . u0 - I0``, so that rho(u) = rho0 + grad I1 . u.
    inv_g2 : ndarray, (H, W) float32
        ``1 / |grad I1|^2``, 0 where there is no data term.
    u1, u2 : ndarray, (H, W) float32
        The flow, updated in place.
    p11, p12, p21, p22 : ndarray, (H, W) float32
        The dual fields p1 = (p11, p12) of u1 and p2 = (p21, p22) of u2, updated in place.
    lambda_, theta, tau : float
        The weight of the data term, the coupling of u and v, the dual time step.
    n_iter : int
        Iterations at most.
    epsilon : float
        Stop once the root-mean-square change of u over an iteration is below
        ``epsilon`` px ([S]'s stopping rule); 0: never stop early.

    Returns
    -------
    int
        Iterations done.
    """
    h, w = u1.shape
    lt = np.float32(lambda_ * theta)
    th = np.float32(theta)
    tau_theta = np.float32(tau / theta)
    if epsilon == 0:
        _iterate_wavefront(a, b, rho0, inv_g2, u1, u2, p11, p12, p21, p22, lt, th, tau_theta, n_iter)
        return n_iter
    stop2 = epsilon * epsilon * h * w
    zeros = np.zeros(w, dtype=np.float32)
    one = np.float32(1.0)
    done = 0
    for _ in range(n_iter):
        change = _primal_row(a[0], b[0], rho0[0], inv_g2[0], u1[0], u2[0], p11[0], p12[0], p21[0], p22[0],
                             zeros, zeros, lt, th)
        for i in range(1, h):
            change += _primal_row(a[i], b[i], rho0[i], inv_g2[i], u1[i], u2[i], p11[i], p12[i], p21[i], p22[i],
                                  p12[i - 1], p22[i - 1], lt, th)
            # row i - 1 has seen its last reader of the old p (row i's div): its dual update may run
            _dual_row(u1[i - 1], u2[i - 1], u1[i], u2[i], p11[i - 1], p12[i - 1], p21[i - 1], p22[i - 1],
                      tau_theta, one)
        _dual_row(u1[h - 1], u2[h - 1], u1[h - 1], u2[h - 1], p11[h - 1], p12[h - 1], p21[h - 1], p22[h - 1],
                  tau_theta, np.float32(0.0))
        done += 1
        if change < stop2:
            break
    return done


@numba.njit(cache=True, fastmath=True, error_model="numpy")
def _iterate_wavefront(a, b, rho0, inv_g2, u1, u2, p11, p12, p21, p22, lt, th, tau_theta, n_iter) -> np.ndarray:
    """All ``n_iter`` iterations of :func:`tv_l1_iterate` in one sweep down the rows, for a cache-sized working set.

    One iteration's unit at row r is: new u of row r, then new p of row r - 1
    (and of row h - 1 after the last row). Iteration k + 1 may run its unit at
    row r once iteration k has run its unit at row r + 1: then the p of rows
    r - 1 and r are iteration k's, and no later reader of iteration k's u of
    row r remains. So sweep step s runs iteration k at row s - k, k ascending:
    every array element sees the same operations in the same order as
    iteration after iteration over the whole image (the same bits; see the
    module notes on fastmath), but the n_iter + 1 rows in flight stay in cache
    instead of streaming all ten arrays through memory n_iter times. Without the stopping rule only:
    iteration k + 1 starts before iteration k's change of u is known.
    """
    h, w = u1.shape
    zeros = np.zeros(w, dtype=np.float32)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    change = np.zeros(n_iter, dtype=np.float32)
    for s in range(h + n_iter - 1):
        for k in range(max(0, s - (h - 1)), min(n_iter - 1, s) + 1):
            r = s - k
            if r == 0:
                change[k] = _primal_row(a[0], b[0], rho0[0], inv_g2[0], u1[0], u2[0], p11[0], p12[0], p21[0],
                                        p22[0], zeros, zeros, lt, th)
            else:
                change[k] += _primal_row(a[r], b[r], rho0[r], inv_g2[r], u1[r], u2[r], p11[r], p12[r], p21[r],
                                         p22[r], p12[r - 1], p22[r - 1], lt, th)
                _dual_row(u1[r - 1], u2[r - 1], u1[r], u2[r], p11[r - 1], p12[r - 1], p21[r - 1], p22[r - 1],
                          tau_theta, one)
            if r == h - 1:
                _dual_row(u1[r], u2[r], u1[r], u2[r], p11[r], p12[r], p21[r], p22[r], tau_theta, zero)
    return change


@numba.njit(cache=True, fastmath=True, error_model="numpy")
def _warp_terms(I0, warped, map_x, map_y, u1, u2, a, b, rho0, inv_g2) -> None:
    """Fill the per-warp terms of :func:`tv_l1_iterate`, linearised about (u1, u2).

    ``warped`` (H, W, 4): I1, I1x, I1y (and an unused 4th channel) sampled at
    ``x + u0``. Where ``x + u0`` falls outside frame t+1, or grad I1 vanishes,
    there is no data term.
    """
    h, w = I0.shape
    zero = np.float32(0.0)
    one = np.float32(1.0)
    xmax = np.float32(w - 1)
    ymax = np.float32(h - 1)
    for i in range(h):
        for j in range(w):
            ga = warped[i, j, 1]
            gb = warped[i, j, 2]
            g2 = ga * ga + gb * gb
            x = map_x[i, j]
            y = map_y[i, j]
            # rho(u) = I1(x + u0) + grad I1 (u - u0) - I0 = rho0 + grad I1 . u
            r = warped[i, j, 0] - ga * u1[i, j] - gb * u2[i, j] - I0[i, j]
            inv = one / g2
            # selects, not a branch, so that the loop vectorises
            ok = (x >= zero) & (x <= xmax) & (y >= zero) & (y <= ymax) & (g2 > _MIN_GRAD2)
            a[i, j] = ga if ok else zero
            b[i, j] = gb if ok else zero
            rho0[i, j] = r if ok else zero
            inv_g2[i, j] = inv if ok else zero


@numba.njit(cache=True, error_model="numpy")
def _sample_points(u1, u2, map_x, map_y) -> None:
    """``map = x + u0``: where each pixel of frame t samples frame t+1 (x, y: pixel indices)."""
    h, w = u1.shape
    for i in range(h):
        y = np.float32(i)
        for j in range(w):
            map_x[i, j] = np.float32(j) + u1[i, j]
            map_y[i, j] = y + u2[i, j]


@numba.njit(cache=True, error_model="numpy")
def _with_gradient(img: np.ndarray) -> np.ndarray:
    """(H, W, 4) float32: ``img``, its central-difference gradient Ix, Iy ([S]), and zeros.

    I_x = (I(x+1) - I(x-1)) / 2, one-sided (edge replicated) at the border; the
    4th channel only makes the stack one that ``cv2.remap`` samples faster
    than 3 channels (the same values per channel).
    """
    h, w = img.shape
    out = np.zeros((h, w, 4), dtype=np.float32)
    half = np.float32(0.5)
    for i in range(h):
        up = max(i - 1, 0)
        dn = min(i + 1, h - 1)
        for j in range(w):
            out[i, j, 0] = img[i, j]
            out[i, j, 1] = half * (img[i, min(j + 1, w - 1)] - img[i, max(j - 1, 0)])
            out[i, j, 2] = half * (img[dn, j] - img[up, j])
    return out


def tv_l1_pyramid(image: np.ndarray, n_scales: int, zoom: float) -> list[np.ndarray]:
    """Finest-first pyramid of ``image`` ``(H, W)`` float32: blur, then resample by ``zoom``.

    A Gaussian anti-alias blur before each reduction ([S]), of sigma
    ``0.8 sqrt(1 / zoom^2 - 1)`` px of the finer level (about 1.39 px for
    halving; ``algorithms.pyramid`` uses the factor 0.5; 0.8 is our choice,
    not tuned); levels
    whose shorter side would drop below 16 px are not built.
    """
    sigma = 0.8 * math.sqrt(1.0 / zoom**2 - 1.0)
    out = [image]
    for _ in range(n_scales - 1):
        prev = out[-1]
        h = int(round(prev.shape[0] * zoom))
        w = int(round(prev.shape[1] * zoom))
        if min(h, w) < _MIN_SIDE_PX:
            break
        blurred = cv2.GaussianBlur(prev, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT_101)
        out.append(cv2.resize(blurred, (w, h), interpolation=cv2.INTER_LINEAR))
    return out


def _normalised(g0: np.ndarray, g1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both frames mapped by one affine map onto 0..255 (a constant pair gives zeros): lambda's units."""
    lo = min(float(g0.min()), float(g1.min()))
    span = max(float(g0.max()), float(g1.max())) - lo
    if span == 0:
        return np.zeros_like(g0), np.zeros_like(g1)
    k = np.float32(255.0 / span)
    return (g0 - np.float32(lo)) * k, (g1 - np.float32(lo)) * k


_INTERPOLATION = {"bicubic": cv2.INTER_CUBIC, "bilinear": cv2.INTER_LINEAR}


@register_flow(cost=4.0)
def tv_l1(frame0: np.ndarray, frame1: np.ndarray, *, lambda_: float = 0.15, tau: float = 0.25,
          theta: float = 0.3, n_scales: int = 5, zoom: float = 0.5, n_warps: int = 5, n_iter: int = 15,
          epsilon: float = 0.0, median_px: int = 3, interpolation: str = "bilinear",
          sigma_px: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """TV-L1 flow (Zach, Pock, Bischof 2007; Wedel et al. 2009; Sanchez et al., IPOL 2013).

    Total variation of each flow component plus the L1 norm of the linearised
    brightness constancy residual, minimised by the thresholding step and
    Chambolle's dual projection (see the module notes), coarse to fine: per
    level, ``n_warps`` times, frame t+1 and its gradient are sampled at
    ``x + u0`` and ``n_iter`` iterations run from the current flow, then a
    median filter ([W]) cleans the flow. The dual fields start at 0 on each
    level and are kept across its warps. Both frames are first mapped by one
    affine map onto 0..255, so ``lambda_`` means the same whatever the input
    range (as the values of [S]).

    Defaults: [S]'s lambda, tau, theta, zoom and warps. Three choices were
    measured (mean EPE on Middlebury RubberWhale, Yosemite and five pairs each
    of the nominal, thesis, fast-vehicles and realistic presets, beside
    scikit-image's ``optical_flow_tvl1``): bilinear sampling beat bicubic on
    the rendered presets (background 0.045 vs 0.055 px on nominal, 0.027 vs
    0.046 on thesis) and on Yosemite; a 3x3 median ([W] uses 5x5) keeps small
    vehicles (nominal vehicles 1.27 vs 1.49 px); 15 iterations per warp instead
    of 10. [S] iterates each warp until its stopping rule holds (``epsilon``
    0.01): many more iterations, too slow here (about 0.75 ms per iteration at
    640x480) for little gain. Fewer warps or iterations cost accuracy on the
    background (``benchmarks/tv_l1_setting.md``).

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
        Frames t and t+1, uint8 or float (see ``algorithms.flow.as_gray``).
    lambda_ : float
        lambda, the weight of the data term, per intensity unit of the 0..255
        scale; larger follows the data more closely, smaller smooths more.
    tau : float
        tau, the time step of the dual projection, in (0, 0.25].
    theta : float
        theta, the coupling of u and v (small: v close to u), in px^2 per unit.
    n_scales : int
        Pyramid levels at most (coarsest side at least 16 px).
    zoom : float
        eta, the size ratio between levels, in (0, 1).
    n_warps : int
        Warps (re-linearisations) per level.
    n_iter : int
        Iterations of the two steps per warp.
    epsilon : float
        Stop a warp's iterations early once the RMS change of u is below
        ``epsilon`` px; 0 runs all ``n_iter``.
    median_px : int
        Median filter of the flow after each warp ([W]): 0 (none), 3 or 5 px.
    interpolation : {"bilinear", "bicubic"}
        How frame t+1 and its gradient are sampled at ``x + u0`` ([S]: bicubic).
    sigma_px : float
        Gaussian pre-smoothing of both frames, px (0: none).

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        (u, v) in px, forward t -> t+1, at the pixel centres of frame t.
    valid : ndarray, (H, W) bool
        ``x + flow`` inside frame t+1; all False if either frame is constant
        (no gradient anywhere: the flow, 0, is undetermined).
    """
    g0, g1 = check_frame_pair(frame0, frame1)
    for name, value in (("lambda_", lambda_), ("theta", theta)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a finite value > 0, got {value}")
    if not (0 < tau <= 0.25):
        raise ValueError(f"tau: expected a time step in (0, 0.25], got {tau}")
    if not (0 < zoom < 1):
        raise ValueError(f"zoom: expected a size ratio in (0, 1), got {zoom}")
    for name, value in (("n_scales", n_scales), ("n_warps", n_warps), ("n_iter", n_iter)):
        if int(value) != value or value < 1:
            raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
    if not (math.isfinite(epsilon) and epsilon >= 0):
        raise ValueError(f"epsilon: expected a finite value >= 0 (px), got {epsilon}")
    if median_px not in (0, 1, 3, 5):
        raise ValueError(f"median_px: expected 0, 3 or 5 px, got {median_px!r}")
    if interpolation not in _INTERPOLATION:
        raise ValueError(f"interpolation: expected one of {sorted(_INTERPOLATION)}, got {interpolation!r}")
    if not (math.isfinite(sigma_px) and sigma_px >= 0):
        raise ValueError(f"sigma_px: expected a finite value >= 0 (px), got {sigma_px}")
    interp = _INTERPOLATION[interpolation]

    n0, n1 = _normalised(g0, g1)
    if sigma_px > 0:
        n0 = cv2.GaussianBlur(n0, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT_101)
        n1 = cv2.GaussianBlur(n1, (0, 0), sigmaX=sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT_101)
    pyr0 = tv_l1_pyramid(n0, int(n_scales), zoom)
    pyr1 = tv_l1_pyramid(n1, int(n_scales), zoom)

    h, w = pyr0[-1].shape
    u1 = np.zeros((h, w), dtype=np.float32)
    u2 = np.zeros((h, w), dtype=np.float32)
    for I0, I1 in zip(reversed(pyr0), reversed(pyr1)):
        if I0.shape != u1.shape:
            # [S]: the flow of the coarser level, resampled and its vectors scaled to the finer pixels
            h, w = I0.shape
            sx, sy = w / u1.shape[1], h / u1.shape[0]
            u1 = cv2.resize(u1, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(sx)
            u2 = cv2.resize(u2, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(sy)
        I1g = _with_gradient(I1)
        p11, p12, p21, p22 = (np.zeros((h, w), dtype=np.float32) for _ in range(4))
        a, b, rho0, inv_g2 = (np.empty((h, w), dtype=np.float32) for _ in range(4))
        map_x, map_y = np.empty((h, w), dtype=np.float32), np.empty((h, w), dtype=np.float32)
        for _ in range(int(n_warps)):
            _sample_points(u1, u2, map_x, map_y)
            # I1 and its gradient at x + u0 (the gradient at the warped image, [S]), in one remap
            warped = cv2.remap(I1g, map_x, map_y, interpolation=interp, borderMode=cv2.BORDER_REPLICATE)
            _warp_terms(I0, warped, map_x, map_y, u1, u2, a, b, rho0, inv_g2)
            tv_l1_iterate(a, b, rho0, inv_g2, u1, u2, p11, p12, p21, p22, float(lambda_), float(theta),
                          float(tau), int(n_iter), float(epsilon))
            if median_px > 1:  # [W]
                u1 = cv2.medianBlur(u1, median_px)
                u2 = cv2.medianBlur(u2, median_px)
    flow = np.dstack([u1, u2])
    flow = np.ascontiguousarray(flow, dtype=FLOW_DTYPE)
    valid = target_inside(flow)
    if np.ptp(g0) == 0 or np.ptp(g1) == 0:
        valid[:] = False
    return flow, valid
