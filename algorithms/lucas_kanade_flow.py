"""Dense Lucas-Kanade optical flow (thesis 2.1.1, eqs. 2.5-2.9), single scale or coarse-to-fine."""

from __future__ import annotations

import cv2
import numba
import numpy as np

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.pyramid import coarse_to_fine
from algorithms.registry import register_flow

__all__ = ["lucas_kanade", "lk_increment"]


@numba.njit(cache=True)
def _lk_products(mean_p, f0, f1, weight, use_weight, flow0, use_flow0, P, Q) -> None:
    """The per-pixel terms of eq. 2.8, ready for the window sums.

    Ix, Iy: Sobel 3x3 (central difference with [1, 2, 1] smoothing, /8) of the
    mean of both frames, as the derivatives in eq. 2.4 are taken between them;
    ``mean_p`` is that mean with a 1 px replicated border. It = f1 - f0; all
    three times ``weight`` if ``use_weight``. Writes
    ``P[..., :] = (Ix Ix, Ix Iy, Iy Iy, Ix It)`` and ``Q[..., 0] = Iy It``, then
    ``Q[..., 1:] = flow0`` if ``use_flow0`` (so one window pass averages it too).
    """
    h, w = f0.shape
    eighth = np.float32(0.125)
    two = np.float32(2.0)
    for i in range(h):
        up = mean_p[i]
        mid = mean_p[i + 1]
        dn = mean_p[i + 2]
        for j in range(w):
            Ix = eighth * ((up[j + 2] - up[j]) + two * (mid[j + 2] - mid[j]) + (dn[j + 2] - dn[j]))
            Iy = eighth * ((dn[j] - up[j]) + two * (dn[j + 1] - up[j + 1]) + (dn[j + 2] - up[j + 2]))
            It = f1[i, j] - f0[i, j]
            if use_weight:
                wt = np.float32(1.0) if weight[i, j] else np.float32(0.0)
                Ix *= wt
                Iy *= wt
                It *= wt
            P[i, j, 0] = Ix * Ix
            P[i, j, 1] = Ix * Iy
            P[i, j, 2] = Iy * Iy
            P[i, j, 3] = Ix * It
            Q[i, j, 0] = Iy * It
            if use_flow0:
                Q[i, j, 1] = flow0[i, j, 0]
                Q[i, j, 2] = flow0[i, j, 1]


@numba.njit(cache=True, error_model="numpy")
def _lk_solve(S, T, min_eigenvalue, check_inside, use_flow0, flow, valid) -> None:
    """Per pixel: the eigenvalue test and the 2x2 solve of eq. 2.9, written into ``flow`` and ``valid``.

    ``S``, ``T``: the window means of :func:`_lk_products`' ``P``, ``Q``. With
    ``use_flow0`` the solve is an increment to the window mean of ``flow0``
    (``T[..., 1:]``); singular pixels get that mean then, 0 otherwise.

    The smallest eigenvalue of ``[[Sxx, Sxy], [Sxy, Syy]]`` reaches ``m`` exactly
    when ``m <= trace / 2`` and the characteristic polynomial
    ``m^2 - trace m + det`` is not negative at ``m`` (``m`` lies at or below
    both roots), which needs no square root.
    """
    h, w = S.shape[:2]
    m = min_eigenvalue
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for i in range(h):
        for j in range(w):
            a = S[i, j, 0]  # Sxx
            b = S[i, j, 1]  # Sxy
            c = S[i, j, 2]  # Syy
            Sxt = S[i, j, 3]
            Syt = T[i, j, 0]
            trace = a + c
            det = a * c - b * b
            ok = (m + m <= trace) & (m * m - m * trace + det >= zero)
            # branch-free, so that the loop vectorises; det may be 0 where not ok
            inv_det = one / (det if ok else one)
            # eq. 2.9: (Vx, Vy) = -(A^T A)^-1 A^T It
            u = (b * Syt - c * Sxt) * inv_det if ok else zero
            v = (b * Sxt - a * Syt) * inv_det if ok else zero
            if use_flow0:
                u += T[i, j, 1]
                v += T[i, j, 2]
            if check_inside:
                x = np.float32(j) + u
                y = np.float32(i) + v
                ok &= (x >= zero) & (x <= np.float32(w - 1)) & (y >= zero) & (y <= np.float32(h - 1))
            flow[i, j, 0] = u
            flow[i, j, 1] = v
            valid[i, j] = ok


def lk_increment(f0: np.ndarray, f1: np.ndarray, *, window: int, min_eigenvalue: float,
                 gaussian_window: bool = False, weight: np.ndarray | None = None,
                 check_inside: bool = False, flow0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One Lucas-Kanade solve per pixel: the flow that takes ``f0`` to ``f1``.

    With ``flow0``, ``f1`` is frame t+1 already warped back by ``flow0`` and the
    solve is an increment to the window mean of ``flow0`` (the same window as
    the sums of eq. 2.8). Added to ``flow0`` pixel by pixel, the increment (a
    window mean itself) cannot correct the flow errors that the window mean
    cancels, and those where the box window's response is negative grow with
    every warp. The window mean preserves a constant or affine flow, so the
    true flow of a translation, rotation or zoom stays a fixed point (unlike
    solving for the total flow with eq. 2.4 linearised about ``flow0`` at each
    pixel of the window, which weights ``flow0`` by the local structure).

    Parameters
    ----------
    f0, f1 : ndarray, (H, W) float32
    window : int
        Side of the square window, odd, px.
    min_eigenvalue : float
        Smallest eigenvalue of the window-averaged structure tensor
        ``mean(A^T A)`` (intensity units / px)^2 below which the 2x2 system is
        taken as singular.
    gaussian_window : bool
        Weight the window with a Gaussian of sigma ``window / 4`` instead of the
        unweighted box of the thesis.
    weight : ndarray, (H, W) bool, optional
        Pixels that take part in the window sums (e.g. where a warp sampled
        inside frame t+1); the others contribute nothing.
    check_inside : bool
        Also clear ``valid`` where ``x + flow`` falls outside the frame.
    flow0 : ndarray, (H, W, 2) float32, optional
        The flow ``f1`` was warped back by (see above); its window mean is
        kept where the system is singular.

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        0 (or the window mean of ``flow0``) where the system is singular.
    valid : ndarray, (H, W) bool
        Where the smallest eigenvalue reaches ``min_eigenvalue`` (and, with
        ``check_inside``, ``x + flow`` lies inside the frame).
    """
    if gaussian_window:
        sigma = window / 4.0

        def window_mean(a: np.ndarray) -> np.ndarray:  # in place: fewer fresh pages per call
            return cv2.GaussianBlur(a, (window, window), sigma, dst=a, borderType=cv2.BORDER_REPLICATE)
    else:
        def window_mean(a: np.ndarray) -> np.ndarray:
            return cv2.blur(a, (window, window), dst=a, borderType=cv2.BORDER_REPLICATE)

    h, w = f0.shape
    use_flow0 = flow0 is not None
    use_weight = weight is not None
    P = np.empty((h, w, 4), dtype=np.float32)
    Q = np.empty((h, w, 3 if use_flow0 else 1), dtype=np.float32)
    f0 = np.ascontiguousarray(f0, dtype=np.float32)
    f1 = np.ascontiguousarray(f1, dtype=np.float32)
    mean = cv2.addWeighted(f0, 0.5, f1, 0.5, 0.0, dtype=cv2.CV_32F)
    mean_p = cv2.copyMakeBorder(mean, 1, 1, 1, 1, cv2.BORDER_REPLICATE)
    _lk_products(mean_p, f0, f1, weight if use_weight else np.ones((1, 1), dtype=np.bool_), use_weight,
                 flow0 if use_flow0 else np.zeros((1, 1, 2), dtype=np.float32), use_flow0, P, Q)
    # A^T A and A^T b of eq. 2.8, averaged over the window: 4 + 1 (+ 2 of flow0) channels
    S = window_mean(P)
    T = window_mean(Q).reshape(h, w, -1)
    flow = np.empty((h, w, 2), dtype=FLOW_DTYPE)
    valid = np.empty((h, w), dtype=np.bool_)
    _lk_solve(S, T, np.float32(min_eigenvalue), check_inside, use_flow0, flow, valid)
    return flow, valid


@register_flow(cost=1.0)
def lucas_kanade(frame0: np.ndarray, frame1: np.ndarray, *, window: int = 15, levels: int = 1,
                 iterations: int = 1, min_eigenvalue: float = 1e-3, gaussian_window: bool = False,
                 median_px: int | None = None, scale: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Dense Lucas-Kanade flow: a least-squares 2x2 solve per pixel over a window (eqs. 2.5-2.9).

    The defaults are the thesis's: a 15x15 unweighted window at one scale, as the
    old OpenCV ``cvCalcOpticalFlowLK`` (box-filtered structure tensor, one 2x2
    solve per pixel). ``levels > 1`` or ``iterations > 1`` give the coarse-to-fine
    form with warping (thesis 6.1): each warp adds the solve to the window mean
    of the current flow (see :func:`lk_increment`), and a median filter
    follows every warp. Tuned on Middlebury RubberWhale,
    Yosemite and an exact sub-pixel translation (``test_external.py``,
    ``benchmarks/flow_speed.py``): ``levels=4, iterations=3`` with the other
    defaults.

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
        Frames t and t+1, uint8 or float (see ``algorithms.flow.as_gray``).
    window : int
        Window side in px, odd, at least 3.
    levels : int
        Pyramid levels (1 = single scale, the thesis); at most as many as keep the
        coarsest level at least ``window`` px on its shorter side.
    iterations : int
        Warps per level: each re-linearises about the current estimate.
    min_eigenvalue : float
        Smallest eigenvalue of the window-mean structure tensor, in
        (intensity units / px)^2 (uint8 frames: gray levels), below which a
        pixel's 2x2 system counts as singular (flat or pure edge).
    gaussian_window : bool
        Gaussian-weighted window (sigma = window/4) instead of the thesis's box.
    median_px : int, optional
        Median filter of the flow after every warp, 0, 3 or 5 px. Default: 0 at
        one scale and one iteration (thesis), 5 otherwise.
    scale : float
        Size ratio between pyramid levels.

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        (u, v) in px, forward t -> t+1, at the pixel centres of frame t. Where the
        system is singular the flow is 0 at one scale (in the coarse-to-fine form,
        the window mean of the estimate it started from) and ``valid`` is False.
    valid : ndarray, (H, W) bool
        Non-singular system and ``x + flow`` inside frame t+1.
    """
    g0, g1 = check_frame_pair(frame0, frame1)
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window: expected an odd size of at least 3 px, got {window}")
    if levels < 1 or iterations < 1:
        raise ValueError(f"levels and iterations: expected at least 1, got {levels} and {iterations}")
    if not min_eigenvalue > 0:
        raise ValueError(f"min_eigenvalue: expected > 0, got {min_eigenvalue}")
    thesis_form = levels == 1 and iterations == 1
    if median_px is None:
        median_px = 0 if thesis_form else 5

    if thesis_form:
        return lk_increment(g0, g1, window=window, min_eigenvalue=min_eigenvalue,
                            gaussian_window=gaussian_window, check_inside=True)

    def update(f0: np.ndarray, f1w: np.ndarray, flow: np.ndarray,
               inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return lk_increment(f0, f1w, window=window, min_eigenvalue=min_eigenvalue,
                            gaussian_window=gaussian_window, weight=inside, flow0=flow)

    # A level smaller than the window averages the structure tensor over replicated
    # borders; on a periodic texture (Middlebury mysine, 100x100) a 12 px coarsest
    # level locked onto the neighbouring period, 21 px off. Fewer levels there.
    return coarse_to_fine(g0, g1, update, levels=levels, warps=iterations, scale=scale, median_px=median_px,
                          min_size_px=window)
