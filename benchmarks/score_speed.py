"""Scoring speed per frame pair: the one-pass ``score_pair`` against the per-region scoring it replaced.

    cd /work/wt-scoring && PYTHONPATH=. python benchmarks/score_speed.py [--preset nominal] [--runs 31]
        [--sequence PATH]

The pair is real: frames 0 -> 1 of ``--preset`` rendered with its exact ground truth
(flow, camera flow, valid mask, instances), or pair 0 of a rendered sequence folder
(``--sequence``, no rendering); the "estimate" is the true flow plus heavy-tailed noise
(Student t, 2 degrees of freedom, 0.5 px scale: errors from hundredths of a pixel to past
the histogram's 100 px edge) and a constant global field. Timed side by side, interleaved,
after one untimed call each (numba's compiled kernels load from its cache):

- ``reference``: ``reference_score_pair`` of ``tests/harness/test_score_fused.py``, the
  per-region numpy scoring (the test that the two agree lives there);
- ``before``: ``score_pair`` as it was before the two-motion pass (two one-motion passes,
  numpy's arccos), kept here as ``_score_pair_before`` so that the ratio stays measurable;
- ``score_pair``: the package's, truth prepared inside;
- ``prepare_pair_truth``: the truth side alone;
- ``score_pair(prepared=)``: one estimate against a truth prepared beforehand;
- ``7 estimates / 7``: ``prepare_pair_truth`` once and seven ``score_pair(prepared=)``, per
  estimate (the runner scores up to seven pipelines of a scene against one truth).

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
"""

from __future__ import annotations

import os

for _var in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
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

import harness.metrics as M  # noqa: E402
from harness.metrics import prepare_pair_truth, score_pair  # noqa: E402
from test_score_fused import reference_score_pair  # noqa: E402

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--sequence", default=None, help="a rendered sequence folder: its pair 0, no rendering")
    ap.add_argument("--runs", type=int, default=31)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    estimate, truth = real_pair(args.preset, args.sequence)
    h, w = truth.valid.shape
    estimates = [SimpleNamespace(**{**vars(estimate), "flow_total": estimate.flow_total + np.float32(0.01 * i)})
                 for i in range(N_SHARED)]

    def shared():
        prepared = prepare_pair_truth(truth)
        for est in estimates:
            score_pair(est, None, frame=0, prepared=prepared)

    prepared = prepare_pair_truth(truth)
    paths = {
        "reference (per region)": lambda: reference_score_pair(estimate, truth, frame=0),
        "before (2 passes)": lambda: _score_pair_before(estimate, truth, frame=0),
        "score_pair": lambda: score_pair(estimate, truth, frame=0),
        "prepare_pair_truth": lambda: prepare_pair_truth(truth),
        "score_pair(prepared=)": lambda: score_pair(estimate, None, frame=0, prepared=prepared),
        f"{N_SHARED} estimates / {N_SHARED}": shared,
    }
    per_call = {f"{N_SHARED} estimates / {N_SHARED}": N_SHARED}
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
    print(f"score_pair on a {w}x{h} {args.sequence or args.preset!r} pair (4 regions x 2 motions), CPU ms over "
          f"{args.runs} interleaved runs, one native thread; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores")
    print(f"  {'path':26s} {'median':>7s} {'min':>7s} {'med/before':>11s} {'min/before':>11s}")
    for k in paths:
        print(f"  {k:26s} {med[k]:7.2f} {low[k]:7.2f} {med[k] / med[ref]:11.3f} {low[k] / low[ref]:11.3f}")


if __name__ == "__main__":
    main()
