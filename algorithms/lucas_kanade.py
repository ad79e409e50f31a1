"""Dense Lucas-Kanade optical flow (thesis 2.1.1, eqs. 2.5-2.9), single scale or coarse-to-fine."""

from __future__ import annotations

import cv2
import numpy as np

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.pyramid import coarse_to_fine, target_inside
from algorithms.registry import register_flow

__all__ = ["lucas_kanade", "lk_increment"]


def lk_increment(f0: np.ndarray, f1: np.ndarray, *, window: int, min_eigenvalue: float,
                 gaussian_window: bool = False, weight: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One Lucas-Kanade solve per pixel: the flow that takes ``f0`` to ``f1``.

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

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        0 where the system is singular.
    valid : ndarray, (H, W) bool
        Where the smallest eigenvalue reaches ``min_eigenvalue``.
    """
    # Ix, Iy at t + 1/2: Sobel 3x3 (central difference with [1, 2, 1] smoothing, /8)
    # of the mean of both frames, as the derivatives in eq. 2.4 are taken between them.
    mean = 0.5 * (f0 + f1)
    Ix = cv2.Sobel(mean, cv2.CV_32F, 1, 0, ksize=3, scale=0.125, borderType=cv2.BORDER_REPLICATE)
    Iy = cv2.Sobel(mean, cv2.CV_32F, 0, 1, ksize=3, scale=0.125, borderType=cv2.BORDER_REPLICATE)
    It = f1 - f0
    if weight is not None:
        w = weight.astype(np.float32)
        Ix, Iy, It = Ix * w, Iy * w, It * w

    if gaussian_window:
        sigma = window / 4.0

        def window_mean(a: np.ndarray) -> np.ndarray:
            return cv2.GaussianBlur(a, (window, window), sigma, borderType=cv2.BORDER_REPLICATE)
    else:
        def window_mean(a: np.ndarray) -> np.ndarray:
            return cv2.blur(a, (window, window), borderType=cv2.BORDER_REPLICATE)

    # A^T A and A^T b of eq. 2.8, averaged over the window
    Sxx = window_mean(Ix * Ix)
    Sxy = window_mean(Ix * Iy)
    Syy = window_mean(Iy * Iy)
    Sxt = window_mean(Ix * It)
    Syt = window_mean(Iy * It)

    half_trace = 0.5 * (Sxx + Syy)
    lambda_min = half_trace - np.sqrt((0.5 * (Sxx - Syy)) ** 2 + Sxy * Sxy)
    valid = lambda_min >= min_eigenvalue
    det = Sxx * Syy - Sxy * Sxy
    inv_det = np.divide(1.0, det, out=np.zeros_like(det), where=valid)
    flow = np.empty(f0.shape + (2,), dtype=FLOW_DTYPE)
    # eq. 2.9: (Vx, Vy) = -(A^T A)^-1 A^T It
    flow[..., 0] = (Sxy * Syt - Syy * Sxt) * inv_det
    flow[..., 1] = (Sxy * Sxt - Sxx * Syt) * inv_det
    return flow, valid


@register_flow
def lucas_kanade(frame0: np.ndarray, frame1: np.ndarray, *, window: int = 15, levels: int = 1,
                 iterations: int = 1, min_eigenvalue: float = 1e-3, gaussian_window: bool | None = None,
                 median_px: int | None = None, scale: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Dense Lucas-Kanade flow: a least-squares 2x2 solve per pixel over a window (eqs. 2.5-2.9).

    The defaults are the thesis's: a 15x15 unweighted window at one scale, as the
    old OpenCV ``cvCalcOpticalFlowLK`` (box-filtered structure tensor, one 2x2
    solve per pixel). ``levels > 1`` or ``iterations > 1`` give the coarse-to-fine
    form with warping (thesis 6.1), whose own defaults are tuned on Middlebury
    RubberWhale and Yosemite (see ``test_external.py``): pass e.g.
    ``levels=4, iterations=3, window=11``.

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
        Frames t and t+1, uint8 or float (see ``algorithms.flow.as_gray``).
    window : int
        Window side in px, odd, at least 3.
    levels : int
        Pyramid levels (1 = single scale, the thesis).
    iterations : int
        Warps per level: each re-linearises about the current estimate.
    min_eigenvalue : float
        Smallest eigenvalue of the window-mean structure tensor, in
        (intensity units / px)^2 (uint8 frames: gray levels), below which a
        pixel's 2x2 system counts as singular (flat or pure edge).
    gaussian_window : bool, optional
        Gaussian-weighted window (sigma = window/4). Default: False at one scale
        and one iteration (thesis), True otherwise.
    median_px : int, optional
        Median filter of the flow after every warp, 0, 3 or 5 px. Default: 0 at
        one scale and one iteration (thesis), 5 otherwise.
    scale : float
        Size ratio between pyramid levels.

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        (u, v) in px, forward t -> t+1, at the pixel centres of frame t. Where the
        system is singular the flow is 0 at one scale (and the coarser level's
        estimate in the coarse-to-fine form) and ``valid`` is False.
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
    if gaussian_window is None:
        gaussian_window = not thesis_form
    if median_px is None:
        median_px = 0 if thesis_form else 5

    if thesis_form:
        flow, valid = lk_increment(g0, g1, window=window, min_eigenvalue=min_eigenvalue,
                                   gaussian_window=gaussian_window)
        return flow, valid & target_inside(flow)

    def update(f0: np.ndarray, f1w: np.ndarray, flow: np.ndarray,
               inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, ok = lk_increment(f0, f1w, window=window, min_eigenvalue=min_eigenvalue,
                             gaussian_window=gaussian_window, weight=inside)
        return flow + d, ok

    return coarse_to_fine(g0, g1, update, levels=levels, warps=iterations, scale=scale, median_px=median_px)
