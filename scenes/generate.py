"""Generate a sequence in memory: frames, ground truth per pair, camera and track tables.

:class:`SceneGenerator` streams: it holds at most two frames' surfaces, so long
sequences stay within a few frames of memory. :mod:`scenes.sequence` writes
what it yields.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from scenes.ground_truth import FrameSurface, GroundTruth, PairTruth
from scenes.motion import camera_path
from scenes.render import SceneRenderer
from scenes.spec import SceneSpec
from scenes.world import build_world, place_vehicles, vehicle_boxes

__all__ = ["SceneGenerator", "FrameOutput", "CAMERA_COLUMNS", "TRACK_COLUMNS"]

CAMERA_COLUMNS = ["frame", "t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz", "fx_px", "fy_px", "cx_px",
                  "cy_px", "jitter_x_px", "jitter_y_px", "global_dx_px", "global_dy_px"]
TRACK_COLUMNS = ["frame", "vehicle_id", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                 "bbox_y1_px", "visible", "speed_mps", "parked"]


def rotation_to_quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    """(qw, qx, qy, qz) of a rotation matrix, qw >= 0 (Shepperd's method)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = (0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s)
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = ((R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s)
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = ((R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s)
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = ((R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s)
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    return tuple(float(v) for v in q)


@dataclass
class FrameOutput:
    """One generated frame, and the truth of the pair that ends at it (None for frame 0)."""

    index: int
    rgb: np.ndarray  # (H, W, 3) uint8, after photometry
    instances: np.ndarray  # (H, W) uint16
    pair_index: int | None  # i - 1 when `pair` is the truth of (i - 1) -> i
    pair: PairTruth | None


class SceneGenerator:
    """Build the world of ``spec`` and stream its frames and ground truth.

    Random streams (independent, from ``numpy.random.SeedSequence(spec.seed)``):
    jitter, world texture and layout, vehicles, sensor noise. Changing the number
    of vehicles therefore does not change the jitter or the ground.
    """

    def __init__(self, spec: SceneSpec):
        self.spec = spec
        ss = np.random.SeedSequence(spec.seed)
        rng_jitter, rng_world, rng_vehicles, rng_noise = (np.random.Generator(np.random.PCG64(s))
                                                            for s in ss.spawn(4))
        self.rng_noise = rng_noise
        img = spec.image
        self.path = camera_path(spec, rng_jitter)
        self.world = build_world(spec, self.path, rng_world)
        self.vehicles = place_vehicles(spec, self.world, self.path, rng_vehicles)
        top_m = self.world.top_m
        lowest_m = float(self.path.C[:, 2].min())
        znear = max(0.1, 0.5 * (lowest_m - max(top_m, spec.vehicles.height_m)))
        zfar = 20.0 * float(self.path.C[:, 2].max()) + 10.0
        self.renderer = SceneRenderer(spec, self.world, self.vehicles, self.path.K, znear_m=znear, zfar_m=zfar)
        self.truth = GroundTruth(self.path.K, img.width_px, img.height_px,
                                 [vehicle_boxes(*v.size_m) for v in self.vehicles])
        self.global_shift_px = np.full((img.n_frames, 2), np.nan)
        self.track_rows: list[tuple] = []

    def vehicle_matrices(self, t_s: float) -> list[np.ndarray]:
        return [v.matrix(t_s) for v in self.vehicles]

    def _photometry(self, rgb: np.ndarray, t_s: float) -> np.ndarray:
        ph, drift = self.spec.photometry, self.spec.light.illumination_drift_per_s
        if ph.blur_sigma_px == 0 and ph.noise_std == 0 and drift == 0:
            return rgb
        img = rgb.astype(np.float32)
        if ph.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), ph.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        if drift != 0:
            img *= 1.0 + drift * t_s
        if ph.noise_std > 0:
            img += self.rng_noise.standard_normal(img.shape, dtype=np.float32) * np.float32(ph.noise_std)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def render_frame(self, i: int) -> tuple[np.ndarray, FrameSurface]:
        """Render frame i: clean rgb (before photometry) and its surface analysis."""
        t = float(self.path.t_s[i])
        Ms = self.vehicle_matrices(t)
        R, C = self.path.R[i], self.path.C[i]
        rgb, depth = self.renderer.render(R, C, Ms)
        return rgb, self.truth.surface(depth, R, C, Ms)

    def _tracks(self, i: int, surf: FrameSurface) -> None:
        t = float(self.path.t_s[i])
        counts = np.bincount(surf.instances.ravel(), minlength=len(self.vehicles) + 1)
        boxes = self.truth.vehicle_bboxes(surf.R, surf.C, surf.vehicle_M)
        for vid, (v, (bbox, centre)) in enumerate(zip(self.vehicles, boxes), start=1):
            self.track_rows.append((i, vid, centre[0], centre[1], *bbox, int(counts[vid] > 0),
                                    v.speed(t), int(v.parked)))

    def frames(self) -> Iterator[FrameOutput]:
        """Yield every frame in order, each with the truth of the pair ending at it."""
        prev = None
        for i in range(self.spec.image.n_frames):
            rgb, surf = self.render_frame(i)
            self._tracks(i, surf)
            pair = None
            if prev is not None:
                pair, shift = self.truth.pair(prev, surf)
                self.global_shift_px[i - 1] = shift
            yield FrameOutput(index=i, rgb=self._photometry(rgb, float(self.path.t_s[i])),
                              instances=surf.instances, pair_index=None if prev is None else i - 1, pair=pair)
            prev = surf

    def camera_rows(self) -> list[dict]:
        """Rows of camera.csv (complete after :meth:`frames` ran to the end)."""
        K = self.path.K
        rows = []
        n = self.spec.image.n_frames
        for i in range(n):
            qw, qx, qy, qz = rotation_to_quaternion(self.path.R[i])
            x, y, z = self.path.C[i]
            last = i == n - 1
            rows.append({"frame": i, "t_s": float(self.path.t_s[i]), "x_m": float(x), "y_m": float(y),
                         "z_m": float(z), "qw": qw, "qx": qx, "qy": qy, "qz": qz,
                         "fx_px": float(K[0, 0]), "fy_px": float(K[1, 1]), "cx_px": float(K[0, 2]),
                         "cy_px": float(K[1, 2]), "jitter_x_px": float(self.path.jitter_px[i, 0]),
                         "jitter_y_px": float(self.path.jitter_px[i, 1]),
                         "global_dx_px": None if last else float(self.global_shift_px[i, 0]),
                         "global_dy_px": None if last else float(self.global_shift_px[i, 1])})
        return rows

    def track_table(self) -> list[dict]:
        return [dict(zip(TRACK_COLUMNS, r)) for r in self.track_rows]
