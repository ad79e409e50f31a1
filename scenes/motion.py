"""Camera and vehicle motion: the smooth flight line, jitter, and vehicle paths on roads.

World frame: x east, y north, z up, metres; the ground is the plane z = 0.
Camera poses are camera-to-world with OpenCV camera axes (x right, y down,
z forward): a world point X maps to camera coordinates ``R.T @ (X - C)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "CameraPath",
    "camera_path",
    "ornstein_uhlenbeck",
    "rotation_nadir",
    "rot_x",
    "rot_y",
    "project",
    "VehiclePath",
    "vehicle_pose_matrix",
    "polyline_arc_lengths",
]


def rot_x(a_rad: float) -> np.ndarray:
    c, s = math.cos(a_rad), math.sin(a_rad)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)


def rot_y(a_rad: float) -> np.ndarray:
    c, s = math.cos(a_rad), math.sin(a_rad)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)


def rotation_nadir(yaw_deg: float) -> np.ndarray:
    """Camera-to-world rotation of a nadir camera whose image 'up' points along compass ``yaw_deg``.

    Columns are the camera axes in the world: z down, y (image down) pointing
    backwards, x = y cross z (image right).
    """
    psi = math.radians(yaw_deg)
    f = np.array([math.sin(psi), math.cos(psi), 0.0])
    y_cam = -f
    z_cam = np.array([0.0, 0.0, -1.0])
    x_cam = np.cross(y_cam, z_cam)
    return np.stack([x_cam, y_cam, z_cam], axis=1)


def ornstein_uhlenbeck(rng: np.random.Generator, n: int, dt_s: float, tau_s: float,
                       std: np.ndarray) -> np.ndarray:
    """Sample a stationary Ornstein-Uhlenbeck process at ``n`` instants ``dt_s`` apart.

    Exact discretisation: ``x_{k+1} = a x_k + std sqrt(1 - a^2) xi_k`` with
    ``a = exp(-dt / tau)``, ``x_0 ~ N(0, std^2)``; the autocorrelation is
    ``std^2 exp(-|lag| / tau)``.

    Returns
    -------
    ndarray, (n, len(std)) float64
    """
    std = np.asarray(std, dtype=np.float64)
    xi = rng.standard_normal((n, std.size))
    a = math.exp(-dt_s / tau_s)
    b = math.sqrt(max(0.0, 1.0 - a * a))
    x = np.empty((n, std.size))
    x[0] = std * xi[0]
    for k in range(1, n):
        x[k] = a * x[k - 1] + b * std * xi[k]
    return x


def project(K: np.ndarray, R_wc: np.ndarray, C_w: np.ndarray, X_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points ``(..., 3)``: returns pixel coordinates ``(..., 2)`` and depth ``(...)``."""
    Xc = (np.asarray(X_w, np.float64) - C_w) @ R_wc  # == R.T @ (X - C) for each row
    z = Xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 0] * Xc[..., 0] / z + K[0, 2]
        v = K[1, 1] * Xc[..., 1] / z + K[1, 2]
    return np.stack([u, v], axis=-1), z


@dataclass(frozen=True)
class CameraPath:
    """Camera poses of a sequence, actual (with jitter) and smooth (flight line only).

    Attributes
    ----------
    t_s : (N,) float64, frame times
    K : (3, 3) float64, intrinsics (pixel centres at integer coordinates)
    R : (N, 3, 3) camera-to-world rotations, actual
    C : (N, 3) camera centres in the world, metres, actual
    R_smooth, C_smooth : the same without jitter
    jitter_px : (N, 2) image displacement of the ground at the image centre caused by jitter
    """

    t_s: np.ndarray
    K: np.ndarray
    R: np.ndarray
    C: np.ndarray
    R_smooth: np.ndarray
    C_smooth: np.ndarray
    jitter_px: np.ndarray = field(repr=False)


def camera_path(spec, rng: np.random.Generator) -> CameraPath:
    """Build the camera poses of ``spec`` (a SceneSpec); jitter is drawn from ``rng``."""
    img, cam = spec.image, spec.camera
    n = img.n_frames
    t = np.arange(n, dtype=np.float64) / img.fps
    f_px = spec.focal_px()
    K = np.array([[f_px, 0, (img.width_px - 1) / 2.0],
                  [0, f_px, (img.height_px - 1) / 2.0],
                  [0, 0, 1]], dtype=np.float64)

    # smooth flight line: constant ground speed, constant turn rate, constant climb
    psi0 = math.radians(cam.heading_deg)
    omega = math.radians(cam.drift.heading_rate_deg_s)
    psi = psi0 + omega * t
    v = cam.ground_speed_mps
    if abs(omega) < 1e-12:
        x = v * t * math.sin(psi0)
        y = v * t * math.cos(psi0)
    else:
        x = v / omega * (math.cos(psi0) - np.cos(psi))
        y = v / omega * (np.sin(psi) - math.sin(psi0))
    z = cam.altitude_m + cam.drift.climb_rate_mps * t
    C_smooth = np.stack([x, y, z], axis=1)

    jit = cam.jitter
    std = np.array([jit.roll_std_deg, jit.pitch_std_deg, jit.yaw_std_deg,
                    jit.x_std_m, jit.y_std_m, jit.z_std_m])
    d = ornstein_uhlenbeck(rng, n, 1.0 / img.fps, jit.correlation_time_s, std)

    R_smooth = np.empty((n, 3, 3))
    R = np.empty((n, 3, 3))
    for k in range(n):
        yaw_deg = math.degrees(psi[k]) + cam.drift.crab_deg
        R_smooth[k] = rotation_nadir(yaw_deg) @ rot_x(math.radians(cam.tilt_deg))
        R[k] = (rotation_nadir(yaw_deg + d[k, 2]) @ rot_x(math.radians(cam.tilt_deg + d[k, 1]))
                @ rot_y(math.radians(d[k, 0])))
    C = C_smooth + d[:, 3:6]

    # jitter in pixels: where the ground point at the smooth camera's image centre appears
    # in the actual image, minus the image centre
    ray = R_smooth[:, :, 2]
    lam = -C_smooth[:, 2] / ray[:, 2]
    G = C_smooth + lam[:, None] * ray
    jitter_px = np.empty((n, 2))
    for k in range(n):
        p, _ = project(K, R[k], C[k], G[k])
        jitter_px[k] = p - K[:2, 2]
    return CameraPath(t_s=t, K=K, R=R, C=C, R_smooth=R_smooth, C_smooth=C_smooth, jitter_px=jitter_px)


# -- vehicles ---------------------------------------------------------------------------

def vehicle_pose_matrix(x_m: float, y_m: float, theta_rad: float) -> np.ndarray:
    """Vehicle-to-world 4x4: local x forward, y left, z up, origin on the ground under its centre."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    M = np.eye(4)
    M[:2, :2] = [[c, -s], [s, c]]
    M[0, 3], M[1, 3] = x_m, y_m
    return M


def polyline_arc_lengths(points_m: np.ndarray) -> np.ndarray:
    """Cumulative arc length (M,) float64 of a polyline (M, 2), starting at 0."""
    seg = np.hypot(*np.diff(np.asarray(points_m, np.float64), axis=0).T)
    return np.concatenate([[0.0], np.cumsum(seg)])


@dataclass
class VehiclePath:
    """A vehicle driving along ``route_m``, a polyline on a road (curves, turns at junctions), with a speed profile.

    ``kind`` is one of ``parked``, ``constant``, ``accelerating``, ``stopping``, ``profile``. At
    time ``t`` the vehicle is at arc length ``s0_m + distance(t)`` along the route, heading along
    the route's tangent (interpolated between the vertices' tangents, so it turns smoothly).
    Beyond either end of the route it continues straight.

    ``profile`` (simulated traffic, :mod:`scenes.traffic`): the arc length is piecewise
    quadratic in time, one constant acceleration per knot interval: from knot k,
    ``S(t) = S_k + v_k (t - t_k) + a_k (t - t_k)^2 / 2``; before the first knot it runs at
    ``v_0``, after the last knot with the last knot's acceleration (0 by construction). The
    positions at any t (rolling-shutter bands, motion-blur sub-frames) come from the same
    closed form the truth uses, so the truth is exact between frames too.
    ``vclass`` is the road user's class (``car, van, truck, bus, motorbike, cyclist, pedestrian``);
    its shape is :func:`scenes.traffic.vehicle_shape`.
    """

    vehicle_id: int
    kind: str
    route_m: np.ndarray  # (M, 2) polyline, metres, M >= 2, in driving order
    s0_m: float  # arc length along the route at t = 0
    v0_mps: float
    v_max_mps: float = 0.0
    accel_mps2: float = 0.0
    t_stop_start_s: float = 0.0
    turning: bool = False  # drawn as a vehicle that turns at junctions (its route was chosen so)
    size_m: tuple[float, float, float] = (4.5, 1.9, 1.5)
    body_rgb: tuple[int, int, int] = (200, 30, 30)
    cabin_rgb: tuple[int, int, int] = (60, 60, 60)
    vclass: str = "car"
    profile_t_s: np.ndarray | None = None  # (K,) knot times, increasing
    profile_s_m: np.ndarray | None = None  # (K,) arc length at each knot (S(0) = s0_m)
    profile_v_mps: np.ndarray | None = None  # (K,) speed at each knot, >= 0
    profile_a_mps2: np.ndarray | None = None  # (K,) acceleration from each knot to the next
    _s: np.ndarray = field(init=False, repr=False)
    _heading: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        route = np.asarray(self.route_m, np.float64)
        if route.ndim != 2 or route.shape[1] != 2 or route.shape[0] < 2:
            raise ValueError(f"route_m: expected (M, 2) with M >= 2, got {route.shape}")
        s = polyline_arc_lengths(route)
        keep = np.concatenate([[True], np.diff(s) > 1e-9])  # repeated points have no direction
        self.route_m, s = route[keep], s[keep]
        d = np.diff(self.route_m, axis=0)
        seg_heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        # a vertex's heading: the mean of its two segments' (ends: their one segment)
        mid = 0.5 * (seg_heading[:-1] + seg_heading[1:])
        self._heading = np.concatenate([[seg_heading[0]], mid, [seg_heading[-1]]])
        self._s = s
        if self.kind == "profile":
            knots = [np.asarray(a, np.float64) for a in (self.profile_t_s, self.profile_s_m, self.profile_v_mps,
                                                         self.profile_a_mps2) if a is not None]
            if len(knots) != 4 or not all(k.ndim == 1 and k.size == knots[0].size and k.size >= 1 for k in knots):
                raise ValueError("profile: expected profile_t_s, profile_s_m, profile_v_mps, profile_a_mps2 of one "
                                 "length >= 1")
            if np.any(np.diff(knots[0]) <= 0):
                raise ValueError("profile_t_s: expected strictly increasing knot times")
            self.profile_t_s, self.profile_s_m, self.profile_v_mps, self.profile_a_mps2 = knots
            self._profile_s0 = self._profile_at(0.0)[0]

    def _profile_at(self, t_s: float) -> tuple[float, float]:
        """(S(t), speed(t)) of a ``profile`` vehicle."""
        tk = self.profile_t_s
        k = int(np.searchsorted(tk, t_s, side="right")) - 1
        if k < 0:
            v = float(self.profile_v_mps[0])
            return float(self.profile_s_m[0]) + v * (t_s - float(tk[0])), v
        dt = t_s - float(tk[k])
        v, a = float(self.profile_v_mps[k]), float(self.profile_a_mps2[k])
        return float(self.profile_s_m[k]) + v * dt + 0.5 * a * dt * dt, max(0.0, v + a * dt)

    @property
    def parked(self) -> bool:
        return self.kind == "parked"

    def speed(self, t_s: float) -> float:
        if self.kind == "parked":
            return 0.0
        if self.kind == "profile":
            return self._profile_at(t_s)[1]
        if self.kind == "accelerating":
            return min(self.v0_mps + self.accel_mps2 * t_s, max(self.v_max_mps, self.v0_mps))
        if self.kind == "stopping":
            return max(0.0, self.v0_mps - self.accel_mps2 * max(0.0, t_s - self.t_stop_start_s))
        return self.v0_mps

    def distance(self, t_s: float) -> float:
        """Distance travelled since t = 0, metres (the integral of :meth:`speed`)."""
        v0, a = self.v0_mps, self.accel_mps2
        if self.kind == "parked":
            return 0.0
        if self.kind == "profile":
            return self._profile_at(t_s)[0] - self._profile_s0
        if self.kind == "accelerating":
            v1 = max(self.v_max_mps, v0)
            t1 = (v1 - v0) / a if a > 0 else math.inf
            if t_s <= t1:
                return v0 * t_s + 0.5 * a * t_s * t_s
            return v0 * t1 + 0.5 * a * t1 * t1 + v1 * (t_s - t1)
        if self.kind == "stopping":
            ts = self.t_stop_start_s
            if t_s <= ts:
                return v0 * t_s
            tb = min(t_s - ts, v0 / a)
            return v0 * ts + v0 * tb - 0.5 * a * tb * tb
        return v0 * t_s

    def at_arc_length(self, s_m: float) -> tuple[float, float, float]:
        """(x_m, y_m, theta_rad) at arc length ``s_m`` along the route (straight on beyond its ends)."""
        s, P, H = self._s, self.route_m, self._heading
        if s_m <= s[0]:
            th = H[0]
            return float(P[0, 0] + (s_m - s[0]) * math.cos(th)), float(P[0, 1] + (s_m - s[0]) * math.sin(th)), float(th)
        if s_m >= s[-1]:
            th = H[-1]
            return (float(P[-1, 0] + (s_m - s[-1]) * math.cos(th)), float(P[-1, 1] + (s_m - s[-1]) * math.sin(th)),
                    float(th))
        k = int(np.searchsorted(s, s_m, side="right")) - 1
        w = (s_m - s[k]) / (s[k + 1] - s[k])
        p = (1 - w) * P[k] + w * P[k + 1]
        return float(p[0]), float(p[1]), float((1 - w) * H[k] + w * H[k + 1])

    def pose(self, t_s: float) -> tuple[float, float, float]:
        """(x_m, y_m, theta_rad) at time ``t_s``; theta is the direction of travel from +x, anticlockwise."""
        return self.at_arc_length(self.s0_m + self.distance(t_s))

    def direction(self, t_s: float) -> np.ndarray:
        """Unit vector (2,) of the direction of travel at ``t_s``."""
        th = self.pose(t_s)[2]
        return np.array([math.cos(th), math.sin(th)])

    def matrix(self, t_s: float) -> np.ndarray:
        return vehicle_pose_matrix(*self.pose(t_s))
