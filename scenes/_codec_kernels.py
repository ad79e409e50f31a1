"""The numba kernels of the file encoders: frame PNGs and compact flow (:mod:`scenes.formats`).

Frame PNGs (:func:`scenes.formats.encode_png_fast`):

PNG (ISO/IEC 15948, W3C PNG 2nd ed.) filters each row and deflates the filtered
rows as one zlib stream (RFC 1950 around RFC 1951). The frames are written with
the Average filter on every row and Huffman coding only (no string matching):
what zlib's ``Z_HUFFMAN_ONLY`` does, but zlib spends ~15 ms a 640x480 frame on it
(per byte: tally, then a bit writer through its pending buffer). Here one pass
counts the bytes of a block, a second writes their codes through a 64-bit
accumulator: ~6x less time for files within a few per cent of zlib's.

What the stream holds (RFC 1951): blocks of at most ``block`` filtered bytes, each
either dynamic Huffman (``BTYPE = 2``) over the 256 literals and end-of-block, no
lengths or distances, or stored (``BTYPE = 0``) when that is smaller (noise).
A dynamic block's header sends HLIT = 257 literal/length code lengths, HDIST = 2
distance code lengths (1 and 1: a complete code, unused, as decoders want one) and
the code-length code (3 bits a length, in the RFC's permuted order); the lengths
themselves follow coded without run-length codes 16-18. Codes are canonical
(RFC 1951 3.2.2), lengths at most 15 (7 for the code-length code): a tree deeper
than that is built again from the counts halved (rounding up), which keeps the code
complete and costs a little size in the rare blocks that need it.

Every kernel is deterministic and releases the GIL (``nogil``), so writer threads
encode while the rendering thread runs. A module of its own so that ``import
scenes`` does not import numba. Compiled kernels are cached on disk (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["avg_filter", "deflate_huffman", "deflate_bound", "flow_rowdelta_planes", "flow_xor", "flow_rowdelta_bits"]

# literals 0..255 and end-of-block 256; HLIT = 257
_N_LIT = 257
_EOB = 256


@numba.njit(cache=True, nogil=True)
def avg_filter(img, bpp, out):  # pragma: no cover - numba
    """PNG filter type 3 (Average) on every row, the filter-type byte in front.

    img : (H, R) uint8, R = width * bytes per pixel; bpp : bytes per pixel.
    out : (H, R + 1) uint8: ``out[y, 0] = 3``,
    ``out[y, 1 + i] = img[y, i] - floor((img[y, i - bpp] + img[y - 1, i]) / 2) mod 256``,
    with 0 for a byte left of the row or above the first row.
    """
    h, r = img.shape
    for y in range(h):
        out[y, 0] = 3
        for i in range(r):
            a = np.int32(img[y, i - bpp]) if i >= bpp else np.int32(0)
            b = np.int32(img[y - 1, i]) if y > 0 else np.int32(0)
            out[y, 1 + i] = np.uint8((np.int32(img[y, i]) - ((a + b) >> 1)) & 255)


@numba.njit(cache=True, nogil=True)
def _code_lengths(freq, max_bits):  # pragma: no cover - numba
    """Huffman code lengths (int64, 0 for an unused symbol) of ``freq``, none above ``max_bits``.

    At least two symbols get a code (a symbol of count 0 is given count 1 when fewer than two
    are used), so the code is complete. Ties are broken by symbol index (a stable sort), so the
    lengths depend on the counts only.
    """
    n = freq.shape[0]
    f = freq.copy()
    used = 0
    for s in range(n):
        if f[s] > 0:
            used += 1
    s = 0
    while used < 2:
        if f[s] == 0:
            f[s] = 1
            used += 1
        s += 1
    lengths = np.zeros(n, np.int64)
    while True:
        # leaves sorted by count, then the two-queue construction: internal nodes are made in
        # order of non-decreasing weight, so the smallest two are always at the queues' heads
        leaves = np.empty(used, np.int64)
        k = 0
        for s in range(n):
            if f[s] > 0:
                leaves[k] = s
                k += 1
        # by count, ties by symbol (stable): an insertion sort of at most 257 leaves. np.argsort's
        # mergesort gives the same order but took ~2.5 s of the first render's numba compilation
        for a in range(1, used):
            leaf = leaves[a]
            b = a
            while b > 0 and f[leaves[b - 1]] > f[leaf]:
                leaves[b] = leaves[b - 1]
                b -= 1
            leaves[b] = leaf
        m = used - 1  # internal nodes
        weight = np.empty(m, np.int64)
        parent = np.full(used + m, -1, np.int64)  # leaves 0..used-1 (sorted order), then nodes
        li = 0
        ni = 0
        for j in range(m):
            pick = np.empty(2, np.int64)
            wsum = 0
            for t in range(2):
                if li < used and (ni >= j or f[leaves[li]] <= weight[ni]):
                    pick[t] = li
                    wsum += f[leaves[li]]
                    li += 1
                else:
                    pick[t] = used + ni
                    wsum += weight[ni]
                    ni += 1
            weight[j] = wsum
            parent[pick[0]] = used + j
            parent[pick[1]] = used + j
        depth = np.zeros(used + m, np.int64)
        for j in range(m - 2, -1, -1):  # the root (last node) has depth 0
            depth[used + j] = depth[parent[used + j]] + 1
        deepest = 0
        for i in range(used):
            d = depth[parent[i]] + 1
            lengths[leaves[i]] = d
            deepest = max(deepest, d)
        if deepest <= max_bits:
            return lengths
        for s in range(n):
            if f[s] > 0:
                f[s] = (f[s] + 1) >> 1
        lengths[:] = 0


@numba.njit(cache=True, nogil=True)
def _canonical_codes(lengths):  # pragma: no cover - numba
    """RFC 1951 3.2.2 canonical codes of ``lengths``, bit-reversed for the LSB-first bit writer."""
    n = lengths.shape[0]
    bl_count = np.zeros(16, np.int64)
    for s in range(n):
        bl_count[lengths[s]] += 1
    bl_count[0] = 0
    next_code = np.zeros(16, np.int64)
    code = 0
    for b in range(1, 16):
        code = (code + bl_count[b - 1]) << 1
        next_code[b] = code
    codes = np.zeros(n, np.int64)
    for s in range(n):
        ln = lengths[s]
        if ln:
            c = next_code[ln]
            next_code[ln] += 1
            rev = 0
            for _ in range(ln):
                rev = (rev << 1) | (c & 1)
                c >>= 1
            codes[s] = rev
    return codes


@numba.njit(cache=True, nogil=True, inline="always")
def _put_bits(out, o, acc, nbits, code, length):  # pragma: no cover - numba
    """Append ``length`` bits of ``code`` (LSB first) to the bit accumulator; flush 4 whole bytes at 32 bits.

    Returns the new (o, acc, nbits).
    """
    acc |= code << nbits
    nbits += length
    if nbits >= 32:
        out[o] = acc & 255
        out[o + 1] = (acc >> 8) & 255
        out[o + 2] = (acc >> 16) & 255
        out[o + 3] = (acc >> 24) & 255
        o += 4
        acc >>= 32
        nbits -= 32
    return o, acc, nbits


def deflate_bound(n_bytes: int, block: int) -> int:
    """Bytes :func:`deflate_huffman` may write at most for ``n_bytes`` input in blocks of ``block``."""
    n_blocks = max(1, -(-n_bytes // block))
    # a block is never larger than stored (5 bytes + data) by more than its header's ~300 bytes
    return n_bytes + n_blocks * 400 + 16


@numba.njit(cache=True, nogil=True)
def deflate_huffman(data, block, out):  # pragma: no cover - numba
    """RFC 1951 deflate of ``data`` (uint8, 1-D) by Huffman coding only; returns the bytes in ``out``.

    data : (N,) uint8; block : bytes per block (<= 65535, the stored block's limit);
    out : uint8 of at least ``deflate_bound(N, block)`` bytes. No zlib header or checksum.
    """
    n = data.shape[0]
    # RFC 1951 3.2.7: the order in which the code-length code's lengths are sent
    cl_order = np.array([16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15], np.int64)
    acc = 0  # bits not yet written, LSB first; never more than 47 of them
    nbits = 0
    o = 0
    start = 0
    while True:
        end = min(n, start + block)
        final = 1 if end == n else 0
        # four tallies, so that consecutive equal bytes do not wait on each other's increment
        tally = np.zeros((4, 257), np.int64)
        i = start
        while i + 4 <= end:
            tally[0, data[i]] += 1
            tally[1, data[i + 1]] += 1
            tally[2, data[i + 2]] += 1
            tally[3, data[i + 3]] += 1
            i += 4
        while i < end:
            tally[0, data[i]] += 1
            i += 1
        freq = tally[0] + tally[1] + tally[2] + tally[3]
        freq[256] = 1
        lit_len = _code_lengths(freq, 15)
        lit_code = _canonical_codes(lit_len)
        # the 257 literal/length lengths and the 2 distance lengths, coded by the code-length code
        seq = np.empty(259, np.int64)
        for q in range(257):  # not ``seq[:257] = lit_len``: its size check compiles numba's string code (~1.5 s)
            seq[q] = lit_len[q]
        seq[257] = 1
        seq[258] = 1
        cl_freq = np.zeros(19, np.int64)
        for v in seq:
            cl_freq[v] += 1
        cl_len = _code_lengths(cl_freq, 7)
        cl_code = _canonical_codes(cl_len)
        hclen = 19
        while hclen > 4 and cl_len[cl_order[hclen - 1]] == 0:
            hclen -= 1
        header_bits = 3 + 5 + 5 + 4 + 3 * hclen
        for v in seq:
            header_bits += cl_len[v]
        data_bits = lit_len[256]
        for s in range(256):
            data_bits += freq[s] * lit_len[s]
        stored_bits = 3 + 7 + 32 + 8 * (end - start)  # header, worst-case padding, LEN/NLEN, data
        if header_bits + data_bits >= stored_bits:
            acc |= (final | (0 << 1)) << nbits
            nbits += 3
            while nbits > 0:  # to the byte boundary
                out[o] = acc & 255
                o += 1
                acc >>= 8
                nbits -= 8
            acc = 0
            nbits = 0
            ln = end - start
            out[o] = ln & 255
            out[o + 1] = ln >> 8
            out[o + 2] = (~ln) & 255
            out[o + 3] = ((~ln) >> 8) & 255
            o += 4
            for i in range(start, end):
                out[o] = data[i]
                o += 1
        else:
            acc |= (final | (2 << 1)) << nbits
            nbits += 3
            acc |= ((_N_LIT - 257) | (1 << 5) | ((hclen - 4) << 10)) << nbits  # HLIT, HDIST = 2 codes, HCLEN
            nbits += 14
            for j in range(hclen):
                o, acc, nbits = _put_bits(out, o, acc, nbits, cl_len[cl_order[j]], 3)
            for v in seq:
                o, acc, nbits = _put_bits(out, o, acc, nbits, cl_code[v], cl_len[v])
            for i in range(start, end):
                s = data[i]
                o, acc, nbits = _put_bits(out, o, acc, nbits, lit_code[s], lit_len[s])
            acc |= lit_code[_EOB] << nbits
            nbits += lit_len[_EOB]
            while nbits >= 8:
                out[o] = acc & 255
                o += 1
                acc >>= 8
                nbits -= 8
        start = end
        if final:
            break
    if nbits > 0:
        out[o] = acc & 255
        o += 1
    return o


@numba.njit(cache=True, nogil=True)
def flow_rowdelta_planes(bits_c, planes):  # pragma: no cover - numba
    """The byte planes of the row differences of the camera flow's bits (compact flow codec).

    bits_c : (H, W, 2) uint32, the float32 bits of ``flow_camera``. Out: planes (4, 2, H, W) uint8,
    ``planes[k, c, y, x]`` = byte k (little-endian) of ``bits_c[y, x, c] - bits_c[y, x - 1, c]``
    modulo 2**32 (``bits_c[y, 0, c]`` itself in the first column): what
    ``_byte_planes(delta)`` gives, in one pass instead of a copy, a subtraction and a transpose.
    """
    h, w, nc = bits_c.shape
    for y in range(h):
        for c in range(nc):
            for x in range(w):  # no carried state: the compiler vectorises it
                d = bits_c[y, x, c] - (bits_c[y, x - 1, c] if x > 0 else np.uint32(0))
                planes[0, c, y, x] = np.uint8(d & np.uint32(255))
                planes[1, c, y, x] = np.uint8((d >> np.uint32(8)) & np.uint32(255))
                planes[2, c, y, x] = np.uint8((d >> np.uint32(16)) & np.uint32(255))
                planes[3, c, y, x] = np.uint8((d >> np.uint32(24)) & np.uint32(255))


@numba.njit(cache=True, nogil=True)
def flow_xor(bits, bits_c):  # pragma: no cover - numba
    """Where the bits of two flat uint32 arrays differ and their XOR: ``(index int64 (K,), xor uint32 (K,))``.

    ``np.flatnonzero(bits ^ bits_c)`` and the XOR there, in two passes without the full XOR array.
    """
    n = bits.shape[0]
    k = 0
    for i in range(n):
        if bits[i] != bits_c[i]:
            k += 1
    index = np.empty(k, np.int64)
    xor = np.empty(k, np.uint32)
    j = 0
    for i in range(n):
        x = bits[i] ^ bits_c[i]
        if x != 0:
            index[j] = i
            xor[j] = x
            j += 1
    return index, xor



@numba.njit(cache=True, nogil=True)
def flow_rowdelta_bits(planes, bits_c):  # pragma: no cover - numba
    """The inverse of :func:`flow_rowdelta_planes`: the camera flow's bits from the byte planes.

    planes : (4, 2, H, W) uint8. Out: bits_c (H, W, 2) uint32, the running sum along each row of
    ``planes[3] << 24 | planes[2] << 16 | planes[1] << 8 | planes[0]`` modulo 2**32: what
    the uint32 ``np.cumsum`` along x of those words gives (component last),
    in one pass instead of four arrays and a transpose.
    """
    nc, h, w = planes.shape[1], planes.shape[2], planes.shape[3]
    for y in range(h):
        for c in range(nc):
            acc = np.uint32(0)
            for x in range(w):
                d = ((np.uint32(planes[3, c, y, x]) << np.uint32(24)) | (np.uint32(planes[2, c, y, x]) << np.uint32(16))
                     | (np.uint32(planes[1, c, y, x]) << np.uint32(8)) | np.uint32(planes[0, c, y, x]))
                acc = np.uint32(acc + d)  # wraps modulo 2**32, as the uint32 cumsum
                bits_c[y, x, c] = acc
