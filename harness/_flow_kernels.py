"""The numba kernels of the one-pass flow scoring (:func:`harness.metrics.score_pair`).

A module of their own so that ``import harness.metrics`` (the CLI, the reports) does
not import numba; the scoring imports them on first use. Compiled kernels are cached
on disk (``cache=True``), as in :mod:`algorithms`.

Both motions of a pair are scored in one pass over the pixels: the total motion
compares ``e`` with ``t``, the local motion ``e - g`` (computed here in float32, as
``np.float32(e) - np.float32(g)``) with ``t_local``. Motion index 0 is total, 1 local.
Each image row is done in two steps: the arithmetic of every pixel (EPE, angular
error) in a branch-free loop that the compiler turns into SIMD code, then the
counting (histogram, totals, outliers) pixel by pixel.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["pair_totals", "values_in_bins", "truth_local", "acos", "acos_array"]

# A pixel's EPE is computed as sqrt(du^2 + dv^2), within 2 ulp of hypot's (libm hypot costs
# more than the rest of the pass). Where that could change a decision (a histogram bin edge,
# which includes the 1, 3 and 5 px outlier limits, or the Fl limit), the pixel's EPE is
# recomputed with hypot, as endpoint_error has it: bins and counts are exactly theirs.
_EDGE = 1e-9

# columns of the pattern totals (stats[motion, pattern, :])
N, S_EPE, S_SQ, S_AE, K1, K3, K5, KFL, KCOV = range(9)

# arcsin series, arcsin x = x + sum_{n>=1} c_n x^(2n+1), c_n = (2n)! / (4^n (n!)^2 (2n+1)); for
# |x| <= 1/2 the terms past n = 24 add less than 1e-17 (relative) to the result
_ASIN_C = tuple(math.comb(2 * n, n) / (4 ** n * (2 * n + 1)) for n in range(1, 25))
_TO_DEG = 180.0 / math.pi  # as np.degrees


@numba.njit(cache=True, inline="always", error_model="numpy")
def acos(cos):  # pragma: no cover - numba
    """arccos of c in [-1, 1], branch-free (SIMD in a loop); within 2 ulp of libm's / numpy's.

    acos c = pi/2 - asin c for |c| <= 1/2, 2 asin sqrt((1 - c) / 2) for c > 1/2,
    pi - 2 asin sqrt((1 + c) / 2) for c < -1/2, asin by its series in x^2 <= 1/4.
    """
    a = abs(cos)
    big = a > 0.5
    x = math.sqrt(0.5 * (1.0 - a)) if big else cos
    z = x * x
    # Estrin's scheme (a tree of depth 5 rather than Horner's chain of 23): the loop over the
    # pixels runs in SIMD registers and is not held up by the latency of one long chain;
    # every term is positive, so the order of the sums costs no accuracy
    c = _ASIN_C
    z2 = z * z
    z4 = z2 * z2
    z8 = z4 * z4
    a0, a1, a2, a3 = c[0] + c[1] * z, c[2] + c[3] * z, c[4] + c[5] * z, c[6] + c[7] * z
    a4, a5, a6, a7 = c[8] + c[9] * z, c[10] + c[11] * z, c[12] + c[13] * z, c[14] + c[15] * z
    a8, a9, a10, a11 = c[16] + c[17] * z, c[18] + c[19] * z, c[20] + c[21] * z, c[22] + c[23] * z
    b0, b1, b2 = a0 + a1 * z2, a2 + a3 * z2, a4 + a5 * z2
    b3, b4, b5 = a6 + a7 * z2, a8 + a9 * z2, a10 + a11 * z2
    d0, d1, d2 = b0 + b1 * z4, b2 + b3 * z4, b4 + b5 * z4
    p = d0 + (d1 + d2 * z8) * z8
    s = x + x * z * p  # asin x
    r_big = 2.0 * s if cos > 0.0 else math.pi - 2.0 * s
    r_small = 0.5 * math.pi - s
    return r_big if big else r_small


@numba.njit(cache=True, error_model="numpy")
def acos_array(c, out):  # pragma: no cover - numba
    """:func:`acos` of every element of the 1-D ``c`` into ``out`` (for tests and benchmarks)."""
    for i in range(c.size):
        out[i] = acos(c[i])


@numba.njit(cache=True, error_model="numpy")
def _acos_deg(c):  # pragma: no cover - numba
    """In place: the cosines ``c`` (1-D) become their angles in degrees (``np.degrees(np.arccos(c))`` to 2 ulp)."""
    for i in range(c.size):
        c[i] = acos(c[i]) * _TO_DEG


@numba.njit(cache=True, inline="always", error_model="numpy")
def _epe(eu, ev, tu, tv):  # pragma: no cover - numba
    """EPE in its sqrt form (float64 in)."""
    du, dv = eu - tu, ev - tv
    return math.sqrt(du * du + dv * dv)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _cos(eu, ev, tu, tv):  # pragma: no cover - numba
    """Clipped cosine of the angular error (float64 in), as angular_error_deg computes it."""
    # Barron 1994: angle between (u_e, v_e, 1) and (u_t, v_t, 1)
    num = eu * tu + ev * tv + 1.0
    den = math.sqrt((eu * eu + ev * ev + 1.0) * (tu * tu + tv * tv + 1.0))
    return min(max(num / den, -1.0), 1.0)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _bin(epe, per_bin, nbins):  # pragma: no cover - numba
    """(histogram bin, near an edge?) of an EPE, branch-free: NaN (unscored) and >= 100 px give the last bin.

    ``per_bin`` is 1 / bin_px: the product is within an ulp of the quotient that decides the bin,
    so the two can only disagree near an edge, where :func:`_bin_exact` divides.
    """
    q = epe * per_bin
    kf = np.floor(q)  # a float: NaN stays NaN (math.floor would give an integer)
    frac = q - kf
    kf = kf if kf < nbins - 1.0 else nbins - 1.0
    return np.int32(kf), (frac < _EDGE) | (frac > 1.0 - _EDGE)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _bin_exact(du, dv, bin_px, nbins):  # pragma: no cover - numba
    """(EPE, bin) of a pixel near a bin edge: EPE by hypot, as endpoint_error, so that the bin is its bin."""
    epe = math.hypot(du, dv)
    kf = np.floor(epe / bin_px)  # clamped as a float: a huge EPE would overflow an integer
    return epe, np.int32(kf if kf < nbins - 1.0 else nbins - 1.0)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _fl(epe, du, dv, tu, tv):  # pragma: no cover - numba
    """KITTI Fl of a pixel with EPE > 3 px: also > 5 % of |w_true| (1.0 or 0.0)."""
    if tu * tu + tv * tv < 3599.0:  # 0.05 |w_true| < 3 px < EPE, without the hypot
        return 1.0
    limit = 0.05 * math.hypot(tu, tv)
    if abs(epe - limit) <= _EDGE * limit:
        epe = math.hypot(du, dv)
    return 1.0 if epe > limit else 0.0


@numba.njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _run_totals(stats, b, epe, ang, ve, x0, x1):  # pragma: no cover - numba
    """Add the totals of the pixels x0 .. x1 - 1 of a row (one pattern ``b``) to ``stats[b]``.

    The sums are reassociated (SIMD): they differ from a sequential sum by rounding only.
    """
    s1 = s2 = sa = k1 = k3 = k5 = kc = 0.0
    for x in range(x0, x1):
        v = epe[x]
        s1 += v
        s2 += v * v
        sa += ang[x]
        k1 += 1.0 if v > 1.0 else 0.0
        k3 += 1.0 if v > 3.0 else 0.0
        k5 += 1.0 if v > 5.0 else 0.0
        kc += 1.0 if ve[x] else 0.0
    stats[b, N] += x1 - x0
    stats[b, S_EPE] += s1
    stats[b, S_SQ] += s2
    stats[b, S_AE] += sa
    stats[b, K1] += k1
    stats[b, K3] += k3
    stats[b, K5] += k5
    stats[b, KCOV] += kc


@numba.njit(cache=True, error_model="numpy")
def _count_row(e, g, t, bits, ve, motion, bin_px, nbins, epe, ang, k, edge, stats, hist, bins,
               rare):  # pragma: no cover - numba
    """Count the scored pixels of a row of one motion from its per-pixel errors (epe, ang, k, edge).

    ``bins`` holds the row's bins already (but for the pixels near an edge: set here); ``rare``
    is the number of the row's pixels near an edge or with EPE > 3 px (0: none to look at).
    """
    w = bits.size
    for x in range(w if rare else 0):
        if bits[x] != 0 and (edge[x] or epe[x] > 3.0):  # rare: hypot decides (bin edge, Fl)
            if motion == 0:
                tu, tv = np.float64(t[x, 0]), np.float64(t[x, 1])
                du, dv = np.float64(e[x, 0]) - tu, np.float64(e[x, 1]) - tv
            else:
                tu, tv = np.float64(t[x, 0]), np.float64(t[x, 1])
                du, dv = np.float64(e[x, 0] - g[x, 0]) - tu, np.float64(e[x, 1] - g[x, 1]) - tv
            if edge[x]:
                epe[x], k[x] = _bin_exact(du, dv, bin_px, nbins)
                bins[x] = k[x]
            if epe[x] > 3.0:
                stats[bits[x], KFL] += _fl(epe[x], du, dv, tu, tv)
    for x in range(w):
        hist[bits[x], k[x]] += 1  # pattern 0 (not scored) is counted too, and ignored
    x0 = 0
    while x0 < w:
        b = bits[x0]
        x1 = x0 + 1
        while x1 < w and bits[x1] == b:
            x1 += 1
        if b != 0:
            _run_totals(stats, b, epe, ang, ve, x0, x1)
        x0 = x1


@numba.njit(cache=True, error_model="numpy")
def pair_totals(e, g, t, tl, bits, bits_l, valid_est, bin_px, nbins, stats, hist, bins):  # pragma: no cover
    """One pass over the pixels: totals and EPE histogram of every membership pattern, both motions.

    e, g : (H, W, 2) float32 estimate (total) and its global field; t, tl : (H, W, 2) float32
    truth, total and local (all four C-contiguous); bits, bits_l : (H, W) uint8, bit r set when
    the pixel is scored in region r for the total / local motion (0: not scored); valid_est :
    (H, W) bool.
    Out: stats (2, 2**R, 9) float64 (columns N .. KCOV) and hist (2, 2**R, nbins) int32, row
    ``[m, b]`` for the pixels of motion m whose bits equal b (a region sums its patterns; row 0
    is garbage); bins (2, H, W) uint16, each scored pixel's bin (for :func:`values_in_bins`).
    Returns the number of pixels whose estimate, total or local, is not finite (the caller
    raises; the totals are then incomplete).
    """
    h, w = bits.shape
    per_bin = 1.0 / bin_px
    # the fields as (H, 2 W) rows, u and v interleaved: indexed [y, x, c] the compiler knows the
    # pixel stride only at run time and vectorises the loop below for a stride of one float (never
    # taken: the scalar loop ran, 3 ms more per pair); with [y, 2 x + c] the stride is a constant
    e2, g2, t2, tl2 = e.reshape(h, 2 * w), g.reshape(h, 2 * w), t.reshape(h, 2 * w), tl.reshape(h, 2 * w)
    epe_t, ang_t, k_t, edge_t = np.empty(w), np.empty(w), np.empty(w, np.int32), np.empty(w, np.bool_)
    epe_l, ang_l, k_l, edge_l = np.empty(w), np.empty(w), np.empty(w, np.int32), np.empty(w, np.bool_)
    bad = 0
    bins_t, bins_l = bins[0], bins[1]
    for y in range(h):
        er, gr, tr, tlr, bt, bl = e2[y], g2[y], t2[y], tl2[y], bins_t[y], bins_l[y]
        # errors of every pixel of the row (NaN where the truth is unknown), branch-free; the
        # arithmetic and the arccos in separate loops, each of which the compiler vectorises;
        # the bins are stored here (in SIMD) and the pixels that _count_row must look at one
        # by one (near a bin edge, or EPE > 3 px for Fl) counted, so that a row without any skips it
        rare_t = rare_l = 0
        for x in range(w):
            e0, e1 = er[2 * x], er[2 * x + 1]
            # local estimate in float32, as np.float32(e) - np.float32(g)
            l0, l1 = e0 - gr[2 * x], e1 - gr[2 * x + 1]
            fin = (e0 - e0) + (e1 - e1) + (l0 - l0) + (l1 - l1)  # NaN unless all four are finite
            bad += fin != fin
            eu, ev, tu, tv = np.float64(e0), np.float64(e1), np.float64(tr[2 * x]), np.float64(tr[2 * x + 1])
            epe_t[x] = epe = _epe(eu, ev, tu, tv)
            k_t[x], edge_t[x] = kx, near = _bin(epe, per_bin, nbins)
            bt[x] = kx
            rare_t += near | (epe > 3.0)
            ang_t[x] = _cos(eu, ev, tu, tv)
            eu, ev, tu, tv = np.float64(l0), np.float64(l1), np.float64(tlr[2 * x]), np.float64(tlr[2 * x + 1])
            epe_l[x] = epe = _epe(eu, ev, tu, tv)
            k_l[x], edge_l[x] = kx, near = _bin(epe, per_bin, nbins)
            bl[x] = kx
            rare_l += near | (epe > 3.0)
            ang_l[x] = _cos(eu, ev, tu, tv)
        _acos_deg(ang_t)
        _acos_deg(ang_l)
        _count_row(e[y], g[y], t[y], bits[y], valid_est[y], 0, bin_px, nbins, epe_t, ang_t, k_t, edge_t,
                   stats[0], hist[0], bt, rare_t)
        _count_row(e[y], g[y], tl[y], bits_l[y], valid_est[y], 1, bin_px, nbins, epe_l, ang_l, k_l, edge_l,
                   stats[1], hist[1], bl, rare_l)
    return bad


@numba.njit(cache=True, error_model="numpy")
def values_in_bins(e, g, t, tl, bits, bits_l, bins, slot, start, out):  # pragma: no cover - numba
    """The EPEs (hypot, as endpoint_error) of the scored pixels in the quantiles' bins, once per pixel and
    motion, grouped by (bin, membership pattern).

    A scored pixel of motion m (pattern ``b = bits[y, x]``, or ``bits_l``, not 0) whose bin
    ``k = bins[m, y, x]`` has ``slot[m, k] = s >= 0`` goes into segment ``c = start[m, s, b]``:
    ``out[c:...]``, in no particular order (a region's samples of bin k are the segments of the
    patterns holding it).
    """
    fill = start.copy()
    h, w = bits.shape
    idx = np.empty(w, np.int64)
    for m in range(2):
        bm = bits if m == 0 else bits_l
        tm = t if m == 0 else tl
        sl = slot[m]
        fm = fill[m]
        bn = bins[m]
        for y in range(h):
            # the row's pixels to collect, compacted without a branch (a target bin may hold a third
            # of the pixels: a branch on it would be mispredicted often)
            n = 0
            for x in range(w):
                idx[n] = x
                n += (sl[bn[y, x]] >= 0) & (bm[y, x] != 0)
            for i in range(n):
                x = idx[i]
                if m == 0:
                    eu, ev = np.float64(e[y, x, 0]), np.float64(e[y, x, 1])
                else:
                    eu, ev = np.float64(e[y, x, 0] - g[y, x, 0]), np.float64(e[y, x, 1] - g[y, x, 1])
                s, b = sl[bn[y, x]], bm[y, x]
                out[fm[s, b]] = math.hypot(eu - np.float64(tm[y, x, 0]), ev - np.float64(tm[y, x, 1]))
                fm[s, b] += 1


@numba.njit(cache=True, error_model="numpy")
def truth_local(t, cam, valid, t_local, ok, ok_local):  # pragma: no cover - numba
    """t_local = t - cam in float32 (as numpy); ok, ok_local: valid and both components finite in t, t_local."""
    h, w = valid.shape
    for y in range(h):
        for x in range(w):
            t0, t1 = t[y, x, 0], t[y, x, 1]
            l0, l1 = t0 - cam[y, x, 0], t1 - cam[y, x, 1]
            t_local[y, x, 0] = l0
            t_local[y, x, 1] = l1
            v = valid[y, x]
            ok[y, x] = v and math.isfinite(t0) and math.isfinite(t1)
            ok_local[y, x] = v and math.isfinite(l0) and math.isfinite(l1)


@numba.njit(cache=True, error_model="numpy")
def region_hists(hist_code, n_code, out):  # pragma: no cover - numba
    """out[m, r] = sum of hist_code[m, b] over the patterns b holding region r that have pixels (n_code[m, b] > 0)."""
    n_m, n_codes, nbins = hist_code.shape
    n_regions = out.shape[1]
    for m in range(n_m):
        for b in range(1, n_codes):
            if n_code[m, b] == 0:
                continue
            for r in range(n_regions):
                if (b >> r) & 1:
                    for k in range(nbins):
                        out[m, r, k] += hist_code[m, b, k]


@numba.njit(cache=True, error_model="numpy")
def quantile_targets(hist, rank, target, start_rank, sizes):  # pragma: no cover - numba
    """Where the samples of 0-based rank ``rank[m, r, j]`` lie in ``hist[m, r]``: their bin ``target``,
    the number of samples in lower bins ``start_rank`` and the size of the bin ``sizes``
    (ranks must be ascending in j; -1 marks an empty histogram: left alone)."""
    n_m, n_regions, nbins = hist.shape
    n_q = rank.shape[2]
    for m in range(n_m):
        for r in range(n_regions):
            if rank[m, r, 0] < 0:
                continue
            below = 0
            j = 0
            for k in range(nbins):
                c = hist[m, r, k]
                while j < n_q and rank[m, r, j] < below + c:
                    target[m, r, j] = k
                    start_rank[m, r, j] = below
                    sizes[m, r, j] = c
                    j += 1
                if j == n_q:
                    break
                below += c
