"""File formats of a sequence folder: Middlebury ``.flo``, PNG images and masks.

One reader and one writer per format; every reader checks what it reads and
names the file in its error. Writers write to a temporary file in the same
folder and rename it, so a reader never sees half a file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

__all__ = [
    "FLO_TAG",
    "FLO_UNKNOWN",
    "FormatError",
    "read_flo",
    "write_flo",
    "read_png",
    "write_png",
    "atomic_write_bytes",
    "encode_flo",
    "encode_png",
]

FLO_TAG = 202021.25
# Middlebury marks unknown flow with values above 1e9 in magnitude.
FLO_UNKNOWN = 1e9


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


class FormatError(ValueError):
    """A file is not what its format says it must be."""


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file 0600; give it the mode an ordinary open() would
        os.fchmod(fd, 0o666 & ~_UMASK)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None:  # ENOSPC and EIO name no file: say which write failed
            raise type(exc)(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_flo(path: str | os.PathLike) -> np.ndarray:
    """Read a Middlebury ``.flo`` file as ``(H, W, 2)`` float32; unknown flow becomes NaN.

    Layout: float32 tag 202021.25, int32 width, int32 height, then
    ``width * height * 2`` float32 values, row-major, (u, v) interleaved.
    """
    path = Path(path)
    raw = path.read_bytes()
    if len(raw) < 12:
        raise FormatError(f"{path}: not a .flo file: {len(raw)} bytes, the header alone is 12")
    tag = np.frombuffer(raw, "<f4", 1, 0)[0]
    if tag != np.float32(FLO_TAG):
        raise FormatError(f"{path}: not a .flo file: tag {float(tag)!r}, expected {FLO_TAG}")
    width, height = (int(x) for x in np.frombuffer(raw, "<i4", 2, 4))
    if width <= 0 or height <= 0 or width > 1_000_000 or height > 1_000_000:
        raise FormatError(f"{path}: implausible size {width}x{height} in the .flo header")
    expected = 12 + width * height * 2 * 4
    if len(raw) != expected:
        raise FormatError(
            f"{path}: {len(raw)} bytes, expected {expected} for a {width}x{height} .flo file"
        )
    flow = np.frombuffer(raw, "<f4", width * height * 2, 12).reshape(height, width, 2).astype(np.float32)
    flow[~(np.abs(flow) < FLO_UNKNOWN)] = np.nan
    return flow


def encode_flo(flow: np.ndarray) -> bytes:
    """The bytes of a Middlebury ``.flo`` file for ``(H, W, 2)`` flow; NaN is written as unknown (1e10)."""
    f = np.asarray(flow)
    if f.ndim != 3 or f.shape[2] != 2 or not np.issubdtype(f.dtype, np.floating):
        raise ValueError(f"flow: expected (H, W, 2) float32, got {tuple(f.shape)} {f.dtype}")
    f = np.where(np.isfinite(f), f, 1e10).astype("<f4")
    h, w = f.shape[:2]
    header = np.array([FLO_TAG], "<f4").tobytes() + np.array([w, h], "<i4").tobytes()
    return header + f.tobytes()


def write_flo(path: str | os.PathLike, flow: np.ndarray) -> None:
    """Write ``(H, W, 2)`` flow as a Middlebury ``.flo`` file; NaN is written as unknown (1e10)."""
    atomic_write_bytes(path, encode_flo(flow))


def encode_png(image: np.ndarray, *, compression: int = 3) -> bytes:
    """PNG bytes of uint8 gray, uint8 RGB or uint16 gray (lossless, deterministic).

    ``compression`` is zlib's level 0..9: 1 is several times faster than 3 on
    textured frames for files a little larger.
    """
    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image: expected uint8 or uint16, got {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
    elif a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, 3), got {tuple(a.shape)}")
    ok, buf = cv2.imencode(".png", a, [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write uint8 gray, uint8 RGB or uint16 gray as PNG (lossless, deterministic bytes)."""
    atomic_write_bytes(path, encode_png(image))


def read_png(path: str | os.PathLike, *, expect: str | None = None) -> np.ndarray:
    """Read a PNG exactly as stored: uint8 RGB ``(H, W, 3)``, or gray uint8 / uint16 ``(H, W)``.

    ``expect`` is one of ``"rgb8"``, ``"gray8"``, ``"gray16"``, ``"rgb16"``; a file
    of another kind raises :class:`FormatError` that names both.
    """
    path = Path(path)
    data = np.frombuffer(path.read_bytes(), np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise FormatError(f"{path}: not a readable PNG (truncated or corrupt)")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    kind = ("rgb" if img.ndim == 3 else "gray") + ("16" if img.dtype == np.uint16 else "8")
    if expect is not None and kind != expect:
        raise FormatError(f"{path}: expected a {expect} PNG, got {kind}")
    return img
