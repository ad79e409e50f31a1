"""Coarse-to-fine estimation with warping, shared by the dense flow methods (thesis 6.1).

The thesis (6.1) names the pyramid as future work for displacements too large
for one linearisation. The scheme here is the usual one: estimate at the
coarsest level, upsample the flow, warp frame t+1 back by it, estimate the
remaining increment, and repeat a few times per level.

Half-pixel conventions: pixel centres sit at integer coordinates at every
level, and a level of scale ``s`` maps its pixel ``x_s`` to ``(x_s + 0.5) / s - 0.5``
at full resolution, the mapping ``cv2.resize`` uses both ways, so a flow field
resized down and up again keeps its location.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from algorithms.flow import FLOW_DTYPE, target_points, warp_backward

__all__ = ["gaussian_pyramid", "resize_flow", "target_inside", "coarse_to_fine", "median_flow"]


def gaussian_pyramid(image: np.ndarray, levels: int, *, scale: float = 0.5,
                     min_size_px: int = 8) -> list[np.ndarray]:
    """Blur-and-subsample pyramid, finest level first.

    Parameters
    ----------
    image : ndarray, (H, W) float32
    levels : int
        Number of levels, at least 1 (1 returns ``[image]``). Levels whose
        shorter side would drop below ``min_size_px`` are not built.
    scale : float
        Size ratio between consecutive levels, in (0, 1).
    min_size_px : int
        Smallest side of a level, px (at least 8).

    Returns
    -------
    list of ndarray, (H_l, W_l) float32
        The anti-alias blur has sigma ``sqrt(1/scale**2 - 1) / 2`` px of the finer
        level (about 0.87 px for halving).
    """
    if levels < 1:
        raise ValueError(f"levels: expected at least 1, got {levels}")
    if not 0.0 < scale < 1.0:
        raise ValueError(f"scale: expected a ratio in (0, 1), got {scale}")
    sigma = 0.5 * np.sqrt(1.0 / scale**2 - 1.0)
    out = [np.asarray(image, dtype=np.float32)]
    for _ in range(levels - 1):
        prev = out[-1]
        h = int(round(prev.shape[0] * scale))
        w = int(round(prev.shape[1] * scale))
        if min(h, w) < max(8, min_size_px):
            break
        blurred = cv2.GaussianBlur(prev, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT_101)
        out.append(cv2.resize(blurred, (w, h), interpolation=cv2.INTER_LINEAR))
    return out


def resize_flow(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resample an ``(h, w, 2)`` flow field to ``shape`` and rescale its vectors to the new pixel size."""
    h, w = flow.shape[:2]
    H, W = shape
    if (h, w) == (H, W):
        return flow.astype(FLOW_DTYPE, copy=True)
    out = cv2.resize(flow, (W, H), interpolation=cv2.INTER_LINEAR)
    out[..., 0] *= W / w
    out[..., 1] *= H / h
    return out.astype(FLOW_DTYPE, copy=False)


def target_inside(flow: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: where ``x + flow`` lands inside frame t+1 (a match can exist there)."""
    h, w = flow.shape[:2]
    if flow.dtype != np.float32:  # float64 sums
        xs = np.arange(w, dtype=np.float32)[None, :] + flow[..., 0]
        ys = np.arange(h, dtype=np.float32)[:, None] + flow[..., 1]
        return (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    inside = np.empty((h, w), dtype=bool)
    target_points(flow, None, None, inside)  # the same float32 sums and tests, one pass
    return inside


def median_flow(flow: np.ndarray, size_px: int) -> np.ndarray:
    """Median-filter each flow component over ``size_px`` x ``size_px`` (3 or 5; 0 or 1 is a no-op).

    Removes the outliers that a warp step leaves near occlusions (Sun, Roth and
    Black, "Secrets of optical flow estimation", CVPR 2010).
    """
    if size_px in (0, 1):
        return flow
    if size_px not in (3, 5):
        raise ValueError(f"median size: expected 0, 3 or 5 px, got {size_px}")
    return cv2.medianBlur(np.ascontiguousarray(flow, dtype=np.float32), size_px)


# update(frame0_l, frame1_l_warped, flow_l, inside_l) -> (new total flow_l, valid_l)
Update = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def coarse_to_fine(g0: np.ndarray, g1: np.ndarray, update: Update, *, levels: int, warps: int,
                   scale: float = 0.5, median_px: int = 0, min_size_px: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Drive ``update`` from the coarsest pyramid level to the finest, warping each time.

    Parameters
    ----------
    g0, g1 : ndarray, (H, W) float32
        Frames t and t+1, already checked.
    update : callable
        ``update(f0, f1_warped, flow, inside) -> (flow_new, valid)``: given frame t,
        frame t+1 warped back by ``flow`` (so that ``f1_warped ~ f0`` where ``flow``
        is right), the current total flow and where the warp sampled inside frame
        t+1 (outside, ``f1_warped`` is a replicated border: no evidence), return the improved total flow
        ``(h, w, 2)`` float32 and a ``(h, w)`` bool mask of where it is determined.
    levels : int
        Pyramid levels (1 = single scale).
    warps : int
        Calls of ``update`` per level (1 = one linearisation, no re-warp).
    median_px : int
        Median filter size applied to the flow after every warp (0 = none).

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
    valid : ndarray, (H, W) bool
        The last ``update``'s mask, and the point ``x + flow`` inside frame t+1.
    """
    if warps < 1:
        raise ValueError(f"iterations (warps per level): expected at least 1, got {warps}")
    pyr0 = gaussian_pyramid(g0, levels, scale=scale, min_size_px=min_size_px)
    pyr1 = gaussian_pyramid(g1, levels, scale=scale, min_size_px=min_size_px)
    flow = np.zeros(pyr0[-1].shape + (2,), dtype=FLOW_DTYPE)
    valid = np.ones(pyr0[-1].shape, dtype=bool)
    for f0, f1 in zip(reversed(pyr0), reversed(pyr1)):
        flow = resize_flow(flow, f0.shape)
        for _ in range(warps):
            if np.any(flow):
                f1w, inside = warp_backward(f1, flow)
            else:
                f1w, inside = f1, np.ones(f1.shape, dtype=bool)
            flow, valid = update(f0, f1w, flow, inside)
            flow = median_flow(flow, median_px)
    return flow, valid & target_inside(flow)
