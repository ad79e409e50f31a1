"""Global motion between two frames: the thesis's NCC shift (3.1) and an affine/homography model.

Every result is the motion of the image content from frame t to frame t+1
(``algorithms.flow`` convention): a shift ``(dx, dy)`` with content moving right
has ``dx > 0``; a matrix maps frame-t points to frame-t+1 points.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.registry import register_stage

__all__ = ["GlobalMotion", "GlobalModel", "ncc_global_motion", "affine_global_motion", "global_flow"]


@dataclass(frozen=True)
class GlobalMotion:
    """A global translation.

    Attributes
    ----------
    shift_px : tuple of float
        ``(dx, dy)`` displacement of the content from frame t to frame t+1, px.
    peak : float
        NCC (eq. 3.1) at the best shift, in [-1, 1]; NaN when undefined.
    valid : bool
        False when there is no clear peak (flat image, peak below the threshold,
        or the peak on the edge of the search range).
    """

    shift_px: tuple[float, float]
    peak: float
    valid: bool


@dataclass(frozen=True)
class GlobalModel:
    """A global 2-D motion model.

    Attributes
    ----------
    matrix : ndarray, (3, 3) float64
        Maps homogeneous frame-t points ``(x, y, 1)`` to frame-t+1 points.
    model : str
        ``"translation"``, ``"affine"`` or ``"homography"``.
    score : float
        ECC correlation coefficient reached (1 = perfect), NaN if it failed.
    valid : bool
        False when the estimate failed (no convergence, flat image).
    """

    matrix: np.ndarray
    model: str
    score: float
    valid: bool


def _parabola_offset(left: float, centre: float, right: float) -> float:
    """Vertex of the parabola through three equally spaced samples, relative to the centre, in (-1/2, 1/2)."""
    curvature = left - 2.0 * centre + right
    if not curvature < 0:
        return 0.0
    return float(np.clip(0.5 * (left - right) / curvature, -0.5, 0.5))


@register_stage("global_motion")
def ncc_global_motion(frame0: np.ndarray, frame1: np.ndarray, *, max_shift: int = 16, subpixel: bool = False,
                      min_peak: float = 0.3, template_px: int | None = 256) -> GlobalMotion:
    """Global shift by normalized cross-correlation (thesis 3.1, eq. 3.1).

    A centred window of frame t is the template; eq. 3.1, with the means
    removed, is evaluated at every integer shift within ``+/- max_shift`` px in
    frame t+1 (``cv2.matchTemplate`` with ``TM_CCOEFF_NORMED``) and the best one
    taken, an integer shift as in the thesis. ``subpixel=True`` refines the
    peak with a parabola through its neighbours, separately in x and y.

    The thesis does not size the template. It is the central part of frame t
    that stays inside frame t+1 at every searched shift, ``(H - 2 max_shift,
    W - 2 max_shift)``, cropped about its centre to at most the larger of
    ``template_px`` and half of it per side: a global shift gives the same
    peak from any part of the frame and the peak stays sharp with tens of
    thousands of pixels, while the correlation costs about a seventh (0.5 ms
    rather than 3.6 ms at 512x512, one thread). Frames up to
    ``template_px + 2 max_shift`` per side use the whole central part, as does
    ``template_px=None``.

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
        Frames t and t+1; each side must exceed ``2 * max_shift + 8`` px.
    max_shift : int
        Largest shift searched, px, each direction.
    subpixel : bool
        Parabolic peak refinement.
    min_peak : float
        Smallest NCC that counts as a match.
    template_px : int, optional
        Template side cap in px (see above), at least 8; None: no cap.

    Returns
    -------
    GlobalMotion
        ``shift_px = (dx, dy)``, the content's displacement t -> t+1.
    """
    g0, g1 = check_frame_pair(frame0, frame1)
    h, w = g0.shape
    if max_shift < 0:
        raise ValueError(f"max_shift: expected >= 0 px, got {max_shift}")
    if min(h, w) < 2 * max_shift + 8:
        raise ValueError(f"frames of {h}x{w} px are too small for max_shift {max_shift} px "
                         f"(each side must exceed {2 * max_shift + 8})")
    if template_px is not None and template_px < 8:
        raise ValueError(f"template_px: expected at least 8 px or None, got {template_px}")
    s = int(max_shift)
    th, tw = h - 2 * s, w - 2 * s
    if template_px is not None:
        th = min(th, max(int(template_px), th // 2))
        tw = min(tw, max(int(template_px), tw // 2))
    top, left = (h - th) // 2, (w - tw) // 2
    template = g0[top:top + th, left:left + tw]
    search = g1[top - s:top + th + s, left - s:left + tw + s]
    if np.ptp(template) == 0 or np.ptp(search) == 0:
        return GlobalMotion((0.0, 0.0), float("nan"), False)
    # r[dy + s, dx + s]: NCC of the template against frame t+1 shifted by (dx, dy)
    r = cv2.matchTemplate(search, template, cv2.TM_CCOEFF_NORMED)
    r = np.where(np.isfinite(r), r, -1.0)
    iy, ix = np.unravel_index(int(np.argmax(r)), r.shape)
    peak = float(r[iy, ix])
    on_edge = s > 0 and (ix in (0, 2 * s) or iy in (0, 2 * s))
    dx, dy = float(ix - s), float(iy - s)
    if subpixel and not on_edge and s > 0:
        dx += _parabola_offset(r[iy, ix - 1], peak, r[iy, ix + 1])
        dy += _parabola_offset(r[iy - 1, ix], peak, r[iy + 1, ix])
    return GlobalMotion((dx, dy), peak, bool(peak >= min_peak and not on_edge))


_ECC_MODELS = {"translation": cv2.MOTION_TRANSLATION, "affine": cv2.MOTION_AFFINE,
               "homography": cv2.MOTION_HOMOGRAPHY}


def affine_global_motion(frame0: np.ndarray, frame1: np.ndarray, *, model: str = "affine",
                         max_shift: int = 16, iterations: int = 100, epsilon: float = 1e-5,
                         blur_px: int = 5, levels: int = 3) -> GlobalModel:
    """Global affine or homography motion by ECC (Evangelidis & Psarakis 2008), beyond the thesis.

    Handles rotation, zoom and the plane-induced parallax that the thesis's
    pure shift cannot. Started from the NCC shift (:func:`ncc_global_motion`,
    so shifts up to ``max_shift`` px are caught), then refined by
    ``cv2.findTransformECC`` from the coarsest of ``levels`` half-size levels to
    full size.

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
    model : {"affine", "homography", "translation"}
    max_shift : int
        Search range of the initial NCC shift, px.
    iterations, epsilon : int, float
        ECC stopping rule per level.
    blur_px : int
        Gaussian pre-filter size of ECC (odd px).
    levels : int
        Pyramid levels for the refinement.

    Returns
    -------
    GlobalModel
        ``matrix`` maps frame-t points to frame-t+1 points.
    """
    if model not in _ECC_MODELS:
        raise ValueError(f"model: expected one of {sorted(_ECC_MODELS)}, got {model!r}")
    g0, g1 = check_frame_pair(frame0, frame1)
    h, w = g0.shape
    shift = max(0, min(max_shift, (min(h, w) - 9) // 2))
    start = ncc_global_motion(g0, g1, max_shift=shift)
    if np.ptp(g0) == 0 or np.ptp(g1) == 0:
        return GlobalModel(np.eye(3), model, float("nan"), False)
    H = np.eye(3)
    if start.valid:
        H[0, 2], H[1, 2] = start.shift_px
    # ECC finds W with frame1(W x) ~ frame0(x): W maps frame-t points to frame-t+1 points.
    n = max(1, int(levels))
    while n > 1 and min(h, w) >> (n - 1) < 32:
        n -= 1
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, int(iterations), float(epsilon))
    score = float("nan")
    for level in range(n - 1, -1, -1):
        f = 0.5 ** level
        a = cv2.resize(g0, None, fx=f, fy=f, interpolation=cv2.INTER_AREA) if level else g0
        b = cv2.resize(g1, None, fx=f, fy=f, interpolation=cv2.INTER_AREA) if level else g1
        # cv2.resize puts pixel centres at (x + 0.5) f - 0.5: conjugate by that map
        C = np.array([[f, 0, 0.5 * f - 0.5], [0, f, 0.5 * f - 0.5], [0, 0, 1.0]])
        Hl = C @ H @ np.linalg.inv(C)
        warp = (Hl if model == "homography" else Hl[:2]).astype(np.float32)
        try:
            score, warp = cv2.findTransformECC(a, b, warp, _ECC_MODELS[model], criteria, None, blur_px)
        except cv2.error:
            return GlobalModel(H, model, float("nan"), False)
        Hl = np.eye(3)
        Hl[: warp.shape[0]] = warp
        H = np.linalg.inv(C) @ Hl @ C
    return GlobalModel(H, model, float(score), bool(np.isfinite(score) and np.all(np.isfinite(H))))


def is_translation(M: np.ndarray) -> bool:
    """Whether the ``(3, 3)`` matrix ``M`` is exactly a translation (identity linear part, last row 0 0 1)."""
    return bool(M[0, 0] == 1.0 and M[0, 1] == 0.0 and M[1, 0] == 0.0 and M[1, 1] == 1.0
                and M[2, 0] == 0.0 and M[2, 1] == 0.0 and M[2, 2] == 1.0)


def global_flow(motion: GlobalMotion | GlobalModel | np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The flow field ``(H, W, 2)`` float32 that a global model induces at each pixel centre.

    Parameters
    ----------
    motion : GlobalMotion, GlobalModel or ndarray (3, 3)
        A shift (constant field) or a matrix mapping frame-t to frame-t+1 points.
    shape : (H, W)

    Returns
    -------
    ndarray, (H, W, 2) float32
        ``flow(x) = M(x) - x`` (the projective division applied for a homography).
    """
    h, w = int(shape[0]), int(shape[1])
    if isinstance(motion, GlobalMotion):
        flow = np.empty((h, w, 2), dtype=FLOW_DTYPE)
        flow[..., 0], flow[..., 1] = motion.shift_px
        return flow
    M = motion.matrix if isinstance(motion, GlobalModel) else np.asarray(motion, dtype=np.float64)
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise ValueError(f"motion: expected a finite (3, 3) matrix, got {M.shape} {M.dtype}")
    flow = np.empty((h, w, 2), dtype=FLOW_DTYPE)
    if is_translation(M):
        # M x = x + t exactly (1 * x + 0 * y = x, Z = 0 * x + 0 * y + 1 = 1): u depends on x only, v on y
        # only, so one row and one column, broadcast, give the values of the 2-D expressions below
        xs, ys = np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)
        flow[..., 0] = ((xs + M[0, 2]) - xs).astype(FLOW_DTYPE)[None, :]
        flow[..., 1] = ((ys + M[1, 2]) - ys).astype(FLOW_DTYPE)[:, None]
        return flow
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    X = M[0, 0] * xs + M[0, 1] * ys + M[0, 2]
    Y = M[1, 0] * xs + M[1, 1] * ys + M[1, 2]
    Z = M[2, 0] * xs + M[2, 1] * ys + M[2, 2]
    flow[..., 0] = X / Z - xs
    flow[..., 1] = Y / Z - ys
    return flow
