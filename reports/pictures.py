"""Flow pictures for the report: frame, ground truth, each method's flow, endpoint-error maps.

Pictures become files of the run folder (:func:`picture_file`): a picture wider than it is shown
(:data:`DISPLAY_WIDTH_PX`) is downscaled to that width (area averaging) and stored as lossy WebP;
one no wider is stored as it is, lossless PNG, and enlarged by the browser pixel by pixel. Both
encoders (OpenCV's) are deterministic, and a file is named by its content, so the same pictures
give the same files. :func:`png_data_uri` and :func:`webp_data_uri` embed a picture where a file cannot be
referenced (the frame inside the trajectories figure, itself a file).
"""

from __future__ import annotations

import base64
import functools
import hashlib
from dataclasses import dataclass

import cv2
import numpy as np
from matplotlib import colormaps

from algorithms.flow import color_wheel_image, flow_to_color
from harness.metrics import endpoint_error

__all__ = ["NO_TRUTH_RGB", "DISPLAY_WIDTH_PX", "WEBP_QUALITY", "PictureFile", "picture_file", "png_bytes",
           "png_data_uri", "webp_data_uri", "row_max_magnitude", "flow_row", "epe_map", "epe_colorbar", "wheel_legend",
           "display_scale", "upscale_nearest", "mask_image", "swatch"]

_EPE_CMAP = "magma"
_EPE_N = colormaps[_EPE_CMAP].N
# pixels without ground truth in an error map: teal, a hue the magma map never takes (its zero is black)
NO_TRUTH_RGB = (0, 160, 160)


# the widest a gallery picture is shown (report.css: columns of at least 260 px in a 1180 px page hold
# 4 columns of about 280 px; under 600 px, 2 columns): pictures are stored at most this wide
DISPLAY_WIDTH_PX = 320
# WebP quality of downscaled pictures: flow colours and error maps within a few levels of the PNG's,
# a tenth of its bytes (640 x 480 -> 320 x 240 flow pictures: 5 kB against 47 kB at PNG level 9)
WEBP_QUALITY = 90


@dataclass(frozen=True)
class PictureFile:
    """An encoded picture: its file name (content hash and extension), bytes and stored size."""

    name: str
    data: bytes
    width_px: int
    height_px: int


def _named(data: bytes, ext: str, width_px: int, height_px: int) -> PictureFile:
    return PictureFile(f"{hashlib.sha1(data).hexdigest()[:16]}.{ext}", data, width_px, height_px)


def picture_file(rgb: np.ndarray, *, max_width_px: int = DISPLAY_WIDTH_PX) -> PictureFile:
    """``rgb`` (uint8 (H, W, 3) or (H, W)) as a file to show at most ``max_width_px`` wide.

    Wider: area-averaged down to ``max_width_px`` (height in proportion, at least 1) and
    encoded as WebP at :data:`WEBP_QUALITY`. Otherwise: lossless PNG of the pixels as they are.
    """
    a = np.ascontiguousarray(rgb)
    if a.dtype != np.uint8 or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        raise ValueError(f"image: expected uint8 (H, W, 3) or (H, W), got {a.dtype} {a.shape}")
    if max_width_px < 1:
        raise ValueError(f"max_width_px: expected a positive width, got {max_width_px}")
    h, w = a.shape[:2]
    if w <= max_width_px:
        return _named(png_bytes(a), "png", w, h)
    size = (max_width_px, max(1, round(h * max_width_px / w)))
    small = cv2.resize(a, size, interpolation=cv2.INTER_AREA)
    if small.ndim == 3:
        small = cv2.cvtColor(small, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".webp", small, [cv2.IMWRITE_WEBP_QUALITY, WEBP_QUALITY])
    if not ok:
        raise ValueError("image: WebP encoding failed")
    return _named(buf.tobytes(), "webp", *size)


def png_bytes(rgb: np.ndarray) -> bytes:
    """PNG bytes of a uint8 RGB or gray image (lossless)."""
    a = np.ascontiguousarray(rgb)
    if a.dtype != np.uint8:
        raise ValueError(f"image: expected uint8, got {a.dtype}")
    if a.ndim == 3:
        a = cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
    # zlib's run-length strategy after PNG's adaptive row filters: flow and error maps are smooth, so the
    # filtered rows are mostly runs; as small as the default strategy at level 6, a third of its CPU time
    ok, buf = cv2.imencode(".png", a, [cv2.IMWRITE_PNG_COMPRESSION, 1,
                                       cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE])
    if not ok:
        raise ValueError("image: PNG encoding failed")
    return buf.tobytes()


def png_data_uri(rgb: np.ndarray) -> str:
    """``data:image/png;base64,...`` of a uint8 RGB or gray image."""
    return "data:image/png;base64," + base64.b64encode(png_bytes(rgb)).decode("ascii")


def webp_data_uri(rgb: np.ndarray) -> str:
    """``data:image/webp;base64,...`` of a uint8 RGB image at its own size, WebP at :data:`WEBP_QUALITY`
    (a frame under a figure: a tenth of the PNG's bytes)."""
    a = np.ascontiguousarray(rgb)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"image: expected uint8 (H, W, 3), got {a.dtype} {a.shape}")
    ok, buf = cv2.imencode(".webp", cv2.cvtColor(a, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_WEBP_QUALITY, WEBP_QUALITY])
    if not ok:
        raise ValueError("image: WebP encoding failed")
    return "data:image/webp;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def display_scale(width_px: int, *, min_width_px: int = 320) -> int:
    """The integer factor that brings a picture ``width_px`` wide to at least ``min_width_px``."""
    if width_px <= 0:
        raise ValueError(f"display_scale: expected a positive width, got {width_px}")
    return max(1, -(-min_width_px // width_px))


def upscale_nearest(rgb: np.ndarray, factor: int) -> np.ndarray:
    """Every pixel repeated ``factor`` x ``factor`` times (nearest neighbour: no invented detail)."""
    if factor < 1:
        raise ValueError(f"upscale_nearest: expected a factor >= 1, got {factor}")
    if factor == 1:
        return rgb
    return np.repeat(np.repeat(rgb, factor, axis=0), factor, axis=1)


def mask_image(mask: np.ndarray) -> np.ndarray:
    """A boolean mask as uint8 RGB: True white, False black."""
    return np.repeat((np.asarray(mask, bool) * np.uint8(255))[..., None], 3, axis=2)


def row_max_magnitude(truth: np.ndarray | None, estimates: list[np.ndarray], valid: np.ndarray | None,
                      *, floor_px: float = 1e-6) -> float:
    """The magnitude [px] that saturates colours across a row: the largest true magnitude.

    Without ground truth, the largest estimated magnitude. At least ``floor_px``
    (a local-motion row of a scene without moving vehicles has a true maximum
    near 0, which would make every estimation error saturate).
    """
    fields = [truth] if truth is not None else estimates
    best = 0.0
    for f in fields:
        mag = np.hypot(f[..., 0], f[..., 1])
        if valid is not None and valid.shape == mag.shape:
            mag = mag[valid]
        mag = mag[np.isfinite(mag)]
        if mag.size:
            best = max(best, float(mag.max()))
    return max(best, floor_px, 1e-6)


def flow_row(flow: np.ndarray, *, max_magnitude: float, valid: np.ndarray | None = None) -> np.ndarray:
    """Middlebury colour coding of ``flow`` with a shared ``max_magnitude`` [px]."""
    return flow_to_color(flow, max_magnitude=max_magnitude, valid=valid)


def epe_map(estimate: np.ndarray, truth: np.ndarray, *, max_epe_px: float,
            valid: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Endpoint-error heat map ``|w_est - w_true|`` (px) coloured 0..``max_epe_px`` (zero error black);
    pixels without ground truth (``valid`` False or non-finite) in :data:`NO_TRUTH_RGB`.

    Returns the RGB image and the mean endpoint error over known pixels [px].
    """
    epe = endpoint_error(estimate, truth)
    known = np.isfinite(epe)
    if valid is not None and valid.shape == epe.shape:
        known &= valid
    scaled = np.clip(np.where(known, epe, 0.0) / max(max_epe_px, 1e-6), 0.0, 1.0)
    rgb = _epe_lut8()[_lut_index(scaled, _EPE_N)]
    rgb[~known] = NO_TRUTH_RGB
    mean = float(epe[known].mean()) if known.any() else float("nan")
    return rgb, mean


def _lut_index(scaled: np.ndarray, n: int) -> np.ndarray:
    """The entry of an ``n``-colour map that matplotlib's ``Colormap.__call__`` picks for values in [0, 1]:
    ``floor(x n)``, with 1 in the last entry."""
    xa = scaled * n
    xa[xa == n] = n - 1
    return xa.astype(np.intp)


@functools.cache
def _epe_lut8() -> np.ndarray:
    """(N, 3) uint8: the error colour map's entries, rounded to 8 bits once (not per pixel)."""
    lut = colormaps[_EPE_CMAP](np.arange(_EPE_N))[:, :3]   # integers index the map's entries
    return (lut * 255.0).round().astype(np.uint8)


def epe_colorbar(width: int = 256, height: int = 12) -> np.ndarray:
    """A horizontal 0 -> max gradient in the endpoint-error colour map."""
    ramp = np.linspace(0.0, 1.0, width)[None, :].repeat(height, axis=0)
    return (colormaps[_EPE_CMAP](ramp)[..., :3] * 255.0).round().astype(np.uint8)


def wheel_legend(size: int = 101) -> np.ndarray:
    """The flow colour wheel (disc edge = the row's max magnitude)."""
    return color_wheel_image(size)


def swatch(rgb: tuple[int, int, int], size: int = 12) -> np.ndarray:
    """A ``size`` x ``size`` square of one colour (legend of a special value)."""
    return np.broadcast_to(np.asarray(rgb, np.uint8), (size, size, 3)).copy()
