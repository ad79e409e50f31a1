"""The numba kernels of the one-pass flow scoring (:func:`harness.metrics.score_flow`).

A module of their own so that ``import harness.metrics`` (the CLI, the reports) does
not import numba; the scoring imports them on first use. Compiled kernels are cached
on disk (``cache=True``), as in :mod:`algorithms`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["field_totals", "values_in_bins"]

# A pixel's EPE is computed as sqrt(du^2 + dv^2), within 2 ulp of hypot's (libm hypot costs
# more than the rest of the pass). Where that could change a decision (a histogram bin edge,
# which includes the 1, 3 and 5 px outlier limits, or the Fl limit), the pixel's EPE is
# recomputed with hypot, as endpoint_error has it: bins and counts are exactly theirs.
_EDGE = 1e-9


@numba.njit(cache=True)
def field_totals(e, t, bits, valid_est, bin_px, nbins, stats, hist, bin_out, cos_out, code_out):  # pragma: no cover
    """One pass over the pixels: the totals and EPE histogram of every membership pattern.

    e, t : (H, W, 2) float32 estimate and truth; bits : (H, W) uint8, bit r set when the pixel
    is in region r (0: not scored); valid_est : (H, W) bool. Out: stats (2**R, 9) float64
    (columns _N .. _KCOV) and hist (2**R, nbins) int64, row b for the pixels whose ``bits``
    equal b (one update per pixel; regions sum their patterns); bin_out (H, W) int32, the
    histogram bin of each scored pixel (for :func:`values_in_bins`); cos_out (H*W,) float64
    and code_out (H*W,) int64, the clipped cosine of each scored pixel's angular error and its
    pattern, in pixel order. Returns the number of scored pixels. The arccos is left to numpy
    (SIMD, several times faster than libm's per call), which is what angular_error_deg uses.
    """
    h, w = bits.shape
    # running totals of the current pattern in locals (a store and reload of stats[b, :] per
    # pixel would chain every pixel on memory), added to stats[cur] when the pattern changes
    cur = -1
    m = 0
    n = s1 = s2 = k1 = k3 = k5 = kfl = kcov = 0.0
    for y in range(h):
        for x in range(w):
            b = bits[y, x]
            if b == 0:
                continue
            if b != cur:
                if cur >= 0:
                    add_totals(stats, cur, n, s1, s2, k1, k3, k5, kfl, kcov)
                cur = b
                n = s1 = s2 = k1 = k3 = k5 = kfl = kcov = 0.0
            eu, ev = np.float64(e[y, x, 0]), np.float64(e[y, x, 1])
            tu, tv = np.float64(t[y, x, 0]), np.float64(t[y, x, 1])
            du, dv = eu - tu, ev - tv
            epe = math.sqrt(du * du + dv * dv)
            q = epe / bin_px
            frac = q - math.floor(q)
            if frac < _EDGE or frac > 1.0 - _EDGE:
                epe = math.hypot(du, dv)
                q = epe / bin_px
            k = math.floor(q)
            k = nbins - 1 if k > nbins - 1 else k
            bin_out[y, x] = k
            hist[b, k] += 1
            # Barron 1994: angle between (u_e, v_e, 1) and (u_t, v_t, 1)
            num = eu * tu + ev * tv + 1.0
            den = math.sqrt((eu * eu + ev * ev + 1.0) * (tu * tu + tv * tv + 1.0))
            cos_out[m] = min(max(num / den, -1.0), 1.0)
            code_out[m] = b
            m += 1
            n += 1.0
            s1 += epe
            s2 += epe * epe
            if epe > 1.0:
                k1 += 1.0
            if epe > 3.0:
                k3 += 1.0
                # KITTI Fl: also > 5 % of |w_true|
                limit = 0.05 * math.hypot(tu, tv)
                if abs(epe - limit) <= _EDGE * limit:
                    epe = math.hypot(du, dv)
                if epe > limit:
                    kfl += 1.0
            if epe > 5.0:
                k5 += 1.0
            if valid_est[y, x]:
                kcov += 1.0
    if cur >= 0:
        add_totals(stats, cur, n, s1, s2, k1, k3, k5, kfl, kcov)
    return m


@numba.njit(cache=True, inline="always")
def add_totals(stats, b, n, s1, s2, k1, k3, k5, kfl, kcov):  # pragma: no cover - numba
    stats[b, 0] += n
    stats[b, 1] += s1
    stats[b, 2] += s2
    stats[b, 4] += k1
    stats[b, 5] += k3
    stats[b, 6] += k5
    stats[b, 7] += kfl
    stats[b, 8] += kcov


@numba.njit(cache=True)
def values_in_bins(e, t, bits, bin_idx, is_target, target, start, out):  # pragma: no cover - numba
    """The EPEs (hypot, as endpoint_error) of region r's pixels in bin ``target[r, j]``, into
    ``out[start[r, j]:...]``.

    The nearest-rank quantile lies in a known bin (from the histogram); the exact value is
    found among the few samples of that bin instead of partitioning every pixel's EPE.
    """
    fill = start.copy()
    h, w = bits.shape
    n_regions, n_q = target.shape
    for y in range(h):
        for x in range(w):
            b = bits[y, x]
            if b == 0 or not is_target[bin_idx[y, x]]:
                continue
            k = bin_idx[y, x]
            epe = math.hypot(np.float64(e[y, x, 0]) - np.float64(t[y, x, 0]),
                             np.float64(e[y, x, 1]) - np.float64(t[y, x, 1]))
            for r in range(n_regions):
                if b & (1 << r):
                    for j in range(n_q):
                        if target[r, j] == k:
                            out[fill[r, j]] = epe
                            fill[r, j] += 1
