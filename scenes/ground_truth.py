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

:class:`GroundTruth` is the pinhole, global-shutter case (one pose per frame, rays
affine in the pixel). :class:`BandedGroundTruth` is the general one the sensor needs
(see :mod:`scenes.sensor`): a rolling shutter gives each band of rows its own pose
and time, a distorting lens bends each pixel's ray to ``U(p)``; the same equations
are solved per pixel ray, the band a point lands in at t+1 by a fixed point over
bands, and flow, valid and instances are given on the distorted grid.

Cost: the pinhole truth's whole-image passes are numba kernels
(:mod:`scenes._truth_kernels`: ground depth, vehicle windows, projection, validity),
each the float32 operations of the numpy expressions they replaced in the same
order, so the arrays are bit for bit the same (tests/scenes/test_ground_truth.py
keeps the numpy formulas as the reference); about 0.1x the render of a 640x480
frame (benchmarks/render_throughput.py). The first use in a process loads numba
(about 1.5 s, shared with the scoring kernels of :mod:`harness._flow_kernels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from scenes.motion import project
from scenes.world import Box

__all__ = ["PairTruth", "FrameSurface", "GroundTruth", "BandedSurface", "BandedGroundTruth", "ray_boxes_depth",
           "clip_box_to_image", "canvas_in_image"]

# depth agreement between the render and an analytic surface, relative + absolute (metres)
SURFACE_TOL_REL = 2e-3
SURFACE_TOL_ABS_M = 0.02
# occlusion test at t+1: a point may lie this far behind the rendered surface
OCCLUSION_TOL_REL = 5e-3
OCCLUSION_TOL_ABS_M = 0.05
# visible fractions: an occluder is this much nearer than the vehicle's surface (a vehicle's own
# parts differ by less: a car's cabin 0.7 m, a truck's cargo over its cab 0.8 m)
OCCLUDER_GAP_M = 1.0


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
    vehicle_bboxes : per vehicle, its projected bbox (x0, y0, x1, y1) and centre (x, y) in px
        (:meth:`GroundTruth.vehicle_bboxes`; NaN when behind the camera)
    """

    depth: np.ndarray
    Z: np.ndarray
    instances: np.ndarray
    R: np.ndarray
    C: np.ndarray
    vehicle_M: list
    vehicle_pixels: list
    vehicle_bboxes: list


def ray_boxes_depth(R: np.ndarray, C: np.ndarray, M: np.ndarray, boxes: list[Box], xn: np.ndarray,
                    yn: np.ndarray) -> np.ndarray:
    """Depth Z of the nearest hit of the rays ``d = (xn, yn, 1)`` with boxes given in a vehicle's frame.

    Slab method. ``R, C``: camera-to-world rotation (3, 3) and centre (3,); ``M``: vehicle-to-world
    (4, 4); ``xn, yn``: broadcastable arrays of normalised ray components (camera axes).
    Returns float64 of their broadcast shape, inf where no box is hit.
    """
    Minv_R = M[:3, :3].T
    o = Minv_R @ (C - M[:3, 3])  # camera centre in the vehicle frame
    A = Minv_R @ R  # camera axes -> vehicle axes
    r = [A[k, 0] * xn + A[k, 1] * yn + A[k, 2] for k in range(3)]  # ray directions, local
    best = np.full(np.broadcast_shapes(np.shape(xn), np.shape(yn)), np.inf)
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


def clip_box_to_image(bbox, width_px: int, height_px: int) -> tuple[float, float, float, float]:
    """A box ``(x0, y0, x1, y1)`` (continuous, pixel-centre coordinates, px) clipped to the image.

    The image of ``width_px`` x ``height_px`` pixels covers ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``
    in these coordinates (a pixel is its centre +- 0.5; :mod:`harness.metrics.matching` reads a
    detection's inclusive pixel range the same way). A box that does not reach into the image,
    or with a NaN corner, gives four NaN: no box in the image.
    """
    x0, y0, x1, y1 = (float(v) for v in bbox)
    lo_x, lo_y, hi_x, hi_y = -0.5, -0.5, width_px - 0.5, height_px - 0.5
    cx0, cy0, cx1, cy1 = max(x0, lo_x), max(y0, lo_y), min(x1, hi_x), min(y1, hi_y)
    if not (cx0 <= cx1 and cy0 <= cy1):  # NaN compares False too
        return (np.nan,) * 4
    return cx0, cy0, cx1, cy1


def canvas_in_image(lens, width_px: int, height_px: int) -> np.ndarray:
    """(Hc, Wc) bool over a lens's undistorted canvas: the pixel centres the lens maps into the output image
    (``[-0.5, W - 0.5] x [-0.5, H - 0.5]``, as :func:`clip_box_to_image`)."""
    cw, ch = lens.canvas_size_px
    ys, xs = np.mgrid[0:ch, 0:cw].astype(np.float64)
    xd, yd = lens.distort_canvas_px(xs, ys)
    with np.errstate(invalid="ignore"):
        return (xd >= -0.5) & (xd <= width_px - 0.5) & (yd >= -0.5) & (yd <= height_px - 0.5)


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
        self._scratch = None  # x1, y1, Z1, D1 of pair()
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
        self.vehicle_corners = corners  # per vehicle (8 per box, 3) in its own frame
        # per vehicle its corners (padded to the most boxes by repeating its first corner, which
        # changes no bbox) and their mean (the centre), stacked for the batch projection
        n_pts = max((len(c) for c in corners), default=0)
        self._corners = np.array([np.vstack([c, np.repeat(c[:1], n_pts - len(c), axis=0)])
                                  for c in corners]).reshape(len(corners), n_pts, 3)
        self._centres = np.array([c.mean(axis=0) for c in corners]).reshape(len(corners), 3)
        # per vehicle its boxes as corner arrays (B, 3): low c - s/2 and high c + s/2
        self._box_lo, self._box_hi = [], []
        for boxes in vehicle_boxes:
            c = np.array([b.centre for b in boxes], np.float64).reshape(-1, 3)
            hs = np.array([b.size for b in boxes], np.float64).reshape(-1, 3) / 2
            self._box_lo.append(c - hs)
            self._box_hi.append(c + hs)

    # -- per frame ----------------------------------------------------------------------
    def _affine_parts(self, a: float, b: float, c: float) -> tuple[np.ndarray, np.ndarray]:
        """``a xn + b yn + c`` (a ray component is affine in pixels) as a column part (W,) and a row part (H,),
        float32: the field is their sum ``ax[None, :] + ay[:, None]``."""
        return np.float32(a) * self.xn32, np.float32(b) * self.yn32 + np.float32(c)

    def vehicle_bboxes(self, R: np.ndarray, C: np.ndarray, vehicle_M: list) -> list:
        """Projected bbox (x0, y0, x1, y1) and centre (x, y) per vehicle, NaN when behind the camera.

        All vehicles' box corners and centres are moved and projected in one batch.
        """
        if not vehicle_M:
            return []
        M = np.asarray(vehicle_M, np.float64)  # (V, 4, 4)
        Mr = M[:, :3, :3]
        # X_w = M_R X + M_t per corner, and per centre
        Xw = np.matmul(self._corners, Mr.transpose(0, 2, 1)) + M[:, None, :3, 3]
        centre_w = np.matmul(Mr, self._centres[:, :, None])[:, None, :, 0] + M[:, None, :3, 3]
        p, z = project(self.K, R, C, Xw)  # (V, n, 2), (V, n)
        pc, zc = project(self.K, R, C, centre_w)  # (V, 1, 2), (V, 1): a row each, as one point is projected
        pc = pc[:, 0]
        lo, hi = p.min(axis=1), p.max(axis=1)
        behind = (z <= 0).any(axis=1) | (zc[:, 0] <= 0)
        out = []
        for v in range(len(M)):
            if behind[v]:
                out.append(((np.nan,) * 4, (np.nan, np.nan)))
            else:
                out.append(((lo[v, 0], lo[v, 1], hi[v, 0], hi[v, 1]), (pc[v, 0], pc[v, 1])))
        return out

    def surface(self, depth: np.ndarray, R: np.ndarray, C: np.ndarray, vehicle_M: list) -> FrameSurface:
        """Classify the pixels of a rendered frame and give each its exact depth."""
        from scenes._truth_kernels import surface_depth, vehicle_window

        D = np.ascontiguousarray(depth, np.float32)
        rel, abs_m = np.float32(SURFACE_TOL_REL), np.float32(SURFACE_TOL_ABS_M)
        # ground z = 0: Z = C_z / (g . d) with g = R^T (0, 0, -1) the world's down in camera axes
        g = -R[2, :]
        gx, gy = self._affine_parts(g[0], g[1], g[2])
        Z = np.empty((self.h, self.w), np.float32)
        surface_depth(D, gx, gy, np.float32(C[2]), rel, abs_m, Z)
        instances = np.zeros((self.h, self.w), np.uint16)
        bboxes = self.vehicle_bboxes(R, C, vehicle_M)
        pixels = []
        for vid, ((bbox, _), boxes, M) in enumerate(zip(bboxes, self.vehicle_boxes, vehicle_M), start=1):
            x0, y0, x1, y1 = bbox
            if not np.isfinite(x0):
                continue
            c0, c1 = max(0, int(np.floor(x0))), min(self.w, int(np.ceil(x1)) + 1)
            r0, r1 = max(0, int(np.floor(y0))), min(self.h, int(np.ceil(y1)) + 1)
            if c0 >= c1 or r0 >= r1:
                continue
            # the boxes in the vehicle's frame: camera centre o and ray axes A there
            Minv_R = M[:3, :3].T
            o = Minv_R @ (C - M[:3, 3])
            A = Minv_R @ R
            Zv = np.empty((r1 - r0, c1 - c0), np.float32)
            err = np.empty_like(Zv)
            hit = np.empty(Zv.shape, bool)
            if not vehicle_window(D, r0, c0, self.xn[c0:c1], self.yn[r0:r1], A, o, self._box_lo[vid - 1],
                                  self._box_hi[vid - 1], rel, abs_m, Zv, err, hit):
                continue
            # where two vehicles claim a pixel, the one whose surface agrees better with the render wins
            pixels.append([vid, r0, c0, hit, err, Zv])
        if len(pixels) > 1:
            self._resolve_overlaps(pixels)
        out = []
        for vid, r0, c0, hit, _, Zv in pixels:
            rows, cols = np.nonzero(hit)
            if rows.size:
                instances[r0:r0 + hit.shape[0], c0:c0 + hit.shape[1]][hit] = vid
                Z[r0:r0 + hit.shape[0], c0:c0 + hit.shape[1]][hit] = Zv[hit]
                out.append((vid, rows + r0, cols + c0))
        return FrameSurface(depth=D, Z=Z, instances=instances, R=R, C=C, vehicle_M=vehicle_M,
                            vehicle_pixels=out, vehicle_bboxes=bboxes)

    @staticmethod
    def _resolve_overlaps(pixels: list) -> None:
        """Where windows overlap, keep each pixel for the first vehicle of least error (in place).

        The same rule as claiming pixels in id order with a strict ``err < best so far``:
        a later vehicle takes a pixel only with a strictly smaller error, and loses it to a
        still later one the same way.
        """
        for k, (_, ra, ca, hit_a, err_a, _) in enumerate(pixels):
            ha, wa = hit_a.shape
            for _, rb, cb, hit_b, err_b, _ in pixels[k + 1:]:
                hb, wb = hit_b.shape
                r0, r1 = max(ra, rb), min(ra + ha, rb + hb)
                c0, c1 = max(ca, cb), min(ca + wa, cb + wb)
                if r0 >= r1 or c0 >= c1:
                    continue
                sa = (slice(r0 - ra, r1 - ra), slice(c0 - ca, c1 - ca))
                sb = (slice(r0 - rb, r1 - rb), slice(c0 - cb, c1 - cb))
                both = hit_a[sa] & hit_b[sb]
                b_wins = both & (err_b[sb] < err_a[sa])
                hit_a[sa] &= ~b_wins
                hit_b[sb] &= ~(both & ~b_wins)

    def visible_fractions(self, depth: np.ndarray, R: np.ndarray, C: np.ndarray, vehicle_M: list,
                          bboxes: list, *, in_view: np.ndarray | None = None) -> np.ndarray:
        """Per vehicle, the share (V,) float64 of its unoccluded projection that the frame shows.

        The unoccluded projection is every pixel centre, inside the image or not, whose ray hits
        the vehicle's boxes (the vehicle's whole projected area, in pixels); a pixel shows the
        vehicle when it is inside the image (and, with ``in_view``, where that is True) and the
        render has nothing more than OCCLUDER_GAP_M nearer than the box there: a tree crown or a
        bridge deck (both stand higher than that above every road user) or another vehicle in
        front hides it; the render's anti-aliased silhouette (the ground's depth, or the vehicle's
        own cabin a sub-pixel away) does not. 0 where nothing projects (behind the camera, or
        smaller than a pixel between the pixel centres).

        ``in_view``: (H, W) bool over this grid, the pixels that belong to the output image; for
        the undistorted canvas of a lens (larger than the image) the canvas pixels the lens maps
        into the image (:func:`canvas_in_image`). None: the whole grid is the image.
        """
        D = np.asarray(depth, np.float32)
        if in_view is not None and np.shape(in_view) != (self.h, self.w):
            raise ValueError(f"in_view: expected shape {(self.h, self.w)}, got {np.shape(in_view)}")
        out = np.zeros(len(vehicle_M))
        for v, ((bbox, _), boxes, M) in enumerate(zip(bboxes, self.vehicle_boxes, vehicle_M)):
            x0, y0, x1, y1 = bbox
            if not np.isfinite(x0):
                continue
            cols = np.arange(int(np.floor(x0)), int(np.ceil(x1)) + 1)
            rows = np.arange(int(np.floor(y0)), int(np.ceil(y1)) + 1)
            Zv = ray_boxes_depth(R, C, M, boxes, ((cols - self.cx) / self.fx)[None, :],
                                 ((rows - self.cy) / self.fy)[:, None])
            hit = np.isfinite(Zv)
            n = int(hit.sum())
            if not n:
                continue
            inside = ((cols >= 0) & (cols < self.w))[None, :] & ((rows >= 0) & (rows < self.h))[:, None]
            if in_view is not None:
                rc, cc_ = np.clip(rows, 0, self.h - 1), np.clip(cols, 0, self.w - 1)
                inside &= in_view[rc[:, None], cc_[None, :]]
            seen = hit & inside
            rr, cc = np.nonzero(seen)
            d = D[rows[rr], cols[cc]].astype(np.float64)
            z = Zv[rr, cc]
            front = (d > 0) & (d < z - OCCLUDER_GAP_M)
            out[v] = (rr.size - int(front.sum())) / n
        return out

    # -- per pair -----------------------------------------------------------------------
    def _project_affine(self, Z: np.ndarray, A: np.ndarray, b: np.ndarray, rows: np.ndarray, cols: np.ndarray):
        """Pixel coordinates and depth in frame t+1 of ``X1 = A (Z d) + b`` for the listed pixels (float64)."""
        xn, yn = self.xn[cols], self.yn[rows]
        Zd = Z.astype(np.float64)
        X = Zd * (A[0, 0] * xn + A[0, 1] * yn + A[0, 2]) + b[0]
        Y = Zd * (A[1, 0] * xn + A[1, 1] * yn + A[1, 2]) + b[1]
        W = Zd * (A[2, 0] * xn + A[2, 1] * yn + A[2, 2]) + b[2]
        return self.fx * X / W + self.cx, self.fy * Y / W + self.cy, W

    def pair(self, s0: FrameSurface, s1: FrameSurface) -> tuple[PairTruth, tuple[float, float]]:
        """Ground truth of the pair (s0 -> s1) and the global shift (dx, dy) in px (NaN if no static pixel).

        The whole-image passes run in :mod:`scenes._truth_kernels` (float32, the operations of
        the equations in the module docstring in their order); the vehicles' pixels in float64.
        """
        from scenes._truth_kernels import project_static, valid_and_shift

        R0, C0, R1, C1 = s0.R, s0.C, s1.R, s1.C
        A = R1.T @ R0
        b = R1.T @ (C0 - C1)
        h, w = self.h, self.w
        parts = [self._affine_parts(A[k, 0], A[k, 1], A[k, 2]) for k in range(3)]
        ax = np.stack([p[0] for p in parts])
        ay = np.stack([p[1] for p in parts])
        # scratch of this object, reused pair after pair: fresh arrays would each cost their pages'
        # faults (~1 ms a 640x480 float32 array); what is returned is fresh
        if self._scratch is None:
            self._scratch = tuple(np.empty((h, w), np.float32) for _ in range(4))
        x1, y1, Z1, D1 = self._scratch
        flow_cam = np.empty((h, w, 2), np.float32)
        # sky (Z = inf) is projected as if at depth 1 and made invalid below
        project_static(s0.Z, ax, ay, b.astype(np.float32), np.float32(self.fx), np.float32(self.fy),
                       np.float32(self.cx), np.float32(self.cy), self.xs32, self.ys32, x1, y1, Z1, flow_cam)
        flow = flow_cam.copy()  # the static world's; the vehicles' pixels are overwritten
        for vid, rows, cols in s0.vehicle_pixels:
            M0, M1 = s0.vehicle_M[vid - 1], s1.vehicle_M[vid - 1]
            Mrel = M1 @ np.linalg.inv(M0)
            Av = R1.T @ Mrel[:3, :3] @ R0
            bv = R1.T @ (Mrel[:3, :3] @ C0 + Mrel[:3, 3] - C1)
            xv, yv, zv = self._project_affine(s0.Z[rows, cols], Av, bv, rows, cols)
            flow[rows, cols, 0] = xv - cols
            flow[rows, cols, 1] = yv - rows
            x1[rows, cols], y1[rows, cols], Z1[rows, cols] = xv, yv, zv
        cv2.remap(s1.depth, x1, y1, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE, dst=D1)
        # valid: in frame t+1, in front of its camera, and not behind what it rendered there
        # (Z1 <= D1 (1 + tol) + tol_abs); sky: never valid, flow 0
        valid = np.empty((h, w), bool)
        sums = np.zeros(3)
        valid_and_shift(s0.Z, x1, y1, Z1, D1, s0.instances, np.float32(w - 1), np.float32(h - 1),
                        np.float32(1 + OCCLUSION_TOL_REL), np.float32(OCCLUSION_TOL_ABS_M), flow, flow_cam,
                        valid, sums)
        n_static = int(sums[2])
        # the mean as cv2.mean has it (the sums in pixel order, times 1 / n), so the figures are bit for bit theirs
        shift = ((float(sums[0] * (1.0 / n_static)), float(sums[1] * (1.0 / n_static))) if n_static
                 else (float("nan"), float("nan")))
        truth = PairTruth(flow=flow, flow_camera=flow_cam, valid=valid, instances=s0.instances)
        return truth, shift


# -- rolling shutter and lens distortion: per-band poses, bent rays ----------------------------

# fixed-point iterations for the band a point lands in (rolling shutter); 2-3 suffice when a
# band moves less than its height between frames
MAX_BAND_ITERATIONS = 8
# a vehicle's pixels look along rays inside its projected box on the canvas: one whose box stays this far
# (canvas px, a margin for rounding only) from every ray of a band has no pixel there
REACH_MARGIN_PX = 2.0


@dataclass
class BandedSurface:
    """What each output pixel sees when every band of rows has its own pose and rays may be bent.

    Attributes
    ----------
    instances : (H, W) uint16, vehicle id (0 = static world)
    points : (H*W, 3) float64, the seen point in its owner's frame: world (static) or vehicle (id > 0)
    world_points : (H*W, 3) float64, the seen point in the world at the pixel's time (0 where sky)
    ids : (H*W,) int64, ``instances`` flattened
    band : (H*W,) int64, the band each pixel was exposed in
    sky : (H*W,) bool, nothing rendered
    depth : (Hc, Wc) float32, the stitched render depth of the canvas (0 = nothing)
    RT : (B, 3, 3) world-to-camera rotation of each band; C : (B, 3) camera centres
    T : (V + 1, B, 3, 4) object-to-world transform of each object at each band's time (0: identity)
    """

    instances: np.ndarray
    points: np.ndarray
    world_points: np.ndarray
    ids: np.ndarray
    band: np.ndarray
    sky: np.ndarray
    depth: np.ndarray
    RT: np.ndarray
    C: np.ndarray
    T: np.ndarray


class BandedGroundTruth:
    """Exact truth for a rolling shutter (one pose per band of rows) and a distorting lens.

    The renders form an undistorted *canvas* (the image itself without distortion); band
    ``b`` covers canvas rows ``edges[b] .. edges[b+1]`` and was rendered at one pose. Output
    pixel ``p`` looks along the canvas ray at ``U(p)`` (``lens.canvas_x/y``; the pixel grid
    itself without a lens) from the pose of the band of its nearest canvas row. A point seen
    in frame t lands in frame t+1 where its projection with band ``b``'s pose falls in band
    ``b`` (fixed-point iteration over bands; no consistent band = not visible, invalid), and
    its flow is ``D(x_{t+1}) - p``.

    Parameters
    ----------
    K : (3, 3) intrinsics of the canvas
    width_px, height_px : output image size
    edges : (B + 1,) first canvas row of each band, then the canvas height
    vehicle_boxes : per vehicle, its boxes in its own frame
    lens : :class:`scenes.sensor.LensGeometry` or None (no distortion: canvas = image)
    """

    def __init__(self, K: np.ndarray, width_px: int, height_px: int, edges: np.ndarray,
                 vehicle_boxes: list[list[Box]], lens=None):
        from scenes.sensor import band_of_rows

        self.K = np.asarray(K, np.float64)
        self.fx, self.fy, self.cx, self.cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        self.w, self.h = int(width_px), int(height_px)
        self.edges = np.asarray(edges, np.int64)
        self.n_bands = len(self.edges) - 1
        self.lens = lens
        self.vehicle_boxes = vehicle_boxes
        self.corner_truth = GroundTruth(K, width_px, height_px, vehicle_boxes)  # vehicle corners
        ys, xs = np.mgrid[0:self.h, 0:self.w].astype(np.float64)
        self.px, self.py = xs.ravel(), ys.ravel()
        if lens is None:
            cxs, cys = self.px, self.py
            self.canvas_w, self.canvas_h = self.w, self.h
        else:
            cxs, cys = lens.canvas_x.ravel().astype(np.float64), lens.canvas_y.ravel().astype(np.float64)
            self.canvas_w, self.canvas_h = lens.canvas_size_px
        self.rays = np.stack([(cxs - self.cx) / self.fx, (cys - self.cy) / self.fy, np.ones_like(cxs)], axis=1)
        self.ray_len = np.linalg.norm(self.rays, axis=1)
        self.nearest = (np.clip(np.rint(cys), 0, self.canvas_h - 1).astype(np.int64) * self.canvas_w
                        + np.clip(np.rint(cxs), 0, self.canvas_w - 1).astype(np.int64))
        self.band = band_of_rows(cys, self.edges)
        self.band_pixels = []  # per band: (its pixel indices, the same as a slice when contiguous)
        # per band the canvas extent (x0, y0, x1, y1) of its pixels' rays: a vehicle whose projected
        # box misses it cannot be seen in that band, and its per-pixel pass is skipped
        self.band_reach = np.full((self.n_bands, 4), np.nan)
        for b in range(self.n_bands):
            idx = np.nonzero(self.band == b)[0]
            contiguous = idx.size and idx[-1] - idx[0] + 1 == idx.size
            self.band_pixels.append((idx, slice(int(idx[0]), int(idx[-1]) + 1) if contiguous else idx))
            if idx.size:
                self.band_reach[b] = (cxs[idx].min(), cys[idx].min(), cxs[idx].max(), cys[idx].max())

    def _transforms(self, vehicle_M_per_band: list[list[np.ndarray]]) -> np.ndarray:
        n_v = len(self.vehicle_boxes)
        T = np.zeros((n_v + 1, self.n_bands, 3, 4))
        T[0, :, :, :3] = np.eye(3)
        for b, Ms in enumerate(vehicle_M_per_band):
            for v, M in enumerate(Ms, start=1):
                T[v, b] = M[:3, :]
        return T

    def surface(self, depth: np.ndarray, R: np.ndarray, C: np.ndarray,
                vehicle_M_per_band: list[list[np.ndarray]]) -> BandedSurface:
        """Classify every output pixel and find its point.

        Parameters
        ----------
        depth : (Hc, Wc) float32, the canvas depth stitched from the band renders (0 = nothing)
        R : (B, 3, 3), C : (B, 3) camera-to-world pose of each band
        vehicle_M_per_band : per band, the vehicle-to-world (4, 4) matrices at its time
        """
        D = np.asarray(depth, np.float32).ravel()[self.nearest].astype(np.float64)
        n = self.w * self.h
        ids = np.zeros(n, np.int64)
        Z = np.full(n, np.inf)
        for b, (idx, take) in enumerate(self.band_pixels):
            if not idx.size:
                continue
            # ground z = 0: Z = C_z / (g . d), g = R^T (0, 0, -1) the world's down in camera axes
            gd = self.rays[take] @ (-R[b][2, :])
            Zg = np.full(idx.size, np.inf)
            np.divide(C[b][2], gd, out=Zg, where=gd > 0)
            Db = D[take]
            Z[take] = np.where(np.abs(Db - Zg) <= SURFACE_TOL_REL * Db + SURFACE_TOL_ABS_M, Zg, Db)
        Z[D <= 0] = np.inf
        best_err = np.full(n, np.inf)
        for b, (idx, _) in enumerate(self.band_pixels):
            if not idx.size:
                continue
            Ms = vehicle_M_per_band[b]
            for vid in self._reaching(R[b], C[b], Ms, b):
                boxes, M = self.vehicle_boxes[vid - 1], Ms[vid - 1]
                cand = self._window(R[b], C[b], M, b)
                if cand is None:
                    continue
                Zv = ray_boxes_depth(R[b], C[b], M, boxes, self.rays[cand, 0], self.rays[cand, 1])
                Dn = D[cand]
                err = np.abs(Dn - Zv)
                # where two vehicles claim a pixel, the one whose surface agrees better with the render wins
                hit = (err <= SURFACE_TOL_REL * Dn + SURFACE_TOL_ABS_M) & (Dn > 0) & (err < best_err[cand])
                ids[cand[hit]] = vid
                Z[cand[hit]] = Zv[hit]
                best_err[cand[hit]] = err[hit]
        sky = ~np.isfinite(Z)
        Z[sky] = 0.0
        world = np.empty((n, 3))
        for b, (idx, take) in enumerate(self.band_pixels):
            if idx.size:
                world[take] = C[b] + (Z[take, None] * self.rays[take]) @ R[b].T  # X_w = C + R (Z d)
        T = self._transforms(vehicle_M_per_band)
        points = world.copy()
        sel = np.nonzero(ids > 0)[0]  # every vehicle pixel at once: each row is its own vehicle's transform
        if sel.size:
            Tb = T[ids[sel], self.band[sel]]  # (m, 3, 4) of each pixel's vehicle at its band's time
            # X_local = M_R^T (X_w - M_t)
            points[sel] = np.einsum("nji,nj->ni", Tb[:, :, :3], world[sel] - Tb[:, :, 3])
        RT = np.transpose(np.asarray(R, np.float64), (0, 2, 1))
        return BandedSurface(instances=ids.reshape(self.h, self.w).astype(np.uint16), points=points,
                             world_points=world, ids=ids, band=self.band.copy(), sky=sky,
                             depth=np.asarray(depth, np.float32), RT=RT, C=np.asarray(C, np.float64), T=T)

    def _reaching(self, R: np.ndarray, C: np.ndarray, vehicle_M: list, band: int) -> list[int]:
        """Ids (from 1, ascending) of the vehicles whose projected box, one batch for all, comes within
        ``REACH_MARGIN_PX`` of the canvas extent of ``band``'s rays (behind the camera: left out, as
        :meth:`_window` leaves them). A vehicle's pixels all lie in its box, so the others have none in
        the band: skipping them changes nothing but the cost (a road user out of view, or in another band).
        """
        if not vehicle_M:
            return []
        boxes = np.array([bbox for bbox, _ in self.corner_truth.vehicle_bboxes(R, C, vehicle_M)], np.float64)
        x0, y0, x1, y1 = self.band_reach[band]
        m = REACH_MARGIN_PX
        with np.errstate(invalid="ignore"):
            near = ((boxes[:, 2] >= x0 - m) & (boxes[:, 0] <= x1 + m)
                    & (boxes[:, 3] >= y0 - m) & (boxes[:, 1] <= y1 + m))
        return [int(v) + 1 for v in np.nonzero(near)[0]]

    def _window(self, R: np.ndarray, C: np.ndarray, M: np.ndarray, band: int) -> np.ndarray | None:
        """Output pixels of ``band`` that may see the vehicle at ``M``: its projected box, distorted."""
        (x0, y0, x1, y1), _ = self.corner_truth.vehicle_bboxes(R, C, [M])[0]
        if not np.isfinite(x0):
            return None
        x0, y0, x1, y1 = x0 - 1, y0 - 1, x1 + 1, y1 + 1
        if self.lens is not None:
            # a radial distortion maps the box's outline around the image of the box
            t = np.linspace(0.0, 1.0, 16)
            bx = np.concatenate([x0 + (x1 - x0) * t, np.full(16, x1), x1 - (x1 - x0) * t, np.full(16, x0)])
            by = np.concatenate([np.full(16, y0), y0 + (y1 - y0) * t, np.full(16, y1), y1 - (y1 - y0) * t])
            bx, by = self.lens.distort_canvas_px(bx, by)
            x0, x1, y0, y1 = bx.min() - 1, bx.max() + 1, by.min() - 1, by.max() + 1
        c0, c1 = max(0, int(np.floor(x0))), min(self.w, int(np.ceil(x1)) + 1)
        r0, r1 = max(0, int(np.floor(y0))), min(self.h, int(np.ceil(y1)) + 1)
        if c0 >= c1 or r0 >= r1:
            return None
        cand = (np.arange(r0, r1)[:, None] * self.w + np.arange(c0, c1)[None, :]).ravel()
        cand = cand[self.band[cand] == band]
        return cand if cand.size else None

    def project(self, points: np.ndarray, ids: np.ndarray, s: BandedSurface,
                band_init: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Where object points appear in the canvas of frame ``s``: the band whose pose sees them in it.

        Returns canvas ``x, y``, depth ``z`` along the band camera's axis (float64) and
        ``converged`` (bool): the point's projection with band b's pose lies in band b.
        """
        from scenes.sensor import band_of_rows

        n = len(points)
        x, y, z = np.empty(n), np.empty(n), np.empty(n)
        ok = np.zeros(n, bool)
        b = np.asarray(band_init, np.int64).copy()
        todo = np.arange(n)
        static = not np.any(ids)
        # X_c = R^T (X_w - C) = [R^T | -R^T C] (X_w, 1), one (3, 4) matrix per band
        P = np.concatenate([s.RT, -np.einsum("bij,bj->bi", s.RT, s.C)[:, :, None]], axis=2).reshape(-1, 12)
        for _ in range(MAX_BAND_ITERATIONS):
            bt = b[todo]
            if static:  # the world does not move: X_w = points
                W = points if todo.size == n else points[todo]
            else:
                Tm = s.T[ids[todo], bt]
                W = np.einsum("nij,nj->ni", Tm[:, :, :3], points[todo]) + Tm[:, :, 3]
            if len(P) > 1 and W.shape[0] > 64 * len(P):
                # many points (the whole image): band by band with the band's matrix as scalars, the same
                # float64 operations per point as the gather below, without a (n, 12) copy of it
                Xc = [np.empty(W.shape[0]) for _ in range(3)]
                order = np.argsort(bt, kind="stable")
                starts = np.searchsorted(bt[order], np.arange(len(P) + 1))
                for band in range(len(P)):
                    sel = order[starts[band]:starts[band + 1]]
                    if not sel.size:
                        continue
                    Wb, pb = W[sel], P[band]
                    for k in range(3):
                        Xc[k][sel] = pb[4 * k] * Wb[:, 0] + pb[4 * k + 1] * Wb[:, 1] + pb[4 * k + 2] * Wb[:, 2] \
                            + pb[4 * k + 3]
            else:
                Pb = P[bt] if len(P) > 1 else P  # one band (a lens, no rolling shutter): no gather
                Xc = [Pb[:, 4 * k] * W[:, 0] + Pb[:, 4 * k + 1] * W[:, 1] + Pb[:, 4 * k + 2] * W[:, 2]
                      + Pb[:, 4 * k + 3] for k in range(3)]
            zz = Xc[2]
            with np.errstate(divide="ignore", invalid="ignore"):
                xx = self.fx * Xc[0] / zz + self.cx
                yy = self.fy * Xc[1] / zz + self.cy
            x[todo], y[todo], z[todo] = xx, yy, zz
            new = band_of_rows(np.where(zz > 0, yy, 0.0), self.edges)
            same = new == bt
            ok[todo[same]] = True
            b[todo[~same]] = new[~same]
            todo = todo[~same]
            if not todo.size:
                break
        return x, y, z, ok

    def _to_output(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.lens is None:
            return x, y
        return self.lens.distort_canvas_px(x, y)

    def pair(self, s0: BandedSurface, s1: BandedSurface) -> tuple[PairTruth, tuple[float, float]]:
        """Ground truth of the pair (s0 -> s1) on the output grid, and the global shift (NaN if none)."""
        statics = np.zeros_like(s0.ids)
        x, y, z, ok = self.project(s0.world_points, statics, s1, s0.band)
        moving = np.nonzero(s0.ids > 0)[0]
        xv, yv, zv, okv = self.project(s0.points[moving], s0.ids[moving], s1, s0.band[moving])
        xd_cam, yd_cam = self._to_output(x, y)
        flow_cam = np.stack([xd_cam - self.px, yd_cam - self.py], axis=1)
        x[moving], y[moving], z[moving], ok[moving] = xv, yv, zv, okv
        xd, yd = self._to_output(x, y)
        flow = np.stack([xd - self.px, yd - self.py], axis=1)
        with np.errstate(invalid="ignore"):
            inside = (xd >= 0) & (xd <= self.w - 1) & (yd >= 0) & (yd <= self.h - 1) & (z > 0) & ok & ~s0.sky
        xs = np.where(inside, x, -1).astype(np.float32).reshape(self.h, self.w)
        ys = np.where(inside, y, -1).astype(np.float32).reshape(self.h, self.w)
        D1 = cv2.remap(s1.depth, xs, ys, interpolation=cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE).ravel().astype(np.float64)
        # not occluded: the point is not behind what frame t+1 rendered where it lands
        valid = inside & (D1 > 0) & (z <= D1 * (1 + OCCLUSION_TOL_REL) + OCCLUSION_TOL_ABS_M)
        flow[s0.sky] = 0.0
        flow_cam[s0.sky] = 0.0
        flow = flow.astype(np.float32).reshape(self.h, self.w, 2)
        flow_cam = flow_cam.astype(np.float32).reshape(self.h, self.w, 2)
        valid = valid.reshape(self.h, self.w)
        static = valid & (s0.instances == 0)
        if static.any():
            m = cv2.mean(flow_cam, mask=static.view(np.uint8))
            shift = (float(m[0]), float(m[1]))
        else:
            shift = (float("nan"), float("nan"))
        return PairTruth(flow=flow, flow_camera=flow_cam, valid=valid, instances=s0.instances), shift

    def vehicle_bboxes(self, s: BandedSurface) -> list:
        """Bbox (x0, y0, x1, y1) and centre (x, y) of each vehicle in the output image, as exposed.

        The box corners and the centre are placed by the same band fixed point as the flow
        (the last iterate where a point has no consistent band), then distorted; NaN when
        behind the camera.
        """
        corners = self.corner_truth.vehicle_corners
        if not corners:
            return []
        # every vehicle's corners and centre in one batch: each point's fixed point is its own
        pts = np.vstack([np.vstack([c, c.mean(axis=0)]) for c in corners])
        ids = np.repeat(np.arange(1, len(corners) + 1), [len(c) + 1 for c in corners])
        x, y, z, _ = self.project(pts, ids, s, np.full(len(pts), self.n_bands // 2))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # behind the camera: NaN below
            xd, yd = self._to_output(x, y)
        out = []
        ends = np.cumsum([len(c) + 1 for c in corners])
        for end, c in zip(ends, corners):
            k = slice(end - len(c) - 1, end - 1)  # the corners; the centre at end - 1
            if (z[end - len(c) - 1:end] <= 0).any():
                out.append(((np.nan,) * 4, (np.nan, np.nan)))
                continue
            out.append(((xd[k].min(), yd[k].min(), xd[k].max(), yd[k].max()), (xd[end - 1], yd[end - 1])))
        return out
