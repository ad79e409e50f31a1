"""File formats of a sequence folder: Middlebury ``.flo``, compact ``.npz`` flow, PNG images and masks.

One reader and one writer per format; every reader checks what it reads and
names the file in its error. Writers write to a temporary file in the same
folder and rename it, so a reader never sees half a file.

The compact flow file (:func:`encode_flow_npz`, :func:`read_flow_npz`) is
lossless: it gives back the float32 fields bit for bit (NaN included), at about
a tenth of two ``.flo`` files. It is an ordinary ``.npz`` (a zip of ``.npy``
members), so ``numpy.load`` opens it anywhere; the members hold the float32 bits
recoded so that a byte compressor finds their redundancy, the large one as a
Zstandard frame (see :func:`encode_flow_npz` for the lines that undo it). Files of
the first version (all members deflated) are still read.
"""

from __future__ import annotations

import io
import os
import tempfile
import threading
import zipfile
import zlib
import re
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import zstandard

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
    "encode_png_fast",
    "FLOW_NPZ_CODEC",
    "FLOW_NPZ_CODEC_V1",
    "FLOW_NPZ_CODECS",
    "encode_flow_npz",
    "decode_flow_npz",
    "read_flow_npz",
    "KITTI_SCALE",
    "KITTI_OFFSET",
    "read_kitti_flow",
    "write_kitti_flow",
    "MOT_LAYOUTS",
    "MOT_ORIGIN_PX",
    "mot_box",
    "box_of_mot",
    "read_mot_gt",
    "read_mot_labels",
    "mot_label_class",
    "read_yolo_boxes",
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


_PNG_STRATEGIES = {"default": cv2.IMWRITE_PNG_STRATEGY_DEFAULT, "rle": cv2.IMWRITE_PNG_STRATEGY_RLE,
                   "filtered": cv2.IMWRITE_PNG_STRATEGY_FILTERED,
                   "huffman": cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY}


_PNG_FILTERS = {"adaptive": cv2.IMWRITE_PNG_ALL_FILTERS, "none": cv2.IMWRITE_PNG_FILTER_NONE,
                "sub": cv2.IMWRITE_PNG_FILTER_SUB, "up": cv2.IMWRITE_PNG_FILTER_UP, "avg": cv2.IMWRITE_PNG_FILTER_AVG,
                "paeth": cv2.IMWRITE_PNG_FILTER_PAETH}


def encode_png(image: np.ndarray, *, compression: int = 3, strategy: str = "default",
               filters: str = "adaptive") -> bytes:
    """PNG bytes of uint8 gray, uint8 RGB or uint16 gray (lossless, deterministic).

    ``compression`` is zlib's level 0..9: 1 is several times faster than 3 on
    textured frames for files a little larger. ``strategy`` is zlib's matching
    strategy, one of ``default``, ``rle``, ``filtered``, ``huffman``: ``rle`` with
    level 1 is faster and smaller than ``default`` on rendered frames. ``filters``
    is PNG's row prediction: ``adaptive`` (libpng tries the five predictors on every
    row and keeps the best: about a third of the encoding time of a frame), one
    predictor for every row (``sub``, ``up``, ``avg``, ``paeth``), or ``none`` (for
    masks and id images, long runs of one value: ~4x faster, files of a few kB
    either way). None of them changes the pixels, only the bytes.
    """
    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image: expected uint8 or uint16, got {a.dtype}")
    if strategy not in _PNG_STRATEGIES:
        raise ValueError(f"strategy: expected one of {', '.join(_PNG_STRATEGIES)}, got {strategy!r}")
    if filters not in _PNG_FILTERS:
        raise ValueError(f"filters: expected one of {', '.join(_PNG_FILTERS)}, got {filters!r}")
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
    elif a.ndim != 2:
        raise ValueError(f"image: expected (H, W) or (H, W, 3), got {tuple(a.shape)}")
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression), cv2.IMWRITE_PNG_STRATEGY, _PNG_STRATEGIES[strategy]]
    if filters != "adaptive":  # libpng's default is adaptive; say nothing then, so its bytes stay as they were
        params += [cv2.IMWRITE_PNG_FILTER, _PNG_FILTERS[filters]]
    ok, buf = cv2.imencode(".png", a, params)
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


# filtered bytes per deflate block of :func:`encode_png_fast`: one Huffman code per block, so
# smaller blocks follow the image's statistics more closely for a header (~150 bytes) each
PNG_FAST_BLOCK = 32768
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_chunk(kind: bytes, payload: bytes) -> bytes:
    # length (big-endian, payload only), type, payload, CRC-32 of type + payload
    return (len(payload).to_bytes(4, "big") + kind + payload
            + zlib.crc32(payload, zlib.crc32(kind)).to_bytes(4, "big"))


_PNG_SCRATCH = threading.local()


def _png_scratch(n_filtered: int, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """This thread's buffers for the filtered rows and the file, grown when too small.

    Reused because fresh megabyte buffers cost their page faults on every frame (~1.5 ms).
    """
    buf = getattr(_PNG_SCRATCH, "buffers", None)
    if buf is None or buf[0].size < n_filtered or buf[1].size < n_out:
        buf = _PNG_SCRATCH.buffers = (np.empty(n_filtered, np.uint8), np.empty(n_out, np.uint8))
    return buf[0][:n_filtered], buf[1][:n_out]


def encode_png_fast(image: np.ndarray, *, block: int = PNG_FAST_BLOCK) -> bytes:
    """PNG bytes of uint8 RGB ``(H, W, 3)`` or gray ``(H, W)``: Average row filter, Huffman coding only.

    The pixels of ``encode_png(image, compression=1, strategy="huffman", filters="avg")``,
    in a file of about the same size (within a few per cent), at about a third of the time:
    our own filter and deflate (:mod:`scenes._codec_kernels`) instead of libpng's and zlib's.
    Any PNG reader reads it: signature, IHDR (8-bit RGB or gray, not interlaced), one IDAT
    holding the zlib stream (RFC 1950: header ``78 01``, deflate blocks, Adler-32 of the
    filtered rows), IEND. The bytes depend on the pixels and ``block`` only. The numba
    kernels release the GIL.
    """
    from scenes import _codec_kernels as K

    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"image: expected uint8, got {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 3:
        bpp, colour_type = 3, 2
    elif a.ndim == 2:
        bpp, colour_type = 1, 0
    else:
        raise ValueError(f"image: expected (H, W) or (H, W, 3), got {tuple(a.shape)}")
    h, w = a.shape[:2]
    if h == 0 or w == 0:
        raise ValueError(f"image: expected at least 1x1 pixels, got {w}x{h}")
    if not 1 <= int(block) <= 65535:
        raise ValueError(f"block: expected 1..65535 bytes (a stored block's limit), got {block}")
    rows = np.ascontiguousarray(a).reshape(h, w * bpp)
    n_raw = h * (w * bpp + 1)
    raw, out = _png_scratch(n_raw, _PNG_Z0 + 2 + K.deflate_bound(n_raw, int(block)) + 4 + 4 + 12)
    K.avg_filter(rows, bpp, raw.reshape(h, w * bpp + 1))
    n = K.deflate_huffman(raw, int(block), out[_PNG_Z0 + 2:])
    return _png_around(out, n, raw, w, h, 8, colour_type)


# where the zlib stream starts in the files of encode_png_fast: after the
# signature (8), the IHDR chunk (25) and the IDAT chunk's length and type (8)
_PNG_Z0 = 8 + 25 + 8


def _png_around(out: np.ndarray, n: int, raw: np.ndarray, w: int, h: int, bit_depth: int,
                colour_type: int) -> bytes:
    """The PNG file around ``n`` deflated bytes of the rows ``raw`` at ``out[_PNG_Z0 + 2:]``.

    In order: signature, IHDR, IDAT (zlib header ``78 01``: deflate, 32 KiB window, FCHECK making
    0x7801 a multiple of 31; the deflate stream; Adler-32 of ``raw``), IEND; written into ``out``.
    """
    z0 = _PNG_Z0
    ihdr = w.to_bytes(4, "big") + h.to_bytes(4, "big") + bytes((bit_depth, colour_type, 0, 0, 0))
    out[:33] = np.frombuffer(_PNG_SIGNATURE + _png_chunk(b"IHDR", ihdr), np.uint8)
    out[37:z0] = np.frombuffer(b"IDAT", np.uint8)
    out[z0:z0 + 2] = (0x78, 0x01)
    e = z0 + 2 + n
    out[e:e + 4] = np.frombuffer(zlib.adler32(raw).to_bytes(4, "big"), np.uint8)
    e += 4
    out[33:37] = np.frombuffer((e - z0).to_bytes(4, "big"), np.uint8)
    out[e:e + 4] = np.frombuffer(zlib.crc32(out[37:e]).to_bytes(4, "big"), np.uint8)  # of type + data
    e += 4
    out[e:e + 12] = np.frombuffer(_png_chunk(b"IEND", b""), np.uint8)
    return out[:e + 12].tobytes()


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


# --------------------------------------------------------------------------- compact flow (.npz)

# the codec this module writes; :func:`decode_flow_npz` reads it and every earlier one
FLOW_NPZ_CODEC = "aerobench-flow-npz-2"
# version 1: the byte planes in a deflated member (zlib level 1): ~20 ms of the ~30 ms a
# 640x480 pair took to encode; version 2 stores them as one Zstandard frame (level 1) in
# a stored member: ~4x faster than zlib level 1 and ~10 % smaller on rendered truth
FLOW_NPZ_CODEC_V1 = "aerobench-flow-npz-1"
FLOW_NPZ_CODECS = (FLOW_NPZ_CODEC_V1, FLOW_NPZ_CODEC)
# zstd level of the byte planes (version 2)
FLOW_NPZ_ZSTD_LEVEL = 1
# zlib level of the deflated members: 1 is ~4x faster than 6 on these planes for files ~20 % larger
FLOW_NPZ_LEVEL = 1
# a fixed timestamp in every zip member, so that the same fields give the same bytes
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def _npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(a), allow_pickle=False)
    return buf.getvalue()


def _byte_planes(bits: np.ndarray) -> np.ndarray:
    """``(H, W, 2)`` uint32 -> ``(4, 2, H, W)`` uint8: byte k (little-endian) of component c."""
    h, w = bits.shape[:2]
    return np.ascontiguousarray(bits.astype("<u4", copy=False).view(np.uint8).reshape(h, w, 2, 4)
                                .transpose(3, 2, 0, 1))


_ZSTD = threading.local()


def _zstd_compressor() -> zstandard.ZstdCompressor:
    """This thread's compressor of the byte planes (a compressor is not shared between threads)."""
    c = getattr(_ZSTD, "compressor", None)
    if c is None:
        c = _ZSTD.compressor = zstandard.ZstdCompressor(level=FLOW_NPZ_ZSTD_LEVEL)
    return c


def _planes_scratch(h: int, w: int) -> np.ndarray:
    """This thread's ``(4, 2, h, w)`` uint8 buffer of byte planes (a fresh one costs ~0.5 ms of page faults)."""
    buf = getattr(_ZSTD, "planes", None)
    if buf is None or buf.size < 8 * h * w:
        buf = _ZSTD.planes = np.empty(8 * h * w, np.uint8)
    return buf[:8 * h * w].reshape(4, 2, h, w)


def _check_field(a: np.ndarray, name: str, shape: tuple | None = None) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] != 2 or a.dtype != np.float32:
        raise ValueError(f"{name}: expected (H, W, 2) float32, got {tuple(a.shape)} {a.dtype}")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape} (as flow_camera), got {tuple(a.shape)}")
    return np.ascontiguousarray(a)


def encode_flow_npz(flow: np.ndarray, flow_camera: np.ndarray, *, level: int = FLOW_NPZ_LEVEL,
                    codec: str = FLOW_NPZ_CODEC) -> bytes:
    """The bytes of a lossless compact ``.npz`` holding a pair's total and camera-induced flow.

    Members (version 2, :data:`FLOW_NPZ_CODEC`):

    - ``codec``: the string :data:`FLOW_NPZ_CODEC`.
    - ``flow_camera_rowdelta_zstd``: ``uint8 (N,)``, stored (not deflated): one Zstandard
      frame (RFC 8878) whose content is the ``uint8 (4, 2, H, W)`` array, C order, of byte k
      (little-endian) of component c = u, v of the float32 bits of ``flow_camera`` as
      uint32, each minus its left neighbour in the row (modulo 2**32; the first column
      kept). The camera-induced flow is smooth, so neighbouring bit patterns differ in
      their low bits only, and the byte planes of the differences are mostly runs.
    - ``flow_camera_shape``: ``int64 (2,)``, ``(H, W)``.
    - ``flow_xor_index`` ``int64 (K,)`` and ``flow_xor_bits`` ``uint32 (K,)`` (deflated): where
      the bits of ``flow`` differ from those of ``flow_camera`` (flat indices into
      ``(H, W, 2)``), their XOR. The total flow is the camera's on the whole static world,
      so K is small (the vehicles' pixels).

    Version 1 (``codec=FLOW_NPZ_CODEC_V1``, still read and, for tests, written) holds the
    same planes as a deflated ``uint8 (4, 2, H, W)`` member ``flow_camera_rowdelta`` and no
    shape member; ``numpy.load`` alone decodes it, version 2 needs ``zstandard`` too.

    Decoding (what :func:`decode_flow_npz` does)::

        planes = zstd_decompress(flow_camera_rowdelta_zstd).reshape(4, 2, H, W)   # version 2
        bits_c = cumsum(planes_to_uint32(planes), axis=W) mod 2**32   # (H, W, 2)
        bits = bits_c.copy();  bits.flat[flow_xor_index] ^= flow_xor_bits
        flow_camera, flow = bits_c.view(float32), bits.view(float32)

    Parameters
    ----------
    flow, flow_camera : (H, W, 2) float32 px; NaN and infinities are kept bit for bit.
    level : zlib level 0..9 of the deflated members.
    codec : :data:`FLOW_NPZ_CODEC` (the default) or :data:`FLOW_NPZ_CODEC_V1`.
    """
    if codec not in FLOW_NPZ_CODECS:
        raise ValueError(f"codec: expected one of {', '.join(FLOW_NPZ_CODECS)}, got {codec!r}")
    from scenes import _codec_kernels as K

    fc = _check_field(flow_camera, "flow_camera")
    f = _check_field(flow, "flow", fc.shape)
    bits_c = fc.view(np.uint32)
    h, w = fc.shape[:2]
    # the byte planes of the row differences (modulo 2**32), and where flow's bits differ: numba
    # kernels, one pass each (the numpy chain, copy, subtract, XOR, nonzero, transpose, took ~6 ms)
    planes = _planes_scratch(h, w)
    K.flow_rowdelta_planes(bits_c, planes)
    index, xor = K.flow_xor(f.view(np.uint32).reshape(-1), bits_c.reshape(-1))
    members: dict[str, tuple[np.ndarray, int]] = {"codec": (np.array(codec), zipfile.ZIP_DEFLATED)}
    if codec == FLOW_NPZ_CODEC_V1:
        members["flow_camera_rowdelta"] = (planes, zipfile.ZIP_DEFLATED)
    else:
        frame = _zstd_compressor().compress(planes.data)
        members["flow_camera_rowdelta_zstd"] = (np.frombuffer(frame, np.uint8), zipfile.ZIP_STORED)
        members["flow_camera_shape"] = (np.array(fc.shape[:2], "<i8"), zipfile.ZIP_DEFLATED)
    members["flow_xor_index"] = (index.astype("<i8", copy=False), zipfile.ZIP_DEFLATED)
    members["flow_xor_bits"] = (xor.astype("<u4", copy=False), zipfile.ZIP_DEFLATED)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, (a, method) in members.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME)
            info.compress_type = method
            info.external_attr = 0o644 << 16
            zf.writestr(info, _npy_bytes(a), compresslevel=int(level))
    return buf.getvalue()


def _zstd_planes(frame: np.ndarray, shape: np.ndarray, name: str) -> np.ndarray:
    """The ``(4, 2, H, W)`` uint8 planes of a version-2 file from its zstd frame and ``(H, W)``."""
    if frame.dtype != np.uint8 or frame.ndim != 1 or shape.shape != (2,) or shape.dtype.kind != "i":
        raise FormatError(f"{name}: flow_camera_rowdelta_zstd {frame.shape} {frame.dtype} and flow_camera_shape "
                          f"{shape.shape} {shape.dtype}: expected N uint8 and 2 integers")
    h, w = (int(x) for x in shape)
    if not (0 < h <= 1_000_000 and 0 < w <= 1_000_000):
        raise FormatError(f"{name}: implausible size {w}x{h} in flow_camera_shape")
    n = 8 * h * w
    try:
        raw = zstandard.ZstdDecompressor().decompress(frame.tobytes(), max_output_size=n)
    except zstandard.ZstdError as err:
        raise FormatError(f"{name}: not a readable compact flow file (ZstdError: {err})") from None
    if len(raw) != n:
        raise FormatError(f"{name}: flow_camera_rowdelta_zstd holds {len(raw)} bytes, expected {n} for {w}x{h}")
    return np.frombuffer(raw, np.uint8).reshape(4, 2, h, w)


def decode_flow_npz(data: bytes, *, name: str = "<bytes>") -> tuple[np.ndarray, np.ndarray]:
    """``(flow, flow_camera)``, each ``(H, W, 2)`` float32 px, from the bytes of :func:`encode_flow_npz`.

    Reads every codec of :data:`FLOW_NPZ_CODECS`. ``name`` (the file) is named in the
    :class:`FormatError` of a damaged or foreign file.
    """
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            codec = str(z["codec"].item()) if "codec" in z.files else None
            if codec not in FLOW_NPZ_CODECS:
                raise FormatError(f"{name}: not a compact flow file: codec {codec!r}, "
                                  f"expected one of {', '.join(map(repr, FLOW_NPZ_CODECS))}")
            if codec == FLOW_NPZ_CODEC_V1:
                delta = z["flow_camera_rowdelta"]
            else:
                delta = _zstd_planes(z["flow_camera_rowdelta_zstd"], z["flow_camera_shape"], name)
            index, xor = z["flow_xor_index"], z["flow_xor_bits"]
    except FormatError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise FormatError(f"{name}: not a readable compact flow file ({type(err).__name__}: {err})") from None
    if delta.dtype != np.uint8 or delta.ndim != 4 or delta.shape[:2] != (4, 2):
        raise FormatError(f"{name}: flow_camera_rowdelta of {delta.shape} {delta.dtype}, expected (4, 2, H, W) uint8")
    n = 2 * delta.shape[2] * delta.shape[3]
    if (index.ndim != 1 or index.shape != xor.shape or index.dtype.kind != "i" or xor.dtype != np.uint32
            or (index.size and (index.min() < 0 or index.max() >= n))):
        raise FormatError(f"{name}: flow_xor_index {index.shape} {index.dtype} and flow_xor_bits {xor.shape} "
                          f"{xor.dtype}: expected K int64 indices below {n} and K uint32 values")
    from scenes import _codec_kernels as K  # numba: only where flow files are read

    # the running sum of each row's deltas, modulo 2**32, (H, W, 2) in one pass
    bits_c = np.empty((delta.shape[2], delta.shape[3], 2), np.uint32)
    K.flow_rowdelta_bits(np.ascontiguousarray(delta), bits_c)
    bits = bits_c.copy()
    bits.ravel()[index] ^= xor
    return bits.view(np.float32), bits_c.view(np.float32)


def read_flow_npz(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a compact flow file: ``(flow, flow_camera)``, each ``(H, W, 2)`` float32 px, bit for bit."""
    path = Path(path)
    return decode_flow_npz(path.read_bytes(), name=str(path))


# --------------------------------------------------------------------------- KITTI flow PNG

KITTI_SCALE = 64.0
KITTI_OFFSET = 2 ** 15


def read_kitti_flow(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a KITTI flow PNG: ``(flow (H, W, 2) float32 with NaN where invalid, valid (H, W) bool)``.

    The file must be a 16-bit RGB PNG: channels u, v, valid with
    ``u = (R - 2**15) / 64`` px (Geiger et al., KITTI devkit).
    """
    path = Path(path)
    try:
        img = read_png(path, expect="rgb16")
    except FormatError as exc:
        raise FormatError(f"{path}: a KITTI flow file must be a 16-bit RGB PNG (u, v, valid): {exc}") from None
    flow = (img[..., :2].astype(np.float32) - KITTI_OFFSET) / KITTI_SCALE
    valid = img[..., 2] > 0
    flow[~valid] = np.nan
    return flow, valid


def write_kitti_flow(path: str | os.PathLike, flow: np.ndarray, valid: np.ndarray | None = None) -> None:
    """Write flow as a KITTI 16-bit PNG (values rounded to 1/64 px; |u|, |v| must stay below 512 px)."""
    f = np.asarray(flow, np.float64)
    v = np.isfinite(f).all(-1) if valid is None else np.asarray(valid, bool) & np.isfinite(f).all(-1)
    q = np.round(np.where(v[..., None], f, 0.0) * KITTI_SCALE + KITTI_OFFSET)
    if q.min() < 0 or q.max() > 65535:
        raise ValueError("flow: KITTI PNG holds |u|, |v| < 512 px; got larger values")
    img = np.dstack([q[..., 0], q[..., 1], v.astype(np.float64)]).astype(np.uint16)
    write_png(path, img)


# --------------------------------------------------------------------------- annotations of real footage

# The classes every reader maps to (the ground truth's ``class`` column of tracks.csv).
TRUTH_CLASSES = ("car", "van", "truck", "bus", "motorbike", "cyclist", "pedestrian")

# MOTChallenge (MOT16/17/20, Milan et al. 2016, sec. 3): class column 8. Classes 8-13 are
# distractors, occluders, reflections and crowds: ignored, never scored.
_MOT_CLASSES = {1: "pedestrian", 2: "pedestrian", 3: "car", 4: "cyclist", 5: "motorbike", 6: "cyclist",
                7: "pedestrian", -1: "car"}
_MOT_IGNORED = {8, 9, 10, 11, 12, 13}
# VisDrone2019-MOT (toolkit README): object_category column 8; 0 = ignored region, 11 = others (ignored).
_VISDRONE_CLASSES = {1: "pedestrian", 2: "pedestrian", 3: "cyclist", 4: "car", 5: "van", 6: "truck",
                     7: "motorbike", 8: "motorbike", 9: "bus", 10: "motorbike"}
_VISDRONE_IGNORED = {0, 11}
# occlusion column 10: 0 none, 1 partial (1-50 % occluded), 2 heavy (50-100 %): middle of each band
_VISDRONE_VISIBLE = {0: 1.0, 1: 0.75, 2: 0.25}
# UAVDT (Du et al. 2018, the benchmark's GT/*_gt_whole.txt): category 1 car, 2 truck, 3 bus;
# occlusion 1 no (0 %), 2 large (70-100 %), 3 medium (30-70 %), 4 small (1-30 %); out-of-view
# 1 no (0 %), 2 medium (30-50 %), 3 small (1-30 %): the visible fraction is the product of the
# middles of the two bands.
_UAVDT_CLASSES = {1: "car", 2: "truck", 3: "bus"}
_UAVDT_OCCLUSION = {1: 1.0, 2: 0.15, 3: 0.5, 4: 0.845}
_UAVDT_OUT_OF_VIEW = {1: 1.0, 2: 0.6, 3: 0.845}

# Label names of a ``labels.txt`` beside a MOTChallenge ``gt.txt`` (CVAT's and Datumaro's "MOT 1.1"
# export: column 8 is the 1-based line of the label in that file, not MOT's class table) -> our
# classes; None: ignored (never scored). Matched lower-case, blanks and "_" / "-" as one space, a
# trailing plural "s" dropped. A name not listed is ignored too, and said so (:func:`read_mot_labels`).
_LABEL_NAMES = {
    "car": "car", "vehicle": "car", "motor vehicle": "car", "auto": "car", "automobile": "car", "taxi": "car",
    "suv": "car", "pickup": "car", "pickup truck": "van", "van": "van", "minibus": "van", "minivan": "van",
    "truck": "truck", "lorry": "truck", "trailer": "truck", "bus": "bus", "coach": "bus",
    "motorbike": "motorbike", "motorcycle": "motorbike", "motor": "motorbike", "scooter": "motorbike",
    "moped": "motorbike", "tricycle": "motorbike", "awning tricycle": "motorbike",
    "bicycle": "cyclist", "bike": "cyclist", "cyclist": "cyclist", "rider": "cyclist",
    "non motorized vehicle": "cyclist", "pedestrian": "pedestrian", "person": "pedestrian",
    "people": "pedestrian", "static person": "pedestrian", "person on vehicle": "pedestrian",
    "distractor": None, "occluder": None, "occluder on the ground": None, "occluder full": None,
    "reflection": None, "crowd": None, "ignore": None, "ignored": None, "ignored region": None,
    "ignore region": None, "other": None, "others": None,
}

MOT_LAYOUTS = ("mot", "visdrone", "uavdt")

# Boxes. Ours (tracks.csv's bbox_*_px, a tracker's, the truth's) are continuous rectangles in pixel-centre
# coordinates: pixel i is centred on i and spans [i - 0.5, i + 0.5], so a box over pixels 3..12 is
# [2.5, 12.5], 10 px wide. MOTChallenge's bb_left, bb_top are the box's left and top edge with pixels
# numbered from 1 (the first pixel spans [1, 2]; TrackEval and py-motmetrics take [bb_left, bb_left +
# bb_width]), so that box is bb_left 4, bb_width 10: bb_left = x0 + MOT_ORIGIN_PX.
MOT_ORIGIN_PX = 1.5


def mot_box(x0, y0, x1, y1):
    """``(bb_left, bb_top, bb_width, bb_height)`` of continuous pixel-centre boxes (scalars or arrays)."""
    return x0 + MOT_ORIGIN_PX, y0 + MOT_ORIGIN_PX, x1 - x0, y1 - y0


def box_of_mot(left, top, width, height):
    """``(x0, y0, x1, y1)``, continuous in pixel-centre coordinates, of MOTChallenge boxes: :func:`mot_box`'s
    inverse."""
    x0, y0 = left - MOT_ORIGIN_PX, top - MOT_ORIGIN_PX
    return x0, y0, x0 + width, y0 + height


MOT_COLUMNS = ["frame", "id", "left", "top", "width", "height", "ignore", "class", "visible_fraction", "line"]


def _fields(line: str) -> list[str]:
    return [f for f in re.split(r"[,\s]+", line.strip()) if f]


def _number(text: str, what: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise FormatError(f"{where}: {what}: expected a number, got {text!r}") from None
    if not np.isfinite(v):
        raise FormatError(f"{where}: {what}: expected a finite number, got {text!r}")
    return v


def _integer(text: str, what: str, where: str, *, lo: int | None = None) -> int:
    v = _number(text, what, where)
    if v != int(v) or (lo is not None and v < lo):
        raise FormatError(f"{where}: {what}: expected an integer{f' >= {lo}' if lo is not None else ''}, "
                          f"got {text!r}")
    return int(v)


def _coded(text: str, what: str, where: str, table: dict | set) -> int:
    v = _integer(text, what, where)
    if v not in table:
        raise FormatError(f"{where}: {what}: expected one of {sorted(table)}, got {text!r}")
    return v


def mot_label_class(name: str) -> tuple[bool, str | None]:
    """``(known, class)`` of a label name of ``labels.txt``: class None = ignored (see :data:`_LABEL_NAMES`)."""
    key = " ".join(re.split(r"[\s_-]+", name.strip().lower())).strip()
    for spelled in (key, key.replace(" ", "")):  # "motor cycle", "motorcycle"
        for k in (spelled, spelled[:-1] if spelled.endswith("s") else spelled):  # "cars", "car"
            if k in _LABEL_NAMES:
                return True, _LABEL_NAMES[k]
    return False, None


def read_mot_labels(path: str | os.PathLike) -> list[str]:
    """The label names of a ``labels.txt`` (CVAT / Datumaro MOT export), one a line, blank lines skipped.

    Line k of the names is class k of the ``gt.txt`` beside it. Raises
    :class:`FormatError` naming the file for an unreadable or empty file, or a name given twice.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise FormatError(f"{path}: not a text file") from None
    names = [line.strip() for line in text.splitlines() if line.strip()]
    if not names:
        raise FormatError(f"{path}: no label name (an empty labels file)")
    seen = set()
    for k, n in enumerate(names, 1):
        if n.lower() in seen:
            raise FormatError(f"{path}: label {n!r} (name {k}) given twice")
        seen.add(n.lower())
    return names


def _ten_columns_have_class(lines: list[tuple[int, list[str]]]) -> bool:
    """Whether the 10-column lines of a ``mot`` file carry class and visibility in columns 8, 9.

    MOT15 writes world coordinates x, y, z there (-1, -1, -1 in its 2D files); MOT16/17/20
    ground truth has class and visibility there, and writers that append a 10th column (CVAT's
    "MOT 1.1" export) keep them, as TrackEval reads any line of 9 or more columns. So: class
    and visibility unless every 10-column line has -1 in columns 8-10, or one has a column 8
    that is not an integer (a world coordinate).
    """
    ten = [f for _, f in lines if len(f) == 10]
    if not ten:
        return False
    try:
        c8 = [float(f[7]) for f in ten]
        if all(v == -1.0 and float(f[8]) == -1.0 and float(f[9]) == -1.0 for v, f in zip(c8, ten)):
            return False
    except ValueError:
        return True  # not numbers: the per-line checks name the field
    return all(v == int(v) for v in c8)


def read_mot_gt(path: str | os.PathLike, *, layout: str = "mot", labels: list[str] | None = None) -> pd.DataFrame:
    """Read a MOTChallenge ground-truth file (or its VisDrone-MOT / UAVDT variant), every line checked.

    Columns read, 1-based as the formats number them (frames are 1-based too):

    * ``mot`` (MOTChallenge ``gt/gt.txt``): 1 frame, 2 id, 3-6 bb_left, bb_top, bb_width,
      bb_height (px, bb_left 1-based), 7 the "consider" flag (0: ignored). With 9 columns
      (MOT16/17/20) also 8 class (1, 2, 7 pedestrian, 3 car, 4 and 6 cyclist, 5 motorbike,
      -1 unspecified: car; 8-13 distractors, occluders, reflections, crowds: ignored) and 9
      visibility (0..1; -1, "not given", reads as 1). 10 columns: the same, column 10 not
      read (TrackEval reads them so; CVAT's "MOT 1.1" export writes a 10th), unless the
      file's columns 8-10 are MOT15's world coordinates (-1, -1, -1 on every 10-column line,
      or a column 8 that is not an integer): then class car, visibility 1. 6 or 7 columns:
      class car, visibility 1.
      With ``labels`` (the names of a ``labels.txt`` beside the file, CVAT's and Datumaro's MOT
      export), class k is the k-th name instead of MOT's table: car, vehicle, van, truck, bus,
      motorbike, motorcycle, bicycle, person, pedestrian and the like map to our classes
      (plural or capitalised alike); MOT's own names (distractor, occluder, reflection ...) and
      names not known are ignored (never scored).
    * ``visdrone`` (VisDrone2019-MOT ``annotations/*.txt``, 10 columns): 1-6 as above, 7 score
      (0: ignored), 8 object_category (0 ignored region and 11 others: ignored; 1, 2
      pedestrian, 3 cyclist, 4 car, 5 van, 6 truck, 7, 8, 10 motorbike, 9 bus), 9 truncation
      (0 or 1; checked, not used), 10 occlusion (0, 1, 2 -> visible fraction 1, 0.75, 0.25).
    * ``uavdt`` (UAVDT ``GT/*_gt_whole.txt``, 9 columns): 1-6 as above, 7 out-of-view (1 no,
      2 medium, 3 small), 8 occlusion (1 no, 2 large, 3 medium, 4 small), 9 object_category
      (1 car, 2 truck, 3 bus); visible fraction = the product of the middles of the two
      bands. UAVDT's ignore regions (``*_gt_ignore.txt``) are a separate file, not read here.

    Fields are separated by commas or white space; blank lines are skipped.

    Returns
    -------
    DataFrame
        :data:`MOT_COLUMNS`: frame (int, 1-based), id (int), left, top (the box's left and top
        pixel, 1-based, float), width, height (px, float > 0), ignore (bool: an ignored
        object or region, never scored), class (str, one of :data:`TRUTH_CLASSES`),
        visible_fraction (float 0..1), line (int, 1-based line in the file).

    Raises
    ------
    FormatError
        naming the file and line: a wrong number of columns, a field that is not a number, a
        frame < 1, a box of zero or negative size, a code outside its table (with a hint when
        the value says the file is of another layout), an id given twice in one frame; or a
        file with no line at all.
    """
    path = Path(path)
    if layout not in MOT_LAYOUTS:
        raise ValueError(f"layout: expected one of {', '.join(MOT_LAYOUTS)}, got {layout!r}")
    if labels is not None and layout != "mot":
        raise ValueError(f"labels: a labels.txt names the classes of the mot layout only, got layout {layout!r}")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise FormatError(f"{path}: not a text file") from None
    lines = [(k, f) for k, f in ((k, _fields(line)) for k, line in enumerate(text.splitlines(), 1)) if f]
    label_classes = [mot_label_class(n)[1] for n in labels] if labels is not None else None
    ten_class = layout == "mot" and _ten_columns_have_class(lines)
    rows = []
    seen: dict[tuple[int, int], int] = {}
    for k, f in lines:
        where = f"{path}: line {k}"
        if layout == "mot" and len(f) not in (6, 7, 9, 10):
            raise FormatError(f"{where}: expected 6, 7, 9 or 10 MOTChallenge columns (frame, id, bb_left, bb_top, "
                              f"bb_width, bb_height, flag[, class, visibility]), got {len(f)}")
        if layout == "visdrone" and len(f) != 10:
            raise FormatError(f"{where}: expected 10 VisDrone-MOT columns (frame, id, left, top, width, height, "
                              f"score, category, truncation, occlusion), got {len(f)}")
        if layout == "uavdt" and len(f) != 9:
            raise FormatError(f"{where}: expected 9 UAVDT columns (frame, id, left, top, width, height, "
                              f"out_of_view, occlusion, category), got {len(f)}")
        frame = _integer(f[0], "frame (column 1)", where)
        if frame < 1:
            raise FormatError(f"{where}: frame (column 1): expected an integer >= 1, got {f[0]!r} (the formats "
                              f"number frames from 1)")
        tid = _integer(f[1], "id (column 2)", where)
        left, top = _number(f[2], "bb_left (column 3)", where), _number(f[3], "bb_top (column 4)", where)
        w, h = _number(f[4], "bb_width (column 5)", where), _number(f[5], "bb_height (column 6)", where)
        ignore, cls, vis = False, "car", 1.0
        if layout == "mot":
            if len(f) >= 7:
                ignore = _number(f[6], "flag (column 7)", where) == 0
            if len(f) == 9 or (len(f) == 10 and ten_class):
                c = _integer(f[7], "class (column 8)", where)
                if label_classes is not None:
                    if not 1 <= c <= len(label_classes):
                        raise FormatError(f"{where}: class (column 8): expected 1..{len(label_classes)}, a line of "
                                          f"labels.txt ({', '.join(labels)}), got {f[7]!r}")
                    named = label_classes[c - 1]
                    ignore, cls = ignore or named is None, named or "car"
                elif c in _MOT_IGNORED:
                    ignore = True
                elif c in _MOT_CLASSES:
                    cls = _MOT_CLASSES[c]
                else:
                    hint = " (a VisDrone-MOT file? --gt-format visdrone)" if c in (0, 11) else ""
                    raise FormatError(f"{where}: class (column 8): expected -1 or 1..13 (MOTChallenge), "
                                      f"got {f[7]!r}{hint}")
                vis = _number(f[8], "visibility (column 9)", where)
                if vis == -1.0:  # MOTChallenge's "not given"
                    vis = 1.0
                elif not 0.0 <= vis <= 1.0:
                    hint = (" (a UAVDT file? --gt-format uavdt)"
                            if vis in (2.0, 3.0) and len(f) == 9 else "")
                    raise FormatError(f"{where}: visibility (column 9): expected 0..1 (or -1: not given), "
                                      f"got {f[8]!r}{hint}")
        elif layout == "visdrone":
            ignore = _coded(f[6], "score (column 7)", where, {0, 1}) == 0
            c = _coded(f[7], "object_category (column 8)", where, set(range(12)))
            ignore = ignore or c in _VISDRONE_IGNORED
            cls = _VISDRONE_CLASSES.get(c, "car")
            _coded(f[8], "truncation (column 9)", where, {0, 1})
            vis = _VISDRONE_VISIBLE[_coded(f[9], "occlusion (column 10)", where, _VISDRONE_VISIBLE)]
        else:
            out = _coded(f[6], "out_of_view (column 7)", where, _UAVDT_OUT_OF_VIEW)
            occ = _coded(f[7], "occlusion (column 8)", where, _UAVDT_OCCLUSION)
            cls = _UAVDT_CLASSES[_coded(f[8], "object_category (column 9)", where, _UAVDT_CLASSES)]
            vis = _UAVDT_OUT_OF_VIEW[out] * _UAVDT_OCCLUSION[occ]
        if not (w > 0 and h > 0):
            raise FormatError(f"{where}: box size: expected width and height > 0 px, got {f[4]} x {f[5]}")
        if not ignore:
            if (frame, tid) in seen:
                raise FormatError(f"{where}: id {tid} appears twice in frame {frame} (first on line "
                                  f"{seen[frame, tid]})")
            seen[frame, tid] = k
        rows.append((frame, tid, left, top, w, h, ignore, cls, vis, k))
    if not rows:
        raise FormatError(f"{path}: no annotation line (an empty ground-truth file)")
    df = pd.DataFrame(rows, columns=MOT_COLUMNS)
    return df.astype({"frame": np.int64, "id": np.int64, "ignore": bool, "line": np.int64})


def read_yolo_boxes(path: str | os.PathLike) -> np.ndarray:
    """Read a YOLO label file: one box a line, ``class cx cy w h``, the centre and size as fractions
    of the image's width and height.

    Returns
    -------
    (N, 5) float64
        class (a non-negative integer), cx, cy (0..1), w, h (0 < w, h <= 1); N may be 0.

    Raises
    ------
    FormatError
        naming the file and line: not 5 fields, a field that is not a number, a class that is
        not a non-negative integer, a centre outside 0..1 or a size outside (0, 1].
    """
    path = Path(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise FormatError(f"{path}: not a text file") from None
    out = []
    for k, line in enumerate(text.splitlines(), 1):
        f = line.split()
        if not f:
            continue
        where = f"{path}: line {k}"
        if len(f) != 5:
            raise FormatError(f"{where}: expected 5 YOLO fields (class cx cy w h), got {len(f)}")
        c = _integer(f[0], "class (field 1)", where, lo=0)
        cx, cy, w, h = (_number(v, n, where) for v, n in zip(f[1:], ("cx (field 2)", "cy (field 3)",
                                                                    "w (field 4)", "h (field 5)")))
        if not (0.0 <= cx <= 1.0 and 0.0 <= cy <= 1.0):
            raise FormatError(f"{where}: centre: expected cx, cy in 0..1 (fractions of the image), got {f[1]}, {f[2]}")
        if not (0.0 < w <= 1.0 and 0.0 < h <= 1.0):
            raise FormatError(f"{where}: size: expected w, h in (0, 1] (fractions of the image), got {f[3]}, {f[4]}")
        out.append((c, cx, cy, w, h))
    return np.asarray(out, np.float64).reshape(-1, 5)
