"""EPE histograms: the totals quantiles are aggregated from, and their compact binary form.

Fixed bins of :data:`HIST_BIN_PX` = 0.01 px from 0 to :data:`HIST_MAX_PX` = 100 px,
plus one overflow bin. :func:`encode_hist` / :func:`decode_hist` / :func:`add_hist`
are the only code that knows the ``hist`` column's layout.
"""

from __future__ import annotations

import math
import struct
import zlib

import numpy as np

HIST_BIN_PX = 0.01
HIST_MAX_PX = 100.0
HIST_NBINS = int(round(HIST_MAX_PX / HIST_BIN_PX)) + 1  # the last bin is the overflow


def epe_histogram(epe: np.ndarray) -> np.ndarray:
    """Counts of ``epe`` in :data:`HIST_NBINS` bins of 0.01 px, the last one for >= 100 px. int64."""
    idx = np.minimum(np.floor(np.asarray(epe, np.float64).ravel() / HIST_BIN_PX), HIST_NBINS - 1)
    return np.bincount(idx.astype(np.int64), minlength=HIST_NBINS).astype(np.int64)


# header of an encoded histogram: format 1, bytes per count (4 or 8), first non-empty bin, bins stored
_HIST_HEADER = struct.Struct("<BBII")
_HIST_FORMAT = 1


def encode_hist(counts: np.ndarray) -> bytes:
    """Compact binary form of a histogram (the results table's ``hist`` column); ``b""`` when empty.

    The counts from the first to the last non-empty bin, little-endian uint32 (uint64 if a
    count needs it), zlib-compressed (level 1), after a 10-byte header (format, bytes per
    count, first bin, number of bins). A 640x480 pair's histogram takes about 0.5 kB, a
    fifth of the ``"bin:count ..."`` text that schema v1 stored, and decodes without parsing.
    """
    counts = np.asarray(counts)
    # first and last non-empty bin by argmax (np.flatnonzero of 10001 bins costs 5 times more)
    nz = counts != 0
    lo = int(nz.argmax()) if nz.size else 0
    if nz.size == 0 or not nz[lo]:
        return b""
    hi = nz.size - int(nz[::-1].argmax())
    part = counts[lo:hi]
    width = 4 if int(part.max()) < 2 ** 32 else 8
    payload = part.astype("<u4" if width == 4 else "<u8").tobytes()
    return _HIST_HEADER.pack(_HIST_FORMAT, width, lo, hi - lo) + zlib.compress(payload, 1)


def decode_hist(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_hist`: dense ``(HIST_NBINS,)`` int64 counts (``b""`` or None: all zero)."""
    out = np.zeros(HIST_NBINS, np.int64)
    add_hist(out, data)
    return out


def add_hist(total: np.ndarray, data: bytes) -> np.ndarray:
    """Add the histogram encoded in ``data`` (:func:`encode_hist`) into the dense int64 ``total``, in place."""
    if data is None or len(data) == 0:
        return total
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ValueError(f"hist: expected bytes from encode_hist, got {type(data).__name__}")
    try:
        fmt, width, lo, n = _HIST_HEADER.unpack_from(data)
        part = np.frombuffer(zlib.decompress(data[_HIST_HEADER.size:]), "<u4" if width == 4 else "<u8")
    except (struct.error, zlib.error) as exc:
        raise ValueError(f"hist: not an encoded histogram ({exc})") from None
    if fmt != _HIST_FORMAT or width not in (4, 8) or part.size != n or lo + n > HIST_NBINS:
        raise ValueError(f"hist: expected format {_HIST_FORMAT} with bins 0..{HIST_NBINS - 1}, got format {fmt}, "
                         f"{width}-byte counts, bins {lo}..{lo + n - 1} ({part.size} stored)")
    total[lo:lo + n] += part.astype(np.int64)
    return total


def hist_quantile(counts: np.ndarray, q: float) -> float:
    """The ``q`` quantile read at the centre of the bin holding it (within 0.005 px); NaN if empty.

    In the overflow bin it reads :data:`HIST_MAX_PX` (a floor).
    """
    total = int(counts.sum())
    if total == 0:
        return float("nan")
    # the sample of rank ceil(q * n) (1-based), the nearest-rank definition
    rank = max(1, math.ceil(q * total))
    b = int(np.searchsorted(np.cumsum(counts), rank))
    if b >= HIST_NBINS - 1:
        return HIST_MAX_PX
    return (b + 0.5) * HIST_BIN_PX
