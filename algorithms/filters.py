"""Clean-up of local flow (thesis 3.3.2 and 4.2): direction / magnitude threshold, spatial and temporal filters.

The thesis deletes (sets to zero) every vector that does not move in the
target's known direction (Appendix B zeroes positive components: only upward
motion survives), then smooths the field with the spatial filter eq. 4.11 and
the temporal filter eq. 4.12; spreading the surviving vectors over their
neighbours is what "increases the density of the object's vector cluster"
(its figs. 4.4-4.6).
"""

from __future__ import annotations

import math

import cv2
import numba
import numpy as np

from algorithms.flow import check_flow
from algorithms.registry import register_stage

__all__ = ["threshold_flow", "zero_outside", "spatial_filter", "temporal_filter", "SPATIAL_KERNEL"]

# eq. 4.11: P_new = 1/2 P + 1/16 (N1 + ... + N8); the weights sum to 1.
SPATIAL_KERNEL = np.array([[1, 1, 1], [1, 8, 1], [1, 1, 1]], dtype=np.float32) / 16.0

_BORDERS = {"replicate": cv2.BORDER_REPLICATE, "reflect": cv2.BORDER_REFLECT_101, "zero": cv2.BORDER_CONSTANT}


def _direction_vector(direction) -> np.ndarray:
    """(2,) unit vector from an angle in degrees (atan2(v, u), +90 = down) or a 2-vector."""
    if isinstance(direction, (int, float, np.integer, np.floating)) and not isinstance(direction, bool):
        if not math.isfinite(float(direction)):
            raise ValueError(f"direction: expected a finite angle in degrees, got {direction}")
        a = math.radians(float(direction))
        return np.array([math.cos(a), math.sin(a)])
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (2,) or not np.isfinite(d).all() or np.hypot(*d) == 0:
        raise ValueError(f"direction: expected an angle in degrees or a non-zero (u, v) vector, got {direction!r}")
    return d / np.hypot(*d)


@register_stage("threshold")
def threshold_flow(flow: np.ndarray, *, direction=None, tolerance_deg: float = 45.0,
                   min_magnitude_px: float = 0.0, max_magnitude_px: float | None = None,
                   valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Keep only vectors moving in an allowed direction with an allowed magnitude (thesis 3.3.2, 4.2).

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float32
        Local flow in px (our layout).
    direction : float or (2,) array-like, optional
        Allowed direction: an angle in degrees in image axes, ``atan2(v, u)``
        (0 = +x right, 90 = +y down, -90 = up), or a ``(u, v)`` vector. ``None``
        keeps every direction. The thesis's "only upward" (Appendix B) is
        ``direction=-90, tolerance_deg=90``.
    tolerance_deg : float
        Largest angle, in degrees, between a kept vector and ``direction``
        (strictly less than, so 90 keeps an open half-plane).
    min_magnitude_px, max_magnitude_px : float
        Kept vectors have ``min <= |w| <= max`` (px). With ``direction`` set,
        zero vectors have no direction and are never kept.
    valid : ndarray, (H, W) bool, optional
        Pixels outside it are rejected.

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        A copy with rejected vectors set to zero, as the thesis deletes them
        (the spatial and temporal filters then average over zeros).
    mask : ndarray, (H, W) bool
        The kept pixels.
    """
    f = check_flow(flow)
    if not 0.0 <= float(tolerance_deg) <= 180.0:
        raise ValueError(f"tolerance_deg: expected 0..180, got {tolerance_deg}")
    if min_magnitude_px < 0:
        raise ValueError(f"min_magnitude_px: expected >= 0, got {min_magnitude_px}")
    if max_magnitude_px is not None and max_magnitude_px < min_magnitude_px:
        raise ValueError(f"max_magnitude_px: expected >= min_magnitude_px ({min_magnitude_px}), got {max_magnitude_px}")
    u, v = f[..., 0].astype(np.float64), f[..., 1].astype(np.float64)
    mag = np.hypot(u, v)
    mask = mag >= min_magnitude_px
    if max_magnitude_px is not None:
        mask &= mag <= max_magnitude_px
    if direction is not None:
        d = _direction_vector(direction)
        # cos of the angle between w and d, compared with cos(tolerance): angle < tolerance
        cos_angle = (u * d[0] + v * d[1]) / np.where(mag > 0, mag, 1.0)
        mask &= (mag > 0) & (cos_angle > math.cos(math.radians(float(tolerance_deg))))
    if valid is not None:
        vm = np.asarray(valid, dtype=bool)
        if vm.shape != f.shape[:2]:
            raise ValueError(f"valid: expected shape {f.shape[:2]}, got {vm.shape}")
        mask &= vm
    return zero_outside(f, mask), mask


def zero_outside(flow: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A float32 copy of ``flow`` with the vectors outside ``mask`` set to zero (deleted, as the thesis does).

    The values of ``np.where(mask[..., None], flow, np.float32(0)).astype(np.float32)``, in
    one pass (numpy's where over a last axis of 2 was 25 times slower at 640x480).

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
    mask : ndarray, (H, W) bool

    Returns
    -------
    ndarray, (H, W, 2) float32
    """
    f = np.asarray(flow)
    m = np.asarray(mask)
    if f.ndim != 3 or f.shape[2] != 2 or m.shape != f.shape[:2] or m.dtype != bool:
        raise ValueError(f"flow and mask: expected (H, W, 2) and (H, W) bool, got {f.shape} and {m.shape} {m.dtype}")
    out = np.empty(f.shape, dtype=np.float32)
    _zero_outside(np.ascontiguousarray(f, dtype=np.float32).reshape(-1), np.ascontiguousarray(m).reshape(-1),
                  out.reshape(-1))
    return out


@numba.njit(cache=True)
def _zero_outside(f, m, out) -> None:
    """Flat ``f``, ``out`` (2 n,) float32 and ``m`` (n,) bool (2-D indexing was 8x slower)."""
    zero = np.float32(0.0)
    for k in range(m.size):
        keep = m[k]
        a = f[2 * k]
        b = f[2 * k + 1]
        out[2 * k] = a if keep else zero
        out[2 * k + 1] = b if keep else zero


@register_stage("spatial")
def spatial_filter(flow: np.ndarray, *, border: str = "replicate") -> np.ndarray:
    """Spatial filter eq. 4.11: half the centre plus 1/16 of each of the eight neighbours.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float32
    border : {"replicate", "reflect", "zero"}
        How pixels outside the image are taken at the one-pixel border.
        ``"replicate"`` (default) keeps a constant field constant everywhere;
        ``"zero"`` treats outside as no motion. (Appendix B leaves the border
        unfiltered and additionally zeroes a 10-pixel frame; that crop is left
        to the caller's ``valid`` mask.)

    Returns
    -------
    ndarray, (H, W, 2) float32
    """
    f = check_flow(flow)
    if border not in _BORDERS:
        raise ValueError(f"border: expected one of {', '.join(_BORDERS)}, got {border!r}")
    # cv2.filter2D correlates; the kernel is symmetric so this is eq. 4.11 as written.
    return cv2.filter2D(f, cv2.CV_32F, SPATIAL_KERNEL, borderType=_BORDERS[border])


@register_stage("temporal")
def temporal_filter(prev: np.ndarray | None, cur: np.ndarray, next: np.ndarray | None) -> np.ndarray:
    """Temporal filter eq. 4.12: ``1/2 P_t + 1/4 (P_{t-1} + P_{t+1})``, pixel by pixel.

    Parameters
    ----------
    prev, cur, next : ndarray, (H, W, 2) float32, or None for prev / next
        The fields of pairs t-1, t, t+1. At the ends of a sequence a missing
        neighbour is left out and the remaining weights renormalised to sum
        to 1 (``2/3 P_t + 1/3 P_{t+1}`` for the first pair, ``P_t`` alone for a
        one-pair sequence), so a field constant in time stays unchanged.

    Returns
    -------
    ndarray, (H, W, 2) float32
    """
    def check_all() -> tuple:  # check_flow of each field in turn, its errors in this order
        c = check_flow(cur, name="cur")
        return (c, None if prev is None else check_flow(prev, name="prev", shape=c.shape[:2]),
                None if next is None else check_flow(next, name="next", shape=c.shape[:2]))

    # layouts first; finiteness from the output: a NaN or infinite input gives a non-finite mean (a convex
    # mean of finite float32 values, taken in float64, cannot overflow), one test instead of three
    try:
        c = check_flow(cur, name="cur", allow_nan=True)
        p = None if prev is None else check_flow(prev, name="prev", shape=c.shape[:2], allow_nan=True)
        n = None if next is None else check_flow(next, name="next", shape=c.shape[:2], allow_nan=True)
    except (TypeError, ValueError):
        check_all()  # raises the first error of the three checks in turn
        raise
    weight = 0.5 + (0.25 if p is not None else 0.0) + (0.25 if n is not None else 0.0)
    out = np.empty(c.shape, dtype=np.float32)
    flat = [np.ascontiguousarray(a).reshape(-1) for a in (c, c if p is None else p, c if n is None else n)]
    _temporal_mean(flat[0], flat[1], p is not None, flat[2], n is not None, weight, out.reshape(-1))
    if not np.isfinite(out).all():
        check_all()
    return out


@numba.njit(cache=True)
def _temporal_mean(c, p, use_p, n, use_n, weight, out) -> None:
    """``out = (1/2 c [+ 1/4 p] [+ 1/4 n]) / weight`` in float64, rounded to float32, in one pass.

    The float64 operations of the numpy form, in its order, per element; 1-D arrays (one
    flat loop vectorises, a loop over the last axis of 2 did not).
    """
    for k in range(c.size):
        t = 0.5 * np.float64(c[k])
        if use_p:
            t += 0.25 * np.float64(p[k])
        if use_n:
            t += 0.25 * np.float64(n[k])
        out[k] = np.float32(t / weight)
