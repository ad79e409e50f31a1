"""Kalman filters: the thesis's scalar filter (eqs. 4.6-4.10) and a 2-D constant-velocity filter.

Thesis 4.1: a random-walk state (A = 1, H = 1, no control) filtered per axis,
with X(1|1) = -1, P(1|1) = 1, Q = 1, R = 0.05. Appendix B sets the first
estimate to X(1|1) and starts updating at the second measurement, so the first
measurement is not used; Table 4.1 ("Kalman Filter" column starts at -1) is
reproduced exactly that way.

The constant-velocity filter tracks (x, y, vx, vy) in px and px/frame with a
piecewise-constant white-acceleration process model (Bar-Shalom, Li,
Kirubarajan 2001, 6.3.3): per axis Q = sigma_a^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

__all__ = ["THESIS_KALMAN", "scalar_kalman", "ConstantVelocityKalman", "CVFilterResult", "kalman_cv_filter",
           "BoxKalman"]

# Thesis 4.1: "The X(1|1) is set to be -1, P(1|1) is 1, Q is 1, R is 0.05." Use as scalar_kalman(z, **THESIS_KALMAN).
THESIS_KALMAN = MappingProxyType({"x0": -1.0, "p0": 1.0, "q": 1.0, "r": 0.05})


def _check_positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name}: expected a finite number {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


def scalar_kalman(measurements, *, x0: float | None, p0: float, q: float, r: float) -> np.ndarray:
    """Scalar Kalman filter of the thesis (eqs. 4.6-4.10), A = H = 1, no control.

    Parameters
    ----------
    measurements : array-like, (N,) float
        Z(1..N), e.g. the optical flow of one pixel along one axis, px/frame.
        NaN means no measurement: that step only predicts.
    x0 : float or None
        X(1|1), the first estimate, which replaces Z(1) as in Appendix B
        (thesis: -1). ``None`` takes X(1|1) = Z(1).
    p0 : float
        P(1|1), its variance (thesis: 1).
    q : float
        Process noise variance Q (thesis: 1).
    r : float
        Measurement noise variance R (thesis: 0.05).

    Returns
    -------
    ndarray, (N,) float64
        X(k|k) for k = 1..N; element 0 is X(1|1).
    """
    z = np.asarray(measurements, dtype=np.float64)
    if z.ndim != 1:
        raise ValueError(f"measurements: expected a 1-D series, got shape {z.shape}")
    p0, q, r = _check_positive("p0", p0, allow_zero=True), _check_positive("q", q, allow_zero=True), _check_positive("r", r)
    n = z.shape[0]
    x_out = np.full(n, np.nan)
    if n == 0:
        return x_out
    if x0 is None:
        if not math.isfinite(z[0]):
            raise ValueError("x0=None takes X(1|1) = Z(1), but measurement 0 is NaN; give x0")
        x0 = z[0]
    X, P = float(x0), p0
    x_out[0] = X
    for k in range(1, n):
        # eq. 4.6: X(k|k-1) = X(k-1|k-1)
        X_pred = X
        # eq. 4.7: P(k|k-1) = P(k-1|k-1) + Q
        P_pred = P + q
        if math.isnan(z[k]):
            X, P = X_pred, P_pred
        else:
            # eq. 4.9: Kg(k) = P(k|k-1) / (P(k|k-1) + R)
            Kg = P_pred / (P_pred + r)
            # eq. 4.8: X(k|k) = X(k|k-1) + Kg(k) (Z(k) - X(k|k-1))
            X = X_pred + Kg * (z[k] - X_pred)
            # eq. 4.10: P(k|k) = (1 - Kg(k)) P(k|k-1)
            P = (1.0 - Kg) * P_pred
        x_out[k] = X
    return x_out


class ConstantVelocityKalman:
    """2-D constant-velocity Kalman filter, state ``x = (x, y, vx, vy)`` in px and px/frame.

    Parameters
    ----------
    x0 : array-like, (4,) or (2,)
        Initial state; a position alone starts at zero velocity.
    dt : float
        Time between frames (frames; 1 means velocities are px/frame).
    sigma_accel_px : float
        Standard deviation of the white acceleration, px/frame^2 (process noise).
    sigma_meas_px : float
        Standard deviation of a position measurement, px (R = sigma^2 I).
    sigma_pos0_px, sigma_vel0_px : float
        Initial standard deviations of position and velocity (diagonal P0).

    Attributes
    ----------
    x : (4,) float64 state, P : (4, 4) covariance, F, H, Q, R : model matrices.
    """

    def __init__(self, x0, *, dt: float = 1.0, sigma_accel_px: float = 0.5, sigma_meas_px: float = 1.0,
                 sigma_pos0_px: float = 1.0, sigma_vel0_px: float = 10.0):
        dt = _check_positive("dt", dt)
        sa = _check_positive("sigma_accel_px", sigma_accel_px, allow_zero=True)
        sm = _check_positive("sigma_meas_px", sigma_meas_px)
        sp = _check_positive("sigma_pos0_px", sigma_pos0_px, allow_zero=True)
        sv = _check_positive("sigma_vel0_px", sigma_vel0_px, allow_zero=True)
        x0 = np.asarray(x0, dtype=np.float64).ravel()
        if x0.shape not in ((2,), (4,)) or not np.isfinite(x0).all():
            raise ValueError(f"x0: expected a finite (x, y) or (x, y, vx, vy), got {x0!r}")
        self.x = np.concatenate([x0, np.zeros(2)]) if x0.shape == (2,) else x0.copy()
        self.P = np.diag([sp**2, sp**2, sv**2, sv**2])
        self.F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)
        self.H = np.array([[1, 0, 0, 0], [0, 1, 0, 0]], dtype=np.float64)
        # white acceleration a ~ N(0, sigma_a^2) held over a step: w = G a, G = (dt^2/2, dt) per axis
        G = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
        self.Q = sa**2 * (G @ G.T)
        self.R = sm**2 * np.eye(2)

    def predict(self) -> np.ndarray:
        """Propagate one step; returns the predicted position (2,)."""
        # x = F x
        self.x = self.F @ self.x
        # P = F P F' + Q
        self.P = self.F @ self.P @ self.F.T + self.Q
        return self.x[:2].copy()

    def update(self, z) -> np.ndarray:
        """Correct with a position measurement ``z = (x, y)`` px; NaN skips the update.

        Returns the filtered position (2,).
        """
        z = np.asarray(z, dtype=np.float64).ravel()
        if z.shape != (2,):
            raise ValueError(f"z: expected a position (x, y), got shape {z.shape}")
        if np.isnan(z).any():
            return self.x[:2].copy()
        # y = z - H x (innovation)
        y = z - self.H @ self.x
        # S = H P H' + R
        S = self.H @ self.P @ self.H.T + self.R
        # K = P H' S^-1
        K = np.linalg.solve(S, self.H @ self.P).T
        # x = x + K y
        self.x = self.x + K @ y
        # P = (I - K H) P (I - K H)' + K R K'  (Joseph form: stays symmetric positive definite)
        I_KH = np.eye(4) - K @ self.H
        self.P = I_KH @ self.P @ I_KH.T + K @ self.R @ K.T
        return self.x[:2].copy()


@dataclass(frozen=True)
class CVFilterResult:
    """Output of :func:`kalman_cv_filter`; NaN before the first measurement.

    filtered_px (N, 2): position after the update at frame k. predicted_px (N, 2):
    the one-step prediction of frame k made at k-1 (equal to the start at the
    first frame). states (N, 4) and covariances (N, 4, 4): after the update.
    """

    filtered_px: np.ndarray
    predicted_px: np.ndarray
    states: np.ndarray
    covariances: np.ndarray


def kalman_cv_filter(measurements, *, x0=None, dt: float = 1.0, sigma_accel_px: float = 0.5,
                     sigma_meas_px: float = 1.0, sigma_pos0_px: float | None = None,
                     sigma_vel0_px: float = 10.0) -> CVFilterResult:
    """Run :class:`ConstantVelocityKalman` over a sequence of positions (function form).

    Parameters
    ----------
    measurements : array-like, (N, 2) float
        Positions in px; a row with NaN is a missing measurement (predict only).
    x0 : array-like, (2,) or (4,), optional
        Initial state; default: the first finite measurement at zero velocity,
        which is then also taken as that frame's filtered position.
    sigma_pos0_px : float, optional
        Default ``sigma_meas_px``. Other parameters as in the class.
    """
    z = np.asarray(measurements, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 2:
        raise ValueError(f"measurements: expected (N, 2) positions in px, got shape {z.shape}")
    n = z.shape[0]
    filt, pred = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    states, covs = np.full((n, 4), np.nan), np.full((n, 4, 4), np.nan)
    start, init_from_z = 0, x0 is None
    if init_from_z:
        finite = np.flatnonzero(np.isfinite(z).all(axis=1))
        if finite.size == 0:
            return CVFilterResult(filt, pred, states, covs)
        start = int(finite[0])
        x0 = z[start]
    kf = ConstantVelocityKalman(x0, dt=dt, sigma_accel_px=sigma_accel_px, sigma_meas_px=sigma_meas_px,
                                sigma_pos0_px=sigma_meas_px if sigma_pos0_px is None else sigma_pos0_px,
                                sigma_vel0_px=sigma_vel0_px)
    for k in range(start, n):
        if k == start:
            pred[k] = kf.x[:2]
            if not init_from_z:  # a given x0 is a prior, the first measurement still corrects it
                kf.update(z[k])
        else:
            pred[k] = kf.predict()
            kf.update(z[k])
        filt[k], states[k], covs[k] = kf.x[:2], kf.x, kf.P
    return CVFilterResult(filt, pred, states, covs)


class BoxKalman:
    """Constant-velocity Kalman filter of a box: state ``x = (cx, cy, w, h, vcx, vcy, vw, vh)``.

    Centre and size (px) each move at a constant rate (px/frame) disturbed by white
    acceleration (Bar-Shalom, Li, Kirubarajan 2001, 6.3.3; per coordinate
    Q = sigma_a^2 [[1/4, 1/2], [1/2, 1]] for dt = 1), as SORT (Bewley 2016) and
    ByteTrack filter boxes, except that here the size has a rate (not the area and a
    fixed aspect ratio: a vehicle that turns changes its box's aspect). A measurement
    is the box ``(cx, cy, w, h)``, optionally with the centre's velocity ``(vcx, vcy)``
    (a detection's mean flow).

    Parameters
    ----------
    box : array-like, (4,)
        Initial ``(cx, cy, w, h)``, px.
    velocity : array-like, (2,), optional
        Initial centre velocity, px/frame (default zero, with ``sigma_vel0_px``).
    sigma_accel_px : float
        Centre acceleration, px/frame^2.
    sigma_size_accel_px : float
        Size acceleration, px/frame^2.
    sigma_meas_px : float
        Centre and size measurement noise, px.
    sigma_vel_meas_px : float
        Velocity measurement noise, px/frame.
    sigma_vel0_px : float
        Initial centre velocity uncertainty, px/frame (the size rate starts at 0 +- sigma_meas_px).
    """

    def __init__(self, box, *, velocity=None, sigma_accel_px: float = 0.5, sigma_size_accel_px: float = 0.2,
                 sigma_meas_px: float = 1.5, sigma_vel_meas_px: float = 1.0, sigma_vel0_px: float = 5.0):
        sa = _check_positive("sigma_accel_px", sigma_accel_px, allow_zero=True)
        ss = _check_positive("sigma_size_accel_px", sigma_size_accel_px, allow_zero=True)
        sm = _check_positive("sigma_meas_px", sigma_meas_px)
        svm = _check_positive("sigma_vel_meas_px", sigma_vel_meas_px)
        sv = _check_positive("sigma_vel0_px", sigma_vel0_px, allow_zero=True)
        b = np.asarray(box, dtype=np.float64).ravel()
        if b.shape != (4,) or not np.isfinite(b).all():
            raise ValueError(f"box: expected a finite (cx, cy, w, h), got {box!r}")
        v0 = np.zeros(2) if velocity is None else np.asarray(velocity, dtype=np.float64).ravel()
        known_v = v0.shape == (2,) and bool(np.isfinite(v0).all())
        self.x = np.concatenate([b, v0 if known_v else np.zeros(2), np.zeros(2)])
        self.P = np.diag([sm**2] * 4 + [(svm if known_v else sv) ** 2] * 2 + [sm**2] * 2)
        self.F = np.eye(8)
        self.F[:4, 4:] = np.eye(4)
        G = np.vstack([0.5 * np.eye(4), np.eye(4)])  # w = G a, per coordinate (dt^2/2, dt), dt = 1
        self.Q = G @ np.diag([sa**2, sa**2, ss**2, ss**2]) @ G.T
        self.R = np.diag([sm**2] * 4 + [svm**2] * 2)

    def predict(self) -> np.ndarray:
        """Propagate one frame; returns the predicted box ``(cx, cy, w, h)``."""
        # x = F x
        self.x = self.F @ self.x
        # P = F P F' + Q
        self.P = self.F @ self.P @ self.F.T + self.Q
        self.x[2:4] = np.maximum(self.x[2:4], 1.0)  # a size never shrinks below a pixel
        return self.x[:4].copy()

    def restart_size(self, w: float, h: float) -> None:
        """Take the size as ``(w, h)``, its rate 0, both with the initial uncertainty (sigma_meas_px), the centre
        and its velocity as they are: the filter had learned a size that was not one vehicle's."""
        if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
            raise ValueError(f"w, h: expected finite sizes > 0, got {w!r}, {h!r}")
        sm2 = self.R[0, 0]
        self.x[[2, 3, 6, 7]] = [w, h, 0.0, 0.0]
        for i in (2, 3, 6, 7):
            self.P[i, :] = 0.0
            self.P[:, i] = 0.0
            self.P[i, i] = sm2

    def update(self, box, velocity=None) -> np.ndarray:
        """Correct with a measured box ``(cx, cy, w, h)`` and, when finite, the centre velocity ``(vcx, vcy)``.

        Returns the filtered box ``(cx, cy, w, h)``.
        """
        z = np.asarray(box, dtype=np.float64).ravel()
        if z.shape != (4,) or not np.isfinite(z).all():
            raise ValueError(f"box: expected a finite (cx, cy, w, h), got {box!r}")
        rows = list(range(4))
        if velocity is not None and np.isfinite(np.asarray(velocity, dtype=np.float64)).all():
            z = np.concatenate([z, np.asarray(velocity, dtype=np.float64).ravel()])
            rows += [4, 5]
        H = np.eye(8)[rows]
        R = self.R[np.ix_(range(len(rows)), range(len(rows)))]
        # y = z - H x
        y = z - H @ self.x
        # S = H P H' + R
        S = H @ self.P @ H.T + R
        # K = P H' S^-1
        K = np.linalg.solve(S, H @ self.P).T
        # x = x + K y
        self.x = self.x + K @ y
        # P = (I - K H) P (I - K H)' + K R K'  (Joseph form)
        I_KH = np.eye(8) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ R @ K.T
        return self.x[:4].copy()
