"""Generate a sequence in memory: frames, ground truth per pair, camera and track tables.

:class:`SceneGenerator` streams: it holds at most two frames' surfaces, so long
sequences stay within a few frames of memory. :mod:`scenes.sequence` writes
what it yields.

The sensor (:mod:`scenes.sensor`) shapes how a frame is rendered: without a rolling
shutter or lens distortion one render (or the mean of the motion-blur sub-frame renders)
of the image, with the pinhole truth of :class:`GroundTruth`; with either, the
undistorted canvas is rendered band by band, each band at its own time, and
:class:`BandedGroundTruth` gives the truth per band and on the distorted grid.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from scenes.ground_truth import (
    BandedGroundTruth,
    FrameSurface,
    GroundTruth,
    PairTruth,
    canvas_in_image,
    clip_box_to_image,
)
from scenes.motion import camera_path
from scenes.render import SceneRenderer
from scenes.sensor import (
    Compressor,
    LensGeometry,
    add_noise,
    apply_haze,
    band_edges,
    band_times_s,
    pose_at,
    subframe_offsets_s,
)
from scenes.spec import SceneSpec
from scenes.traffic import max_height_m, place_traffic, vehicle_shape
from scenes.world import build_world, place_vehicles

__all__ = ["SceneGenerator", "FrameOutput", "CAMERA_COLUMNS", "TRACK_COLUMNS"]

CAMERA_COLUMNS = ["frame", "t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz", "fx_px", "fy_px", "cx_px",
                  "cy_px", "jitter_x_px", "jitter_y_px", "global_dx_px", "global_dy_px", "k1", "k2",
                  "line_delay_s", "exposure_s"]
TRACK_COLUMNS = ["frame", "vehicle_id", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                 "bbox_y1_px", "visible", "speed_mps", "parked", "class", "visible_fraction"]


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
    rgb: np.ndarray  # (H, W, 3) uint8, after the sensor
    instances: np.ndarray  # (H, W) uint16
    pair_index: int | None  # i - 1 when `pair` is the truth of (i - 1) -> i
    pair: PairTruth | None


def _only(bboxes: list, seen: set[int]) -> list:
    """``bboxes`` with those of the vehicles not in ``seen`` (ids from 1) made NaN: the visible fraction
    of a road user the frame does not show is 0 in tracks.csv whatever it computes, and its pass over the
    pixels of its box (out of view: pixels that are not there) is skipped."""
    nan = ((np.nan,) * 4, (np.nan, np.nan))
    return [b if vid in seen else nan for vid, b in enumerate(bboxes, start=1)]


class SceneGenerator:
    """Build the world of ``spec`` and stream its frames and ground truth.

    Random streams (independent, from ``numpy.random.SeedSequence(spec.seed)``):
    jitter, world texture and layout, vehicles, sensor noise. Changing the number
    of vehicles therefore does not change the jitter or the ground.
    """

    def __init__(self, spec: SceneSpec):
        self.spec = spec
        ss = np.random.SeedSequence(spec.seed)
        # the fifth stream (traffic) is new: the first four are what they were with spawn(4)
        rng_jitter, rng_world, rng_vehicles, rng_noise, rng_traffic = (np.random.Generator(np.random.PCG64(s))
                                                                       for s in ss.spawn(5))
        self.rng_noise = rng_noise
        img = spec.image
        self.path = camera_path(spec, rng_jitter)
        self.world = build_world(spec, self.path, rng_world)
        self.vehicles = place_vehicles(spec, self.world, self.path, rng_vehicles)
        self.vehicles += place_traffic(spec, self.world, self.path, rng_traffic, first_id=len(self.vehicles) + 1)
        top_m = self.world.top_m
        lowest_m = float(self.path.C[:, 2].min())
        tallest_m = max([spec.vehicles.height_m] + [max_height_m()] * bool(len(self.vehicles) > spec.vehicles.count))
        znear = max(0.1, 0.5 * (lowest_m - max(top_m, tallest_m)))
        zfar = 20.0 * float(self.path.C[:, 2].max()) + 10.0
        sensor = spec.sensor
        boxes = [vehicle_shape(v) for v in self.vehicles]
        self.truth = GroundTruth(self.path.K, img.width_px, img.height_px, boxes)
        self.lens = (LensGeometry.build(self.path.K, img.width_px, img.height_px, k1=sensor.lens.k1,
                                        k2=sensor.lens.k2) if sensor.lens.k1 or sensor.lens.k2 else None)
        self.rolling = sensor.rolling_shutter.line_delay_s > 0
        self.banded = self.rolling or self.lens is not None
        self.subframe_offsets_s = subframe_offsets_s(sensor.motion_blur.exposure_s, sensor.motion_blur.subframes)
        view = None
        if self.banded:
            self.canvas_K = self.lens.canvas_K if self.lens is not None else self.path.K
            canvas_w, canvas_h = self.lens.canvas_size_px if self.lens is not None else (img.width_px,
                                                                                        img.height_px)
            rows = sensor.rolling_shutter.band_rows if self.rolling else canvas_h
            self.edges = band_edges(canvas_h, min(rows, canvas_h))
            view = (canvas_w, int(np.diff(self.edges).max()))
            self.canvas_truth = GroundTruth(self.canvas_K, canvas_w, canvas_h, boxes)  # visible fractions
            # the canvas pixels the lens maps into the image: a vehicle's share is counted there, not on the
            # whole canvas (which reaches beyond the image's border)
            self.canvas_in_image = (canvas_in_image(self.lens, img.width_px, img.height_px)
                                    if self.lens is not None else None)
            self.banded_truth = BandedGroundTruth(self.canvas_K, img.width_px, img.height_px, self.edges, boxes,
                                                  lens=self.lens)
        self.renderer = SceneRenderer(spec, self.world, self.vehicles, self.path.K, znear_m=znear, zfar_m=zfar,
                                      view_size_px=view)
        self.global_shift_px = np.full((img.n_frames, 2), np.nan)
        self.track_rows: list[tuple] = []

    def vehicle_matrices(self, t_s: float) -> list[np.ndarray]:
        return [v.matrix(t_s) for v in self.vehicles]

    def pose_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Camera pose (R camera-to-world, C) at any time (the frame poses at frame times)."""
        return pose_at(self.path.t_s, self.path.R, self.path.C, t_s)

    def _exposure_times_s(self, i: int) -> np.ndarray:
        """Read time of each band of frame i (one band, the frame time, without a rolling shutter)."""
        t = float(self.path.t_s[i])
        if not self.rolling:
            return np.full(len(self.edges) - 1 if self.banded else 1, t)
        return band_times_s(t, self.edges, cy_px=float(self.canvas_K[1, 2]),
                            line_delay_s=self.spec.sensor.rolling_shutter.line_delay_s)

    def _expose(self, render, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
        """Light collected over the exposure centred on ``t_s``: the mean of the sub-frame renders.

        Returns rgb (uint8 for one render, float32 for a mean), the depth and pose of the
        middle render (at ``t_s``: the truth's instant) and the vehicle matrices then. Under sun
        light with shadow maps the frame's first render draws the map, the others reuse it
        (``_fresh_shadow_map``): moving shadows are where the vehicles were at that render,
        under 1 px away at ``realistic``'s exposure and read-out (14 ms, 28 m/s at most, 0.22 m a px).
        """
        acc = None
        for offset in self.subframe_offsets_s:
            t = t_s + float(offset)
            R, C = self.pose_at(t)
            Ms = self.vehicle_matrices(t)
            rgb, depth = render(R, C, Ms, shadow_map=self._fresh_shadow_map, depth=offset == 0)
            self._fresh_shadow_map = False
            if offset == 0:
                mid = (depth, R, C, Ms)
            if len(self.subframe_offsets_s) == 1:
                return (rgb, *mid)
            acc = rgb.astype(np.float32) if acc is None else acc + rgb
        return (acc * np.float32(1.0 / len(self.subframe_offsets_s)), *mid)

    def _light(self, rgb: np.ndarray, depth: np.ndarray, t_s: float, K: np.ndarray) -> np.ndarray:
        """Illumination gain and haze on the (canvas) render; float32 out, or the input when both are off."""
        drift, haze = self.spec.light.illumination_drift_per_s, self.spec.sensor.haze
        if drift == 0 and haze.extinction_per_km == 0:
            return rgb
        img = rgb.astype(np.float32)
        if drift != 0:
            img *= np.float32(1.0 + drift * t_s)
        if haze.extinction_per_km > 0:
            h, w = depth.shape
            xn = (np.arange(w, dtype=np.float32) - np.float32(K[0, 2])) / np.float32(K[0, 0])
            yn = (np.arange(h, dtype=np.float32) - np.float32(K[1, 2])) / np.float32(K[1, 1])
            # distance along the line of sight = z depth * |(xn, yn, 1)|; nothing rendered = infinitely far
            distance = np.where(depth > 0, depth, np.float32(np.inf)) * np.sqrt(
                np.float32(1.0) + xn[None, :] ** 2 + yn[:, None] ** 2)
            apply_haze(img, distance, extinction_per_km=haze.extinction_per_km, airlight=haze.airlight)
        return img

    def _lens_and_sensor(self, img: np.ndarray) -> np.ndarray:
        """Distortion, optics blur, noise, 8 bits, compression: the frame as stored."""
        sensor = self.spec.sensor
        if self.lens is not None:
            img = self.lens.resample(img)
        if sensor.lens.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), sensor.lens.blur_sigma_px,
                                   borderType=cv2.BORDER_REFLECT)
        noise = sensor.noise
        if noise.gaussian_std > 0 or noise.full_well_e > 0:
            img = add_noise(img.astype(np.float32), self.rng_noise, gaussian_std=noise.gaussian_std,
                            full_well_e=noise.full_well_e)
        if img.dtype != np.uint8:
            img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if self.compressor is not None:
            img = self.compressor(img)
        return img

    def render_frame(self, i: int) -> tuple[np.ndarray, FrameSurface]:
        """Render frame i with the pinhole global shutter: light (before lens and sensor) and its surfaces."""
        if self.banded:
            raise RuntimeError("render_frame: this spec has a rolling shutter or lens distortion; use frames()")
        t = float(self.path.t_s[i])
        self._fresh_shadow_map = True
        rgb, depth, R, C, Ms = self._expose(self.renderer.render, t)
        surf = self.truth.surface(depth, R, C, Ms)
        return self._light(rgb, depth, t, self.path.K), surf

    def render_banded_frame(self, i: int):
        """Render frame i band by band on the canvas: light (before lens and sensor) and its :class:`BandedSurface`."""
        K = self.canvas_K
        times = self._exposure_times_s(i)
        canvas_h = int(self.edges[-1])
        rgb = depth = None
        Rs, Cs, Ms_per_band = [], [], []
        self._fresh_shadow_map = True
        for b, t_b in enumerate(times):
            r0, r1 = int(self.edges[b]), int(self.edges[b + 1])

            def render(R, C, Ms, *, shadow_map, depth, r0=r0):
                return self.renderer.render_view(R, C, Ms, cx_px=float(K[0, 2]), cy_px=float(K[1, 2]) - r0,
                                                 shadow_map=shadow_map, depth=depth)

            band_rgb, band_depth, R, C, Ms = self._expose(render, float(t_b))
            if rgb is None:
                rgb = np.empty((canvas_h, band_rgb.shape[1], 3), band_rgb.dtype)
                depth = np.empty((canvas_h, band_depth.shape[1]), np.float32)
            rgb[r0:r1] = band_rgb[:r1 - r0]
            depth[r0:r1] = band_depth[:r1 - r0]
            Rs.append(R)
            Cs.append(C)
            Ms_per_band.append(Ms)
        surf = self.banded_truth.surface(depth, np.asarray(Rs), np.asarray(Cs), Ms_per_band)
        return self._light(rgb, depth, float(self.path.t_s[i]), K), surf

    def _tracks(self, i: int, surf) -> None:
        """The rows of tracks.csv of frame i, as an annotator would box the frame (docs/architecture.md).

        The box is the vehicle's projected box clipped to the image (:func:`clip_box_to_image`;
        NaN when none of it is in the image); ``x_px, y_px`` stay the projected centre of the
        whole vehicle (its position, perhaps outside the image); ``visible_fraction`` is the
        share of the vehicle's whole projected area that the image shows unoccluded.
        """
        t = float(self.path.t_s[i])
        w, h = self.spec.image.width_px, self.spec.image.height_px
        if self.banded:
            counts = np.bincount(surf.instances.ravel(), minlength=len(self.vehicles) + 1)
            seen = {vid for vid in range(1, len(self.vehicles) + 1) if counts[vid] > 0}
            boxes = self.banded_truth.vehicle_bboxes(surf)
            # on the undistorted canvas at the frame time (the middle band's pose): under a rolling
            # shutter and a lens this share is approximate (the lens scales pixel areas a little)
            b = len(surf.RT) // 2
            R, C = surf.RT[b].T, surf.C[b]
            Ms = [np.vstack([surf.T[vid, b], [0.0, 0.0, 0.0, 1.0]]) for vid in range(1, len(self.vehicles) + 1)]
            canvas_truth = self.canvas_truth
            vis = canvas_truth.visible_fractions(surf.depth, R, C, Ms, _only(canvas_truth.vehicle_bboxes(R, C, Ms),
                                                                              seen), in_view=self.canvas_in_image)
        else:  # the surface listed each vehicle's pixels and projected its box already
            seen = {vid for vid, _, _ in surf.vehicle_pixels}
            boxes = surf.vehicle_bboxes
            vis = self.truth.visible_fractions(surf.depth, surf.R, surf.C, surf.vehicle_M, _only(boxes, seen))
        for vid, (v, (bbox, centre)) in enumerate(zip(self.vehicles, boxes), start=1):
            self.track_rows.append((i, vid, centre[0], centre[1], *clip_box_to_image(bbox, w, h), int(vid in seen),
                                    v.speed(t), int(v.parked), v.vclass, float(vis[vid - 1]) if vid in seen else 0.0))

    def frames(self) -> Iterator[FrameOutput]:
        """Yield every frame in order, each with the truth of the pair ending at it."""
        img, comp = self.spec.image, self.spec.sensor.compression
        self.compressor = None
        if comp.codec != "none":
            self.compressor = Compressor(comp.codec, width_px=img.width_px, height_px=img.height_px, fps=img.fps,
                                         jpeg_quality=comp.jpeg_quality, h264_crf=comp.h264_crf,
                                         h264_gop=comp.h264_gop)
        truth = self.banded_truth if self.banded else self.truth
        prev = None
        for i in range(img.n_frames):
            light, surf = self.render_banded_frame(i) if self.banded else self.render_frame(i)
            self._tracks(i, surf)
            pair = None
            if prev is not None:
                pair, shift = truth.pair(prev, surf)
                self.global_shift_px[i - 1] = shift
            yield FrameOutput(index=i, rgb=self._lens_and_sensor(light), instances=surf.instances,
                              pair_index=None if prev is None else i - 1, pair=pair)
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
                         "global_dy_px": None if last else float(self.global_shift_px[i, 1]),
                         **self._sensor_columns()})
        return rows

    def _sensor_columns(self) -> dict:
        s = self.spec.sensor
        return {"k1": s.lens.k1, "k2": s.lens.k2, "line_delay_s": s.rolling_shutter.line_delay_s,
                "exposure_s": s.motion_blur.exposure_s}

    def sensor_meta(self) -> dict:
        """What a reader needs to use the frames' geometry: distortion, readout and exposure (meta.json)."""
        s = self.spec.sensor
        return {**self._sensor_columns(),
                "band_rows": s.rolling_shutter.band_rows if self.rolling else None,
                "subframes": len(self.subframe_offsets_s),
                "distortion_model": "brown-conrady radial: x_d = x_n (1 + k1 r^2 + k2 r^4), normalised by K",
                "row_time": "t_frame + (y - cy) * line_delay_s, y the undistorted row, in bands of band_rows",
                "truth_time": "frame time (mid-exposure) to frame time; per band under a rolling shutter"}

    def track_table(self) -> list[dict]:
        return [dict(zip(TRACK_COLUMNS, r)) for r in self.track_rows]
