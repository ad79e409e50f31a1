"""Detection of moving regions and tracking: the thesis point tracker (4.1) and a multi-target tracker.

Point tracker (thesis 4.1, Appendix B): a pixel of a target is followed frame
by frame by the global shift plus the local flow at its (rounded) position,

    p(t+1) = p(t) + s(t) + w(t)(round(p(t)))

and the scalar Kalman filter (eqs. 4.6-4.10) is run on the series of local flow
measurements w per axis. Appendix B moves the column by the correlation alone
(its targets moved vertically); here both axes use global + local flow.

Thesis 4.1 also says "we track the same single pixel of an object all the
time, which means we use the image correlation data to track the pixel", and
3.1 names NCC the best of the feature-tracking methods it compared. With
``correlation`` set, the flow step above is the prediction and the image
correlation places the point: the template of the pixel (a square around it,
taken where the tracking starts) is searched by NCC (eq. 3.1) in frame t+1
within a few pixels of the prediction, to sub-pixel precision
(:func:`ncc_refine`). The flow alone is open loop: single-level LK or HS on a
vehicle of about 17x7 px whose window also covers ground sees 60-70 % of its
motion, and the point integrates that shortfall into a straight-line drift
(4.7 px mean on the `thesis` preset). The template is kept from the first
frame (not taken again every frame, which would integrate the same
shortfall, since a template that covers ground matches partly as ground) and
is renewed only when its match falls below ``renew_ncc`` (turns, light), so
the point does not drift between renewals. The Kalman filter's measurement
Z(k) is then the local motion of the tracked pixel, p(t+1) - p(t) - s(t).

What is ours, not the thesis's: Appendix B reads one pair of correlation
values per frame (``icx``, ``icy``: the frame's correlation shift, as far as the
listing shows) and rounds the position every frame, which freezes a point
moving under 0.5 px/frame; it gives no template, search range, sub-pixel peak
or renewal. Placing the pixel's own template by eq. 3.1 is our reading of
"use the image correlation data to track the pixel"; the sizes are in
``CORRELATION_DEFAULTS``. The Kalman filter is the thesis's (eqs. 4.6-4.10,
P(1|1) = 1, Q = 1, R = 0.05) except X(1|1), see :class:`PointTracker`.

Multi-target tracker (beyond the thesis): the moving regions of
:func:`~algorithms.detection.detect_vehicles` are detections with a box and a
velocity; each track is a constant-velocity Kalman filter of its box's centre
and size (:class:`~algorithms.kalman.BoxKalman`); detections are assigned to
tracks by the Hungarian method on IoU and distance to each track's prediction,
gated; a track is confirmed after ``birth_hits`` hits (gaps of up to ``birth_gap``
frames allowed) once it has left a quarter of its box at a steady velocity (flicker
on a tree crown or a roof edge recurs in place), completes partial views to its
size, is held where its template matches when it loses
its detection (a vehicle that slows and stops at a light leaves the motion
detector but not the image), coasts through short occlusions, fills the frames
of a gap it bridges (interpolated, where its template matches) and is dropped
after ``death_misses`` consecutive misses; confirmed tracks that are parts of one vehicle (a truck whose
region splits in some frames and is found whole in others) are joined into one. It works in a ground-fixed frame: given the camera path (the
cumulative global shift of frame t), it subtracts it from detections before
filtering and adds it back to its output, so a car driving straight is a
constant-velocity target even when the camera sways.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from collections import deque
from dataclasses import dataclass, field

import cv2
import numba
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from algorithms.detection import Detection, box_extents
from algorithms.global_motion import _parabola_offset
from algorithms.kalman import THESIS_KALMAN, BoxKalman, ConstantVelocityKalman, kalman_cv_filter, scalar_kalman
from algorithms.registry import register_stage

__all__ = ["Detection", "MULTI_DEFAULTS", "boxes_in_image", "motion_mask", "detect_moving_objects", "recentre_on_region", "point_template", "ncc_refine",
           "CorrelationMatch", "CORRELATION_DEFAULTS", "PointTracker", "MultiTargetTracker", "TRACK_COLUMNS"]

# Column order of the rows trackers produce (the tracks table of docs/architecture.md).
# Box columns are NaN where a tracker has no box (the point tracker).
TRACK_COLUMNS = ("frame", "track_id", "x_px", "y_px", "x_filt_px", "y_filt_px", "x_pred_px", "y_pred_px",
                 "source", "seed_vehicle_id", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px")


def motion_mask(flow: np.ndarray, valid: np.ndarray, min_magnitude_px: float) -> np.ndarray:
    """The moving pixels: ``valid & (np.hypot(u, v) >= min_magnitude_px)``, bit for bit, in one pass.

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Filtered local flow (u, v), px.
    valid : ndarray, (H, W) bool
    min_magnitude_px : float
        Compared as numpy compares it with the magnitude (a Python number in the flow's
        dtype, NumPy 2's rule for Python scalars).

    Returns
    -------
    ndarray, (H, W) bool

    Notes
    -----
    For a float32 field the magnitude is settled from ``q = u^2 + v^2`` in float64 (exact
    squares) wherever ``q`` lies outside ``t^2 (1 +- 2^-20)``; inside that band, where
    rounding could decide, the C library's ``hypotf`` that ``np.hypot`` calls decides (its
    error, under an ulp of float32, is far inside the band). The numpy form took 1.6 ms
    at 640x480 (float32 ``hypot`` over strided channels), this 0.3 ms.
    """
    f, v = np.asarray(flow), np.asarray(valid)
    if not (f.dtype == np.float32 and f.ndim == 3 and f.shape[2] == 2 and v.dtype == bool
            and v.shape == f.shape[:2]):
        return v & (np.hypot(f[..., 0], f[..., 1]) >= min_magnitude_px)
    # the threshold the comparison of a float32 magnitude with min_magnitude_px uses
    t = float(np.result_type(f.dtype, min_magnitude_px).type(min_magnitude_px))
    lo = hi = -1.0  # t <= 0: every finite magnitude passes
    if t > 0:
        lo, hi = t * t * (1.0 - 2.0**-20), t * t * (1.0 + 2.0**-20)
    out = np.empty(v.shape, dtype=bool)
    _motion_mask(np.ascontiguousarray(f).reshape(-1), np.ascontiguousarray(v).reshape(-1), t, lo, hi,
                 out.reshape(-1))
    return out


@numba.njit(cache=True)
def _motion_mask(f, valid, t, lo, hi, out) -> None:
    """Flat ``f`` (2 n,) float32, ``valid`` and ``out`` (n,) bool; see :func:`motion_mask`.

    A first pass without branches (it vectorises) settles every pixel outside the band; a second
    one, only when some valid pixel lies in the band (or is NaN), asks ``hypotf`` there.
    """
    n = valid.size
    in_band = 0
    for k in range(n):
        u = np.float64(f[2 * k])
        v = np.float64(f[2 * k + 1])
        q = u * u + v * v
        vk = valid[k]
        out[k] = vk & (q > hi)
        in_band += np.int64(vk & (not (q < lo)) & (not (q > hi)))
    if in_band:
        for k in range(n):
            if valid[k]:
                u = np.float64(f[2 * k])
                v = np.float64(f[2 * k + 1])
                q = u * u + v * v
                if not (q < lo) and not (q > hi):  # near the threshold, NaN or infinite: numpy's hypotf
                    out[k] = np.float64(math.hypot(f[2 * k], f[2 * k + 1])) >= t


@register_stage("detection")
def detect_moving_objects(mask: np.ndarray, *, min_area_px: int = 20,
                          connectivity: int = 8) -> list[Detection]:
    """Connected regions of a motion mask as detections.

    Parameters
    ----------
    mask : ndarray, (H, W) bool
        Moving pixels of frame t.
    min_area_px : int
        Regions with fewer pixels are dropped.
    connectivity : {4, 8}

    Returns
    -------
    list of Detection
        Centroid (frame t pixel coordinates, x right, y down), area and bounding box
        of each region, largest first (no flow: ``u_px, v_px`` NaN). The pipeline's
        detection stage is :func:`~algorithms.detection.detect_vehicles`, which
        cleans, splits, merges and rejects these regions.
    """
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool:
        raise ValueError(f"mask: expected (H, W) bool, got {tuple(m.shape)} {m.dtype}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity: expected 4 or 8, got {connectivity}")
    # a bool array's bytes are 0 / 1: the uint8 view is the image astype would copy
    image = np.ascontiguousarray(m).view(np.uint8)
    if connectivity == 8:
        # BBDT (Grana 2010) scans the same 2x2 blocks in the same order as the default (Spaghetti), so it
        # numbers the regions alike and gives the same labels, stats and centroids; with stats it ran
        # 3x faster here (0.8 vs 2.5 ms at 640x480; tests/algorithms/test_tracking.py compares the two)
        n, _, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(image, 8, cv2.CV_32S,
                                                                               cv2.CCL_BBDT)
    else:
        n, _, stats, centroids = cv2.connectedComponentsWithStats(image, connectivity=connectivity)
    out = []
    for i in range(1, n):
        s = stats[i]
        if s[cv2.CC_STAT_AREA] >= min_area_px:
            x0, y0 = float(s[cv2.CC_STAT_LEFT]), float(s[cv2.CC_STAT_TOP])
            out.append(Detection(float(centroids[i, 0]), float(centroids[i, 1]), int(s[cv2.CC_STAT_AREA]), x0, y0,
                                 x0 + float(s[cv2.CC_STAT_WIDTH]) - 1, y0 + float(s[cv2.CC_STAT_HEIGHT]) - 1))
    return sorted(out, key=lambda d: -d[2])


def recentre_on_region(flow: np.ndarray, x_px: float, y_px: float, *, radius_px: float,
                       min_magnitude_px: float = 0.5, rel_tol: float = 0.3,
                       valid: np.ndarray | None = None) -> tuple[float, float]:
    """The centroid of the region that moves like the point, within ``radius_px`` of it.

    The region: pixels of the square window of half-side ``radius_px`` around
    the point whose flow differs from the flow at the point's pixel ``w0`` by at most
    ``max(min_magnitude_px, rel_tol |w0|)`` and is itself at least
    ``min_magnitude_px`` long, 8-connected to the point's pixel. A vehicle's
    pixels move alike and unlike the ground and unlike other vehicles (unless they
    drive side by side at the same velocity), so the region is the vehicle (with
    the flow method's halo, which is symmetric about it).

    Parameters
    ----------
    flow : ndarray, (H, W, 2) float
        Local flow (u, v) of the pair in px, frame t pixels (x right, y down).
    x_px, y_px : float
        The point in frame t.
    radius_px : float
        Half-side of the search window, px; larger than the vehicle, smaller than
        the distance to the next vehicle.
    min_magnitude_px : float
        Slower pixels are ground (and a point slower than this is not re-centred).
    rel_tol : float
        Relative flow tolerance (fraction of ``|w0|``).
    valid : ndarray, (H, W) bool, optional
        Pixels the flow method marks invalid never join the region.

    Returns
    -------
    (x_px, y_px) : float
        The region's centroid; the point itself when it is outside the image or
        does not move faster than ``min_magnitude_px``.
    """
    f = np.asarray(flow)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"flow: expected (H, W, 2), got {tuple(f.shape)}")
    if not (math.isfinite(radius_px) and radius_px > 0):
        raise ValueError(f"radius_px: expected a finite number > 0, got {radius_px!r}")
    h, w = f.shape[:2]
    if not (math.isfinite(x_px) and math.isfinite(y_px)):
        return x_px, y_px
    c, r = round(x_px), round(y_px)
    if not (0 <= c < w and 0 <= r < h) or (valid is not None and not valid[r, c]):
        return x_px, y_px
    w0 = f[r, c].astype(np.float64)
    m0 = math.hypot(w0[0], w0[1])
    if not m0 >= min_magnitude_px:
        return x_px, y_px
    rad = int(math.ceil(radius_px))
    x0, x1, y0, y1 = max(0, c - rad), min(w, c + rad + 1), max(0, r - rad), min(h, r + rad + 1)
    win = f[y0:y1, x0:x1].astype(np.float64)
    similar = (np.hypot(win[..., 0] - w0[0], win[..., 1] - w0[1]) <= max(min_magnitude_px, rel_tol * m0)) \
        & (np.hypot(win[..., 0], win[..., 1]) >= min_magnitude_px)
    if valid is not None:
        similar &= np.asarray(valid, bool)[y0:y1, x0:x1]
    _, labels = cv2.connectedComponents(similar.astype(np.uint8), connectivity=8)
    ys, xs = np.nonzero(labels == labels[r - y0, c - x0])
    return float(xs.mean() + x0), float(ys.mean() + y0)


# The thesis point tracker's image correlation (tracking.point.correlation), defaults:
# template_px: side of the pixel's square template (odd), the thesis's 15 x 15 LK window, which holds a
#   17 x 7 px vehicle's width and most of its length at 0.27 m/px;
# search_px: half-side of the NCC search around the flow's prediction; the prediction is one frame's flow
#   error away (under 1 px in the thesis domain), 3 px leaves room for a flow that missed a frame;
# min_ncc: a weaker peak is no match (the point keeps the flow's prediction);
# renew_ncc: a match weaker than this renews the template from the new frame (turns, shadows).
CORRELATION_DEFAULTS = {"template_px": 15, "search_px": 3, "min_ncc": 0.5, "renew_ncc": 0.8}


@dataclass(frozen=True)
class CorrelationMatch:
    """Result of :func:`ncc_refine`.

    x_px, y_px : float
        Where the template's centre lies in the searched image (sub-pixel); NaN when not valid.
    ncc : float
        Eq. 3.1 at the best integer offset, in [-1, 1]; NaN when undefined (flat template
        or flat search area, or the search area outside the image).
    valid : bool
        A clear peak inside the search area with ``ncc >= min_ncc``.
    reason : str
        Why not valid ("" when valid): "flat template", "outside the image",
        "flat search area", "peak on the search border", "peak below min_ncc".
    """

    x_px: float
    y_px: float
    ncc: float
    valid: bool
    reason: str = ""


def _check_gray(name: str, image) -> np.ndarray:
    g = np.asarray(image)
    if g.ndim != 2 or not np.issubdtype(g.dtype, np.number):
        raise ValueError(f"{name}: expected an (H, W) gray image, got {tuple(g.shape)} {g.dtype}")
    return g


def point_template(image: np.ndarray, x_px: float, y_px: float, *, half_px: int) -> np.ndarray | None:
    """The square patch of ``image`` centred on the sub-pixel point, bilinearly interpolated.

    Parameters
    ----------
    image : ndarray, (H, W) float or integer
        A gray frame.
    x_px, y_px : float
        The patch centre (pixel centres at integer coordinates, x right, y down).
    half_px : int
        Half-side: the patch is ``(2 half_px + 1)`` px square.

    Returns
    -------
    ndarray, (2 half_px + 1, 2 half_px + 1) float32, or None
        ``patch[i, j] = image(y_px - half_px + i, x_px - half_px + j)``; None when
        the patch (with the interpolation's neighbours) does not lie wholly inside
        the image (never a padded patch).
    """
    g = _check_gray("image", image)
    if isinstance(half_px, bool) or not isinstance(half_px, (int, np.integer)) or half_px < 1:
        raise ValueError(f"half_px: expected an integer >= 1, got {half_px!r}")
    h, w = g.shape
    if not (math.isfinite(x_px) and math.isfinite(y_px)):
        return None
    if not (half_px <= x_px and math.floor(x_px) + half_px + 1 <= w - 1
            and half_px <= y_px and math.floor(y_px) + half_px + 1 <= h - 1):
        return None
    side = 2 * int(half_px) + 1
    return cv2.getRectSubPix(g.astype(np.float32, copy=False), (side, side), (float(x_px), float(y_px)))


def ncc_refine(template: np.ndarray, image: np.ndarray, x_px: float, y_px: float, *, search_px: int = 3,
               min_ncc: float = 0.5) -> CorrelationMatch:
    """Place a point's template in ``image`` near a predicted position by NCC (thesis eq. 3.1), sub-pixel.

    The candidate centres are ``(x_px + dx, y_px + dy)`` for integer ``dx, dy`` in
    ``[-search_px, search_px]``; at each, eq. 3.1 compares the template with the
    image patch there (bilinear for a sub-pixel prediction),

        r = sum (T - T_bar)(I - I_bar) / sqrt(sum (T - T_bar)^2 sum (I - I_bar)^2)      (eq. 3.1)

    and the best offset is refined by a parabola through its neighbours,
    separately in x and y (as :func:`~algorithms.global_motion.ncc_global_motion`
    does with ``subpixel=True``).

    Parameters
    ----------
    template : ndarray, (2h+1, 2h+1) float
        The point's patch (:func:`point_template`), centred on the point.
    image : ndarray, (H, W)
        The frame to search.
    x_px, y_px : float
        The predicted position of the template's centre in ``image``.
    search_px : int
        Half-side of the search, px (integer offsets).
    min_ncc : float
        Smallest peak that counts as a match.

    Returns
    -------
    CorrelationMatch
        Not valid, with NaN position, for a flat template, a search area not
        wholly inside the image, a flat search area, a peak on the border of the
        search (the best match may lie beyond it) or a peak below ``min_ncc``.
    """
    t = np.asarray(template, dtype=np.float64)
    if t.ndim != 2 or t.shape[0] != t.shape[1] or t.shape[0] % 2 != 1 or t.shape[0] < 3:
        raise ValueError(f"template: expected an odd square (2h+1, 2h+1) array, h >= 1, got {tuple(t.shape)}")
    if isinstance(search_px, bool) or not isinstance(search_px, (int, np.integer)) or search_px < 1:
        raise ValueError(f"search_px: expected an integer >= 1, got {search_px!r}")
    if not (math.isfinite(min_ncc) and -1.0 <= min_ncc <= 1.0):
        raise ValueError(f"min_ncc: expected a number in [-1, 1], got {min_ncc!r}")
    nan = math.nan
    t = t - t.mean()
    t_energy = float((t * t).sum())
    # a flat template correlates with nothing (eq. 3.1's denominator is 0)
    if not t_energy > 1e-9 * t.size:
        return CorrelationMatch(nan, nan, nan, False, "flat template")
    half, r = t.shape[0] // 2, int(search_px)

    area = point_template(image, x_px, y_px, half_px=half + r)
    if area is None:
        return CorrelationMatch(nan, nan, nan, False, "outside the image")
    # c[j, i]: eq. 3.1 with the image patch centred at (x_px + i - r, y_px + j - r); NaN where undefined
    win = sliding_window_view(area.astype(np.float64), t.shape)   # (2r+1, 2r+1, 2h+1, 2h+1)
    wz = win - win.mean(axis=(2, 3), keepdims=True)
    num = np.einsum("ijkl,kl->ij", wz, t)
    energy = np.einsum("ijkl,ijkl->ij", wz, wz)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.where(energy > 1e-9 * t.size, num / np.sqrt(energy * t_energy), np.nan)
    if not np.isfinite(c).any():
        return CorrelationMatch(nan, nan, nan, False, "flat search area")
    iy, ix = np.unravel_index(int(np.nanargmax(c)), c.shape)
    peak = float(c[iy, ix])
    if ix in (0, 2 * r) or iy in (0, 2 * r):
        return CorrelationMatch(nan, nan, peak, False, "peak on the search border")
    if peak < min_ncc:
        return CorrelationMatch(nan, nan, peak, False, "peak below min_ncc")
    # the vertex of a parabola through the peak and its neighbours, per axis; an undefined neighbour (flat
    # patch) gives no curvature, so the integer peak stands on that axis. A 3-point fit is biased by the
    # NCC peak's asymmetry (up to about 0.15 px on the tests' textures), without accumulating: the
    # template stays the same between renewals.
    cz = np.nan_to_num(c, nan=-1.0)
    x = x_px + ix - r + _parabola_offset(cz[iy, ix - 1], peak, cz[iy, ix + 1])
    y = y_px + iy - r + _parabola_offset(cz[iy - 1, ix], peak, cz[iy + 1, ix])
    return CorrelationMatch(float(x), float(y), peak, True)


def _check_correlation(given: Mapping) -> dict:
    """``CORRELATION_DEFAULTS`` overlaid by ``given``, checked."""
    unknown = set(given) - set(CORRELATION_DEFAULTS)
    if unknown:
        raise ValueError(f"correlation: unknown key(s) {sorted(unknown)}; valid: {', '.join(CORRELATION_DEFAULTS)}")
    c = {**CORRELATION_DEFAULTS, **given}
    for k in ("template_px", "search_px"):
        v = c[k]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < (3 if k == "template_px" else 1):
            raise ValueError(f"correlation.{k}: expected an integer >= {3 if k == 'template_px' else 1}, got {v!r}")
    if c["template_px"] % 2 != 1:
        raise ValueError(f"correlation.template_px: expected an odd side (the point is its centre), "
                         f"got {c['template_px']}")
    for k in ("min_ncc", "renew_ncc"):
        v = c[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and -1 <= v <= 1):
            raise ValueError(f"correlation.{k}: expected a number in [-1, 1], got {v!r}")
    return {"template_px": int(c["template_px"]), "search_px": int(c["search_px"]),
            "min_ncc": float(c["min_ncc"]), "renew_ncc": float(c["renew_ncc"])}


class PointTracker:
    """The thesis point tracker: one pixel followed by global shift + local flow (+ image correlation), Kalman-filtered.

    Parameters
    ----------
    x_px, y_px : float
        The seed pixel in frame 0.
    track_id : int
    seed_vehicle_id : optional
        Carried into the rows (the runner seeds with ground-truth vehicles).
    kalman : mapping, optional
        ``x0, p0, q, r`` of :func:`~algorithms.kalman.scalar_kalman` per axis.
        Default: the thesis's P(1|1), Q, R with ``x0=None`` (X(1|1) = the first
        flow measurement), since the thesis's X(1|1) = -1 encodes its video's
        upward motion. Pass ``THESIS_KALMAN`` for the thesis exactly. With
        Q / R = 20 the thesis's gain is about 0.95: X(k|k) stays within 5 % of the
        measurement (its Table 4.1 shows as much), so its filtered track is
        nearly the raw one.
    recentre_px : float, optional
        Re-centre on the region that moves like the point (see :meth:`step`).
    correlation : mapping, optional
        Thesis 4.1's image correlation (see :meth:`step`): keys of
        ``CORRELATION_DEFAULTS`` (``template_px`` odd side of the template,
        ``search_px``, ``min_ncc``, ``renew_ncc``), missing ones take those
        defaults. None: the flow alone moves the point (open loop).
    position_filter : mapping, optional
        ``{"sigma_accel_px": ..., "sigma_meas_px": ...}``: instead of the thesis's
        filter on the flow, filter the raw positions with a constant-velocity
        Kalman filter (:func:`~algorithms.kalman.kalman_cv_filter`) in the
        ground-fixed frame (raw position minus the cumulative global shift, so
        camera sway is not read as vehicle acceleration), then add the camera
        path back. Meant with ``recentre_px``, whose positions are measurements
        with noise of their own (the region's centroid), not integrated flow.

    Use :meth:`step` once per pair in order, then :meth:`rows`.
    """

    def __init__(self, x_px: float, y_px: float, *, track_id: int = 0, seed_vehicle_id=None,
                 kalman: Mapping | None = None, recentre_px: float | None = None,
                 position_filter: Mapping | None = None, correlation: Mapping | None = None):
        if position_filter is not None:
            unknown = set(position_filter) - {"sigma_accel_px", "sigma_meas_px"}
            if unknown:
                raise ValueError(f"position_filter: unknown key(s) {sorted(unknown)}; valid: sigma_accel_px, "
                                 "sigma_meas_px")
            ConstantVelocityKalman((0.0, 0.0), **position_filter)  # its own checks, now rather than in rows()
        self.position_filter = None if position_filter is None else dict(position_filter)
        if recentre_px is not None and not (math.isfinite(recentre_px) and recentre_px > 0):
            raise ValueError(f"recentre_px: expected None or a finite number > 0, got {recentre_px!r}")
        self.track_id, self.seed_vehicle_id = int(track_id), seed_vehicle_id
        self.kalman = dict(THESIS_KALMAN, x0=None) if kalman is None else dict(kalman)
        self.recentre_px = None if recentre_px is None else float(recentre_px)
        self.correlation = None if correlation is None else _check_correlation(correlation)
        self._pos = [(float(x_px), float(y_px))]
        self._shift: list[tuple[float, float]] = []
        self._w: list[tuple[float, float]] = []
        self._template: np.ndarray | None = None
        #: per step, the correlation's match (None without ``correlation``)
        self.matches: list[CorrelationMatch | None] = []

    def step(self, global_shift_px, flow_local: np.ndarray, valid: np.ndarray | None = None, *,
             frames: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Advance by pair t -> t+1: sample the local flow at the current position.

        Outside the image, or where ``valid`` is False, the measurement is NaN
        (the Kalman filter only predicts) and the point moves by the global shift.

        With ``correlation`` set, ``frames`` are the gray frames t and t+1
        (uncompensated, the frames the point's coordinates live in). The flow
        step is the prediction; :func:`ncc_refine` of the point's template
        around it in frame t+1 gives the new position when it finds a match
        (``self.matches[t]``), else the prediction stands. The template is taken
        from frame t at the point when there is none (the first step, or the
        last one was flat), and from frame t+1 at the new position when the
        match's NCC is below ``renew_ncc``.

        With ``recentre_px`` set, the point is first moved to the centroid of the
        region around it that moves like it (:func:`recentre_on_region` on the
        same flow field, twice, ``radius_px=recentre_px``): that centroid is the
        raw position of frame t. Integrating flow alone is open loop: a flow that
        is biased on the target (a window that also covers ground shrinks a small
        vehicle's flow; coarse-to-fine LK stops short of large motions) makes the
        point slide off its vehicle in a straight line, and once on the ground it
        follows the ground for good. The vehicle's region closes the loop.
        """
        corr = self.correlation
        if corr is not None:
            if frames is None or len(frames) != 2:
                raise ValueError("frames: the correlation needs the gray frames (t, t+1), got none")
            f0, f1 = _check_gray("frames[0]", frames[0]), _check_gray("frames[1]", frames[1])
            if f0.shape != f1.shape or f0.shape != flow_local.shape[:2]:
                raise ValueError(f"frames: expected two frames of the flow's shape {flow_local.shape[:2]}, "
                                 f"got {f0.shape} and {f1.shape}")
        x, y = self._pos[-1]
        if self.recentre_px is not None:
            for _ in range(2):
                x, y = recentre_on_region(flow_local, x, y, radius_px=self.recentre_px, valid=valid)
            self._pos[-1] = (x, y)
        h, w = flow_local.shape[:2]
        c, r = (round(x), round(y)) if math.isfinite(x) and math.isfinite(y) else (-1, -1)
        inside = 0 <= c < w and 0 <= r < h and (valid is None or bool(valid[r, c]))
        wu, wv = (float(flow_local[r, c, 0]), float(flow_local[r, c, 1])) if inside else (math.nan, math.nan)
        sx, sy = float(global_shift_px[0]), float(global_shift_px[1])
        # p(t+1) = p(t) + s(t) + w(t)(p(t))  (Appendix B: row = row + ofy + icy)
        x1, y1 = x + sx + (wu if inside else 0.0), y + sy + (wv if inside else 0.0)
        if corr is not None:
            half = corr["template_px"] // 2
            if self._template is None:
                self._template = point_template(f0, x, y, half_px=half)
            match = (ncc_refine(self._template, f1, x1, y1, search_px=corr["search_px"], min_ncc=corr["min_ncc"])
                     if self._template is not None else
                     CorrelationMatch(math.nan, math.nan, math.nan, False, "outside the image"))
            self.matches.append(match)
            if match.valid:
                x1, y1 = match.x_px, match.y_px
                # Z(k): the local motion of the tracked pixel, which the correlation measured
                wu, wv = x1 - x - sx, y1 - y - sy
                if match.ncc < corr["renew_ncc"]:
                    self._template = point_template(f1, x1, y1, half_px=half)
            elif match.reason == "flat template":
                self._template = None
        else:
            self.matches.append(None)
        self._shift.append((sx, sy))
        self._w.append((wu, wv))
        self._pos.append((x1, y1))

    def rows(self) -> list[dict]:
        """One row per frame 0..len(steps): raw, filtered and one-step-predicted positions.

        The filtered path makes the same moves as the raw one (global shift, and
        re-centring jumps) with the Kalman-filtered local motion X(k|k) in place of
        the measured one Z(k) (the flow at the point, or with ``correlation`` the
        motion the correlation found): ``filt(k) = raw(k) + sum_{j<k} (X(j|j) - Z(j))``.
        """
        n = len(self._w)
        rows = []
        raw = np.array(self._pos)
        if n == 0:
            x, y = raw[0]
            return [self._row(0, x, y, x, y, x, y)]
        s, w = np.array(self._shift), np.array(self._w)
        if self.position_filter is not None:
            # ground-fixed frame: the camera path c(k) = sum of the global shifts before frame k
            cam = np.vstack([np.zeros((1, 2)), np.cumsum(s, axis=0)])
            res = kalman_cv_filter(raw - cam, sigma_accel_px=self.position_filter.get("sigma_accel_px", 0.5),
                                   sigma_meas_px=self.position_filter.get("sigma_meas_px", 1.0))
            filt, pred = res.filtered_px + cam, res.predicted_px + cam
            return [self._row(k, *raw[k], *filt[k], *pred[k]) for k in range(n + 1)]
        w_f = np.column_stack([self._filter(w[:, a]) for a in (0, 1)])  # X(k|k) per axis
        # where the raw point moved by the shift alone (no measurement), the filtered one moves by the
        # shift plus the prediction X(k|k) (NaN only before any measurement)
        delta = np.nan_to_num(w_f) - np.nan_to_num(w)
        filt = raw + np.vstack([np.zeros((1, 2)), np.cumsum(delta, axis=0)])
        rows.append(self._row(0, *raw[0], *filt[0], *raw[0]))
        for k in range(1, n + 1):
            # eq. 4.6: the prediction of the flow of pair k-1 is X(k-1|k-1) of the pair before
            w_pred = w_f[k - 2] if k >= 2 else np.zeros(2)
            pred = filt[k - 1] + s[k - 1] + np.nan_to_num(w_pred)
            rows.append(self._row(k, *raw[k], *filt[k], *pred))
        return rows

    def _filter(self, z: np.ndarray) -> np.ndarray:
        finite = np.isfinite(z)
        if not finite.any():
            return np.full_like(z, np.nan)
        kw = dict(self.kalman)
        if kw.get("x0") is None and not finite[0]:
            kw["x0"] = float(z[finite][0])
        return scalar_kalman(z, **kw)

    def _row(self, frame, x, y, xf, yf, xp, yp) -> dict:
        return {"frame": int(frame), "track_id": self.track_id, "x_px": float(x), "y_px": float(y),
                "x_filt_px": float(xf), "y_filt_px": float(yf), "x_pred_px": float(xp), "y_pred_px": float(yp),
                "source": "point", "seed_vehicle_id": self.seed_vehicle_id,
                "bbox_x0_px": math.nan, "bbox_y0_px": math.nan, "bbox_x1_px": math.nan, "bbox_y1_px": math.nan}


@dataclass
class _Track:
    id: int
    kf: BoxKalman
    hits: int = 1
    misses: int = 0
    confirmed: bool = False
    pending: list = field(default_factory=list)  # rows held until confirmation
    start: np.ndarray | None = None  # ground-fixed centre of its first detection
    travel: float = 0.0  # farthest its ground-fixed centre has been from start, px
    template: np.ndarray | None = None  # the image inside its box at its last detection (float32)
    held: int = 0  # consecutive frames placed by the template (no detection)
    hist: list = field(default_factory=list)  # (frame, filtered ground-fixed box cx, cy, w, h) at its detections
    seen: list = field(default_factory=list)  # (frame, ground-fixed centre of the detection) until confirmed
    flows: list = field(default_factory=list)  # the detections' ground-fixed flow (u, v) px/frame, until confirmed
    sizes: deque = field(default_factory=lambda: deque(maxlen=25))  # filtered (w, h) at its last detections
    ground_checked: bool = False  # its template was compared with the place before the vehicle came
    first: tuple | None = None  # (frame, ground-fixed box, template) of its first detection, to extend it back
    shown: tuple | None = None  # (frame, ground-fixed box) of its latest output row with a box
    gap: list = field(default_factory=list)  # rows output without a box since then, to fill (fill_gaps)
    merged: bool = False  # it took in another track as a part of the same vehicle (merge_hits)
    excused: int = 0  # consecutive frames a detection abreast held it with another track (abreast_shared)
    partial: list = field(default_factory=list)  # (axis, raw extent) of its consecutive completed detections


# The multi-target tracker's keys (tracking.multi) and their defaults, one home (pipeline_spec checks against it):
# gate_px: largest distance from a track's predicted centre to a detection it may take (a vehicle at 35 m/s,
#   10 fps, 0.22 m/px moves 16 px a frame; the prediction, not the last position, is what is gated);
# min_iou: a pair whose boxes overlap at least this much is feasible whatever its distance (a bus's centre
#   can jump when its region is found whole after being found in part);
# birth_hits: detections before a track is confirmed (the detections' minimum persistence);
# birth_gap: frames in a row a tentative track may go without a detection (a slow vehicle's flow is near the
#   threshold and its detection comes and goes); 0, a tentative track ends at its first miss, is the default: 1
#   lifted the 640x480 town scene (realistic, most cars under 1 px a frame) by 0.02-0.12 MOTA but let flicker
#   through at 1080p and on KIT AIS (1080p city stand-in: farneback 0.246 -> 0.155, pyramidal-lk 0.151 -> 0.093);
# min_travel_px, min_travel_rel: a track is confirmed only once its ground-fixed centre has moved this far from
#   its first detection, and this many times its box's larger side (flow noise, compression artefacts, flicker
#   and a tree crown's sway make regions that recur in place; a vehicle leaves its own box; the rows of the
#   frames before confirmation are output when it comes, so a slow car loses nothing by the wait); min_travel_rel
#   0.08 in dis: a car creeping in a queue is detected in short runs that never cover a quarter of its side (figures
#   there);
# travel_lengthwise_rel: a track whose box reaches at least this many times as far along its fitted motion as across
#   it (a vehicle driving along its length) is judged by min_travel_rel on its extent across the motion, its width,
#   and not its larger side (_travel_side): it leaves its place sideways by its width, while a bus creeping at 0.2-0.4
#   px a frame (realistic's bus 5: 59 px long, 2.1 -> 0.9 m/s, 8 px in 30 frames) does not travel a quarter of its
#   length within a clip. A region jumping about in place still has no trend (min_trend_f); a box elongated across
#   its motion (a roof's edge band) and a joined box of two cars side by side (farneback on the synthetic city, an
#   80 x 50 px box confirmed ahead of its car's own track when every box moving along its longer side was judged
#   on its shorter one: MOTA 0.626 -> 0.456) stay judged on their larger side. 0: off, the default; 2.5 in
#   pyramidal-hs, pyramidal-lk and farneback, with detection.parallax_lengthwise_rel (figures in their files);
# min_trend_f: ... and a constant velocity fitted to its detections' centres explains their scatter: the F
#   statistic of the fit, (explained / 2) / (residual / (2n - 4)) over its n detections, reaches this (a
#   vehicle drives on at a steady speed however much its box jitters, and the trend grows with every frame;
#   a region that jumps about in place has none: with 10, about 1 in 10 places that jitter by the travel
#   ever pass; a car at 0.4 px a frame whose centre jitters by 1 px passes after about 15 frames; 0: off);
# partial_rel: a confirmed track's detection whose box is narrower than the median box the track had at its last 25
#   detections by more than this fraction along an axis, with one side within this fraction of that box's placed
#   at the prediction, is a partial view (the vehicle's front under a crown or past the image border, one edge of a
#   uniform roof): that side is kept and the box completed to that size, so that a vehicle that passes under a
#   crown a little at a time keeps its size (a top view does not shrink); a box inside on both sides is taken as it
#   is (1: off);
# partial_abreast: a partial view is not completed where the completed box would cover half or more of another
#   detection of the frame that lies abreast of it (side by side across the motion): two cars in adjacent lanes
#   that the detector joined into one region when their track was born gave the track the two cars' size, and
#   every later detection of one of them, found apart, was completed back over the other (the 1080p city-wide world
#   at seed 3: a 47 px wide track over two 17 px cars for 50 frames, each row a false positive and two misses): the
#   track's size then starts again from the detection's (BoxKalman.restart_size; filtered, a 47 px size took 30
#   frames to shrink to one car). Nose to tail (a cab and its trailer found apart) it still completes. False: off,
#   the default; on in dis (figures there);
# partial_steady_frames: a track whose detections were completed (partial_rel) along the same axis this many times
#   in a row, their extents along it within PARTIAL_STEADY_PX of their median, starts its size again from the
#   detection's (BoxKalman.restart_size): a view that stays the same is the vehicle, and the size the track had came
#   from detections that held something else too (a car's first boxes with its shadow or a neighbour: the 1080p
#   city-wide world at seed 3, a 20 x 37 px car tracked as 37 x 41 px for 68 frames, completed back from each good
#   detection, every row a false positive and a miss). A vehicle sliding under a crown or across the border changes
#   its partial view frame by frame. 0: off, the default; 6 in dis (figures there);
# abreast_shared: a detection whose box holds the predicted centres of two tracks that lie abreast (side by side across
#   their motion, _abreast; their boxes long along the same image axis) is two vehicles in adjacent lanes that the
#   detector joined in that frame (a queue creeping away from a light: their flows agree and the road between them is
#   narrower than a car); it is neither track's and starts none, and the two tracks miss nothing in that frame (a
#   confirmed one is held or coasts; a tentative one, which birth_gap 0 ends at its first miss, lives on). Without it
#   the joined box went to one car's track and the other car's tentative track ended, again each time it was joined (the
#   world at seed 3: two cars abreast at 0.5 px a frame, the upper one's tentative tracks ended at 14, 2, 2 and 11
#   hits). The boxes' axis keeps a truck's whole box from being taken for two vehicles where a part of it, split off
#   crosswise, had a tentative track beside a car's (pyramidal-lk on the world at seed 1: that part then followed the
#   truck for 98 frames, each a false positive). A tentative track is held so birth_hits frames in a row at most: a
#   car split once into two halves abreast left its track at one half's size and a tentative track on the other, and
#   each whole box of it after was neither's (world 3, car 160: for the clip's last 26 frames, its track coasting at
#   8 of its 22 px). Bounded (the tracker replayed on dis's captured detections): worlds pooled 0.604 -> 0.607 (world 3
#   0.679 -> 0.685), on the captures of the first renders and of an older dis unchanged; the 15 synthetic cells of
#   dis, pyramidal-hs and pyramidal-lk (--frames 30) and KIT AIS unchanged. False: off, the default; on in dis,
#   pyramidal-hs and pyramidal-lk (figures there);
# death_misses: consecutive frames without a detection after which a confirmed track ends; it coasts on its
#   prediction meanwhile (tree crowns, an overpass: 10 frames are 1 s at 10 fps, 0.33 s at 30 fps);
# coast_gate_growth: the gate grows by this fraction of gate_px per frame of coasting;
# report_coasting: coasting frames are output with the prediction as position (false: with NaN, no
#   prediction of a vehicle that is hidden);
# fill_gaps: coasting frames that a track bridges (it is detected or held again before it ends) are output with the
#   box interpolated linearly, in the ground-fixed frame, between its boxes before and after the gap: the vehicle
#   was there, its detection flickered (a slow vehicle near the flow threshold, a frame its region split), and
#   the two ends place it better than the prediction from one side; offline: the rows are filled when the track is
#   found again, a track that ends keeps its gap empty (linear interpolation of tracks: Zhang et al. 2022, ByteTrack);
# fill_min_ncc: ... and only where the track's template (at the gap's end) matches the kept frame (hold_history)
#   within hold_search_px of the interpolated place, at this NCC; the box is put where it matches: a vehicle
#   hidden under a crown or an overpass through the gap is not there to be scored (truth counts what is visible),
#   and a camera whose sway the path does not follow exactly moves it off the line (0: no check, every row filled);
# min_area_rel: a track whose median box area is under this fraction of the median over the sequence's tracks (5 or
#   more) is left out of the output: a pedestrian or a cyclist among vehicles (a top view of a person is about
#   0.3 m^2, a bicycle 1 m^2, a motorbike 1.5 m^2, a car 8 m^2), where no ground sampling distance gives the m^2
#   limits of the detection; 0: off; 0.15, the default, is those areas' ratios; a detected box holds its object's
#   cast shadow and a pixel or two of blur on each side, which add far more to a small box than to a car's (on
#   the 1080p city-wide worlds a cyclist's 10 x 12 px truth was tracked as 16 x 18 px, 0.22-0.26 of the median
#   track, a motorbike's 0.2; the cars' tracks 0.39 and up): 0.3 in dis, farneback and the pyramidal pair
#   (figures in dis.yaml), which leaves motorbikes out too;
# use_velocity: a detection's mean flow (its ground-fixed motion) is a velocity measurement and starts a
#   new track at the vehicle's speed;
# hold_min_ncc: a confirmed track without a detection is placed where its template (the image inside its box
#   at its last detection) matches the frame best, when that normalised cross-correlation reaches this: a
#   vehicle that slows down and stops (a queue at a light) leaves the motion detector but not the image
#   (0 turns holding off; needs the frames);
# hold_search_px: the template is searched within this distance of the prediction, and at least half the box's
#   larger side (a stopping vehicle falls behind its constant-velocity prediction by its deceleration, a
#   fraction of a pixel a frame; searching back to its last place would let a fast car's template, whose box
#   holds ground, match the ground it left);
# hold_min_travel_rel: only a track whose ground-fixed centre has travelled this many times its box's larger side is
#   held (a vehicle that drove; a region that recurs in place, flicker on a tree crown or a roof edge, would otherwise
#   be held for ever). Under 1, a car that crept up a queue by less than its length and stopped is held too: no kept
#   frame shows its place without it, so the test that its template is no ground's (hold_history) asks instead that the
#   track have twice birth_hits detections and its template match what it held in its oldest kept frame (_of_ground).
#   0.1, the default (1 until 30 November): on the three 1080p city-wide worlds six cars that crept and stopped lost
#   their tracks where they stopped (about 260 rows); dis, one suite run of the three exported clips, 1 -> 0.1: 0.480 /
#   0.522 / 0.646 -> 0.499 / 0.543 / 0.673 (pooled 0.563 -> 0.587, FP 648 -> 570, FN 4627 -> 4426); on the worlds'
#   first renders (the tracker replayed on dis's captured detections) 0.550 -> 0.569; the 1080p city and realistic
#   stand-ins unchanged (0.325, 0.638). Without the detections' rule, 0.586 and 0.563 (farneback held a roof that
#   parallax moved on urban-parallax, seed 2 at 60 frames: 0.690 -> 0.577); with it and 0, a passing truck's track
#   held on the parked car it slid onto (2 px of travel, 76 rows); 0.05 0.592 and 0.563, 0.15 0.581 and 0.555, 0.25
#   0.581 and 0.546 (before the rule). Synthetic, 30 frames (benchmarks/tracking_quality.py --scene nominal realistic
#   urban-parallax fast-vehicles city --frames 30), MOTA 1 -> 0.1: pyramidal-hs realistic 0.888 -> 0.944, fast-vehicles
#   0.885 -> 0.893; farneback realistic 0.775 -> 0.803, city 0.636 -> 0.655; dis city 0.723 -> 0.733; thesis-lk
#   realistic 0.758 -> 0.747, thesis-hs realistic 0.697 -> 0.685; the other 28 cells unchanged. KIT AIS (--kit-ais)
#   pseudo-MOT MOTA dis -0.250 -> -0.247 (tracks recall 0.562 -> 0.570), pyramidal-lk -0.490 -> -0.495, tv-l1 -0.531 ->
#   -0.533, pyramidal-hs unchanged;
# hold_same_frames: the kept frame in which a track that never was a box side away must show what its template holds
#   (_of_ground, hold_min_travel_rel) is the oldest within this many frames before the template's detection, or, with
#   none there, the latest before them; 0, the default: the oldest kept (up to hold_history frames back). A car or a
#   bus that slowed over 80 frames looks different in its box by then (its box, light on its roof), and was refused
#   its hold where it stopped: the 1080p city-wide world at seed 1, a 94 x 70 px bus lost 19 frames before the clip's
#   end at 0.1 m/s, a car 56 frames. A box that slides off its car does so within a few frames. 12 in dis (figures there);
# back_min_travel_rel: a confirmed track is followed back from its first detection (a vehicle that waited at a light
#   when the clip began stood where it was first found: once it has left that place, which then looks different, the
#   kept frames before are searched for its first template, :meth:`MultiTargetTracker._extend_back`) once its
#   ground-fixed centre has travelled this many times its first box's larger side. 1.0, the default, was the
#   hold's travel (hold_min_travel_rel) before it had a key of its own: a car of a queue that creeps at 0.5-2 m/s
#   (0.15-0.6 px a frame at 0.13 m a pixel and 25 fps) does not travel its 35 px length within a 100-frame clip,
#   and was never followed back to the frames in which it crept too slowly to be detected. Its place looks
#   different well before it leaves its box (the one-off test that the first template no longer matches there
#   stays: a template of ground or a marking matches the place after the "vehicle" left and is never followed back);
#   at or under min_travel_rel every confirmed track is tried at its confirmation. 0.25 in dis (three 1080p city-wide
#   worlds, MOTA pooled 0.342 -> 0.366; the figures, KIT AIS's and the synthetic scenes' are there); measured on
#   pyramidal-hs too (figures in its file), off there until its twin pyramidal-lk is measured;
# back_track_size: the rows a track is followed back by get the size it has had at its detections (the median of its
#   filtered box at its last 25, as partial_rel completes a partial view), centred where its first template matched;
#   false, the default: the first detection's box, which is part of the vehicle where that detection was (a slow
#   car's first long-baseline box is often its front or rear edge, or half the car: world 3 below, a 17 x 36 px
#   box on a 30 x 36 px car followed back through 54 frames at IoU 0.24, each row a false positive and a miss). Off in
#   the built-ins (figures in dis.yaml and pyramidal-hs.yaml: with back_min_travel_rel 0.25 it gains a world for dis
#   and costs a KIT AIS row; on pyramidal-hs it is part of the pair that wins there; alone its effect is mixed);
# back_stop_inside: the following back stops at a frame where this share of the followed box lies within the box of
#   another confirmed track's row in that frame: that vehicle was tracked there already. A part of a vehicle found
#   late (a van's front corner, a bus's front end, where a region split) gets a track of its own that merge_covered
#   joins only while it runs; followed back, its first template matches the part along the vehicle's whole way
#   (the hold's search radius follows a car at 2-3 px a frame), each row beside the vehicle's track a false positive
#   (the world at seed 2 of the 1080p city-wide view: two such tracks, 166 rows). 0: off, the default; 0.8 in dis
#   (figures there);
# hold_frames: the most consecutive frames a track is held without a detection (250: 10 s at 25 fps), and the
#   most it is followed back from its first detection (back_min_travel_rel);
# hold_history: frames the tracker keeps (8 bits: 2 MB a 1080p frame) to follow tracks back, and to check, before
#   it first holds a track, that the place looked
#   different before the vehicle came: in the latest kept frame in which the track was a box side or more away,
#   the template must not match that place (at hold_min_ncc); a template of ground, a roof edge or a tree crown
#   (a false track, or a box that slid off its vehicle) matches it then too, and is not held (a track never a side
#   away: see hold_min_travel_rel);
# steady_flow_rel: steady: the mean of the detections' flow vectors is at least this fraction of their mean speed
#   (flow noise turns about from frame to frame and averages out; 1: every detection moved alike);
# end_min_hits: offline, as MOTChallenge scores: a tentative track detected in its last frames when the clip ends,
#   with at least this many detections whose flow is steady (steady_flow_rel), is confirmed then and its rows
#   output: the clip's end, not the vehicle, cut the frames it needed to travel (a car pulling away from a light in
#   the last second). 0: off, the default: on two 50-frame city-wide worlds (dis, merge_hits 0) MOTA 0.234 -> 0.240
#   (seed 1: a car that pulls away in its last 6 frames) but 0.494 -> 0.481 (seed 2: a pair of pedestrians walking
#   together, one car-sized region, confirmed 17 frames before the travel rule would), 3 to 8 alike;
# steady_min_hits: a tentative track detected this many times (in as many frames in a row, with birth_gap 0) whose
#   detections measured one steady motion (steady_flow_rel; its boxes went that way) is confirmed though it has not
#   travelled min_travel_px: a car creeping up a queue at 0.1-0.4 px a frame, found in runs of 5-25 frames broken by
#   one it is not, whose tentative tracks died at each break. 0: off, the default; 8 in dis (figures there);
# merge_hits: confirmed tracks that are parts of one vehicle are joined: a truck, bus or van whose region splits
#   (cab and body, the shadow side) in some frames and is found whole in others gets a confirmed track per part,
#   and the whole detection, whose centre lies outside both parts' gates, starts a tentative track the next split
#   frame ends; a detection no track took that covers two confirmed tracks moving alike (merge_inside of each
#   one's box inside it) counts a frame for the pair, and after this many frames they are one track (the rows
#   before: the union of the two parts' boxes; after: the parts found within its box joined into one detection).
#   50-frame city-wide worlds (dis): seed 1 MOTA 0.234 -> 0.376 (false positives 523 -> 323: trucks and a bus
#   boxed as two parts), seeds 2 and 3 unchanged (0.494, 0.369); 0: off;
# merge_inside: the share of a track's box a detection must cover to count it as one of its parts, and of a
#   detection's box inside a joined track's for it to be one of that vehicle's parts;
# merge_covered: ... and a frame is also counted for a confirmed track detected in it whose box covers another
#   confirmed track's smaller box (merge_inside) moving alike, that other track not detected in the frame: the
#   whole detection went to one part's track (it overlapped it by min_iou) and the other part's track stays inside
#   the grown box (a car whose uniform roof does not move in the flow, found as its two ends); a track detected
#   apart in the same frame is an object of its own (a car beside a track that took two cars' joined region: counted
#   without that condition, seed 3 lost one, 39 misses). With merge_hits 3, seeds 1 / 2 / 3: 0.376 / 0.494 / 0.369
#   -> 0.376 / 0.556 / 0.392 (false positives 323 / 210 / 291 -> 323 / 114 / 246, misses 992 / 749 / 1192 ->
#   992 / 726 / 1184); both keys leave all 35 cells of the five synthetic scenes x seven pipelines (30 frames)
#   unchanged, and dis on the 1080p city stand-in (0.564), the city-wide stand-in (0.364, older generator: cars and
#   motorbikes only) and KIT AIS (dis / pyramidal-hs track precision 0.429 / 0.319, recall 0.438 / 0.382);
# merge_whole_spares: a track without a detection that a detection no track took covers together with another track
#   (merge_inside of each one's predicted box inside it) is not ended as a tentative track is at its first miss
#   (birth_gap): the vehicle it is a part of was found whole. It still counts the miss (death_misses). A bus found as
#   its two ends in most frames and whole in every few had each end's tentative track ended by each whole frame
#   before it could be confirmed, and merge_hits, which joins confirmed tracks only, never joined them: the ends were
#   confirmed apart late or never, each row a false positive beside a miss. false, the default; true in dis (figures
#   there);
# merge_rigid_rel: ... and a frame is counted for a pair (either way) only while the two tracks have kept their
#   distance (_kept_their_distance), and so has each track either took in before from each track of the other's
#   (offline, a joined track's rows are the union of all its parts' rows, so every two of them must be one vehicle):
#   over the frames both were detected in, the length of their union along the line between their centres (the
#   centres' distance and half of each box's extent along that line, ground-fixed) drifted by at most this many times
#   the smaller track's larger side, the drift being the Theil-Sen slope of that length over the frames times the
#   frames spanned (at least MERGE_RIGID_MIN_FRAMES frames; fewer: no test). A truck's or a bus's parts keep the
#   length of their union however their boxes breathe (a part's box growing towards the other part moves its centre,
#   not its far edge) and wherever the vehicle turns; two cars nose to tail shorten it as the gap closes, and the
#   detector joins them when it has: drift at seed 3 (60 frames), a car gaining on the one ahead from 26 px to 8 px
#   behind it was joined with it in its last frames and the union of the two boxes replaced both tracks' rows from
#   their first frame (dis 0.502, pyramidal-lk 0.474 with the test off; the pair's drift is 0.93 of a side for dis).
#   0.5, the default, sits between the pairs that chose it, on dis's captured inputs (benchmarks/tracker_replay.py):
#   a car of the 1080p world at seed 1 closing from 97 px to 77 px behind the one ahead over 64 frames (0.63 of a
#   side: refused below it) and a part pair of realistic at seed 3 (0.40: joined above it). The test in use until
#   then, the difference of the median centre distance of the later and the earlier half of the frames, with 0.2
#   (0.3 in dis), met both at once only by luck: it halves a steady closing (the world's pair scored 0.19, under the
#   0.2 allowed) and takes a part's box growing for a trend (a bus's breathing ends scored over 0.2 and were never
#   joined), and it checked only the two tracks at hand, not the parts one had taken in: the world's car had been
#   taken in, through the track that took over the car ahead, with the car it followed, both lost for 60 frames and
#   100 false rows. Old test (0.2, dis 0.3) -> this one at 0.5, replayed on captured inputs: dis on the three worlds
#   through the real-footage path 0.618 / 0.620 / 0.756 -> 0.706 / 0.620 / 0.746 (pooled 0.677 -> 0.696; world 3's
#   truck and its side strip no longer joined), pyramidal-lk / pyramidal-hs on world 1 0.701 / 0.674 -> 0.702 / 0.679;
#   the 18 standard cells (nominal, realistic, urban-parallax, fast-vehicles, city, drift x seeds 1-3) of all seven
#   built-ins identical but thesis-hs realistic seed 3 0.319 -> 0.387; dis on KIT AIS identical. 0: off;
# merge_union_rel: offline, a joined part's row is unioned with the whole's row of the same frame unless the union is
#   longer or wider than 1 + this many times the whole's size when it took the part in and the frame (kept while
#   the clip's last hold_history frames) shows road between the two boxes (_road_between: the gap's grey within
#   merge_bridge_grey levels, at least 10, of the ground beside it and further than that from both boxes' ends):
#   then they are two vehicles, and the part's row stays its own track's in that frame. The 1080p city-wide world
#   at seed 3: a track followed car 223 for 33 frames, lost it, took the front of car 155 behind it at the same
#   speed and was taken in as 155's part (merge_covered) at frame 50; the union of the two tracks' rows over their
#   shared frames 8-48 was one box over both cars (each row a false positive and two misses). 0.5 on size alone
#   (benchmarks/tracker_replay.py, the tracker replayed on captured inputs of the three worlds): dis 0.692 / 0.568 /
#   0.706 -> 0.692 / 0.568 / 0.715, pyramidal-hs identical (0.570 / 0.560 / 0.649), but pyramidal-lk 0.591 / 0.533 /
#   0.667 -> 0.591 / 0.479 / 0.667: at seed 2 the whole was itself one end of bus 38 (37 x 28 px of 96 x 46) when
#   it took in the other end, and the bus's two ends were kept apart (FP 118 -> 256). With the road test: dis 0.692
#   / 0.568 / 0.713 (pooled over 12,090 counted rows 0.659 -> 0.662), pyramidal-lk and pyramidal-hs identical to
#   off; the gap as dark as the ground but not unlike the ends (the first form of the test) left pyramidal-lk
#   0.531. 0: off (always the union), the default;
# merge_bridge_grey: ... and a frame is also counted for two confirmed tracks both placed in it (detected or held),
#   moving alike and having kept their distance (merge_rigid_rel), whose boxes lie apart along the line between their
#   centres by at most twice the larger box's larger side, where that gap is the vehicle's body (_bridge_greys): its
#   median grey within this many grey levels of the pixels of each box next to it, and at least twice as far from the
#   ground beside it on both sides. A bus or truck creeping in a queue moves in the flow only at its ends, a uniform
#   roof between them, and is found as two parts that no detection ever covers (the 1080p city-wide world at seed 1: a
#   yellow bus, 91 x 67 px, tracked as its two ends for 100 frames, each row a miss and two false positives; the gap
#   grey 206, its ends 200 and 207, the road beside it 118 and 50). Two cars nose to tail have the road between them,
#   which is the ground beside them; a grey car behind a grey car on grey asphalt is not joined, nor a bus whose colour
#   is the road's. 0: off, the default;
# smooth_size_frames: offline, as MOTChallenge scores: each output box takes the median width and height of the
#   boxes of its track within this many frames either side that share its heading (at least 3 of them; within
#   SMOOTH_HEADING_DEG, or where the track moved under SMOOTH_SLOW_PX a frame), placed where a robust line through the
#   track's ground-fixed centres puts it as far as the box it replaces lets it (within it where that is larger, over
#   it where smaller; a box of the vehicle's size stays where it was). A detection's
#   box jumps where the detector joins the vehicle to a neighbour or its shadow for a few frames, or finds one end of
#   a uniform roof, and the Kalman filter follows each jump: a box half or twice the vehicle's size scores as a false
#   positive and a miss (IoU under 0.5). The median keeps the size the vehicle has most of the time; the heading
#   keeps a turning vehicle's box, whose shape changes with it, from taking the shape it had before the turn (a
#   window of any heading: nominal at 30 frames, dis MOTA 0.982 -> 0.806, a car boxed across its new lane).
#   0: off. 40, the default (1.6 s at 25 fps), as measured off -> on (benchmarks/tracking_quality.py --scene nominal
#   realistic urban-parallax fast-vehicles city --frames 30 [--kit-ais] --set tracking.multi.smooth_size_frames=0;
#   the worlds: the tracker replayed on dis's captured detections, as the suite scores): every pipeline gains or keeps its
#   MOTA on the five synthetic scenes but farneback, whose boxes are a halo larger than the vehicle all along
#   (nominal / realistic / urban-parallax / city -0.023 / -0.011 / -0.040 / -0.010, fast-vehicles +0.020; off in
#   its file); dis nominal / realistic / urban-parallax / fast-vehicles / city 0.982 / 0.640 / 0.906 / 0.758 / 0.694
#   -> 0.994 / 0.674 / 0.946 / 0.806 / 0.723, thesis-hs city 0.316 -> 0.529; dis on the three 1080p city-wide
#   worlds 0.468 / 0.504 / 0.599 -> 0.470 / 0.514 / 0.640 (pooled 0.535 -> 0.556); KIT AIS (2-3 fps, 20-25
#   frames: the window is the whole sequence) pseudo-MOT MOTA dis -0.255 -> -0.250, pyramidal-hs -0.829 -> -0.860,
#   tv-l1 -0.607 -> -0.531, pyramidal-lk -0.480 -> -0.490, dis tracks precision / recall 0.647 / 0.567 -> 0.641 / 0.562;
# part_inside: offline, after smooth_size_frames: a row whose box lies this share or more inside the larger box of
#   another track's row of the same frame, the two moving alike (velocities, from the robust line through each
#   track's ground-fixed centres, within a pixel a frame or a quarter of the larger speed), is a part of that vehicle
#   and is left out: a truck's cast shadow or one end of its uniform roof tracked beside the truck, which merge_hits
#   does not join while both are detected in every frame. A car crossing a truck's box moves otherwise and stays.
#   0: off, the default; 0.5 in dis (figures there);
# sigma_*: BoxKalman noise (algorithms.kalman), px, px/frame, px/frame^2.
MULTI_DEFAULTS = {"gate_px": 20.0, "min_iou": 0.3, "birth_hits": 3, "birth_gap": 0, "min_travel_px": 3.0, "min_travel_rel": 0.25,
                  "travel_lengthwise_rel": 0.0, "min_trend_f": 10.0, "partial_rel": 0.25, "partial_abreast": False,
                  "partial_steady_frames": 0,
                  "abreast_shared": False, "death_misses": 10, "coast_gate_growth": 0.5,
                  "report_coasting": False, "fill_gaps": True, "fill_min_ncc": 0.8, "min_area_rel": 0.15,
                  "use_velocity": True, "hold_min_ncc": 0.8, "hold_search_px": 6.0,
                  "hold_min_travel_rel": 0.1, "hold_same_frames": 0, "back_min_travel_rel": 1.0, "back_track_size": False,
                  "back_stop_inside": 0.0,
                  "hold_frames": 250, "hold_history": 100,
                  "steady_flow_rel": 0.8,
                  "end_min_hits": 0, "steady_min_hits": 0, "merge_hits": 3, "merge_inside": 0.8, "merge_covered": True,
                  "merge_whole_spares": False, "merge_rigid_rel": 0.5, "merge_union_rel": 0.0, "merge_bridge_grey": 0.0, "smooth_size_frames": 40, "part_inside": 0.0,
                  "sigma_accel_px": 0.5, "sigma_size_accel_px": 0.3, "sigma_meas_px": 1.5,
                  "sigma_vel_meas_px": 1.0, "sigma_vel0_px": 5.0}


def boxes_in_image(boxes_px: np.ndarray, shape_px: tuple[int, int]) -> np.ndarray:
    """``(N, 4)`` float64: the tracker's boxes as a sequence holds them, clipped to the image as an annotator would.

    ``boxes_px``: ``x0, y0, x1, y1`` rows, inclusive pixel ranges (the tracker's rows: a box ``w`` px
    wide spans ``cx +- (w - 1) / 2``). Returned continuous in pixel-centre coordinates, as every box of
    a sequence and its truth (:data:`scenes.formats.MOT_ORIGIN_PX`): half a pixel out on every side,
    ``[x0 - 0.5, x1 + 0.5]``, so ``w`` px wide.

    The multi-target tracker keeps a vehicle's whole size while part of it is past the border
    (``partial_rel``: a top view does not shrink), so its box may reach past the edge; the truth
    boxes what the frame shows (``scenes`` clips its boxes to ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``,
    as MOTChallenge annotation does), and a box that holds the unseen part misses IoU 0.5 with the
    part seen. Each box is clipped to those bounds; one wholly outside the image becomes NaN (the
    vehicle is out of view: nothing to box); NaN rows stay NaN. ``shape_px``: (H, W) of the frames.
    """
    b = np.array(boxes_px, dtype=np.float64, copy=True).reshape(-1, 4) + np.array([-0.5, -0.5, 0.5, 0.5])
    h, w = (float(v) for v in shape_px)
    with np.errstate(invalid="ignore"):
        b[:, 0] = np.maximum(b[:, 0], -0.5)
        b[:, 1] = np.maximum(b[:, 1], -0.5)
        b[:, 2] = np.minimum(b[:, 2], w - 0.5)
        b[:, 3] = np.minimum(b[:, 3], h - 0.5)
        b[~((b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1]))] = np.nan
    return b


def _box_of(d) -> tuple[np.ndarray, np.ndarray]:
    """``(cx, cy, w, h)`` and ``(u, v)`` of a detection; a plain ``(x, y, area)`` is a square of that area."""
    if len(d) >= 7:
        box = np.array([d[0], d[1], d[5] - d[3] + 1.0, d[6] - d[4] + 1.0], dtype=np.float64)
    else:
        side = math.sqrt(max(float(d[2]), 1.0))
        box = np.array([d[0], d[1], side, side], dtype=np.float64)
    vel = np.array([d[7], d[8]], dtype=np.float64) if len(d) >= 9 else np.full(2, np.nan)
    return box, vel


def _completed(box: np.ndarray, ref: np.ndarray, rel: float) -> np.ndarray:
    """A detection's box ``(cx, cy, w, h)`` completed to the size of ``ref`` (the track's predicted centre and the
    median size it had at its last 25 detections) along each axis where it is a partial view (``partial_rel``):
    narrower than ``ref`` by more than ``rel`` of its size, with one side within ``rel`` of ``ref``'s (the vehicle's
    front under a tree crown, its rear past the image border, one edge of a uniform roof). That side is the
    vehicle's own; the box is ``ref``'s size from it. A box inside ``ref`` on both sides (a track whose box was too
    large) is no partial view, nor is one wider than ``ref`` by more than half ``rel`` along an axis (a vehicle
    that turns: its axis-aligned box grows along one axis as it shrinks along the other); both are taken as they
    are."""
    out = np.array(box, dtype=np.float64)
    if (out[2] > (1.0 + rel / 2) * ref[2]) or (out[3] > (1.0 + rel / 2) * ref[3]):
        return out  # wider along the other axis: a vehicle that turns, whose axis-aligned box changes shape
    for c, s in ((0, 2), (1, 3)):
        if out[s] < (1.0 - rel) * ref[s]:
            lo, hi = out[c] - out[s] / 2, out[c] + out[s] / 2
            d_lo, d_hi = abs(lo - (ref[c] - ref[s] / 2)), abs(hi - (ref[c] + ref[s] / 2))
            if min(d_lo, d_hi) > rel * ref[s]:
                continue
            out[c] = lo + ref[s] / 2 if d_lo <= d_hi else hi - ref[s] / 2
            out[s] = ref[s]
    return out


def _abreast(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> bool:
    """Whether the boxes ``a`` and ``b`` ``(cx, cy, w, h)`` lie side by side across the motion ``v``: their centres
    apart across it by at least half their mean extent across it, and along it by less than half their mean extent
    along it (two cars in adjacent lanes; not a cab and its trailer, nor a car close behind another)."""
    mu, mv = float(v[0]), float(v[1])
    ext = box_extents((a[2] + b[2]) / 2, (a[3] + b[3]) / 2, mu, mv)  # their mean extents along and across
    if ext is None:
        return False
    speed = math.hypot(mu, mv)
    dx, dy = float(b[0] - a[0]), float(b[1] - a[1])
    along, across = abs(dx * mu + dy * mv) / speed, abs(dy * mu - dx * mv) / speed
    return across >= 0.5 * ext[1] and along < 0.5 * ext[0]


def _lengthwise_alike(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the boxes ``a`` and ``b`` ``(cx, cy, w, h)`` are long along the same image axis: two vehicles driving
    side by side are (a car beside the box of a truck's part that its flow split off crosswise is not)."""
    return bool((a[2] >= a[3]) == (b[2] >= b[3]))


def _completes_over_abreast(box: np.ndarray, full: np.ndarray, v: np.ndarray, boxes: np.ndarray, own: int) -> bool:
    """Whether completing the detection ``box`` to ``full`` (``partial_rel``) covers half or more of another
    detection of the frame (``boxes``, ``own`` the index of ``box``) that lies abreast of it (:func:`_abreast`): the
    rest of the track's size is another vehicle, seen, not a part of this one out of view (``partial_abreast``)."""
    if np.array_equal(box, full):
        return False
    x0, y0, x1, y1 = full[0] - full[2] / 2, full[1] - full[3] / 2, full[0] + full[2] / 2, full[1] + full[3] / 2
    for j, o in enumerate(boxes):
        if j == own:
            continue
        iw = min(x1, o[0] + o[2] / 2) - max(x0, o[0] - o[2] / 2)
        ih = min(y1, o[1] + o[3] / 2) - max(y0, o[1] - o[3] / 2)
        if iw > 0 and ih > 0 and iw * ih >= 0.5 * o[2] * o[3] and _abreast(box, o, v):
            return True
    return False


def _crop(img: np.ndarray, box: np.ndarray, off: np.ndarray, *, min_std: float = 2.0) -> np.ndarray | None:
    """The pixels of ``img`` inside the ground-fixed box ``(cx, cy, w, h)`` (image = ground + ``off``), float32;
    None when it is not wholly inside, under 4 px a side, or without contrast (std under ``min_std`` grey levels)."""
    cx, cy = box[0] + off[0], box[1] + off[1]
    tw, th = int(round(box[2])), int(round(box[3]))
    x0, y0 = int(round(cx - (tw - 1) / 2)), int(round(cy - (th - 1) / 2))
    h, w = img.shape
    if tw < 4 or th < 4 or x0 < 0 or y0 < 0 or x0 + tw > w or y0 + th > h:
        return None
    t = np.ascontiguousarray(img[y0:y0 + th, x0:x0 + tw], dtype=np.float32)
    return t if float(t.std()) >= min_std else None


def _best_match(img: np.ndarray, tpl: np.ndarray, centre_px, radius_px: float) -> tuple[float, np.ndarray] | None:
    """The best NCC of ``tpl`` in ``img`` with its centre within ``radius_px`` of ``centre_px`` (image coordinates,
    a square search), and that centre; None when the search reaches past the border."""
    th, tw = tpl.shape
    cx, cy = centre_px
    xa, ya = int(math.floor(cx - radius_px - (tw - 1) / 2)), int(math.floor(cy - radius_px - (th - 1) / 2))
    xb, yb = int(math.ceil(cx + radius_px + (tw - 1) / 2)), int(math.ceil(cy + radius_px + (th - 1) / 2))
    if xa < 0 or ya < 0 or xb >= img.shape[1] or yb >= img.shape[0] or yb - ya + 1 < th or xb - xa + 1 < tw:
        return None
    ncc = cv2.matchTemplate(img[ya:yb + 1, xa:xb + 1].astype(np.float32, copy=False), tpl, cv2.TM_CCOEFF_NORMED)
    iy, ix = np.unravel_index(int(np.argmax(ncc)), ncc.shape)
    return float(ncc[iy, ix]), np.array([xa + ix + (tw - 1) / 2, ya + iy + (th - 1) / 2])


def _ncc_at(img: np.ndarray, tpl: np.ndarray, centre_ground, off: np.ndarray) -> float | None:
    """The NCC of ``tpl`` with the pixels of ``img`` it covers centred at a ground-fixed place; None off the image."""
    th, tw = tpl.shape
    here = _crop(img.astype(np.float32, copy=False), np.array([centre_ground[0], centre_ground[1], tw, th]), off,
                 min_std=0.0)
    return None if here is None else float(cv2.matchTemplate(here, tpl, cv2.TM_CCOEFF_NORMED)[0, 0])


def _row_boxes(rows: list[dict], idx) -> np.ndarray:
    """The boxes of ``rows[i]`` for ``i`` in ``idx``: ``(n, 4)`` float64 inclusive ``x0, y0, x1, y1`` in the image."""
    return np.array([[rows[i]["bbox_x0_px"], rows[i]["bbox_y0_px"], rows[i]["bbox_x1_px"], rows[i]["bbox_y1_px"]]
                     for i in idx], dtype=np.float64).reshape(-1, 4)


def _inside_share(box: np.ndarray, others: np.ndarray) -> float:
    """The largest share of ``box`` (``cx, cy, w, h``, its rows' inclusive extent ``cx +- (w - 1) / 2``) that lies
    within one of ``others`` (``(n, 4)`` inclusive ``x0, y0, x1, y1``, the same frame of reference)."""
    hw, hh = (box[2] - 1.0) / 2, (box[3] - 1.0) / 2
    x0, y0, x1, y1 = box[0] - hw, box[1] - hh, box[0] + hw, box[1] + hh
    iw = np.clip(np.minimum(x1, others[:, 2]) - np.maximum(x0, others[:, 0]) + 1.0, 0.0, None)
    ih = np.clip(np.minimum(y1, others[:, 3]) - np.maximum(y0, others[:, 1]) + 1.0, 0.0, None)
    return float((iw * ih).max() / (box[2] * box[3])) if len(others) else 0.0


def _intersections(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Areas of intersection of boxes (x0, y0, x1, y1) a (N, 4) with b (M, 4): (N, M)."""
    iw = np.clip(np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    ih = np.clip(np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    return iw * ih


def _corners(q: np.ndarray) -> np.ndarray:
    """Boxes (cx, cy, w, h) (N, 4) as (x0, y0, x1, y1) (N, 4)."""
    return np.stack([q[:, 0] - q[:, 2] / 2, q[:, 1] - q[:, 3] / 2, q[:, 0] + q[:, 2] / 2, q[:, 1] + q[:, 3] / 2], axis=1)


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of boxes (cx, cy, w, h) a (N, 4) against b (M, 4): (N, M)."""
    inter = _intersections(_corners(a), _corners(b))
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _trend(t: np.ndarray, z: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """Least-squares constant velocity through positions ``z`` (N, 2) px at frames ``t`` (N,): the distance it
    covers from the first frame to the last (px), its F statistic ((explained / 2) / (residual / (2N - 4)),
    infinite for N <= 2), each position's squared distance from the fit (N,) and the velocity (2,) px/frame; None
    when all frames are one."""
    tc, zc = t - t.mean(), z - z.mean(axis=0)
    span = float(tc @ tc)
    if span == 0:
        return None
    vel = (tc @ zc) / span
    net = float(np.hypot(*vel)) * float(t.max() - t.min())
    explained = float(vel @ vel) * span
    off = zc - tc[:, None] * vel[None, :]
    dof = 2 * len(t) - 4
    f = math.inf if dof <= 0 else (explained / 2) / (max(float((off ** 2).sum()), 1e-12) / dof)
    return net, f, (off ** 2).sum(axis=1), vel


def _travel_side(w: float, h: float, vel, lengthwise_rel: float) -> float:
    """The box side the birth travel is judged on: the larger side of a ``w`` x ``h`` px axis-aligned box, or its
    extent across the motion ``vel`` (px/frame) where it reaches ``lengthwise_rel`` (> 0) times as far along the
    motion as across it (a vehicle driving along its length, up, down or across the image: its width)."""
    ext = box_extents(w, h, float(vel[0]), float(vel[1])) if lengthwise_rel > 0 else None
    return ext[1] if ext is not None and ext[0] >= lengthwise_rel * ext[1] else max(w, h)


# smooth_size_frames: a box's size is the median over the boxes of the window whose heading is within
# SMOOTH_HEADING_DEG of its own (mod 180 degrees: an axis-aligned box is the same either way), or whose track moved
# under SMOOTH_SLOW_PX a frame there (no heading to tell); a heading is that of the robust line through the track's
# ground-fixed centres within SMOOTH_LINE_FRAMES either side, and the line's centre is where the box goes, as far as
# the box it replaces lets it
SMOOTH_HEADING_DEG = 20.0
SMOOTH_SLOW_PX = 0.3
SMOOTH_LINE_FRAMES = 8

# _of_ground: a track that never was a box side from where it is to be held must have its template match its place
# in its oldest kept frame (hold_same_frames) within this, px (its Kalman centre then, not its template's; dis on the worlds, pooled
# with hold_min_travel_rel 0.1: 2 px 0.586 / 0.558, 4 px 0.586 / 0.563, 7 px, the hold's search, 0.580 / 0.564 on the
# two sets of renders; the match asked at NCC 0.7 instead of hold_min_ncc gained two worlds and lost the third:
# benchmarks/heldout_rehearsal.md, "Misses by how fast the vehicle moves")
HOLD_SAME_SEARCH_PX = 4.0

# _partial_steady: a partial view's extent that changes by no more than this, px, over partial_steady_frames
# detections is not sliding under a crown or across the border (a vehicle at 0.5 px a frame changes it by 4 px in 8)
PARTIAL_STEADY_PX = 3.0

# _kept_their_distance: the frames both tracks of a pair must have been detected in for their distance to be judged
# (merge_rigid_rel), and the most of them its trend is fitted to (evenly spaced: the fit weighs every pair of them)
MERGE_RIGID_MIN_FRAMES = 6
MERGE_RIGID_MAX_FRAMES = 64


def _kept_their_distance(a, b, rel: float) -> bool:
    """Whether the tracks ``a`` and ``b`` kept their distance (``merge_rigid_rel``): over the frames both were detected
    in (their ``hist``), the length of their union along the line between their centres (the distance between the
    centres and half of each box's extent along that line) drifted by at most ``rel`` times the smaller track's larger
    side. The drift is the Theil-Sen slope of that length over the frames (the median of the slopes between every two
    of them) times the frames spanned. One vehicle's parts keep the length of their union however their boxes
    breathe (a part's box that grows towards the other part moves its centre but not its far edge) and however the
    vehicle turns (a length, not an offset); a car closing up on the one ahead shortens it steadily, and a jump in the
    boxes for a few frames does not move the median slope. True under :data:`MERGE_RIGID_MIN_FRAMES` such frames and
    with ``rel`` 0 (no test)."""
    if not rel > 0:
        return True
    at = dict(a.hist)
    shared = [(f, at[f], q) for f, q in b.hist if f in at]
    if len(shared) < MERGE_RIGID_MIN_FRAMES:
        return True
    if len(shared) > MERGE_RIGID_MAX_FRAMES:
        shared = [shared[i] for i in np.linspace(0, len(shared) - 1, MERGE_RIGID_MAX_FRAMES).round().astype(int)]
    f = np.array([s[0] for s in shared], np.float64)
    qa, qb = np.array([s[1] for s in shared]), np.array([s[2] for s in shared])
    offsets = qa[:, :2] - qb[:, :2]
    dist = np.hypot(offsets[:, 0], offsets[:, 1])
    e = np.abs(offsets) / np.maximum(dist, 1e-9)[:, None]
    length = dist + (e[:, 0] * (qa[:, 2] + qb[:, 2]) + e[:, 1] * (qa[:, 3] + qb[:, 3])) / 2
    i, j = np.triu_indices(len(f), 1)
    drift = abs(float(np.median((length[j] - length[i]) / (f[j] - f[i])))) * (f[-1] - f[0])
    side = min(max(float(a.kf.x[2]), float(a.kf.x[3])), max(float(b.kf.x[2]), float(b.kf.x[3])))
    return bool(drift <= rel * side)


def _bridge_greys(img: np.ndarray, a: np.ndarray, b: np.ndarray, *, max_gap_px: float,
                  end_px: int = 6) -> tuple[float, ...] | None:
    """The greys that tell one vehicle's two parts from two vehicles nose to tail (``merge_bridge_grey``).

    Along the line between the centres of the boxes ``a`` and ``b`` (``cx, cy, w, h``, image coordinates), averaged
    over a band 3 px wide: the median grey of the gap (the line's pixels outside both boxes), of the ``end_px`` pixels
    of each box next to the gap, and of the gap's line moved to either side by half the smaller box's extent across
    the line and 2 px more (the ground beside the vehicle). ``(gap, end_a, end_b, side_1, side_2)``; None when the
    gap is under 3 px or over ``max_gap_px``, or any of it lies off the image."""
    d = np.asarray(b[:2], np.float64) - np.asarray(a[:2], np.float64)
    length = math.hypot(float(d[0]), float(d[1]))
    if length < 4.0:
        return None
    e = d / length
    n = np.array([-e[1], e[0]])
    t = np.arange(0.0, length + 0.5)
    pts = a[:2] + t[:, None] * e
    in_a = (np.abs(pts[:, 0] - a[0]) <= a[2] / 2) & (np.abs(pts[:, 1] - a[1]) <= a[3] / 2)
    in_b = (np.abs(pts[:, 0] - b[0]) <= b[2] / 2) & (np.abs(pts[:, 1] - b[1]) <= b[3] / 2)
    gap = ~in_a & ~in_b
    if not 3 <= gap.sum() <= max_gap_px:
        return None
    across = min(box_extents(float(q[2]), float(q[3]), float(e[0]), float(e[1]))[1] for q in (a, b))
    side = across / 2 + 2.0
    h, w = img.shape

    def band(shift: float, sel: np.ndarray) -> np.ndarray | None:
        q = np.concatenate([pts[sel] + (shift + k) * n for k in (-1.0, 0.0, 1.0)]).astype(np.float32)
        if q[:, 0].min() < 0 or q[:, 1].min() < 0 or q[:, 0].max() > w - 1 or q[:, 1].max() > h - 1:
            return None
        v = cv2.remap(img, q[:, :1], q[:, 1:], cv2.INTER_LINEAR)
        return v.reshape(3, -1).mean(axis=0)

    own_a, own_b = np.flatnonzero(in_a & ~in_b), np.flatnonzero(in_b & ~in_a)
    if not len(own_a) or not len(own_b):
        return None
    end_a, end_b = np.zeros(len(t), bool), np.zeros(len(t), bool)
    end_a[own_a[own_a < np.flatnonzero(gap)[0]][-end_px:]] = True
    end_b[own_b[own_b > np.flatnonzero(gap)[-1]][:end_px]] = True
    vals = [band(0.0, gap), band(0.0, end_a) if end_a.any() else None, band(0.0, end_b) if end_b.any() else None,
            band(side, gap), band(-side, gap)]
    if any(v is None for v in vals):
        return None
    return tuple(float(np.median(v)) for v in vals)


def _alike(va, vb) -> bool:
    """Whether two vehicles move alike: velocities (px a frame) within a pixel a frame or a quarter of the larger
    speed of each other (the parts of one vehicle, ``merge_hits``, ``merge_covered``, ``part_inside``)."""
    va, vb = np.asarray(va, np.float64), np.asarray(vb, np.float64)
    return float(np.hypot(*(va - vb))) <= max(1.0, 0.25 * max(float(np.hypot(*va)), float(np.hypot(*vb))))


def _window_median(f: np.ndarray, values: np.ndarray, k: int, heading: np.ndarray, *, min_n: int = 3) -> np.ndarray:
    """``values`` ``(n, d)`` at frames ``f`` ``(n,)``, each replaced by the median of those within ``k`` frames of it
    (itself included) that share its heading (``heading``: ``(n,)`` radians, NaN where the track moved too slowly to
    have one; :data:`SMOOTH_HEADING_DEG`), where there are at least ``min_n`` (``smooth_size_frames``). A turning
    vehicle's axis-aligned box changes shape as its heading does; its size before the turn is not its size after."""
    out = values.copy()
    tol = math.radians(SMOOTH_HEADING_DEG)
    for n in range(len(f)):
        turn = np.abs((heading - heading[n] + math.pi / 2) % math.pi - math.pi / 2)
        near = (np.abs(f - f[n]) <= k) & ~(turn > tol)  # NaN on either side: no heading to tell, kept
        if near.sum() >= min_n:
            out[n] = np.median(values[near], axis=0)
    return out


def _robust_line(f: np.ndarray, xy: np.ndarray, k: int, *, min_n: int = 4, tukey_c: float = 2.0,
                 iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The positions ``xy`` ``(n, 2)`` at frames ``f`` ``(n,)`` as a straight line fitted about each frame sees them:
    its value and slope there (px, px a frame; ``(n, 2)`` each, NaN where there was no line), fitted to the positions
    within ``k`` frames where there are at least ``min_n``: weighted least squares, reweighted ``iterations`` times
    by Tukey's biweight at ``tukey_c`` times the residuals' robust spread (1.4826 MAD, at least 1 px; a centre a
    joined box pulled aside weighs nothing), each axis on its own."""
    level, slope = np.full(xy.shape, np.nan), np.full(xy.shape, np.nan)
    for n in range(len(f)):
        near = np.abs(f - f[n]) <= k
        if near.sum() < min_n:
            continue
        t = f[near] - f[n]
        for a in range(xy.shape[1]):
            x, wt = xy[near, a], np.ones(len(t))
            for _ in range(iterations):
                sw, st, stt = wt.sum(), (wt * t).sum(), (wt * t * t).sum()
                sx, stx = (wt * x).sum(), (wt * t * x).sum()
                det = sw * stt - st * st
                if sw < min_n - 1 or det <= 1e-9:
                    break
                level[n, a], slope[n, a] = (stt * sx - st * stx) / det, (sw * stx - st * sx) / det
                r = x - (level[n, a] + slope[n, a] * t)
                u = np.abs(r) / (tukey_c * max(1.0, 1.4826 * float(np.median(np.abs(r)))))
                wt = np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)
    return level, slope


class MultiTargetTracker:
    """Boxes tracked by constant-velocity Kalman filters, Hungarian assignment on IoU and distance, birth / death.

    Each track is a :class:`~algorithms.kalman.BoxKalman` of its box's centre and size in a
    ground-fixed frame: given the camera path (the cumulative global shift of frame t), it
    subtracts it from detections before filtering and adds it back to its output, so a car
    driving straight is a constant-velocity target even when the camera sways. A frame's
    detections are assigned to the tracks' predictions by the Hungarian method
    (``scipy.optimize.linear_sum_assignment``) on the cost ``(1 - IoU) + distance / gate``,
    a pair feasible when the distance is within the gate (``gate_px``, growing by
    ``coast_gate_growth`` per frame a track has coasted) or the boxes overlap by ``min_iou``.
    A new track is confirmed after ``birth_hits`` hits once it has travelled
    ``min_travel_px`` and ``min_travel_rel`` box sides over the ground at a steady velocity
    (``min_trend_f``; its rows, from its first frame, are then output; more than
    ``birth_gap`` misses in a row before that delete it; a detection that holds two tracks abreast is neither's,
    and they miss nothing, ``abreast_shared``). A confirmed track without a
    detection is held where its template matches the frame (``hold_*`` keys, given ``image``), else coasts on its
    prediction through up to ``death_misses - 1`` frames (short occlusions) and ends at the
    ``death_misses``-th; the frames of a gap it bridges are filled when it is found again
    (``fill_gaps``, ``fill_min_ncc``). Confirmed tracks that a detection no track took covers, moving alike, in
    ``merge_hits`` frames are parts of one vehicle and become one track (:meth:`_merge_parts`; and a confirmed
    track whose grown box covers another, ``merge_covered``; and two tracks apart along the line between them whose
    gap is the vehicle's body, ``merge_bridge_grey``, :meth:`_merge_bridged`). Offline, each output box takes the
    median size of its track's boxes of its heading nearby (``smooth_size_frames``). Keys and defaults:
    ``MULTI_DEFAULTS``.

    Use :meth:`step` once per frame, then :meth:`rows`.
    """

    def __init__(self, **params):
        unknown = sorted(set(params) - set(MULTI_DEFAULTS))
        if unknown:
            raise ValueError(f"multi: unknown key(s) {unknown}; valid: {', '.join(MULTI_DEFAULTS)}")
        p = {**MULTI_DEFAULTS, **params}
        for name in ("merge_hits", "end_min_hits", "steady_min_hits", "smooth_size_frames", "partial_steady_frames",
                     "hold_same_frames"):
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"{name}: expected an integer >= 0 (0: off), got {v!r}")
        v = p["merge_inside"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 1:
            raise ValueError(f"merge_inside: expected a number in (0, 1], got {v!r}")
        for name in ("steady_flow_rel", "back_stop_inside", "part_inside"):
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                raise ValueError(f"{name}: expected a number in [0, 1] (0: off), got {v!r}")
        for name in ("birth_hits", "death_misses", "hold_frames", "hold_history"):
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("report_coasting", "fill_gaps", "use_velocity", "merge_covered", "back_track_size",
                     "partial_abreast", "abreast_shared", "merge_whole_spares"):
            if not isinstance(p[name], bool):
                raise ValueError(f"{name}: expected true/false, got {p[name]!r}")
        for name in ("gate_px", "min_iou", "coast_gate_growth", "min_travel_px", "min_travel_rel", "hold_search_px",
                     "hold_min_travel_rel", "back_min_travel_rel", "min_trend_f", "travel_lengthwise_rel",
                     "merge_rigid_rel", "merge_union_rel", "merge_bridge_grey"):
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
        v = p["birth_gap"]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"birth_gap: expected an integer >= 0, got {v!r}")
        if not p["gate_px"] > 0:
            raise ValueError(f"gate_px: expected > 0, got {p['gate_px']}")
        if not 0 < p["min_iou"] <= 1:
            raise ValueError(f"min_iou: expected a number in (0, 1], got {p['min_iou']}")
        v = p["partial_rel"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
            raise ValueError(f"partial_rel: expected a number in [0, 1] (1: off), got {v!r}")
        v = p["min_area_rel"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < 1:
            raise ValueError(f"min_area_rel: expected a number in [0, 1) (0: off), got {v!r}")
        for name, zero in (("hold_min_ncc", "no holding"), ("fill_min_ncc", "no check")):
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                raise ValueError(f"{name}: expected a number in [0, 1] (0: {zero}), got {v!r}")
        self.params = p
        self.gate_px, self.birth_hits, self.death_misses = float(p["gate_px"]), int(p["birth_hits"]), int(p["death_misses"])
        self._kf_kw = {k: p[k] for k in ("sigma_accel_px", "sigma_size_accel_px", "sigma_meas_px",
                                          "sigma_vel_meas_px", "sigma_vel0_px")}
        BoxKalman((0.0, 0.0, 1.0, 1.0), **self._kf_kw)  # its own checks of the noise keys, now
        self._tracks: list[_Track] = []
        self._seen: deque = deque(maxlen=int(p["hold_history"]))  # (frame, gray image, camera path)
        self._rows: list[dict] = []
        self._next_id = 0
        self._joint: dict[tuple[int, int], int] = {}  # frames a detection covered both tracks of a pair (merge_hits)
        self._merges: list[tuple[int, int]] = []  # (part, whole): the part's rows join the whole's
        self._merge_size: dict[int, np.ndarray] = {}  # part -> the whole's (w, h) when it took the part in
        self._members: dict[int, list[_Track]] = {}  # whole -> the tracks it took in (theirs too): its rows' sources
        self._path: dict[int, np.ndarray] = {}  # the camera path at each frame (smooth_size_frames)

    def step(self, frame: int, detections, *, offset_px=(0.0, 0.0), image=None) -> None:
        """Take the detections of ``frame`` (:class:`~algorithms.detection.Detection` s, or ``(x_px, y_px, area_px)``).

        ``offset_px`` is the camera path at this frame (ground content displacement
        since frame 0); tracks live in ``image - offset`` coordinates. ``image``, the gray
        frame (H, W), lets a confirmed track without a detection be held on its template
        (``hold_min_ncc``); without it tracks only coast.
        """
        p = self.params
        off = np.asarray(offset_px, dtype=np.float64)
        self._path[int(frame)] = off.copy()
        img = None
        if image is not None:
            img = np.asarray(image)
            if img.ndim != 2:
                raise ValueError(f"image: expected a gray frame (H, W), got shape {img.shape}")
            img = img.astype(np.float32, copy=False)
        parsed = [_box_of(d) for d in detections]
        boxes = np.array([b for b, _ in parsed], dtype=np.float64).reshape(-1, 4)
        boxes[:, :2] -= off
        vels = np.array([v for _, v in parsed], dtype=np.float64).reshape(-1, 2)
        if not p["use_velocity"]:
            vels[:] = np.nan
        # x = F x, P = F P F' + Q for every track (BoxKalman.predict)
        preds = np.array([t.kf.predict() for t in self._tracks]).reshape(-1, 4)
        boxes, vels, within = self._join_parts(preds, boxes, vels)
        shared, excused = self._shared_abreast(preds, boxes) if p["abreast_shared"] else (set(), set())
        pairs = []
        if len(preds) and len(boxes):
            dist = np.hypot(preds[:, None, 0] - boxes[None, :, 0], preds[:, None, 1] - boxes[None, :, 1])
            iou = _iou(preds, boxes)
            gate = self.gate_px * (1.0 + p["coast_gate_growth"] * np.array([t.misses for t in self._tracks]))
            feasible = (dist <= gate[:, None]) | (iou >= p["min_iou"]) | within
            feasible[:, sorted(shared)] = False
            cost = (1.0 - iou) + dist / gate[:, None]
            # infeasible pairs cost more than any feasible assignment could
            big = 10.0 * (2.0 + float(cost[feasible].max(initial=0.0))) * (len(preds) + len(boxes))
            from scipy.optimize import linear_sum_assignment  # on first use: scipy.optimize takes 0.7 s to import

            r_idx, c_idx = linear_sum_assignment(np.where(feasible, cost, big))
            pairs = [(r, c) for r, c in zip(r_idx, c_idx) if feasible[r, c]]
        det_of = dict(pairs)
        taken_d = set(det_of.values()) | shared
        detected = [boxes[c] for c in det_of.values()]
        spared = self._within_whole(preds, boxes, taken_d, set(det_of)) if p["merge_whole_spares"] else set()
        survivors = []
        for i, trk in enumerate(self._tracks):
            pred = preds[i]
            if i in det_of:
                c = det_of[i]
                z = boxes[c]
                if trk.confirmed and trk.sizes:  # the size it has had lately, against a partial view
                    full = _completed(z, np.concatenate([pred[:2], np.median(trk.sizes, axis=0)]), p["partial_rel"])
                    # the size it had was two vehicles' (completed over the one abreast), or not the vehicle's (the
                    # same partial view detection after detection): it starts again from this detection's
                    if (p["partial_abreast"] and _completes_over_abreast(z, full, vels[c], boxes, c)) \
                            or self._partial_steady(trk, z, full):
                        trk.kf.restart_size(float(z[2]), float(z[3]))
                        trk.sizes.clear()
                        trk.partial.clear()
                    else:
                        z = full
                trk.kf.update(z, vels[c])
                trk.sizes.append(trk.kf.x[2:4].copy())
                trk.hits, trk.misses, trk.held, trk.excused = trk.hits + 1, 0, 0, 0
                trk.travel = max(trk.travel, float(np.hypot(*(trk.kf.x[:2] - trk.start))))
                trk.hist.append((int(frame), trk.kf.x[:4].copy()))
                if not trk.confirmed:
                    trk.seen.append((int(frame), z[:2].copy()))
                    trk.flows.append(vels[c].copy())
                trk.ground_checked = False
                if img is not None:
                    trk.template = _crop(img, trk.kf.x[:4], off)
            else:
                z = self._hold(trk, img, pred, off, detected) if img is not None else None
                if z is not None:
                    trk.kf.update(z)
                    trk.held, trk.misses = trk.held + 1, 0
                elif i in excused:
                    trk.excused += 1
                else:
                    trk.misses += 1
                    if (not trk.confirmed and trk.misses > p["birth_gap"] and i not in spared) \
                            or trk.misses >= self.death_misses:
                        continue
            self._emit(trk, frame, z, trk.kf.x[:4], pred, off)
            if not trk.confirmed and (trk.hits >= self.birth_hits and self._travelled(trk)
                                       or self._steady_run(trk, p["steady_min_hits"])):
                trk.confirmed = True
                self._rows.extend(trk.pending)
                trk.pending = []
            survivors.append(trk)
        taken_d |= self._merge_parts(survivors, boxes, taken_d, frame, img, off)
        if p["merge_bridge_grey"] > 0 and p["merge_hits"] > 0 and img is not None:
            self._merge_bridged(survivors, frame, img, off)
        for c in range(len(boxes)):
            if c not in taken_d:
                trk = _Track(self._next_id, BoxKalman(boxes[c], velocity=vels[c], **self._kf_kw),
                             start=boxes[c][:2].copy(),
                             hist=[(int(frame), boxes[c][:4].copy())], seen=[(int(frame), boxes[c][:2].copy())],
                             flows=[vels[c].copy()])
                if img is not None and p["hold_min_ncc"] > 0:
                    first = _crop(img, boxes[c], off)
                    trk.first = None if first is None else (int(frame), boxes[c].copy(), first)
                self._next_id += 1
                self._emit(trk, frame, boxes[c], boxes[c], boxes[c], off)
                if self.birth_hits == 1 and p["min_travel_px"] == 0 and p["min_travel_rel"] == 0:
                    trk.confirmed = True
                    self._rows.extend(trk.pending)
                    trk.pending = []
                survivors.append(trk)
        self._tracks = survivors
        if img is not None:
            for trk in survivors:
                if trk.confirmed and trk.first is not None and \
                        trk.travel >= p["back_min_travel_rel"] * max(trk.first[2].shape):
                    self._extend_back(trk, img, off)
        # kept as 8 bits: 2 MB a 1080p frame
        if img is not None and (p["hold_min_ncc"] > 0 or (p["fill_gaps"] and p["fill_min_ncc"] > 0)
                                or p["merge_union_rel"] > 0):
            self._seen.append((int(frame), np.clip(img, 0, 255).astype(np.uint8), off.copy()))

    def _shared_abreast(self, preds: np.ndarray, boxes: np.ndarray) -> tuple[set, set]:
        """The detections that hold two tracks side by side, and those tracks (``abreast_shared``).

        A detection holds a track when the track's predicted centre lies in its box; two tracks it holds that lie
        abreast (:func:`_abreast`, across their mean motion), their boxes long along the same image axis
        (:func:`_lengthwise_alike`), are two vehicles in adjacent lanes that the detector joined in this frame (a queue
        at a light: their flows agree, and the road between them is narrower than a car). Such a detection is neither
        track's, nor a new one's; the tracks it holds are not detected in the frame and miss nothing (a tentative one
        lives on, ``birth_hits`` frames in a row at most)."""
        shared, excused = set(), set()
        if len(preds) < 2 or not len(boxes):
            return shared, excused
        vel = np.array([t.kf.x[4:6] for t in self._tracks])
        # a tentative track held so birth_hits frames in a row is done with: the joined box is one vehicle's, of which
        # it held a part (a car split once into two halves abreast, one half's tentative track beside the car's, then
        # found whole: excused every frame, the tentative track lived on and the car's track got no detection)
        may = np.array([t.confirmed or t.excused < self.birth_hits for t in self._tracks])
        for c, d in enumerate(boxes):
            held = np.flatnonzero((np.abs(preds[:, 0] - d[0]) <= d[2] / 2) & (np.abs(preds[:, 1] - d[1]) <= d[3] / 2)
                                  & may)
            pairs = [(a, b) for k, a in enumerate(held) for b in held[k + 1:]
                     if _lengthwise_alike(preds[a], preds[b]) and _abreast(preds[a], preds[b], (vel[a] + vel[b]) / 2)]
            if pairs:
                shared.add(c)
                excused.update(int(i) for pair in pairs for i in pair)
        return shared, excused

    def _partial_steady(self, trk: _Track, z: np.ndarray, full: np.ndarray) -> bool:
        """Whether ``trk``'s detection ``z``, completed to ``full`` (``partial_rel``), is the last of
        ``partial_steady_frames`` detections in a row completed along the same axis whose extents along it lie
        within ``PARTIAL_STEADY_PX`` of their median: the view is not partial, the track's size is wrong."""
        n = self.params["partial_steady_frames"]
        done = [k for k in (0, 1) if full[2 + k] != z[2 + k]]
        if n <= 0 or len(done) != 1:
            trk.partial.clear()
            return False
        k = done[0]
        if trk.partial and trk.partial[-1][0] != k:
            trk.partial.clear()
        trk.partial.append((k, float(z[2 + k])))
        del trk.partial[:-n]
        if len(trk.partial) < n:
            return False
        ext = np.array([e for _, e in trk.partial])
        return bool(np.abs(ext - np.median(ext)).max() <= PARTIAL_STEADY_PX)

    def _within_whole(self, preds: np.ndarray, boxes: np.ndarray, taken: set, detected: set) -> set:
        """The tracks without a detection that a detection no track took covers together with another track
        (``merge_inside`` of each one's predicted box inside it): the vehicle they are parts of was found whole
        (``merge_whole_spares``)."""
        if not len(preds) or not len(boxes):
            return set()
        share = self.params["merge_inside"]
        area = preds[:, 2] * preds[:, 3]
        inter = _intersections(_corners(preds), _corners(boxes))
        out: set = set()
        for c in range(len(boxes)):
            if c in taken:
                continue
            inside = np.flatnonzero(inter[:, c] >= share * area)
            if len(inside) >= 2:
                out.update(int(i) for i in inside if int(i) not in detected)
        return out

    def _merge_parts(self, tracks: list, boxes: np.ndarray, taken: set, frame, img, off) -> set:
        """Join confirmed tracks that are parts of one vehicle (``merge_hits``); the detections this takes.

        A truck, a bus or a van whose region splits at a gap in its flow (cab and body, a uniform roof, the
        shadow side) in some frames and is found whole in others gets a track per part, each confirmed, while
        the whole detection, which neither part's track takes (its centre lies outside their gates), starts a
        tentative track that the next split frame ends. A detection that no track took and that covers two or
        more confirmed tracks (``merge_inside`` of each one's box inside it) moving alike (their velocities
        within a pixel a frame or a quarter of their speed) counts once for each pair; a pair counted in
        ``merge_hits`` frames is one vehicle: the track with more detections takes the detection's box and the
        other ends, its rows joining the first's (offline: in each frame both output, the box is the union of
        the two parts'). A track that took in a part does not start tracks from detections lying
        ``merge_inside`` within its box (the other part, in frames the vehicle splits again): the parts within
        its box are joined into one detection first (:meth:`_join_parts`), one part alone is completed to its
        size (``partial_rel``). Two cars nose to tail that the detector joins now
        and then are counted in the frames it joins them; ``merge_hits`` frames of it are needed.
        """
        p = self.params
        took: set = set()
        n = p["merge_hits"]
        if n <= 0 or not len(boxes):
            return took

        def weigh():  # the confirmed tracks, their box areas and their overlaps with the frame's detections
            conf = [t for t in tracks if t.confirmed]
            tb = np.array([t.kf.x[:4] for t in conf]).reshape(-1, 4)
            return conf, tb[:, 2] * tb[:, 3], _intersections(_corners(tb), _corners(boxes))

        conf, ta, overlap = weigh()
        if len(conf) < 1:
            return took
        for c in range(len(boxes)):
            if c in taken:
                continue
            d, inter = boxes[c], overlap[:, c]
            if any(conf[i].merged for i in np.flatnonzero(inter >= p["merge_inside"] * d[2] * d[3])):
                took.add(c)  # the other part of a vehicle already joined: no new track
                continue
            inside = np.flatnonzero(inter >= p["merge_inside"] * ta)
            if len(inside) < 2:
                continue
            for a in range(len(inside)):
                for b in range(a + 1, len(inside)):
                    ta_, tb_ = conf[inside[a]], conf[inside[b]]
                    if not self._may_be_parts(ta_, tb_):
                        continue
                    key = (min(ta_.id, tb_.id), max(ta_.id, tb_.id))
                    self._joint[key] = self._joint.get(key, 0) + 1
            group = [conf[i] for i in inside]
            pairs = [(x, y) for i, x in enumerate(group) for y in group[i + 1:]
                     if self._joint.get((min(x.id, y.id), max(x.id, y.id)), 0) >= n]
            if not pairs:
                continue
            whole = max(group, key=lambda t: (t.hits, -t.id))
            parts = {t.id for pair in pairs for t in pair if whole in pair} - {whole.id}
            if not parts:
                continue
            self._take_whole(whole, d, frame, img, off)
            for t in list(tracks):
                if t.id in parts:
                    tracks.remove(t)
                    self._joined_into(t, whole)
            took.add(c)
            conf, ta, overlap = weigh()  # the join removed tracks and moved the whole: weigh the rest against these
        if p["merge_covered"]:
            self._merge_covered(tracks, frame, off)
        return took

    def _joined_into(self, part: _Track, whole: _Track) -> None:
        """Record that ``part``'s rows join ``whole``'s (offline, :meth:`_joined`), with the whole's size now."""
        self._merges.append((part.id, whole.id))
        self._merge_size[part.id] = whole.kf.x[2:4].copy()
        self._members.setdefault(whole.id, []).extend([part, *self._members.pop(part.id, [])])

    def _take_whole(self, whole: _Track, box: np.ndarray, frame, img, off: np.ndarray) -> None:
        """``whole`` takes the box of the vehicle it was joined into (``merge_hits``, ``merge_bridge_grey``): its state,
        its row of this frame, its size history and its template start again from ``box``."""
        whole.kf.x[:4] = box
        whole.merged = True
        self._reshow(whole, frame, box, off)
        whole.sizes.clear()
        whole.sizes.append(box[2:4].copy())
        if img is not None:
            whole.template = _crop(img, box, off)

    def _may_be_parts(self, a: _Track, b: _Track) -> bool:
        """Whether two confirmed tracks may be parts of one vehicle (``merge_hits``, ``merge_covered``): they move alike
        (:func:`_alike`) and have kept their distance (``merge_rigid_rel``, :func:`_kept_their_distance`), and so has
        each track either took in before from each track of the other's: offline, every one's rows join the union."""
        if not _alike(a.kf.x[4:6], b.kf.x[4:6]):
            return False
        rel = self.params["merge_rigid_rel"]
        return all(_kept_their_distance(x, y, rel) for x in (a, *self._members.get(a.id, ()))
                   for y in (b, *self._members.get(b.id, ())))

    def _merge_covered(self, tracks: list, frame, off) -> None:
        """Join confirmed tracks whose box a confirmed track detected in this frame covers (``merge_inside``),
        moving alike, without a detection of their own in the frame, in ``merge_hits`` frames (``merge_covered``):
        the whole vehicle's detection went to one part's track (its box overlapped by ``min_iou``) while the
        other part's track stayed in it."""
        p = self.params
        conf = [t for t in tracks if t.confirmed]
        for big in conf:
            if big.misses or big.held or big not in tracks:
                continue
            d = big.kf.x[:4]
            inner = []
            for t in conf:
                if t is big or t not in tracks or not (t.misses or t.held):
                    continue  # a track detected in this frame apart from big's detection is an object of its own
                b = t.kf.x[:4]
                iw = max(0.0, min(b[0] + b[2] / 2, d[0] + d[2] / 2) - max(b[0] - b[2] / 2, d[0] - d[2] / 2))
                ih = max(0.0, min(b[1] + b[3] / 2, d[1] + d[3] / 2) - max(b[1] - b[3] / 2, d[1] - d[3] / 2))
                if iw * ih < p["merge_inside"] * b[2] * b[3] or b[2] * b[3] >= d[2] * d[3]:
                    continue
                if not self._may_be_parts(big, t):
                    continue
                key = (min(big.id, t.id), max(big.id, t.id))
                self._joint[key] = self._joint.get(key, 0) + 1
                if self._joint[key] >= p["merge_hits"]:
                    inner.append(t)
            if inner:
                big.merged = True
                for t in inner:
                    tracks.remove(t)
                    self._joined_into(t, big)

    def _merge_bridged(self, tracks: list, frame, img: np.ndarray, off: np.ndarray) -> None:
        """Join confirmed tracks placed in this frame that are the two ends of one vehicle, its body between them
        (``merge_bridge_grey``, :func:`_bridge_greys`), moving alike, in ``merge_hits`` frames: the track with more
        detections takes the union of the two boxes, the other ends, its rows joining the first's."""
        p = self.params
        grey = float(p["merge_bridge_grey"])
        conf = [t for t in tracks if t.confirmed and not t.misses]
        if len(conf) < 2:
            return
        tb = np.array([t.kf.x[:4] for t in conf])
        # a gap of at most twice the larger box's larger side (a bus found as its two ends, each a quarter of it)
        reach = 2.0 * np.max(tb[:, 2:4], axis=1)
        half_diag = np.hypot(tb[:, 2], tb[:, 3]) / 2
        dist = np.hypot(tb[:, None, 0] - tb[None, :, 0], tb[:, None, 1] - tb[None, :, 1])
        near = dist <= half_diag[:, None] + half_diag[None, :] + np.maximum(reach[:, None], reach[None, :])
        gone: set = set()
        for i, j in zip(*np.nonzero(np.triu(near, 1))):
            a, b = conf[i], conf[j]
            if a.id in gone or b.id in gone or not self._may_be_parts(a, b):
                continue
            ba, bb = a.kf.x[:4].copy(), b.kf.x[:4].copy()
            ba[:2] += off
            bb[:2] += off
            greys = _bridge_greys(img, ba, bb, max_gap_px=max(reach[i], reach[j]))
            if greys is None:
                continue
            gap, end_a, end_b, side_1, side_2 = greys
            body = abs(gap - end_a) <= grey and abs(gap - end_b) <= grey
            if not body or min(abs(gap - side_1), abs(gap - side_2)) < 2 * grey:
                continue
            key = (min(a.id, b.id), max(a.id, b.id))
            self._joint[key] = self._joint.get(key, 0) + 1
            if self._joint[key] < p["merge_hits"]:
                continue
            whole, part = (a, b) if (a.hits, -a.id) >= (b.hits, -b.id) else (b, a)
            lo = np.minimum(a.kf.x[:2] - a.kf.x[2:4] / 2, b.kf.x[:2] - b.kf.x[2:4] / 2)
            hi = np.maximum(a.kf.x[:2] + a.kf.x[2:4] / 2, b.kf.x[:2] + b.kf.x[2:4] / 2)
            union = np.concatenate([(lo + hi) / 2, hi - lo])
            self._take_whole(whole, union, frame, img, off)
            tracks.remove(part)
            gone.add(part.id)
            self._joined_into(part, whole)

    def _join_parts(self, preds: np.ndarray, boxes: np.ndarray, vels: np.ndarray):
        """The detections with those that lie within a joined track's predicted box (``merge_inside`` of their
        area; a track that took in a part, ``merge_hits``) made one: their union's box and their mean flow. Also
        ``(tracks, detections)`` bool: a detection within a joined track's box may be assigned to it whatever
        its distance (a part's centre lies off the vehicle's)."""
        within = np.zeros((len(preds), len(boxes)), dtype=bool)
        if not len(boxes) or not any(t.merged and t.confirmed for t in self._tracks):
            return boxes, vels, within
        keep = np.ones(len(boxes), dtype=bool)
        boxes, vels = boxes.copy(), vels.copy()
        x0, y0 = boxes[:, 0] - boxes[:, 2] / 2, boxes[:, 1] - boxes[:, 3] / 2
        x1, y1 = boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3] / 2
        for i, t in enumerate(self._tracks):
            if not (t.merged and t.confirmed):
                continue
            b = preds[i]
            iw = np.clip(np.minimum(x1, b[0] + b[2] / 2) - np.maximum(x0, b[0] - b[2] / 2), 0, None)
            ih = np.clip(np.minimum(y1, b[1] + b[3] / 2) - np.maximum(y0, b[1] - b[3] / 2), 0, None)
            idx = np.flatnonzero(keep & (iw * ih >= self.params["merge_inside"] * boxes[:, 2] * boxes[:, 3]))
            if len(idx) >= 2:
                u0, v0, u1, v1 = x0[idx].min(), y0[idx].min(), x1[idx].max(), y1[idx].max()
                boxes[idx[0]] = [(u0 + u1) / 2, (v0 + v1) / 2, u1 - u0, v1 - v0]
                vels[idx[0]] = vels[idx].mean(axis=0)
                keep[idx[1:]] = False
            within[i, idx[:1]] = True
        return boxes[keep], vels[keep], within[:, keep]

    def _reshow(self, trk: _Track, frame, box: np.ndarray, off: np.ndarray) -> None:
        """Give ``trk``'s row of ``frame`` (emitted this step) the ground-fixed ``box`` (cx, cy, w, h); a gap it
        ended (no box before) is filled up to it (``fill_gaps``)."""
        rows = self._rows if trk.confirmed else trk.pending
        for row in reversed(rows):
            if row["track_id"] == trk.id and row["frame"] == int(frame):
                break
        else:
            return
        fx, fy = box[0] + off[0], box[1] + off[1]
        hw, hh = (box[2] - 1.0) / 2, (box[3] - 1.0) / 2
        row.update(x_filt_px=float(fx), y_filt_px=float(fy), bbox_x0_px=float(fx - hw), bbox_y0_px=float(fy - hh),
                   bbox_x1_px=float(fx + hw), bbox_y1_px=float(fy + hh))
        if trk.gap and trk.gap[-1][0] is row:
            trk.gap.pop()
            if trk.gap and trk.shown is not None and self.params["fill_gaps"]:
                self._fill(trk.gap, *trk.shown, int(frame), np.asarray(box, dtype=np.float64), trk.template)
        trk.gap, trk.shown = [], (int(frame), np.asarray(box, dtype=np.float64).copy())

    def _travelled(self, trk: _Track) -> bool:
        """Whether a tentative track has moved enough, and steadily enough, to be confirmed (``min_travel_px``,
        ``min_travel_rel``, ``min_trend_f``).

        A constant velocity is fitted to its detections' centres (ground-fixed) by least squares: the
        distance it covers over the track's frames must reach the travel, and the fit's F statistic,
        the scatter it explains per parameter over the residual's per degree of freedom, must reach
        ``min_trend_f`` (with ``birth_hits`` under 3 there is no residual to test: the travel decides).
        If it fails, the n // 8 detections farthest from the fit are left out and the fit made again,
        and passes at twice ``min_trend_f`` (a frame whose region split gives a box of part of the
        vehicle, its centre many pixels off: a long track should not wait for that frame's scatter to be
        outweighed; twice, because leaving out the worst points makes any scatter look steadier: a crown
        swaying in place was confirmed in 21 of 100 clips at 1x, 14 at 2x, 13 without the second fit).
        """
        p = self.params
        t = np.array([f for f, _ in trk.seen], dtype=np.float64)
        z = np.array([c for _, c in trk.seen])
        fit = _trend(t, z)
        if fit is None:
            return False
        # the direction of motion: the detections' mean flow where they carry one (a slow bus's box jitters along
        # its length, which turns the fit of its centres by 10-15 degrees: a 20 x 60 px box then reaches 2 times
        # as far along as across), else the fit's
        f = np.asarray(trk.flows, dtype=np.float64).reshape(-1, 2)
        vel = f.mean(axis=0) if len(f) and np.isfinite(f).all() and np.hypot(*f.mean(axis=0)) > 0 else fit[3]
        side = _travel_side(float(trk.kf.x[2]), float(trk.kf.x[3]), vel, p["travel_lengthwise_rel"])
        need = max(p["min_travel_px"], p["min_travel_rel"] * side)
        if fit[0] >= need and fit[1] >= p["min_trend_f"]:
            return True
        drop = len(t) // 8
        if drop == 0:
            return False
        keep = np.argsort(fit[2], kind="stable")[:len(t) - drop]
        fit = _trend(t[keep], z[keep])
        return fit is not None and fit[0] >= need and fit[1] >= 2 * p["min_trend_f"]

    def _steady_flow(self, trk: _Track, need: float) -> bool:
        """Whether a tentative track's detections measured one steady motion covering ``need`` px (``end_min_hits``,
        ``steady_min_hits``).

        Each detection carries its region's flow over the ground (``u_px, v_px``): a vehicle's is the same
        from frame to frame, whatever its box does (a box that is part of the car in some frames, the car
        with its shadow in others, scatters the centres a fit of positions sees, not the flow). Steady: the
        mean flow ``m`` is at least ``steady_flow_rel`` of the mean flow speed (1: every detection moves
        alike; flow noise, whose direction changes from frame to frame, averages out); and the motion
        ``|m|`` times the frames from the first detection to the last reaches ``need``; and the boxes went
        that way: the median centre of the later half of the detections lies, along ``m``, at least half
        the flow's distance past the median of the earlier half (a region that recurs in place stays). False
        when a detection has no flow (``use_velocity`` off, or plain ``(x, y, area)`` detections), and with
        ``steady_flow_rel`` 0.
        """
        rel = self.params["steady_flow_rel"]
        if not rel > 0 or len(trk.flows) < max(3, self.birth_hits):
            return False
        f = np.asarray(trk.flows, dtype=np.float64)
        if not np.isfinite(f).all():
            return False
        m = f.mean(axis=0)
        speed = float(np.hypot(*m))
        if not speed > 0 or speed < rel * float(np.hypot(f[:, 0], f[:, 1]).mean()):
            return False
        t = np.array([fr for fr, _ in trk.seen], dtype=np.float64)
        if speed * float(t[-1] - t[0]) < need:
            return False
        along = np.array([c for _, c in trk.seen]) @ (m / speed)
        half = len(t) // 2
        moved = float(np.median(along[-half:]) - np.median(along[:half]))
        return moved >= 0.5 * speed * float(np.median(t[-half:]) - np.median(t[:half]))

    def _hold(self, trk: _Track, img: np.ndarray, pred: np.ndarray, off: np.ndarray, others: list) -> np.ndarray | None:
        """The ground-fixed box where ``trk``'s template matches ``img`` (``hold_min_ncc``), or None.

        Only a confirmed track that has travelled ``hold_min_travel_rel`` box sides, for at most
        ``hold_frames`` frames in a row; the search covers ``hold_search_px`` around the
        prediction (at least half the box's larger side); a
        place a track with a detection in this frame covers (IoU >= 0.5) is not taken twice, and a template of
        the ground (:meth:`_of_ground`, tested once after each detection) is not held.
        """
        p = self.params
        if (not p["hold_min_ncc"] > 0 or trk.template is None or not trk.confirmed or trk.held >= p["hold_frames"]
                or trk.travel < p["hold_min_travel_rel"] * max(trk.template.shape)):
            return None
        th, tw = trk.template.shape
        # at the border (None) the vehicle may be leaving: the track coasts (a search over what lies inside held a box
        # left on the road by the edge: benchmarks/heldout_rehearsal.md, "Misses by how fast the vehicle moves")
        found = _best_match(img, trk.template, pred[:2] + off, max(p["hold_search_px"], 0.5 * max(th, tw)))
        if found is None or not found[0] >= p["hold_min_ncc"]:
            return None
        box = np.array([found[1][0] - off[0], found[1][1] - off[1], tw, th])
        if others and (_iou(box[None], np.asarray(others)) >= 0.5).any():
            return None
        if not trk.ground_checked:
            if self._of_ground(trk, box):
                trk.template = None  # not a vehicle's: never held
                return None
            trk.ground_checked = True
        return box

    def _extend_back(self, trk: _Track, img: np.ndarray, off: np.ndarray) -> None:
        """Follow a track back from its first detection through the kept frames while its first template matches.

        A vehicle waiting at a light when the clip starts is found only when it drives off; it
        stood where its first detection was. Once the track has travelled ``back_min_travel_rel`` sides
        of its first box, the place must look different now (else the template is of the ground, and
        nothing is added; the test is made once), and the kept frames before the first detection are searched
        (``hold_search_px`` around the place found in the frame after, ``hold_min_ncc``), newest
        first, until a frame does not match, a frame is not kept, ``hold_frames`` are added, or (with
        ``back_stop_inside``) the place found lies that much within another confirmed track's box in
        that frame: the vehicle, of which this track's first box may be a part, was tracked there.
        """
        p = self.params
        f0, box, tpl = trk.first
        trk.first = None  # once
        th, tw = tpl.shape
        now = _ncc_at(img, tpl, box[:2], off)
        if now is None or now >= p["hold_min_ncc"]:
            return
        kept = {f: (g, o) for f, g, o in self._seen}
        at = box[:2].copy()
        r = max(p["hold_search_px"], 0.5 * max(th, tw))
        # the rows' box: the first detection's, or the size the track has had since (back_track_size)
        bw, bh = (np.median(np.asarray(trk.sizes), axis=0) if p["back_track_size"] and trk.sizes else (tw, th))
        first = max(-1, f0 - 1 - p["hold_frames"])
        taken = self._boxes_between(first + 1, f0) if p["back_stop_inside"] > 0 else {}
        for frame in range(f0 - 1, first, -1):
            if frame not in kept:
                return
            g, o = kept[frame]
            found = _best_match(g, tpl, at + o, r)
            if found is None or not found[0] >= p["hold_min_ncc"]:
                return
            at = found[1] - o
            box_then = np.array([at[0], at[1], bw, bh])
            if frame in taken and _inside_share(box_then + np.r_[o, 0.0, 0.0], taken[frame]) >= p["back_stop_inside"]:
                return
            self._emit(trk, frame, box_then, box_then, box_then, o)

    def _boxes_between(self, f0: int, f1: int) -> dict[int, np.ndarray]:
        """The boxes of the confirmed tracks' rows of frames ``f0 <= frame < f1``, by frame: ``(n, 4)`` inclusive
        ``x0, y0, x1, y1`` in the image."""
        out: dict[int, list] = {}
        for r in self._rows:
            if f0 <= r["frame"] < f1 and not math.isnan(r["bbox_x0_px"]):
                out.setdefault(r["frame"], []).append((r["bbox_x0_px"], r["bbox_y0_px"], r["bbox_x1_px"],
                                                       r["bbox_y1_px"]))
        return {f: np.asarray(b, dtype=np.float64) for f, b in out.items()}

    def _steady_run(self, trk: _Track, n: int) -> bool:
        """Whether a tentative track detected ``n`` times or more (``n`` > 0; with ``birth_gap`` 0, in as many frames in
        a row) measured one steady motion (:meth:`_steady_flow`, without the distance): fewer detections, or a flow
        that turns about (flicker), do not.

        Two rules confirm on it where the travel rule cannot. ``steady_min_hits``, in any frame: a car creeping up a
        queue at 0.1-0.4 px a frame, found in runs of frames broken by a frame it is not, never travels
        ``min_travel_px`` within one run, and its tentative tracks die at each break. ``end_min_hits``, when the clip
        ends (offline, as MOTChallenge scores a tracker): the clip's end, not the vehicle, cut the frames in which it
        would have travelled far enough (a car that pulls away from a light in the last second, one that enters the
        view).
        """
        return n > 0 and trk.hits >= n and self._steady_flow(trk, 0.0)

    def _of_ground(self, trk: _Track, box: np.ndarray) -> bool:
        """Whether ``trk``'s template, about to be held at the ground-fixed ``box``, is not a vehicle's: True refuses
        the hold, as it does where the kept frames cannot tell.

        A track that has been a box side or more away from ``box``: the template matched that place in the
        latest kept frame in which it was, before the vehicle came (a template of ground, a roof edge or a
        tree crown: a false track, or a box that slid off its vehicle). A track that never was, a car that
        crept up a queue by less than its length: no frame shows the place without it. It must then have been
        detected twice ``birth_hits`` times (a track confirmed on its first few detections and lost at once is as
        often a roof that parallax moved, or a passing truck's box left on a parked car), and its template must
        match the track's place in its oldest kept frame (before the template's; with ``hold_same_frames``, the oldest
        within that many frames before it), within ``HOLD_SAME_SEARCH_PX``:
        what it holds now is what it was found on; a box that slid off a car onto the crossing the car had stood on
        does not match the car it held then.
        """
        th, tw = trk.template.shape
        side = max(th, tw)
        ncc = self.params["hold_min_ncc"]
        where = {f: q[:2] for f, q in trk.hist}
        for frame, img, off in reversed(self._seen):
            c = where.get(frame)
            if c is None or float(np.hypot(*(c - box[:2]))) < side:
                continue
            then = _ncc_at(img, trk.template, box[:2], off)
            return then is None or then >= ncc
        if trk.hits < 2 * self.birth_hits:
            return True
        last = trk.hist[-1][0]  # the detection the template was taken at
        then = [(frame, img, off) for frame, img, off in self._seen if frame in where and frame < last]
        n = self.params["hold_same_frames"]
        if n > 0:  # the oldest within n frames, else the latest before them
            then = [x for x in then if x[0] >= last - n] or then[-1:]
        if not then:
            return True
        frame, img, off = then[0]
        found = _best_match(img, trk.template, where[frame] + off, HOLD_SAME_SEARCH_PX)
        return found is None or not found[0] >= ncc

    def extrapolate(self, frame: int, *, offset_px=(0.0, 0.0), image=None) -> None:
        """Output ``frame`` (the sequence's last, which starts no pair and so has no detections) for every confirmed
        track that had a detection (or was held) in the frame before: where its template matches ``image``
        (``hold_min_ncc``), else at the prediction, its box moved by its velocity."""
        off = np.asarray(offset_px, dtype=np.float64)
        self._path[int(frame)] = off.copy()
        img = None if image is None else np.asarray(image).astype(np.float32, copy=False)
        for trk in self._tracks:
            if not trk.confirmed and trk.misses == 0 and self._steady_run(trk, self.params["end_min_hits"]):
                trk.confirmed = True
                self._rows.extend(trk.pending)
                trk.pending = []
            if trk.confirmed and trk.misses == 0:
                pred = trk.kf.F @ trk.kf.x
                held = self._hold(trk, img, pred, off, []) if img is not None else None
                self._emit(trk, frame, None, pred[:4] if held is None else held, pred[:4], off, shown=True)

    def _emit(self, trk: _Track, frame, z, filt, pred, off, *, shown: bool = False) -> None:
        """A row: the detection's centre (NaN when coasting), the filtered centre and box, the prediction."""
        nan = math.nan
        coasting = z is None
        shown = filt if (shown or not coasting or self.params["report_coasting"]) else None
        zx, zy = (nan, nan) if coasting else (z[0] + off[0], z[1] + off[1])
        if shown is None:
            fx = fy = x0 = y0 = x1 = y1 = nan
        else:
            fx, fy = shown[0] + off[0], shown[1] + off[1]
            hw, hh = (shown[2] - 1.0) / 2, (shown[3] - 1.0) / 2
            x0, y0, x1, y1 = fx - hw, fy - hh, fx + hw, fy + hh
        row = {"frame": int(frame), "track_id": trk.id, "x_px": float(zx), "y_px": float(zy),
               "x_filt_px": float(fx), "y_filt_px": float(fy),
               "x_pred_px": float(pred[0] + off[0]), "y_pred_px": float(pred[1] + off[1]), "source": "multi",
               "seed_vehicle_id": None, "bbox_x0_px": float(x0), "bbox_y0_px": float(y0),
               "bbox_x1_px": float(x1), "bbox_y1_px": float(y1)}
        (self._rows if trk.confirmed else trk.pending).append(row)
        if trk.shown is not None and frame < trk.shown[0]:  # followed back (_extend_back): before every gap
            return
        if shown is None:
            trk.gap.append((row, off.copy()))
            return
        box = np.asarray(shown[:4], dtype=np.float64)
        if trk.gap and trk.shown is not None and self.params["fill_gaps"] and not coasting:
            self._fill(trk.gap, *trk.shown, int(frame), box, trk.template)
        trk.gap, trk.shown = [], (int(frame), box.copy())

    def _fill(self, gap: list, f0: int, box0: np.ndarray, f1: int, box1: np.ndarray, tpl: np.ndarray | None) -> None:
        """Fill the rows of ``gap`` (``(row, camera path)`` between frames ``f0`` and ``f1``) with the ground-fixed
        boxes ``(cx, cy, w, h)`` interpolated linearly in time from ``box0`` at ``f0`` to ``box1`` at ``f1``; with
        ``fill_min_ncc``, only where the template ``tpl`` matches the kept frame near there (placed where it does)."""
        p = self.params
        kept = {f: g for f, g, _ in self._seen} if p["fill_min_ncc"] > 0 else {}
        for row, off in gap:
            a = (row["frame"] - f0) / (f1 - f0)
            b = (1.0 - a) * box0 + a * box1
            if p["fill_min_ncc"] > 0:
                g = kept.get(row["frame"])
                if g is None or tpl is None:
                    continue
                found = _best_match(g, tpl, b[:2] + off, max(p["hold_search_px"], 0.5 * max(tpl.shape)))
                if found is None or not found[0] >= p["fill_min_ncc"]:
                    continue
                b[:2] = found[1] - off
            fx, fy = b[0] + off[0], b[1] + off[1]
            hw, hh = (b[2] - 1.0) / 2, (b[3] - 1.0) / 2
            row.update(x_filt_px=float(fx), y_filt_px=float(fy), bbox_x0_px=float(fx - hw),
                       bbox_y0_px=float(fy - hh), bbox_x1_px=float(fx + hw), bbox_y1_px=float(fy + hh))

    def _joined(self, rows: list[dict]) -> list[dict]:
        """``rows`` with each joined part's rows given to the track that took it in (``merge_hits``): in a frame
        both output, one row whose box is the union of the two; a part's row of a frame the whole has none of
        (or one without a box) becomes the whole's. With ``merge_union_rel``, a union wider or longer than that
        many times the whole's size when it took the part in is two vehicles, not one vehicle's parts (a track
        that followed the car ahead until it lost it, then took the front of the car behind and was taken in
        as its part): in that frame the part's row stays its own track's."""
        if not self._merges:
            return rows
        into = dict(self._merges)
        rel = self.params["merge_union_rel"]
        kept = {f: g for f, g, _ in self._seen} if rel > 0 else {}

        def final(i):
            while i in into:
                i = into[i]
            return i

        def limit(*ids) -> np.ndarray | None:
            sizes = [self._merge_size[i] for i in ids if i in self._merge_size]
            return (1.0 + rel) * np.max(sizes, axis=0) if rel > 0 and sizes else None

        out: dict[tuple[int, int], dict] = {}
        origin: dict[tuple[int, int], int] = {}
        order = []
        for r in rows:
            tid = final(r["track_id"])
            key = (r["frame"], tid)
            if key not in out:
                out[key], origin[key] = dict(r, track_id=tid), r["track_id"]
                order.append(key)
                continue
            have = out[key]
            if math.isnan(r["bbox_x0_px"]):
                continue
            if math.isnan(have["bbox_x0_px"]):
                out[key], origin[key] = dict(r, track_id=tid), r["track_id"]
                continue
            x0, y0 = min(have["bbox_x0_px"], r["bbox_x0_px"]), min(have["bbox_y0_px"], r["bbox_y0_px"])
            x1, y1 = max(have["bbox_x1_px"], r["bbox_x1_px"]), max(have["bbox_y1_px"], r["bbox_y1_px"])
            most = limit(origin[key], r["track_id"])
            if most is not None and (x1 - x0 > most[0] or y1 - y0 > most[1]) and self._road_between(kept, have, r):
                # two vehicles: the part's row stays its own track's, the whole's row the whole's
                part = r if r["track_id"] != tid else out[key]
                own = (r["frame"], origin[key] if part is out[key] else r["track_id"])
                if part is out[key]:
                    out[key], origin[key] = dict(r, track_id=tid), tid
                out[own], origin[own] = dict(part, track_id=own[1]), own[1]
                order.append(own)
                continue
            have.update(bbox_x0_px=x0, bbox_y0_px=y0, bbox_x1_px=x1, bbox_y1_px=y1,
                        x_filt_px=(x0 + x1) / 2, y_filt_px=(y0 + y1) / 2)
        return [out[k] for k in order]

    def _road_between(self, kept: dict, a: dict, b: dict) -> bool:
        """Whether the frame of rows ``a`` and ``b`` shows road between their boxes (:func:`_bridge_greys`: the gap's
        grey within ``merge_bridge_grey`` levels, at least 10, of the ground beside it and not of both boxes' ends):
        two vehicles, not one vehicle's two ends. False where the frame is no longer kept or the test cannot be made."""
        img = kept.get(a["frame"])
        if img is None:
            return False
        box = [np.array([(q["bbox_x0_px"] + q["bbox_x1_px"]) / 2, (q["bbox_y0_px"] + q["bbox_y1_px"]) / 2,
                         q["bbox_x1_px"] - q["bbox_x0_px"], q["bbox_y1_px"] - q["bbox_y0_px"]]) for q in (a, b)]
        greys = _bridge_greys(img.astype(np.float32), box[0], box[1], max_gap_px=2.0 * max(*box[0][2:], *box[1][2:]))
        if greys is None:
            return False
        gap, end_a, end_b, side_1, side_2 = greys
        tol = max(10.0, float(self.params["merge_bridge_grey"]))
        return min(abs(gap - end_a), abs(gap - end_b)) > tol and min(abs(gap - side_1), abs(gap - side_2)) <= tol

    def _motion(self, rows: list[dict]) -> dict[int, tuple]:
        """Per track, its rows with a box: their indices into ``rows``, frames, boxes ``(n, 4)``, the camera path
        ``(n, 2)``, and the robust line through the ground-fixed centres (:func:`_robust_line` over
        :data:`SMOOTH_LINE_FRAMES`): its centres and velocities ``(n, 2)`` (NaN where too few rows)."""
        at: dict[int, list[int]] = {}
        for i, r in enumerate(rows):
            if not math.isnan(r["bbox_x0_px"]):
                at.setdefault(r["track_id"], []).append(i)
        zero, out = np.zeros(2), {}
        for tid, idx in at.items():
            b = _row_boxes(rows, idx)
            f = np.array([rows[i]["frame"] for i in idx], dtype=np.float64)
            path = np.array([self._path.get(int(t), zero) for t in f])  # lines over the ground, not the image
            line, vel = _robust_line(f, (b[:, 2:] + b[:, :2]) / 2 - path, SMOOTH_LINE_FRAMES)
            out[tid] = (idx, f, b, path, line, vel)
        return out

    def _smoothed(self, rows: list[dict], motion: dict[int, tuple]) -> list[dict]:
        """``rows`` with each box's size the median over its track's nearby boxes of its heading, placed by the robust
        line through the track's centres within the box it replaces (``smooth_size_frames``); rows without a box as
        they are."""
        k = int(self.params["smooth_size_frames"])
        if k == 0:
            return rows
        out = list(rows)
        for idx, f, b, path, line, vel in motion.values():
            size, centre = b[:, 2:] - b[:, :2], (b[:, 2:] + b[:, :2]) / 2
            heading = np.where(np.hypot(vel[:, 0], vel[:, 1]) >= SMOOTH_SLOW_PX, np.arctan2(vel[:, 1], vel[:, 0]),
                               np.nan)
            half = _window_median(f, size, k, heading) / 2
            # the box goes where the line puts it, as far as it can while it stays within a larger box of the row (a
            # joined one) or holds a smaller one (a partial view); a box of the vehicle's size stays where it was
            lo, hi = b[:, :2] + half, b[:, 2:] - half
            placed = np.where(np.isnan(line), centre - path, line) + path
            centre = np.clip(placed, np.minimum(lo, hi), np.maximum(lo, hi))
            for n, i in enumerate(idx):
                (cx, cy), (w, h) = centre[n], half[n]
                out[i] = dict(rows[i], bbox_x0_px=float(cx - w), bbox_y0_px=float(cy - h), bbox_x1_px=float(cx + w),
                              bbox_y1_px=float(cy + h), x_filt_px=float(cx), y_filt_px=float(cy))
        return out

    def _without_parts(self, rows: list[dict], motion: dict[int, tuple]) -> list[dict]:
        """``rows`` without those whose box lies ``part_inside`` or more inside the larger box of another track's row
        of the same frame, the two moving alike (:func:`_alike`; a row without a velocity is kept)."""
        share = float(self.params["part_inside"])
        if share <= 0:
            return rows
        vel_of = {i: v for idx, *_, vel in motion.values() for i, v in zip(idx, vel)}
        by_frame: dict[int, list[int]] = {}
        for i in vel_of:
            by_frame.setdefault(rows[i]["frame"], []).append(i)
        drop = set()
        for idx in by_frame.values():
            if len(idx) < 2:
                continue
            b = _row_boxes(rows, idx)
            area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
            inside = (_intersections(b, b) >= share * area[:, None]) & (area[None, :] > area[:, None])  # [part, whole]
            for p_, w_ in zip(*np.nonzero(inside)):
                va, vb = vel_of[idx[p_]], vel_of[idx[w_]]
                if np.isfinite(va).all() and np.isfinite(vb).all() and _alike(va, vb):
                    drop.add(idx[p_])
        return [r for i, r in enumerate(rows) if i not in drop]

    def rows(self) -> list[dict]:
        """Rows of confirmed tracks, in the order produced (frame-major), parts joined (``merge_hits``), boxes smoothed
        (``smooth_size_frames``), parts of a tracked vehicle left out (``part_inside``), and those of tracks much
        smaller than the sequence's vehicles too (``min_area_rel``)."""
        rows = self._joined(self._rows)
        motion = self._motion(rows) if self.params["smooth_size_frames"] or self.params["part_inside"] else {}
        rows = self._without_parts(self._smoothed(rows, motion), motion)
        rel = self.params["min_area_rel"]
        if rel > 0:
            areas: dict[int, list[float]] = {}
            for r in rows:
                if not math.isnan(r["bbox_x0_px"]):
                    areas.setdefault(r["track_id"], []).append(
                        (r["bbox_x1_px"] - r["bbox_x0_px"] + 1) * (r["bbox_y1_px"] - r["bbox_y0_px"] + 1))
            typical = {k: float(np.median(v)) for k, v in areas.items()}
            if len(typical) >= 5:
                floor = rel * float(np.median(list(typical.values())))
                rows = [r for r in rows if typical.get(r["track_id"], math.inf) >= floor]
        return sorted(rows, key=lambda r: (r["frame"], r["track_id"]))
