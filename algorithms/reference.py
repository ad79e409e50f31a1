"""Reference flow methods from OpenCV and scikit-image, adapted to our layout and sign.

One adapter each: the foreign call, its input range and dtype, and its output
layout are handled here and nowhere else. All return ``(H, W, 2)`` float32
(u, v), forward t -> t+1, and a ``(H, W)`` bool mask: ``x + flow`` inside frame
t+1, all False when either frame is constant (no gradient: flow undetermined).
"""

from __future__ import annotations

import cv2
import numpy as np

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.pyramid import target_inside
from algorithms.registry import register_flow

__all__ = ["farneback", "dis", "tvl1", "ilk"]


def _joint_unit_range(g0: np.ndarray, g1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both frames mapped by the same affine map onto [0, 1] (a constant pair gives zeros)."""
    lo = min(float(g0.min()), float(g1.min()))
    span = max(float(g0.max()), float(g1.max())) - lo
    if span == 0:
        return np.zeros_like(g0), np.zeros_like(g1)
    return (g0 - lo) / span, (g1 - lo) / span


def _finish(flow: np.ndarray, g0: np.ndarray, g1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    flow = np.ascontiguousarray(flow, dtype=FLOW_DTYPE)
    if not np.isfinite(flow).all():
        raise FloatingPointError("reference method returned non-finite flow")
    valid = target_inside(flow)
    if np.ptp(g0) == 0 or np.ptp(g1) == 0:
        valid[:] = False
    return flow, valid


def _from_vu(vu: np.ndarray) -> np.ndarray:
    """scikit-image's ``(2, H, W)`` stack with ``[0] = v`` (rows) and ``[1] = u`` (cols) -> ours."""
    return np.stack([vu[1], vu[0]], axis=-1)


@register_flow(cost=1.0)
def farneback(frame0: np.ndarray, frame1: np.ndarray, *, pyr_scale: float = 0.5, levels: int = 4,
              winsize: int = 15, iterations: int = 3, poly_n: int = 5, poly_sigma: float = 1.2,
              gaussian_window: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Farneback polynomial-expansion flow (``cv2.calcOpticalFlowFarneback``).

    Its polynomial fit assumes a 0..255 range (on [0, 1] floats it returns
    zeros): uint8 frames pass as they are, others are mapped onto 0..255 by one
    affine map shared by both frames. OpenCV's output is already ``(H, W, 2)``
    (u, v) forward, so the adapter only checks it.
    """
    g0, g1 = check_frame_pair(frame0, frame1)
    a0, a1 = g0, g1
    if not (np.asarray(frame0).dtype == np.uint8 and np.asarray(frame1).dtype == np.uint8):
        n0, n1 = _joint_unit_range(g0, g1)
        a0, a1 = 255.0 * n0, 255.0 * n1
    flags = cv2.OPTFLOW_FARNEBACK_GAUSSIAN if gaussian_window else 0
    flow = cv2.calcOpticalFlowFarneback(a0, a1, None, pyr_scale, levels, winsize, iterations, poly_n,
                                        poly_sigma, flags)
    return _finish(flow, g0, g1)


_DIS_PRESETS = {"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
                "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}


_DIS_MIN_SIDE_PX = 32


@register_flow(cost=0.5)
def dis(frame0: np.ndarray, frame1: np.ndarray, *, preset: str = "medium",
        finest_scale: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Dense Inverse Search flow (``cv2.DISOpticalFlow``, Kroeger et al. 2016).

    DIS takes uint8 only: uint8 frames pass unchanged, others are mapped onto
    0..255 by one affine map shared by both frames (so brightness constancy
    between them survives) and rounded.

    ``finest_scale``: the pyramid level whose flow is upsampled to the output (0: full
    resolution; None: the preset's, 1 for ``medium``, 2 for ``fast`` and ``ultrafast``).
    At half resolution a car of 24 x 13 px is smaller than DIS's 8 px patch, whose
    inverse search then averages the car's motion with the ground's.
    """
    if preset not in _DIS_PRESETS:
        raise ValueError(f"preset: expected one of {sorted(_DIS_PRESETS)}, got {preset!r}")
    if finest_scale is not None and (isinstance(finest_scale, bool) or not isinstance(finest_scale, (int, np.integer))
                                     or finest_scale < 0):
        raise ValueError(f"finest_scale: expected None or an integer >= 0, got {finest_scale!r}")
    g0, g1 = check_frame_pair(frame0, frame1)
    if min(g0.shape) < _DIS_MIN_SIDE_PX:
        # OpenCV 5.0's DIS segfaults (15x48, 8x48) or raises cv2.error (20x7) below its patch scale
        raise ValueError(f"dis: expected frames of at least {_DIS_MIN_SIDE_PX}x{_DIS_MIN_SIDE_PX} px, "
                         f"got {g0.shape[1]}x{g0.shape[0]}")
    if np.asarray(frame0).dtype == np.uint8 and np.asarray(frame1).dtype == np.uint8:
        b0, b1 = np.round(g0).astype(np.uint8), np.round(g1).astype(np.uint8)
    else:
        n0, n1 = _joint_unit_range(g0, g1)
        b0 = np.round(255.0 * n0).astype(np.uint8)
        b1 = np.round(255.0 * n1).astype(np.uint8)
    method = cv2.DISOpticalFlow.create(_DIS_PRESETS[preset])
    if finest_scale is not None:
        method.setFinestScale(int(finest_scale))
    flow = method.calc(b0, b1, None)
    return _finish(flow, g0, g1)


@register_flow(cost=8.0)
def tvl1(frame0: np.ndarray, frame1: np.ndarray, *, attachment: float = 15.0, tightness: float = 0.3,
         num_warp: int = 5, num_iter: int = 10, tol: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """TV-L1 flow (``skimage.registration.optical_flow_tvl1``, Zach et al. 2007).

    scikit-image wants intensities in [0, 1] (its ``attachment`` assumes it) and
    returns ``(v, u)``: both frames share one map onto [0, 1], and the output is
    reordered to (u, v).
    """
    from skimage.registration import optical_flow_tvl1  # here: skimage.registration takes 0.3 s to import

    g0, g1 = check_frame_pair(frame0, frame1)
    n0, n1 = _joint_unit_range(g0, g1)
    vu = optical_flow_tvl1(n0, n1, attachment=attachment, tightness=tightness, num_warp=num_warp,
                           num_iter=num_iter, tol=tol, dtype=np.float32)
    return _finish(_from_vu(vu), g0, g1)


@register_flow(cost=2.0)
def ilk(frame0: np.ndarray, frame1: np.ndarray, *, radius: int = 7, num_warp: int = 10,
        gaussian: bool = False, prefilter: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Iterative dense Lucas-Kanade (``skimage.registration.optical_flow_ilk``), output reordered from (v, u)."""
    from skimage.registration import optical_flow_ilk  # here: skimage.registration takes 0.3 s to import

    g0, g1 = check_frame_pair(frame0, frame1)
    n0, n1 = _joint_unit_range(g0, g1)
    vu = optical_flow_ilk(n0, n1, radius=radius, num_warp=num_warp, gaussian=gaussian, prefilter=prefilter,
                          dtype=np.float32)
    return _finish(_from_vu(vu), g0, g1)
