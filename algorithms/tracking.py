"""Detection of moving regions and tracking: the thesis point tracker (4.1) and a multi-target tracker.

Point tracker (thesis 4.1, Appendix B): a pixel of a target is followed frame
by frame by the global shift plus the local flow at its (rounded) position,

    p(t+1) = p(t) + s(t) + w(t)(round(p(t)))

and the scalar Kalman filter (eqs. 4.6-4.10) is run on the series of local flow
measurements w per axis. Appendix B moves the column by the correlation alone
(its targets moved vertically); here both axes use global + local flow.

Multi-target tracker (beyond the thesis): connected moving regions of the
motion mask are detections; each track is a constant-velocity Kalman filter
(:class:`~algorithms.kalman.ConstantVelocityKalman`); detections are assigned
to tracks by the Hungarian method on the distance to each track's prediction,
gated; a track is confirmed after ``birth_hits`` consecutive hits and dropped
after ``death_misses`` consecutive misses. It can work in a ground-fixed
frame: given the camera path (the cumulative global shift of frame t), it
subtracts it from detections before filtering and adds it back to its output,
so a car driving straight is a constant-velocity target even when the
camera sways.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from algorithms.kalman import THESIS_KALMAN, ConstantVelocityKalman, kalman_cv_filter, scalar_kalman
from algorithms.registry import register_stage

__all__ = ["detect_moving_objects", "recentre_on_region", "PointTracker", "MultiTargetTracker", "TRACK_COLUMNS"]

# Column order of the rows trackers produce (the tracks table of docs/architecture.md).
TRACK_COLUMNS = ("frame", "track_id", "x_px", "y_px", "x_filt_px", "y_filt_px", "x_pred_px", "y_pred_px",
                 "source", "seed_vehicle_id")


@register_stage("detection")
def detect_moving_objects(mask: np.ndarray, *, min_area_px: int = 20,
                          connectivity: int = 8) -> list[tuple[float, float, int]]:
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
    list of (x_px, y_px, area_px)
        Centroid (frame t pixel coordinates, x right, y down) and area of each
        region, largest first.
    """
    m = np.asarray(mask)
    if m.ndim != 2 or m.dtype != bool:
        raise ValueError(f"mask: expected (H, W) bool, got {tuple(m.shape)} {m.dtype}")
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity: expected 4 or 8, got {connectivity}")
    n, _, stats, centroids = cv2.connectedComponentsWithStats(m.astype(np.uint8), connectivity=connectivity)
    out = [(float(centroids[i, 0]), float(centroids[i, 1]), int(stats[i, cv2.CC_STAT_AREA]))
           for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_area_px]
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


class PointTracker:
    """The thesis point tracker: one pixel followed by global shift + local flow, Kalman-filtered flow.

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
                 position_filter: Mapping | None = None):
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
        self._pos = [(float(x_px), float(y_px))]
        self._shift: list[tuple[float, float]] = []
        self._w: list[tuple[float, float]] = []

    def step(self, global_shift_px, flow_local: np.ndarray, valid: np.ndarray | None = None) -> None:
        """Advance by pair t -> t+1: sample the local flow at the current position.

        Outside the image, or where ``valid`` is False, the measurement is NaN
        (the Kalman filter only predicts) and the point moves by the global shift.

        With ``recentre_px`` set, the point is first moved to the centroid of the
        region around it that moves like it (:func:`recentre_on_region` on the
        same flow field, twice, ``radius_px=recentre_px``): that centroid is the
        raw position of frame t. Integrating flow alone is open loop: a flow that
        is biased on the target (a window that also covers ground shrinks a small
        vehicle's flow; coarse-to-fine LK stops short of large motions) makes the
        point slide off its vehicle in a straight line, and once on the ground it
        follows the ground for good. The vehicle's region closes the loop.
        """
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
        self._shift.append((sx, sy))
        self._w.append((wu, wv))
        # p(t+1) = p(t) + s(t) + w(t)(p(t))  (Appendix B: row = row + ofy + icy)
        self._pos.append((x + sx + (wu if inside else 0.0), y + sy + (wv if inside else 0.0)))

    def rows(self) -> list[dict]:
        """One row per frame 0..len(steps): raw, filtered and one-step-predicted positions.

        The filtered path makes the same moves as the raw one (global shift, and
        re-centring jumps) with the Kalman-filtered flow X(k|k) in place of the
        measured flow Z(k): ``filt(k) = raw(k) + sum_{j<k} (X(j|j) - Z(j))``.
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
                "source": "point", "seed_vehicle_id": self.seed_vehicle_id}


@dataclass
class _Track:
    id: int
    kf: ConstantVelocityKalman
    hits: int = 1
    misses: int = 0
    confirmed: bool = False
    pending: list = field(default_factory=list)  # rows held until confirmation


class MultiTargetTracker:
    """Constant-velocity Kalman tracks, Hungarian assignment with a distance gate, birth / death rules.

    Parameters
    ----------
    gate_px : float
        Largest distance between a track's predicted position and a detection
        it may take.
    birth_hits : int
        M: a new track is confirmed (and its rows, from its first frame, are
        output) after M consecutive frames with a detection; a miss before that
        deletes it.
    death_misses : int
        K: a confirmed track is deleted after K consecutive misses (it coasts on
        its prediction meanwhile; its rows have NaN raw positions then).
    sigma_accel_px, sigma_meas_px, sigma_vel0_px : float
        :class:`~algorithms.kalman.ConstantVelocityKalman` noise (px/frame^2, px, px/frame).

    Use :meth:`step` once per frame, then :meth:`rows`.
    """

    def __init__(self, *, gate_px: float = 8.0, birth_hits: int = 3, death_misses: int = 3,
                 sigma_accel_px: float = 0.5, sigma_meas_px: float = 1.0, sigma_vel0_px: float = 5.0):
        if not gate_px > 0:
            raise ValueError(f"gate_px: expected > 0, got {gate_px}")
        for name, v in (("birth_hits", birth_hits), ("death_misses", death_misses)):
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        self.gate_px, self.birth_hits, self.death_misses = float(gate_px), int(birth_hits), int(death_misses)
        self._kf_kw = dict(sigma_accel_px=sigma_accel_px, sigma_meas_px=sigma_meas_px,
                           sigma_pos0_px=sigma_meas_px, sigma_vel0_px=sigma_vel0_px)
        self._tracks: list[_Track] = []
        self._rows: list[dict] = []
        self._next_id = 0

    def step(self, frame: int, detections, *, offset_px=(0.0, 0.0)) -> None:
        """Take the detections ``[(x_px, y_px, ...), ...]`` of ``frame``.

        ``offset_px`` is the camera path at this frame (ground content displacement
        since frame 0); tracks live in ``image - offset`` coordinates.
        """
        off = np.asarray(offset_px, dtype=np.float64)
        det = np.array([[d[0], d[1]] for d in detections], dtype=np.float64).reshape(-1, 2) - off
        preds = np.array([t.kf.predict() for t in self._tracks]).reshape(-1, 2)
        cost = np.linalg.norm(preds[:, None, :] - det[None, :, :], axis=2)
        pairs = []
        if cost.size:
            # infeasible pairs cost more than any feasible assignment could
            big = self.gate_px * (1 + len(self._tracks) + len(det)) * 10
            rows, cols = linear_sum_assignment(np.where(cost <= self.gate_px, cost, big))
            pairs = [(r, c) for r, c in zip(rows, cols) if cost[r, c] <= self.gate_px]
        taken_t, taken_d = {r for r, _ in pairs}, {c for _, c in pairs}
        survivors = []
        for i, trk in enumerate(self._tracks):
            pred = preds[i]
            if i in taken_t:
                z = det[[c for r, c in pairs if r == i][0]]
                trk.kf.update(z)
                trk.hits, trk.misses = trk.hits + 1, 0
            else:
                z = np.full(2, np.nan)
                trk.misses += 1
                if not trk.confirmed or trk.misses >= self.death_misses:
                    continue
            self._emit(trk, frame, z, trk.kf.x[:2], pred, off)
            if not trk.confirmed and trk.hits >= self.birth_hits:
                trk.confirmed = True
                self._rows.extend(trk.pending)
                trk.pending = []
            survivors.append(trk)
        for c in range(len(det)):
            if c not in taken_d:
                trk = _Track(self._next_id, ConstantVelocityKalman(det[c], **self._kf_kw))
                self._next_id += 1
                self._emit(trk, frame, det[c], det[c], det[c], off)
                if self.birth_hits == 1:
                    trk.confirmed = True
                    self._rows.extend(trk.pending)
                    trk.pending = []
                survivors.append(trk)
        self._tracks = survivors

    def _emit(self, trk: _Track, frame, z, filt, pred, off) -> None:
        z, filt, pred = z + off, filt + off, pred + off
        row = {"frame": int(frame), "track_id": trk.id, "x_px": float(z[0]), "y_px": float(z[1]),
               "x_filt_px": float(filt[0]), "y_filt_px": float(filt[1]),
               "x_pred_px": float(pred[0]), "y_pred_px": float(pred[1]), "source": "multi",
               "seed_vehicle_id": None}
        (self._rows if trk.confirmed else trk.pending).append(row)

    def rows(self) -> list[dict]:
        """Rows of confirmed tracks, in the order produced (frame-major)."""
        return sorted(self._rows, key=lambda r: (r["frame"], r["track_id"]))
