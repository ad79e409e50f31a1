"""Scoring speed per frame pair: the one-pass ``score_pair`` against the per-region scoring it replaced.

    python benchmarks/score_speed.py [--preset nominal] [--runs 31]
        [--sequence PATH [--pipelines [--pair 0]]]

The pair is real: frames 0 -> 1 of ``--preset`` rendered with its exact ground truth
(flow, camera flow, valid mask, instances), or pair 0 of a rendered sequence folder
(``--sequence``, no rendering); the "estimate" is the true flow plus heavy-tailed noise
(Student t, 2 degrees of freedom, 0.5 px scale: errors from hundredths of a pixel to past
the histogram's 100 px edge) and a constant global field. With ``--pipelines`` the estimates
are instead the ``standard`` suite's seven pipelines' own estimates of pair ``--pair`` of the
``--sequence``: their errors crowd into a few bins of hundredths of a pixel, a third of the
pixels in the median's bin, which is what the quantiles cost in a real run. Timed side by
side, interleaved, after one untimed call each (numba's compiled kernels load from its cache):

- ``reference``: ``reference_score_pair`` of ``tests/harness/test_score_fused.py``, the
  per-region numpy scoring (the test that the two agree lives there);
- ``before``: ``score_pair`` as it was before the two-motion pass (two one-motion passes,
  numpy's arccos), kept here as ``_score_pair_before`` so that the ratio stays measurable;
- ``score_pair``: the package's, truth prepared inside;
- ``prepare_pair_truth``: the truth side alone;
- ``score_pair(prepared=)``: one estimate against a truth prepared beforehand;
- ``7 estimates / 7``: ``prepare_pair_truth`` once and seven ``score_pair(prepared=)``, per
  estimate (the runner scores up to seven pipelines of a scene against one truth);
- ``pair_totals (the pass alone)``: the numba pass of ``score_pair`` on one estimate, the
  package's against 95a9436's (its copy here);
- ``95a9436 ...``: the same with ``score_pair`` as of commit 95a9436 (kept here as
  ``score_pair_95a9436``: its ``pair_totals``, whose per-pixel loop ran scalar, every pixel
  of both motions scanned again for the quantiles' bins, each sample written once per region,
  ``np.flatnonzero`` in ``encode_hist``), with the ratios of today's to it and a bit-for-bit
  comparison of the rows of every estimate (the run fails if they differ).

Figures are medians and minima over ``--runs`` interleaved rounds of CPU (process) time, with
one native thread (``cv2.setNumThreads(1)``, numba and BLAS at 1); the machine is shared,
so the minimum is the nearer to a quiet machine's figure, and the ratios are the result.

Measured 2026-11-24 on the 2-core znver3 VM (AVX2, no AVX-512: numpy's arccos is glibc's
scalar acos there, 12-18 ns per value), load average 8.2 from other jobs, pair 0 of the
nominal-4199262fbd20a0bbc166 render (``--sequence``), 31 runs, CPU ms:

    ======================  ======  ======  ==========  ==========
    path                    median  min     med/before  min/before
    ======================  ======  ======  ==========  ==========
    reference (per region)  232.96  205.67  5.582       5.525
    before (2 passes)        41.73   37.23  1.000       1.000
    score_pair               21.56   17.62  0.517       0.473
    prepare_pair_truth        2.91    2.07  0.070       0.056
    score_pair(prepared=)    18.05   15.69  0.433       0.421
    7 estimates / 7          18.92   16.53  0.453       0.444
    ======================  ======  ======  ==========  ==========

(an earlier run at load 8.8: medians 47.05 / 23.49 / 18.79 / 20.24 ms, the same ratios to
within 0.03). The new pass is about half the time of the one before it on a loaded machine;
on a quiet one every figure is lower (the minima are the nearer), score_pair under 18 ms.
Of the remaining time about two thirds is the pass itself (square roots and divisions
of both motions in float64, 4 lanes), then the quantile scan, the histogram encoding
(zlib) and the truth side.

Against 95a9436 (2026-11-24, same VM, load average about 2 from other jobs, 21 runs, the
nominal render's pair 0; ratios today / 95a9436 of the medians, the minima and the median
of the per-round ratios; rows identical bit for bit in both):

    =====================================  ==============  =====  =====  =========
    estimates                              path            med    min    per round
    =====================================  ==============  =====  =====  =========
    the standard pipelines' (--pipelines)  prepared=        0.891  0.896  0.891
    the standard pipelines' (--pipelines)  7 estimates / 7  0.924  0.922  0.916
    truth + noise                          prepared=        1.024  0.974  0.987
    truth + noise                          7 estimates / 7  0.955  0.962  0.975
    =====================================  ==============  =====  =====  =========

(pipelines: 18.05 against 20.25 ms median per estimate.) The gain is in the quantiles: with
real estimates a median bin holds 40 000 to 100 000 pixels of a region, which 95a9436
collected once per region they belong to behind a mispredicted branch per pixel; now each
pixel once per motion, grouped by membership pattern, a region's samples gathered from its
patterns' segments. With truth + noise the bins are small and the two are within noise.

Later the same day, with ``pair_totals``' per-pixel loop in SIMD (it ran scalar before), the
ratios to 95a9436 are 0.712 (prepared=), 0.724 (7 estimates) and 0.681 (the pass alone) with
the pipelines' estimates, 0.817 / 0.825 with truth + noise (21 runs, load 2.4-3.2; figures in
benchmarks/standard_cost.md).
"""

from __future__ import annotations

import os

for _var in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import cv2  # noqa: E402
import numba  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "harness"))

from test_score_fused import reference_score_pair  # noqa: E402

import harness._flow_kernels as FK  # noqa: E402
import harness.metrics as M  # noqa: E402
from harness._flow_kernels import region_hists  # noqa: E402
from harness.metrics import prepare_pair_truth, score_pair  # noqa: E402

N_SHARED = 7


# --------------------------------------------------------------------------- score_pair before the two-motion pass
# (commit 95fabaa: one numba pass per motion, numpy's arccos on a buffer of cosines), for the ratio only

@numba.njit(cache=True, inline="always")
def _add_totals_before(stats, b, n, s1, s2, k1, k3, k5, kfl, kcov):
    """A pattern's running totals into its row of ``stats`` (column 3, the angular error, is numpy's)."""
    stats[b, 0] += n
    stats[b, 1] += s1
    stats[b, 2] += s2
    stats[b, 4] += k1
    stats[b, 5] += k3
    stats[b, 6] += k5
    stats[b, 7] += kfl
    stats[b, 8] += kcov


@numba.njit(cache=True)
def _field_totals_before(e, t, bits, valid_est, bin_px, nbins, stats, hist, bin_out, cos_out, code_out):
    h, w = bits.shape
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
                    _add_totals_before(stats, cur, n, s1, s2, k1, k3, k5, kfl, kcov)
                cur = b
                n = s1 = s2 = k1 = k3 = k5 = kfl = kcov = 0.0
            eu, ev = np.float64(e[y, x, 0]), np.float64(e[y, x, 1])
            tu, tv = np.float64(t[y, x, 0]), np.float64(t[y, x, 1])
            du, dv = eu - tu, ev - tv
            epe = np.sqrt(du * du + dv * dv)
            q = epe / bin_px
            frac = q - np.floor(q)
            if frac < 1e-9 or frac > 1.0 - 1e-9:
                epe = np.hypot(du, dv)
                q = epe / bin_px
            k = int(np.floor(q))
            k = nbins - 1 if k > nbins - 1 else k
            bin_out[y, x] = k
            hist[b, k] += 1
            num = eu * tu + ev * tv + 1.0
            den = np.sqrt((eu * eu + ev * ev + 1.0) * (tu * tu + tv * tv + 1.0))
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
                limit = 0.05 * np.hypot(tu, tv)
                if abs(epe - limit) <= 1e-9 * limit:
                    epe = np.hypot(du, dv)
                if epe > limit:
                    kfl += 1.0
            if epe > 5.0:
                k5 += 1.0
            if valid_est[y, x]:
                kcov += 1.0
    if cur >= 0:
        _add_totals_before(stats, cur, n, s1, s2, k1, k3, k5, kfl, kcov)
    return m


@numba.njit(cache=True)
def _values_in_bins_before(e, t, bits, bin_idx, is_target, target, start, out):
    fill = start.copy()
    h, w = bits.shape
    n_regions, n_q = target.shape
    for y in range(h):
        for x in range(w):
            b = bits[y, x]
            if b == 0 or not is_target[bin_idx[y, x]]:
                continue
            k = bin_idx[y, x]
            epe = np.hypot(np.float64(e[y, x, 0]) - np.float64(t[y, x, 0]),
                           np.float64(e[y, x, 1]) - np.float64(t[y, x, 1]))
            for r in range(n_regions):
                if b & (1 << r):
                    for j in range(n_q):
                        if target[r, j] == k:
                            out[fill[r, j]] = epe
                            fill[r, j] += 1


def _quantile_targets_before(hist, qs):
    cum = np.cumsum(hist, axis=1)
    target = np.full((hist.shape[0], len(qs)), -1, np.int64)
    rank = np.zeros_like(target)
    for r in range(hist.shape[0]):
        n = int(cum[r, -1])
        if n == 0:
            continue
        for j, q in enumerate(qs):
            k = M._rank_index(q, n)
            b = int(np.searchsorted(cum[r], k + 1))
            target[r, j] = b
            rank[r, j] = k - (int(cum[r, b - 1]) if b else 0)
    sizes = np.where(target >= 0, hist[np.arange(hist.shape[0])[:, None], np.maximum(target, 0)], 0)
    return target, rank, sizes


def _score_field_before(e, t, masks, ve, *, motion, frame, bits=None):
    names = list(masks)
    if bits is None:
        bits = M._region_bits(masks)
    by_code = np.zeros((1 << len(names), 9))
    hist_code = np.zeros((1 << len(names), M.HIST_NBINS), np.int64)
    e = np.ascontiguousarray(e, np.float32)
    t = np.ascontiguousarray(t, np.float32)
    bin_idx = np.empty(ve.shape, np.int32)
    cos = np.empty(ve.size)
    code = np.empty(ve.size, np.int64)
    m = _field_totals_before(e, t, bits, np.ascontiguousarray(ve, np.bool_), M.HIST_BIN_PX, M.HIST_NBINS, by_code,
                             hist_code, bin_idx, cos, code)
    by_code[:, 3] = np.bincount(code[:m], weights=np.degrees(np.arccos(cos[:m])), minlength=len(by_code))
    member = (np.arange(1 << len(names))[None, :] >> np.arange(len(names))[:, None]) & 1
    stats = np.zeros((len(names), 9))
    hist = np.zeros((len(names), M.HIST_NBINS), np.int64)
    for c in np.flatnonzero(by_code[:, 0]):
        for j in np.flatnonzero(member[:, c]):
            stats[j] += by_code[c]
            hist[j] += hist_code[c]
    # quantiles: the bin from the histogram, the value among that bin's samples
    target, rank, sizes = _quantile_targets_before(hist, (0.5, 0.95))
    start = np.zeros_like(sizes)
    start.ravel()[1:] = np.cumsum(sizes.ravel())[:-1]
    values = np.empty(int(sizes.sum()))
    is_target = np.zeros(M.HIST_NBINS, np.bool_)
    is_target[target[target >= 0]] = True
    _values_in_bins_before(e, t, bits, bin_idx, is_target, target, start, values)
    quant = np.full(target.shape, np.nan)
    for idx in zip(*np.nonzero(target >= 0)):
        seg = values[start[idx]:start[idx] + sizes[idx]]
        quant[idx] = np.partition(seg, rank[idx])[rank[idx]]
    rows = []
    for j, r in enumerate(names):
        st = stats[j]
        n = int(st[0])
        rows += M._error_rows_from_totals(n, float(st[1]), float(st[2]), float(st[3]),
                                          [int(st[4]), int(st[5]), int(st[6])], int(st[7]),
                                          float(quant[j, 0]), float(quant[j, 1]), hist[j],
                                          region=r, motion=motion, frame=frame)
        k = int(st[8])
        rows.append(M._row("coverage", 100.0 * k / n if n else float("nan"), k, n, region=r, motion=motion,
                           frame=frame))
    return rows


def _score_pair_before(estimate, truth, *, frame):
    t = M.check_flow(truth.flow, name="flow_true", allow_nan=True)
    e = M.check_flow(estimate.flow_total, name="flow_est", shape=t.shape[:2])
    vt0 = np.asarray(truth.valid, bool)
    ve = np.ones(vt0.shape, bool) if estimate.valid is None else np.asarray(estimate.valid, bool)
    e_local = M.check_flow(np.asarray(estimate.flow_total, np.float32) - np.asarray(estimate.flow_global, np.float32),
                           name="flow_est", shape=t.shape[:2])
    t_local = M.check_flow(t - np.asarray(truth.flow_camera, np.float32), name="flow_true", allow_nan=True)
    vt = vt0 & M._finite_uv(t)
    vt_local = vt0 & M._finite_uv(t_local)
    masks = M.region_masks(vt, truth.instances)
    masks_local = masks if np.array_equal(vt, vt_local) else M.region_masks(vt_local, truth.instances)
    bits = M._region_bits(masks)
    rows = _score_field_before(e, t, masks, ve, motion="total", frame=frame, bits=bits)
    rows += _score_field_before(e_local, t_local, masks_local, ve, motion="local", frame=frame,
                                bits=bits if masks_local is masks else None)
    return rows


# --------------------------------------------------------------------------- score_pair as of 95a9436
# (a scan of all pixels for the quantiles' bins, each sample stored once per region), for the ratio and the
# identity check only: what has changed since that commit, renamed with _old. pair_totals, _count_row and
# _run_totals are copied as they were then (the package's pair_totals has changed since, and the check must not
# compare it with itself); the element kernels they inline (_epe, _bin, _cos, _acos_deg, _fl, _bin_exact) and
# _error_rows_from_totals are as they were then: the package's own serve both paths.
_error_rows_from_totals_old = M._error_rows_from_totals


@numba.njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _run_totals_old(stats, b, epe, ang, ve, x0, x1):
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
    stats[b, FK.N] += x1 - x0
    stats[b, FK.S_EPE] += s1
    stats[b, FK.S_SQ] += s2
    stats[b, FK.S_AE] += sa
    stats[b, FK.K1] += k1
    stats[b, FK.K3] += k3
    stats[b, FK.K5] += k5
    stats[b, FK.KCOV] += kc


@numba.njit(cache=True, error_model="numpy")
def _count_row_old(e, g, t, bits, ve, motion, bin_px, nbins, epe, ang, k, edge, stats, hist, bins):
    w = bits.size
    for x in range(w):
        if bits[x] != 0 and (edge[x] or epe[x] > 3.0):  # rare: hypot decides (bin edge, Fl)
            if motion == 0:
                tu, tv = np.float64(t[x, 0]), np.float64(t[x, 1])
                du, dv = np.float64(e[x, 0]) - tu, np.float64(e[x, 1]) - tv
            else:
                tu, tv = np.float64(t[x, 0]), np.float64(t[x, 1])
                du, dv = np.float64(e[x, 0] - g[x, 0]) - tu, np.float64(e[x, 1] - g[x, 1]) - tv
            if edge[x]:
                epe[x], k[x] = FK._bin_exact(du, dv, bin_px, nbins)
            if epe[x] > 3.0:
                stats[bits[x], FK.KFL] += FK._fl(epe[x], du, dv, tu, tv)
    for x in range(w):
        bins[x] = k[x]
        hist[bits[x], k[x]] += 1  # pattern 0 (not scored) is counted too, and ignored
    x0 = 0
    while x0 < w:
        b = bits[x0]
        x1 = x0 + 1
        while x1 < w and bits[x1] == b:
            x1 += 1
        if b != 0:
            _run_totals_old(stats, b, epe, ang, ve, x0, x1)
        x0 = x1


@numba.njit(cache=True, error_model="numpy")
def pair_totals_old(e, g, t, tl, bits, bits_l, valid_est, bin_px, nbins, stats, hist, bins):
    h, w = bits.shape
    per_bin = 1.0 / bin_px
    epe_t, ang_t, k_t, edge_t = np.empty(w), np.empty(w), np.empty(w, np.int32), np.empty(w, np.bool_)
    epe_l, ang_l, k_l, edge_l = np.empty(w), np.empty(w), np.empty(w, np.int32), np.empty(w, np.bool_)
    bad = 0
    for y in range(h):
        # errors of every pixel of the row (NaN where the truth is unknown), branch-free; the
        # arithmetic and the arccos in separate loops, each of which the compiler vectorises
        for x in range(w):
            e0, e1 = e[y, x, 0], e[y, x, 1]
            # local estimate in float32, as np.float32(e) - np.float32(g)
            l0, l1 = e0 - g[y, x, 0], e1 - g[y, x, 1]
            fin = (e0 - e0) + (e1 - e1) + (l0 - l0) + (l1 - l1)  # NaN unless all four are finite
            bad += fin != fin
            eu, ev, tu, tv = np.float64(e0), np.float64(e1), np.float64(t[y, x, 0]), np.float64(t[y, x, 1])
            epe_t[x] = epe = FK._epe(eu, ev, tu, tv)
            k_t[x], edge_t[x] = FK._bin(epe, per_bin, nbins)
            ang_t[x] = FK._cos(eu, ev, tu, tv)
            eu, ev, tu, tv = np.float64(l0), np.float64(l1), np.float64(tl[y, x, 0]), np.float64(tl[y, x, 1])
            epe_l[x] = epe = FK._epe(eu, ev, tu, tv)
            k_l[x], edge_l[x] = FK._bin(epe, per_bin, nbins)
            ang_l[x] = FK._cos(eu, ev, tu, tv)
        FK._acos_deg(ang_t)
        FK._acos_deg(ang_l)
        _count_row_old(e[y], g[y], t[y], bits[y], valid_est[y], 0, bin_px, nbins, epe_t, ang_t, k_t, edge_t,
                       stats[0], hist[0], bins[0, y])
        _count_row_old(e[y], g[y], tl[y], bits_l[y], valid_est[y], 1, bin_px, nbins, epe_l, ang_l, k_l, edge_l,
                       stats[1], hist[1], bins[1, y])
    return bad


@numba.njit(cache=True, error_model="numpy")
def values_in_bins_old(e, g, t, tl, bits, bits_l, bins, is_target, target, start, out):  # pragma: no cover - numba
    """The EPEs (hypot, as endpoint_error) of motion m, region r's pixels in bin ``target[m, r, j]``,
    into ``out[start[m, r, j]:...]``.

    The nearest-rank quantile lies in a known bin (from the histogram); the exact value is
    found among the few samples of that bin instead of partitioning every pixel's EPE.
    """
    fill = start.copy()
    h, w = bits.shape
    _, n_regions, n_q = target.shape
    for m in range(2):
        bm = bits if m == 0 else bits_l
        tm = t if m == 0 else tl
        tgt = is_target[m]
        for y in range(h):
            for x in range(w):
                k = bins[m, y, x]
                b = bm[y, x]
                if not tgt[k] or b == 0:
                    continue
                if m == 0:
                    eu, ev = np.float64(e[y, x, 0]), np.float64(e[y, x, 1])
                else:
                    eu, ev = np.float64(e[y, x, 0] - g[y, x, 0]), np.float64(e[y, x, 1] - g[y, x, 1])
                epe = math.hypot(eu - np.float64(tm[y, x, 0]), ev - np.float64(tm[y, x, 1]))
                for r in range(n_regions):
                    if (b >> r) & 1:
                        for j in range(n_q):
                            if target[m, r, j] == k:
                                out[fill[m, r, j]] = epe
                                fill[m, r, j] += 1


def _quantiles_old(e, g, t, tl, bits, bits_l, bins, hist, qs: tuple[float, ...]) -> np.ndarray:
    """Exact nearest-rank quantiles ``(2, R, len(qs))`` of each motion's and region's EPE (NaN when empty)."""
    target, rank, sizes = M._quantile_targets(hist, qs)
    out = np.full(target.shape, np.nan)
    # quantiles of a region in the same bin share one segment (an almost constant error puts
    # most pixels in one bin: a segment may hold most of the image)
    first = np.broadcast_to(np.arange(len(qs)), target.shape).copy()  # the first quantile of the same bin
    for j in range(1, len(qs)):
        for i in range(j - 1, -1, -1):
            first[..., j] = np.where(target[..., j] == target[..., i], i, first[..., j])
    own = (first == np.arange(len(qs))) & (target >= 0)
    fill_target = np.where(own, target, -2)  # -2 matches no bin: nothing collected
    fill_sizes = np.where(own, sizes, 0)
    start = np.zeros_like(fill_sizes)
    start.ravel()[1:] = np.cumsum(fill_sizes.ravel())[:-1]
    values = np.empty(int(fill_sizes.sum()), np.float64)
    is_target = np.zeros((2, hist.shape[-1]), np.bool_)
    for m in range(2):
        is_target[m, target[m][target[m] >= 0]] = True
    values_in_bins_old(e, g, t, tl, bits, bits_l, bins, is_target, fill_target, start, values)
    for m, r in zip(*np.nonzero(target[..., 0] >= 0)):
        for j in np.flatnonzero(own[m, r]):
            shared = np.flatnonzero(first[m, r] == j)  # the quantiles read from this segment
            seg = values[start[m, r, j]:start[m, r, j] + fill_sizes[m, r, j]]
            part = np.partition(seg, rank[m, r, shared])
            out[m, r, shared] = part[rank[m, r, shared]]
    return out


def _score_motions_old(e: np.ndarray, g: np.ndarray, truth: M.PreparedTruth, ve: np.ndarray, *, frame: int | None,
                   motions: tuple[str, ...] = M.MOTIONS) -> tuple[list[dict], int]:
    """Flow rows of both motions in every region, and the number of non-finite estimate pixels.

    e, g : (H, W, 2) float32 C-contiguous estimate and global field (local estimate = e - g);
    ve : (H, W) bool. ``motions`` names motion 0 (total) and, if two, motion 1 (local); with
    one, the local motion is left unscored. When the count returned is not 0 the rows are
    meaningless: the caller raises.
    """
    names = truth.regions
    h, w = truth.shape
    n_codes = 1 << len(names)
    stats = np.zeros((2, n_codes, 9), np.float64)
    hist_code = np.zeros((2, n_codes, M.HIST_NBINS), np.int32)
    bins = np.empty((2, h, w), np.uint16)
    bits_l = truth.bits_local if len(motions) > 1 else M._read_only(np.zeros_like(truth.bits))
    bad = pair_totals_old(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, ve, M.HIST_BIN_PX, M.HIST_NBINS,
                      stats, hist_code, bins)
    if bad:
        return [], bad
    hist = np.zeros((2, len(names), M.HIST_NBINS), np.int64)
    region_hists(hist_code, stats[:, :, M._N], hist)
    quant = _quantiles_old(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, bins, hist, (0.5, 0.95))
    # region totals: the sum of the patterns it belongs to
    member = (np.arange(n_codes)[None, :] >> np.arange(len(names))[:, None]) & 1  # (R, codes)
    rows: list[dict] = []
    for m, motion in enumerate(motions):
        by_code = stats[m]
        used = np.flatnonzero(by_code[:, M._N])
        for j, r in enumerate(names):
            st = np.zeros(9)
            for c in used:
                if member[j, c]:
                    st += by_code[c]
            n = int(st[M._N])
            rows += _error_rows_from_totals_old(n, float(st[M._S_EPE]), float(st[M._S_SQ]), float(st[M._S_AE]),
                                            [int(st[M._K1]), int(st[M._K3]), int(st[M._K5])], int(st[M._KFL]),
                                            float(quant[m, j, 0]), float(quant[m, j, 1]), hist[m, j],
                                            region=r, motion=motion, frame=frame)
            k = int(st[M._KCOV])
            rows.append(M._row("coverage", 100.0 * k / n if n else float("nan"), k, n, region=r, motion=motion,
                             frame=frame))
    return rows, 0


def score_pair_95a9436(estimate, *, frame, prepared):
    """``score_pair(estimate, None, frame=frame, prepared=prepared)`` as of 95a9436."""
    shape = prepared.shape
    e = np.ascontiguousarray(M.check_flow(estimate.flow_total, name="flow_est", shape=shape, allow_nan=True))
    g = np.asarray(estimate.flow_global, np.float32)
    if g.shape != e.shape:
        g = np.broadcast_to(g, e.shape)
    e, g, ve = M._read_only(e), M._read_only(np.ascontiguousarray(g)), M._read_only(M._valid_est(estimate.valid, shape))
    rows, bad = _score_motions_old(e, g, prepared, ve, frame=frame)
    if bad:
        raise ValueError("score_pair_95a9436: non-finite estimate")
    if getattr(estimate, "stage_ms", None):
        rows += M.timing_rows(estimate.stage_ms, frame=frame)
    return rows


# --------------------------------------------------------------------------- the pair

def real_pair(preset: str, sequence: str | None):
    """(estimate, truth) of frames 0 -> 1 of ``preset`` (rendered), or pair 0 of the sequence folder."""
    if sequence:
        from scenes import open_sequence

        truth = open_sequence(sequence).pair_truth(0)
    else:
        from scenes.generate import SceneGenerator
        from scenes.spec import load_scene_spec

        frames = SceneGenerator(load_scene_spec(preset, {"image.n_frames": 2})).frames()
        next(frames)
        truth = next(frames).pair
    rng = np.random.default_rng(0)
    noise = rng.standard_t(2, size=truth.flow.shape).astype(np.float32) * np.float32(0.5)
    glob = np.broadcast_to(np.nanmedian(truth.flow_camera.reshape(-1, 2), axis=0).astype(np.float32),
                           truth.flow.shape).copy()
    estimate = SimpleNamespace(flow_total=truth.flow + noise, flow_global=glob,
                               valid=rng.random(truth.valid.shape) > 0.1, stage_ms={})
    return estimate, truth


def pipeline_estimates(sequence: str, pair: int = 0) -> tuple[list, object]:
    """The estimates of pair ``pair`` of the sequence folder by the ``standard`` suite's pipelines, and its truth."""
    from algorithms.pipeline import PairEstimate, Pipeline
    from harness.cell_scoring import point_seeds
    from harness.suites import expand, load_suite
    from scenes import open_sequence

    seq = open_sequence(sequence)
    specs = {c.pipeline: c.pipeline_spec for c in expand(load_suite("standard"))}
    out = []
    for spec in specs.values():
        for est in Pipeline.from_dict(spec).run(seq, seeds=point_seeds(seq.tracks)):
            if isinstance(est, PairEstimate) and est.index == pair:
                out.append(SimpleNamespace(flow_total=est.flow_total, flow_global=est.flow_global, valid=est.valid,
                                           stage_ms={}))
                break
    return out, seq.pair_truth(pair)


def _pass(kernel, estimate, prepared) -> int:
    """``kernel`` (``pair_totals`` or its 95a9436 copy) on one estimate, as ``_score_motions`` calls it."""
    e = M._read_only(np.ascontiguousarray(estimate.flow_total, np.float32))
    g = M._read_only(np.ascontiguousarray(np.broadcast_to(np.asarray(estimate.flow_global, np.float32), e.shape)))
    ve = M._read_only(M._valid_est(estimate.valid, prepared.shape))
    n_codes = 1 << len(prepared.regions)
    stats = np.zeros((2, n_codes, 9))
    hist = np.zeros((2, n_codes, M.HIST_NBINS), np.int32)
    bins = np.empty((2,) + prepared.shape, np.uint16)
    return kernel(e, g, prepared.flow, prepared.flow_local, prepared.bits, prepared.bits_local, ve, M.HIST_BIN_PX,
                  M.HIST_NBINS, stats, hist, bins)


def _same_rows(a: list[dict], b: list[dict]) -> bool:
    """Rows equal field by field, bit for bit (NaN equal to NaN)."""
    def same(x, y):
        return x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))
    return len(a) == len(b) and all(ra.keys() == rb.keys() and all(same(ra[k], rb[k]) for k in ra)
                                    for ra, rb in zip(a, b))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--sequence", default=None, help="a rendered sequence folder: its pair 0, no rendering")
    ap.add_argument("--runs", type=int, default=31)
    ap.add_argument("--pipelines", action="store_true",
                    help="score the standard suite's pipelines' estimates of pair --pair of --sequence instead of "
                         "the truth plus noise (their errors crowd into a few low bins, as in a real run)")
    ap.add_argument("--pair", type=int, default=0, help="with --pipelines: the pair")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    if args.pipelines:
        if not args.sequence:
            ap.error("--pipelines needs --sequence")
        estimates, truth = pipeline_estimates(args.sequence, args.pair)
        estimate = estimates[0]
    else:
        estimate, truth = real_pair(args.preset, args.sequence)
        estimates = [SimpleNamespace(**{**vars(estimate), "flow_total": estimate.flow_total + np.float32(0.01 * i)})
                     for i in range(N_SHARED)]
    h, w = truth.valid.shape

    def shared(score):
        def run():
            prepared = prepare_pair_truth(truth)
            for est in estimates:
                score(est, prepared)
        return run

    def new(est, prepared):
        return score_pair(est, None, frame=0, prepared=prepared)

    def old(est, prepared):
        return score_pair_95a9436(est, frame=0, prepared=prepared)

    prepared = prepare_pair_truth(truth)
    same = all(_same_rows(new(est, prepared), old(est, prepared)) for est in estimates)
    n7 = f"{len(estimates)} estimates / {len(estimates)}"
    paths = {
        "reference (per region)": lambda: reference_score_pair(estimate, truth, frame=0),
        "before (2 passes)": lambda: _score_pair_before(estimate, truth, frame=0),
        "score_pair": lambda: score_pair(estimate, truth, frame=0),
        "prepare_pair_truth": lambda: prepare_pair_truth(truth),
        "score_pair(prepared=)": lambda: new(estimate, prepared),
        "95a9436 score_pair(prepared=)": lambda: old(estimate, prepared),
        n7: shared(new),
        f"95a9436 {n7}": shared(old),
        "pair_totals (the pass alone)": lambda: _pass(FK.pair_totals, estimate, prepared),
        "95a9436 pair_totals": lambda: _pass(pair_totals_old, estimate, prepared),
    }
    per_call = {n7: len(estimates), f"95a9436 {n7}": len(estimates)}
    for fn in paths.values():
        fn()
    cpu: dict[str, list[float]] = {k: [] for k in paths}
    for _ in range(args.runs):
        for name, fn in paths.items():
            c0 = time.process_time()
            fn()
            cpu[name].append(1e3 * (time.process_time() - c0) / per_call.get(name, 1))
    med = {k: statistics.median(v) for k, v in cpu.items()}
    low = {k: min(v) for k, v in cpu.items()}
    ref = "before (2 passes)"
    what = f"the standard pipelines' estimates of pair {args.pair}" if args.pipelines else "truth + noise"
    print(f"score_pair on a {w}x{h} {args.sequence or args.preset!r} pair ({what}; 4 regions x 2 motions), CPU ms over "
          f"{args.runs} interleaved runs, one native thread; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores")
    print(f"  {'path':34s} {'median':>7s} {'min':>7s} {'med/before':>11s} {'min/before':>11s}")
    for k in paths:
        print(f"  {k:34s} {med[k]:7.2f} {low[k]:7.2f} {med[k] / med[ref]:11.3f} {low[k] / low[ref]:11.3f}")
    print("now against 95a9436, side by side (ratio of medians, of minima; median of the per-round ratios):")
    for k in ("score_pair(prepared=)", n7, "pair_totals (the pass alone)"):
        o = f"95a9436 {k.split(' (')[0]}" if k.startswith("pair_totals") else f"95a9436 {k}"
        rounds = statistics.median(a / b for a, b in zip(cpu[k], cpu[o]))
        print(f"  {k:34s} {med[k] / med[o]:7.3f} {low[k] / low[o]:7.3f} {rounds:7.3f}")
    print(f"rows of the {len(estimates)} estimates identical to 95a9436's, bit for bit: {same}")
    if not same:
        raise SystemExit("the rows differ from 95a9436's")


if __name__ == "__main__":
    main()
