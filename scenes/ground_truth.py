"""Exact ground truth from geometry: flow, the camera-induced flow, occlusion, instances.

Nothing here matches images. Each pixel ``(x, y)`` of frame t is a ray
``d = K^-1 (x, y, 1)`` (its z component is 1, so the ray parameter *is* the
depth ``Z``). The rendered depth only says *which* surface a pixel sees; the
point itself comes from the analytic surface where there is one (the ground
plane z = 0, the vehicle boxes), so the flow of the ground is exact up to
float32 rounding of the whole-image arithmetic (about 3e-5 px at 160x120, see
tests/scenes/test_ground_truth.py). Buildings take the rendered depth
(24-bit z-buffer: millimetres at 100 m).

For a point ``X0 = Z d`` in camera t coordinates, with camera-to-world poses
``(R0, C0)``, ``(R1, C1)`` and a rigid world motion ``(M_R, M_t)`` of the point
(identity for the static world, ``M_v(t+1) M_v(t)^-1`` for vehicle v)::

    X1 = R1^T (M_R (R0 X0 + C0) + M_t - C1) = A X0 + b
    x1 = fx X1_x / X1_z + cx,   y1 = fy X1_y / X1_z + cy
    flow = (x1 - x, y1 - y)

A pixel is valid when ``(x1, y1)`` lies in frame t+1 and the point is not
behind what frame t+1 rendered there (z-buffer test with a relative tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from scenes.motion import project
from scenes.world import Box

__all__ = ["PairTruth", "FrameSurface", "GroundTruth"]

# depth agreement between the render and an analytic surface, relative + absolute (metres)
SURFACE_TOL_REL = 2e-3
SURFACE_TOL_ABS_M = 0.02
# occlusion test at t+1: a point may lie this far behind the rendered surface
OCCLUSION_TOL_REL = 5e-3
OCCLUSION_TOL_ABS_M = 0.05


@dataclass(frozen=True)
class PairTruth:
    """Ground truth of the frame pair i -> i+1.

    Attributes
    ----------
    flow : (H, W, 2) float32, px, forward i -> i+1, ``[..., 0] = u`` (+x right), ``[..., 1] = v`` (+y down)
    flow_camera : (H, W, 2) float32, px, the flow if every point were static
    valid : (H, W) bool, in view in i+1 and not occluded there
    instances : (H, W) uint16, vehicle id per pixel of frame i, 0 = static world
    """

    flow: np.ndarray
    flow_camera: np.ndarray
    valid: np.ndarray
    instances: np.ndarray


@dataclass
class FrameSurface:
    """What each pixel of one frame sees.

    Attributes
    ----------
    depth : (H, W) float32, rendered depth along z (0 = nothing)
    Z : (H, W) float32, depth of the visible point (analytic where possible), inf = nothing
    instances : (H, W) uint16, vehicle id (0 = static world)
    R, C : camera-to-world rotation (3, 3) and centre (3,)
    vehicle_M : list of (4, 4) vehicle-to-world matrices at this frame
    vehicle_pixels : list of (vehicle id, rows, cols) of the pixels showing each vehicle
    """

    depth: np.ndarray
    Z: np.ndarray
    instances: np.ndarray
    R: np.ndarray
    C: np.ndarray
    vehicle_M: list
    vehicle_pixels: list


class GroundTruth:
    """Ground-truth computations for one image size, intrinsics and set of vehicle shapes.

    Parameters
    ----------
    K : (3, 3) intrinsics, pixel centres at integer coordinates
    width_px, height_px : image size
    vehicle_boxes : list (one per vehicle, in id order 1..) of lists of :class:`Box` in the vehicle frame
    """

    def __init__(self, K: np.ndarray, width_px: int, height_px: int, vehicle_boxes: list[list[Box]]):
        self.K = np.asarray(K, np.float64)
        self.w, self.h = int(width_px), int(height_px)
        self.fx, self.fy, self.cx, self.cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        xs = np.arange(self.w, dtype=np.float64)
        ys = np.arange(self.h, dtype=np.float64)
        self.xn = (xs - self.cx) / self.fx  # (W,) ray x per column
        self.yn = (ys - self.cy) / self.fy  # (H,) ray y per row
        self.xn32, self.yn32 = self.xn.astype(np.float32), self.yn.astype(np.float32)
        self.xs32, self.ys32 = xs.astype(np.float32), ys.astype(np.float32)
        self.vehicle_boxes = vehicle_boxes
        corners = []
        for boxes in vehicle_boxes:
            pts = []
            for b in boxes:
                c, hs = np.asarray(b.centre), np.asarray(b.size) / 2
                for sx in (-1, 1):
                    for sy in (-1, 1):
                        for sz in (-1, 1):
                            pts.append(c + hs * (sx, sy, sz))
            corners.append(np.asarray(pts))
        self.vehicle_corners = corners  # per vehicle (16, 3) in its own frame

    # -- per frame ----------------------------------------------------------------------
    def _affine_field(self, a: float, b: float, c: float) -> np.ndarray:
        """``a xn + b yn + c`` over the image, (H, W) float32 (a ray component is affine in pixels)."""
        return (np.float32(a) * self.xn32)[None, :] + (np.float32(b) * self.yn32 + np.float32(c))[:, None]

    def vehicle_bboxes(self, R: np.ndarray, C: np.ndarray, vehicle_M: list) -> list:
        """Projected bbox (x0, y0, x1, y1) and centre (x, y) per vehicle, NaN when behind the camera."""
        out = []
        for corners, M in zip(self.vehicle_corners, vehicle_M):
            Xw = corners @ M[:3, :3].T + M[:3, 3]
            p, z = project(self.K, R, C, Xw)
            centre_w = M[:3, :3] @ corners.mean(axis=0) + M[:3, 3]
            pc, zc = project(self.K, R, C, centre_w)
            if (z <= 0).any() or zc <= 0:
                out.append(((np.nan,) * 4, (np.nan, np.nan)))
            else:
                out.append(((p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max()), (pc[0], pc[1])))
        return out

    def surface(self, depth: np.ndarray, R: np.ndarray, C: np.ndarray, vehicle_M: list) -> FrameSurface:
        """Classify the pixels of a rendered frame and give each its exact depth."""
        D = np.asarray(depth, np.float32)
        # ground z = 0: Z = C_z / (g . d) with g = R^T (0, 0, -1) the world's down in camera axes
        g = -R[2, :]
        gd = self._affine_field(g[0], g[1], g[2])
        Zg = np.full_like(gd, np.inf)
        np.divide(np.float32(C[2]), gd, out=Zg, where=gd > 0)
        tol = D * np.float32(SURFACE_TOL_REL)
        tol += np.float32(SURFACE_TOL_ABS_M)
        Z = np.where(np.abs(D - Zg) <= tol, Zg, D)
        Z[D <= 0] = np.inf
        instances = np.zeros((self.h, self.w), np.uint16)
        best_err = np.full((self.h, self.w), np.inf, np.float32)
        windows = []
        for vid, ((bbox, _), boxes, M) in enumerate(
                zip(self.vehicle_bboxes(R, C, vehicle_M), self.vehicle_boxes, vehicle_M), start=1):
            x0, y0, x1, y1 = bbox
            if not np.isfinite(x0):
                continue
            c0, c1 = max(0, int(np.floor(x0))), min(self.w, int(np.ceil(x1)) + 1)
            r0, r1 = max(0, int(np.floor(y0))), min(self.h, int(np.ceil(y1)) + 1)
            if c0 >= c1 or r0 >= r1:
                continue
            Zv = self._ray_boxes(R, C, M, boxes, r0, r1, c0, c1).astype(np.float32)
            Dw = D[r0:r1, c0:c1]
            err = np.abs(Dw - Zv)
            # where two vehicles claim a pixel, the one whose surface agrees better with the render wins
            hit = ((err <= SURFACE_TOL_REL * Dw + SURFACE_TOL_ABS_M) & (Dw > 0)
                   & (err < best_err[r0:r1, c0:c1]))
            instances[r0:r1, c0:c1][hit] = vid
            Z[r0:r1, c0:c1][hit] = Zv[hit]
            best_err[r0:r1, c0:c1][hit] = err[hit]
            windows.append((vid, r0, r1, c0, c1))
        pixels = []
        for vid, r0, r1, c0, c1 in windows:
            rows, cols = np.nonzero(instances[r0:r1, c0:c1] == vid)
            if rows.size:
                pixels.append((vid, rows + r0, cols + c0))
        return FrameSurface(depth=D, Z=Z, instances=instances, R=R, C=C, vehicle_M=vehicle_M,
                            vehicle_pixels=pixels)

    def _ray_boxes(self, R, C, M, boxes, r0, r1, c0, c1) -> np.ndarray:
        """Depth of the nearest hit of each pixel ray in the window with the vehicle's boxes (slab method)."""
        Minv_R = M[:3, :3].T
        o = Minv_R @ (C - M[:3, 3])  # camera centre in the vehicle frame
        A = Minv_R @ R  # camera axes -> vehicle axes
        xn = self.xn[c0:c1][None, :]
        yn = self.yn[r0:r1][:, None]
        r = [A[k, 0] * xn + A[k, 1] * yn + A[k, 2] for k in range(3)]  # ray directions, local
        best = np.full((r1 - r0, c1 - c0), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for b in boxes:
                c, hs = np.asarray(b.centre), np.asarray(b.size) / 2
                t_near = np.full_like(best, -np.inf)
                t_far = np.full_like(best, np.inf)
                for k in range(3):
                    ta = (c[k] - hs[k] - o[k]) / r[k]
                    tb = (c[k] + hs[k] - o[k]) / r[k]
                    t_near = np.maximum(t_near, np.minimum(ta, tb))
                    t_far = np.minimum(t_far, np.maximum(ta, tb))
                hit = (t_near <= t_far) & (t_near > 0)
                best = np.where(hit & (t_near < best), t_near, best)
        return best

    # -- per pair -----------------------------------------------------------------------
    def _project_affine(self, Z: np.ndarray, A: np.ndarray, b: np.ndarray, rows=None, cols=None):
        """Pixel coordinates and depth in frame t+1 of ``X1 = A (Z d) + b`` (d the pixel rays).

        Whole image (float32, in place) when ``rows`` is None, else the listed pixels (float64).
        """
        if rows is None:
            X = self._affine_field(A[0, 0], A[0, 1], A[0, 2])
            Y = self._affine_field(A[1, 0], A[1, 1], A[1, 2])
            W = self._affine_field(A[2, 0], A[2, 1], A[2, 2])
            for F, bk in ((X, b[0]), (Y, b[1]), (W, b[2])):
                F *= Z
                F += np.float32(bk)
            inv = np.float32(1.0) / W
            X *= inv
            X *= np.float32(self.fx)
            X += np.float32(self.cx)
            Y *= inv
            Y *= np.float32(self.fy)
            Y += np.float32(self.cy)
            return X, Y, W
        xn, yn = self.xn[cols], self.yn[rows]
        Zd = Z.astype(np.float64)
        X = Zd * (A[0, 0] * xn + A[0, 1] * yn + A[0, 2]) + b[0]
        Y = Zd * (A[1, 0] * xn + A[1, 1] * yn + A[1, 2]) + b[1]
        W = Zd * (A[2, 0] * xn + A[2, 1] * yn + A[2, 2]) + b[2]
        return self.fx * X / W + self.cx, self.fy * Y / W + self.cy, W

    def pair(self, s0: FrameSurface, s1: FrameSurface) -> tuple[PairTruth, tuple[float, float]]:
        """Ground truth of the pair (s0 -> s1) and the global shift (dx, dy) in px (NaN if no static pixel)."""
        R0, C0, R1, C1 = s0.R, s0.C, s1.R, s1.C
        A = R1.T @ R0
        b = R1.T @ (C0 - C1)
        sky = ~np.isfinite(s0.Z)
        has_sky = bool(sky.any())
        Z = np.where(sky, np.float32(1.0), s0.Z) if has_sky else s0.Z
        x1, y1, Z1 = self._project_affine(Z, A, b)
        flow_cam = np.empty((self.h, self.w, 2), np.float32)
        np.subtract(x1, self.xs32[None, :], out=flow_cam[..., 0])
        np.subtract(y1, self.ys32[:, None], out=flow_cam[..., 1])
        flow = flow_cam.copy()
        for vid, rows, cols in s0.vehicle_pixels:
            M0, M1 = s0.vehicle_M[vid - 1], s1.vehicle_M[vid - 1]
            Mrel = M1 @ np.linalg.inv(M0)
            Av = R1.T @ Mrel[:3, :3] @ R0
            bv = R1.T @ (Mrel[:3, :3] @ C0 + Mrel[:3, 3] - C1)
            xv, yv, zv = self._project_affine(s0.Z[rows, cols], Av, bv, rows=rows, cols=cols)
            flow[rows, cols, 0] = xv - cols
            flow[rows, cols, 1] = yv - rows
            x1[rows, cols], y1[rows, cols], Z1[rows, cols] = xv, yv, zv
        inside = (x1 >= 0) & (x1 <= self.w - 1) & (y1 >= 0) & (y1 <= self.h - 1) & (Z1 > 0)
        if has_sky:
            inside &= ~sky
        D1 = cv2.remap(s1.depth, x1, y1, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        # not occluded: the point is not behind what frame t+1 rendered where it lands
        limit = D1 * np.float32(1 + OCCLUSION_TOL_REL)
        limit += np.float32(OCCLUSION_TOL_ABS_M)
        valid = inside & (D1 > 0) & (Z1 <= limit)
        if has_sky:
            flow[sky] = 0.0
            flow_cam[sky] = 0.0
        static = valid & (s0.instances == 0)
        n_static = int(np.count_nonzero(static))
        if n_static:
            m = cv2.mean(flow_cam, mask=static.view(np.uint8))
            shift = (float(m[0]), float(m[1]))
        else:
            shift = (float("nan"), float("nan"))
        truth = PairTruth(flow=flow, flow_camera=flow_cam, valid=valid, instances=s0.instances)
        return truth, shift
