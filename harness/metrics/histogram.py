"""EPE histograms: the totals quantiles are aggregated from, and their compact binary form.

Fixed bins of :data:`HIST_BIN_PX` = 0.01 px from 0 to :data:`HIST_MAX_PX` = 100 px,
plus one overflow bin. The overflow bin's samples are kept beside it as a *tail*: a
sparse histogram of the same 0.01 px bins above 100 px (:func:`overflow_tail`), so that
a quantile that falls there is read from them (within half a bin, as below 100 px), not
floored at 100 px. They are few on most scenes (none on nearly every synthetic pair),
and a sparse tail holds at most one entry per distinct bin. :func:`encode_hist` /
:func:`decode_hist` / :func:`decode_tail` / :func:`add_hist` are the only code that knows
the ``hist`` column's layout.

A tail is a pair ``(bins, counts)``: int64 bin indices ``floor(epe / HIST_BIN_PX)``
(>= ``HIST_NBINS - 1``), ascending and unique, and their int64 counts; :data:`NO_TAIL`
is the empty one. A histogram's tail is *complete* when its counts sum to the overflow
bin's count; one written before tails were kept (format 1 with an overflow) has none.
"""

from __future__ import annotations

import math
import struct
import zlib

import numpy as np

HIST_BIN_PX = 0.01
HIST_MAX_PX = 100.0
HIST_NBINS = int(round(HIST_MAX_PX / HIST_BIN_PX)) + 1  # the last bin is the overflow
NO_TAIL = (np.zeros(0, np.int64), np.zeros(0, np.int64))
_MAX_BIN = 2 ** 62  # a finite EPE beyond 4.6e16 px shares the last representable bin


def epe_histogram(epe: np.ndarray) -> np.ndarray:
    """Counts of ``epe`` in :data:`HIST_NBINS` bins of 0.01 px, the last one for >= 100 px. int64."""
    idx = np.minimum(np.floor(np.asarray(epe, np.float64).ravel() / HIST_BIN_PX), HIST_NBINS - 1)
    return np.bincount(idx.astype(np.int64), minlength=HIST_NBINS).astype(np.int64)


def overflow_tail(epe: np.ndarray, *, collected: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The tail of ``epe`` (px, any shape): its samples of the overflow bin as ``(bins, counts)``.

    Bins are ``floor(epe / HIST_BIN_PX)``, the division :func:`epe_histogram` bins by, so the
    tail holds exactly the samples it puts in its last bin. With ``collected`` the samples are
    known to be the overflow bin's (gathered by the bin a pass gave them): none is dropped, and
    one that the division puts a bin lower is counted in the first overflow bin.
    """
    k = np.floor(np.asarray(epe, np.float64).ravel() / HIST_BIN_PX)
    k = np.maximum(k, HIST_NBINS - 1) if collected else k[k >= HIST_NBINS - 1]
    if k.size == 0:
        return NO_TAIL
    bins, counts = np.unique(np.minimum(k, _MAX_BIN).astype(np.int64), return_counts=True)
    return bins, counts.astype(np.int64)


def merge_tails(tails) -> tuple[np.ndarray, np.ndarray]:
    """The sum of several tails (an iterable of ``(bins, counts)``), as one tail."""
    tails = [t for t in tails if len(t[0])]
    if not tails:
        return NO_TAIL
    if len(tails) == 1:
        return tails[0]
    bins = np.concatenate([t[0] for t in tails])
    counts = np.concatenate([t[1] for t in tails])
    u, inv = np.unique(bins, return_inverse=True)
    return u, np.bincount(inv, weights=counts, minlength=len(u)).astype(np.int64)


# header of an encoded histogram: format (1, or 2 with a tail), bytes per count (4 or 8), first non-empty bin,
# bins stored; format 2 adds the number of tail bins
_HIST_HEADER = struct.Struct("<BBII")
_TAIL_HEADER = struct.Struct("<I")
_HIST_FORMAT = 1
_HIST_FORMAT_TAIL = 2


def encode_hist(counts: np.ndarray, *, tail: tuple[np.ndarray, np.ndarray] | None = None) -> bytes:
    """Compact binary form of a histogram (the results table's ``hist`` column); ``b""`` when empty.

    The counts from the first to the last non-empty bin, little-endian uint32 (uint64 if a
    count needs it), zlib-compressed (level 1), after a 10-byte header (format, bytes per
    count, first bin, number of bins). A 640x480 pair's histogram takes about 0.5 kB, a
    fifth of the ``"bin:count ..."`` text that schema v1 stored, and decodes without parsing.

    With a non-empty ``tail`` (:func:`overflow_tail`, complete: its counts sum to the
    overflow bin's) the format is 2: a 4-byte count K of tail bins follows the header, and
    the compressed payload carries, after the counts, the K bins (the first, then the steps
    between them) and their K counts, uint64 each. Without one the bytes are format 1's,
    as before tails were kept.
    """
    counts = np.asarray(counts)
    # first and last non-empty bin by argmax (np.flatnonzero of 10001 bins costs 5 times more)
    nz = counts != 0
    lo = int(nz.argmax()) if nz.size else 0
    if nz.size == 0 or not nz[lo]:
        if tail is not None and len(tail[0]):
            raise ValueError(f"tail: expected none for an empty histogram, got {int(np.sum(tail[1]))} samples")
        return b""
    hi = nz.size - int(nz[::-1].argmax())
    part = counts[lo:hi]
    width = 4 if int(part.max()) < 2 ** 32 else 8
    payload = part.astype("<u4" if width == 4 else "<u8").tobytes()
    if tail is None or len(tail[0]) == 0:
        return _HIST_HEADER.pack(_HIST_FORMAT, width, lo, hi - lo) + zlib.compress(payload, 1)
    bins, tc = (np.asarray(a, np.int64) for a in tail)
    if bins.shape != tc.shape or bins.ndim != 1 or (np.diff(bins) <= 0).any() or bins[0] < HIST_NBINS - 1:
        raise ValueError(f"tail: expected ascending unique bins >= {HIST_NBINS - 1} with one count each, got "
                         f"{bins.size} bins from {int(bins[0])} and {tc.size} counts")
    if len(counts) != HIST_NBINS or int(tc.sum()) != int(counts[-1]):
        raise ValueError(f"tail: expected the {int(counts[-1]) if len(counts) == HIST_NBINS else '?'} samples of the "
                         f"overflow bin, got {int(tc.sum())}")
    steps = np.diff(bins, prepend=np.int64(0))
    payload += steps.astype("<u8").tobytes() + tc.astype("<u8").tobytes()
    return (_HIST_HEADER.pack(_HIST_FORMAT_TAIL, width, lo, hi - lo) + _TAIL_HEADER.pack(bins.size)
            + zlib.compress(payload, 1))


def decode_hist(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_hist`: dense ``(HIST_NBINS,)`` int64 counts (``b""`` or None: all zero)."""
    out = np.zeros(HIST_NBINS, np.int64)
    add_hist(out, data)
    return out


def decode_tail(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The tail stored in ``data`` (:func:`encode_hist`); :data:`NO_TAIL` when it has none."""
    tails: list = []
    add_hist(np.zeros(HIST_NBINS, np.int64), data, tails=tails)
    return merge_tails(tails)


def add_hist(total: np.ndarray, data: bytes, *, tails: list | None = None) -> np.ndarray:
    """Add the histogram encoded in ``data`` (:func:`encode_hist`) into the dense int64 ``total``, in place.

    With ``tails`` (a list), the tail ``data`` holds, if any, is appended to it (for :func:`merge_tails`).
    """
    if data is None or len(data) == 0:
        return total
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ValueError(f"hist: expected bytes from encode_hist, got {type(data).__name__}")
    k = 0
    try:
        fmt, width, lo, n = _HIST_HEADER.unpack_from(data)
        start = _HIST_HEADER.size
        if fmt == _HIST_FORMAT_TAIL:
            (k,) = _TAIL_HEADER.unpack_from(data, start)
            start += _TAIL_HEADER.size
        raw = zlib.decompress(data[start:])
    except (struct.error, zlib.error) as exc:
        raise ValueError(f"hist: not an encoded histogram ({exc})") from None
    dense_bytes = n * width if width in (4, 8) else -1
    if (fmt not in (_HIST_FORMAT, _HIST_FORMAT_TAIL) or width not in (4, 8) or lo + n > HIST_NBINS
            or len(raw) != dense_bytes + 16 * k):
        stored = len(raw) // width if width in (4, 8) else len(raw)
        raise ValueError(f"hist: expected format {_HIST_FORMAT} or {_HIST_FORMAT_TAIL} with bins 0..{HIST_NBINS - 1}, "
                         f"got format {fmt}, {width}-byte counts, bins {lo}..{lo + n - 1} ({stored} stored)")
    part = np.frombuffer(raw, "<u4" if width == 4 else "<u8", count=n)
    total[lo:lo + n] += part.astype(np.int64)
    if k and tails is not None:
        rest = np.frombuffer(raw, "<u8", offset=dense_bytes).astype(np.int64)
        tails.append((np.cumsum(rest[:k]), rest[k:]))
    return total


def hist_quantile(counts: np.ndarray, q: float, *, tail: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """The ``q`` quantile read at the centre of the bin holding it (within 0.005 px); NaN if empty.

    In the overflow bin it is read from the complete ``tail`` (:func:`overflow_tail`) at the
    centre of its bin, as below; without one (or with an incomplete one) it reads
    :data:`HIST_MAX_PX`, a floor.
    """
    total = int(counts.sum())
    if total == 0:
        return float("nan")
    # the sample of rank ceil(q * n) (1-based), the nearest-rank definition
    rank = max(1, math.ceil(q * total))
    cum = np.cumsum(counts)
    b = int(np.searchsorted(cum, rank))
    if b >= HIST_NBINS - 1:
        if tail is None or len(tail[0]) == 0 or int(tail[1].sum()) != int(counts[-1]):
            return HIST_MAX_PX
        below = int(cum[-2]) if len(cum) > 1 else 0
        j = int(np.searchsorted(np.cumsum(tail[1]), rank - below))
        return (int(tail[0][j]) + 0.5) * HIST_BIN_PX
    return (b + 0.5) * HIST_BIN_PX


# per-alpha totals of a HOTA row (harness.metrics.mot.hota_rows): format 16, the number of alphas, then
# the numerators and the denominators, float64 little-endian
_ALPHA_HEADER = struct.Struct("<BB")
_ALPHA_FORMAT = 16


def encode_alpha_totals(num: np.ndarray, den: np.ndarray) -> bytes:
    """The ``hist`` bytes of a HOTA row: its per-alpha numerators and denominators, (K,) float each."""
    num, den = np.asarray(num, "<f8").ravel(), np.asarray(den, "<f8").ravel()
    if num.shape != den.shape or not 0 < num.size < 256:
        raise ValueError(f"alpha totals: expected two arrays of the same size (1..255), got {num.size} and {den.size}")
    return _ALPHA_HEADER.pack(_ALPHA_FORMAT, num.size) + num.tobytes() + den.tobytes()


def decode_alpha_totals(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_alpha_totals`: ``(num, den)`` float64."""
    try:
        fmt, k = _ALPHA_HEADER.unpack_from(data)
    except (struct.error, TypeError) as exc:
        raise ValueError(f"alpha totals: not encoded alpha totals ({exc})") from None
    if fmt != _ALPHA_FORMAT or len(data) != _ALPHA_HEADER.size + 16 * k:
        raise ValueError(f"alpha totals: expected format {_ALPHA_FORMAT} with 2 x {k} float64, got format {fmt}, "
                         f"{len(data)} bytes")
    a = np.frombuffer(bytes(data), "<f8", offset=_ALPHA_HEADER.size).astype(np.float64)
    return a[:k], a[k:]
