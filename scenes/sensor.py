"""The camera's sensor: what happens to the rendered light before it becomes a frame.

The effects, in the order they are applied (each off at its spec default):

1. exposure in time, at render (:mod:`scenes.generate`): **rolling shutter** (row ``y``
   is read at ``t + (y - cy) * line_delay_s``, rendered in bands of rows, each band at its
   centre time) and **motion blur** (the mean of ``subframes`` renders evenly spread over
   ``exposure_s``, centred on the frame or band time);
2. illumination gain (brightness drift, a property of the light);
3. **haze**: ``I = J t + A (1 - t)``, ``t = exp(-beta * distance)`` (Koschmieder);
4. **lens distortion**: Brown-Conrady radial ``x_d = x_u (1 + k1 r^2 + k2 r^4)`` on normalised
   coordinates, the distorted image resampled from an undistorted render, then the optics'
   Gaussian **blur**;
5. **noise**: Poisson shot noise on ``full_well_e`` photo-electrons at gray 255 (Gaussian with the
   same mean and variance above 100 electrons), then
   Gaussian read noise, then rounding to 8 bits;
6. **compression** through a real encoder: JPEG (OpenCV) or H.264 (libx264 through PyAV).

Ground truth convention: the motion field of the surfaces between the frame times
(mid-exposure to mid-exposure); under a rolling shutter each pixel's point is taken at its
band's time in both frames, and under distortion flow and masks live on the distorted
pixel grid: ``flow_d(p_d) = D(U(p_d) + flow_u(U(p_d))) - p_d``. Haze, noise, blur and
compression leave the truth unchanged.

Everything here is a pure function of arrays except :class:`Compressor`, which holds
the encoder state of a video stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "distort_normalised",
    "undistort_normalised",
    "LensGeometry",
    "band_edges",
    "band_of_rows",
    "band_times_s",
    "subframe_offsets_s",
    "pose_at",
    "apply_haze",
    "add_noise",
    "Compressor",
    "EncoderUnavailableError",
    "VIDEO_EXTRA",
]

VIDEO_EXTRA = "aerobench[video]"
UNDISTORT_ITERATIONS = 20


class EncoderUnavailableError(RuntimeError):
    """The H.264 encoder (PyAV with libx264) is missing; the message names the pip extra."""


# -- lens distortion -------------------------------------------------------------------------

def distort_normalised(xn: np.ndarray, yn: np.ndarray, *, k1: float, k2: float) -> tuple[np.ndarray, np.ndarray]:
    """Brown-Conrady radial distortion of normalised image coordinates.

    ``x_d = x (1 + k1 r^2 + k2 r^4)``, ``r^2 = x^2 + y^2`` (Brown 1966, radial terms only).

    Parameters
    ----------
    xn, yn : ndarray, same shape, float
        Undistorted normalised coordinates ``((x - cx) / fx, (y - cy) / fy)``.
    k1, k2 : float
        Radial coefficients.

    Returns
    -------
    (xd, yd) : ndarrays of the same shape, distorted normalised coordinates.
    """
    r2 = xn * xn + yn * yn
    g = 1.0 + r2 * (k1 + k2 * r2)
    return xn * g, yn * g


def undistort_normalised(xd: np.ndarray, yd: np.ndarray, *, k1: float, k2: float,
                         iterations: int = UNDISTORT_ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort_normalised` by Newton's method on the radius.

    Solves ``r (1 + k1 r^2 + k2 r^4) = r_d`` for each point (``r_d`` its distorted radius);
    the spec check (``SceneSpec``) guarantees a single root up to the image corner.

    Returns
    -------
    (xn, yn) : undistorted normalised coordinates, float64, same shape as the input.
    """
    xd = np.asarray(xd, np.float64)
    yd = np.asarray(yd, np.float64)
    rd = np.hypot(xd, yd)
    r = rd.copy()
    for _ in range(iterations):
        r2 = r * r
        f = r * (1.0 + r2 * (k1 + k2 * r2)) - rd
        df = 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2)
        r -= f / df
    scale = np.divide(r, rd, out=np.ones_like(rd), where=rd > 0)
    return xd * scale, yd * scale


@dataclass(frozen=True)
class LensGeometry:
    """Where each pixel of the output (distorted) image looks in the undistorted render.

    The render is a *canvas* larger than the image by ``margin_px`` on each side when
    barrel distortion pulls content in from outside the pinhole view.

    Attributes
    ----------
    K : (3, 3) float64, intrinsics of the output image (pixel centres at integers)
    k1, k2 : radial coefficients
    width_px, height_px : output image size
    margin_px : int, canvas border on each side
    canvas_x, canvas_y : (H, W) float32, canvas coordinates of ``U(p_d)`` for each output pixel
    """

    K: np.ndarray
    k1: float
    k2: float
    width_px: int
    height_px: int
    margin_px: int
    canvas_x: np.ndarray
    canvas_y: np.ndarray

    @classmethod
    def build(cls, K: np.ndarray, width_px: int, height_px: int, *, k1: float, k2: float) -> "LensGeometry":
        K = np.asarray(K, np.float64)
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        ys, xs = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
        xu, yu = undistort_normalised((xs - cx) / fx, (ys - cy) / fy, k1=k1, k2=k2)
        px, py = fx * xu + cx, fy * yu + cy
        overhang = max(-px.min(), px.max() - (width_px - 1), -py.min(), py.max() - (height_px - 1))
        margin = int(math.ceil(overhang)) + 1 if overhang > 0 else 0
        return cls(K=K, k1=float(k1), k2=float(k2), width_px=int(width_px), height_px=int(height_px),
                   margin_px=margin, canvas_x=(px + margin).astype(np.float32),
                   canvas_y=(py + margin).astype(np.float32))

    @property
    def canvas_size_px(self) -> tuple[int, int]:
        """(width, height) of the undistorted render."""
        return self.width_px + 2 * self.margin_px, self.height_px + 2 * self.margin_px

    @property
    def canvas_K(self) -> np.ndarray:
        K = self.K.copy()
        K[0, 2] += self.margin_px
        K[1, 2] += self.margin_px
        return K

    def distort_canvas_px(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output-image coordinates of undistorted canvas coordinates (any shape, float64)."""
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        m = self.margin_px
        xd, yd = distort_normalised((x - m - cx) / fx, (y - m - cy) / fy, k1=self.k1, k2=self.k2)
        return fx * xd + cx, fy * yd + cy

    def resample(self, canvas: np.ndarray, *, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """The distorted image from an undistorted canvas (bilinear by default)."""
        return cv2.remap(canvas, self.canvas_x, self.canvas_y, interpolation=interpolation,
                         borderMode=cv2.BORDER_REPLICATE)


# -- time: rolling-shutter bands, exposure sub-frames, poses between frames -----------------

def band_edges(height_px: int, band_rows: int) -> np.ndarray:
    """First row of each band and the end: ``(n_bands + 1,)`` int, 0 .. height_px."""
    if band_rows < 1:
        raise ValueError(f"band_rows: expected >= 1, got {band_rows}")
    return np.append(np.arange(0, height_px, band_rows), height_px).astype(np.int64)


def band_of_rows(y: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Band index of continuous row coordinates (the band of the nearest pixel row), clipped to the bands."""
    rows = np.floor(np.asarray(y, np.float64) + 0.5)
    return np.clip(np.searchsorted(edges, rows, side="right") - 1, 0, len(edges) - 2)


def band_times_s(frame_t_s: float, edges: np.ndarray, *, cy_px: float, line_delay_s: float) -> np.ndarray:
    """Read time of each band: its centre row's ``t + (y - cy) * line_delay_s``, ``(n_bands,)`` float64."""
    centres = 0.5 * (edges[:-1] + edges[1:] - 1)
    return frame_t_s + (centres - cy_px) * line_delay_s


def subframe_offsets_s(exposure_s: float, n: int) -> np.ndarray:
    """Times of ``n`` renders (odd) spread evenly over the exposure, relative to its centre."""
    if exposure_s == 0:
        return np.zeros(1)
    return exposure_s * ((np.arange(n) + 0.5) / n - 0.5)


def _rotation_power(R: np.ndarray, s: float) -> np.ndarray:
    """``R^s`` for a rotation (axis-angle scaled by s)."""
    rvec, _ = cv2.Rodrigues(np.asarray(R, np.float64))
    out, _ = cv2.Rodrigues(rvec * s)
    return out


def pose_at(t_frames_s: np.ndarray, R: np.ndarray, C: np.ndarray, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose at any time: linear in the centre, slerp in rotation between the frame poses.

    Outside the frame times the first or last interval is extended. At a frame time
    the frame's own pose is returned exactly.

    Parameters
    ----------
    t_frames_s : (N,) float64, increasing frame times, N >= 2
    R : (N, 3, 3) camera-to-world rotations; C : (N, 3) camera centres, metres
    t_s : the time wanted

    Returns
    -------
    (R (3, 3), C (3,)) float64
    """
    n = len(t_frames_s)
    k = int(np.clip(np.searchsorted(t_frames_s, t_s, side="right") - 1, 0, n - 2))
    s = (t_s - t_frames_s[k]) / (t_frames_s[k + 1] - t_frames_s[k])
    if s == 0.0:
        return R[k].copy(), C[k].copy()
    if s == 1.0:
        return R[k + 1].copy(), C[k + 1].copy()
    R_s = R[k] @ _rotation_power(R[k].T @ R[k + 1], s)
    return R_s, C[k] + s * (C[k + 1] - C[k])


# -- appearance: haze, noise, compression ------------------------------------------------

def apply_haze(img: np.ndarray, distance_m: np.ndarray, *, extinction_per_km: float, airlight: float) -> np.ndarray:
    """Koschmieder's law: ``I = J t + A (1 - t)``, ``t = exp(-beta d)``.

    Parameters
    ----------
    img : (H, W, 3) float32, gray levels 0..255 (J, modified in place)
    distance_m : (H, W) float32, metres along the line of sight; inf (nothing rendered) gives t = 0
    extinction_per_km : beta, per km; airlight : A, gray level

    Returns
    -------
    img, (H, W, 3) float32
    """
    if img.ndim != 3 or img.shape[:2] != distance_m.shape:
        raise ValueError(f"apply_haze: expected img (H, W, 3) and distance (H, W), got {img.shape} and "
                         f"{distance_m.shape}")
    t = np.exp(np.float32(-extinction_per_km / 1000.0) * distance_m.astype(np.float32))
    img *= t[..., None]
    img += (np.float32(airlight) * (1.0 - t))[..., None]
    return img


POISSON_EXACT_BELOW_E = 100.0


def add_noise(img: np.ndarray, rng: np.random.Generator, *, gaussian_std: float, full_well_e: float) -> np.ndarray:
    """Shot noise then read noise on gray levels (float32, 0..255, modified in place).

    Shot noise: ``n_e ~ Poisson(lambda)``, ``lambda = I / 255 * full_well_e``, ``I = n_e * 255 /
    full_well_e`` (0 = off); drawn exactly where ``lambda < POISSON_EXACT_BELOW_E`` and as
    ``N(lambda, lambda)`` above, the same mean and variance (the Poisson law's skewness there is
    ``lambda^-1/2 < 0.1``, and one electron is under 0.1 gray level at a full well of 4000), drawn
    with the read noise as one Gaussian of variance ``I 255 / full_well_e + gaussian_std^2``:
    about four times cheaper than numpy's Poisson sampler on a bright frame. Read noise:
    ``+ N(0, gaussian_std^2)`` gray levels (0 = off).
    """
    if full_well_e > 0:
        scale = np.float32(full_well_e / 255.0)
        signal = np.clip(img, 0, None)
        dark = signal * scale < POISSON_EXACT_BELOW_E
        # bright: shot and read noise in one Gaussian draw, variance I / scale + read^2 (gray levels)
        std = signal * np.float32(1.0 / scale)
        std += np.float32(gaussian_std) ** 2
        np.sqrt(std, out=std)
        noise = rng.standard_normal(img.shape, dtype=np.float32)
        noise *= std
        img[...] = signal + noise
        if dark.any():
            electrons = rng.poisson(signal[dark].astype(np.float64) * float(scale))
            read = rng.standard_normal(electrons.shape, dtype=np.float32) * np.float32(gaussian_std)
            img[dark] = (electrons / float(scale)).astype(np.float32) + read
        return img
    if gaussian_std > 0:
        img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(gaussian_std)
    return img


def _import_av():
    try:
        import av
    except ImportError as err:
        raise EncoderUnavailableError(
            f"sensor.compression.codec 'h264' needs PyAV with libx264: pip install '{VIDEO_EXTRA}' "
            f"(or pip install av) ({err})") from None
    if "libx264" not in av.codecs_available:
        raise EncoderUnavailableError(
            f"sensor.compression.codec 'h264': this PyAV {av.__version__} has no libx264 encoder; "
            f"reinstall it from the wheel: pip install --force-reinstall '{VIDEO_EXTRA}'")
    return av


class Compressor:
    """Lossy coding of a stream of frames: each frame goes through the encoder and back.

    ``codec`` is ``"jpeg"`` (each frame alone, ``cv2.imencode`` at ``jpeg_quality``) or
    ``"h264"`` (one x264 stream: ``crf``, key frame every ``gop`` frames, no B-frames and
    zero-latency tuning so each frame comes back as soon as it is sent; one thread, so
    the bytes do not depend on the machine).

    Raises
    ------
    EncoderUnavailableError
        ``h264`` without PyAV / libx264 (the message names the pip extra).
    """

    def __init__(self, codec: str, *, width_px: int, height_px: int, fps: float, jpeg_quality: int = 75,
                 h264_crf: int = 23, h264_gop: int = 30):
        if codec not in ("jpeg", "h264"):
            raise ValueError(f"codec: expected 'jpeg' or 'h264', got {codec!r}")
        self.codec = codec
        self.jpeg_quality = int(jpeg_quality)
        self.width_px, self.height_px = int(width_px), int(height_px)
        if codec == "h264":
            av = _import_av()
            from fractions import Fraction

            enc = av.CodecContext.create("libx264", "w")
            enc.width, enc.height = self.width_px, self.height_px
            enc.pix_fmt = "yuv420p"
            enc.time_base = Fraction(1, 1000)
            enc.framerate = Fraction(fps).limit_denominator(1000)
            enc.gop_size = int(h264_gop)
            enc.max_b_frames = 0
            enc.thread_count = 1
            enc.options = {"crf": str(int(h264_crf)), "preset": "veryfast", "tune": "zerolatency",
                           "threads": "1", "keyint": str(int(h264_gop)), "min-keyint": str(int(h264_gop)),
                           "scenecut": "0"}
            self._av = av
            self._enc = enc
            self._dec = av.CodecContext.create("h264", "r")
            self._dec.thread_count = 1
            self._pts = 0
            self._frame_ms = 1000.0 / fps

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """The frame as the decoder sees it: (H, W, 3) uint8 RGB in, (H, W, 3) uint8 RGB out."""
        if rgb.dtype != np.uint8 or rgb.shape != (self.height_px, self.width_px, 3):
            raise ValueError(f"Compressor: expected ({self.height_px}, {self.width_px}, 3) uint8, "
                             f"got {rgb.shape} {rgb.dtype}")
        if self.codec == "jpeg":
            ok, data = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                                    [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality])
            if not ok:
                raise RuntimeError("cv2.imencode('.jpg') failed")
            return cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        frame = self._av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
        frame = frame.reformat(format="yuv420p")
        frame.pts = int(round(self._pts * self._frame_ms))
        self._pts += 1
        out = []
        for packet in self._enc.encode(frame):
            out.extend(self._dec.decode(packet))
        if len(out) != 1:
            raise RuntimeError(f"H.264 round trip gave {len(out)} frames for one (encoder latency); "
                               "expected exactly one")
        return out[0].to_ndarray(format="rgb24")
