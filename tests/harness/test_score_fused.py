"""The one-pass flow scoring gives the numbers of the per-region numpy scoring it replaced.

The reference below is the scoring as it was before the fused pass (one boolean mask
and one ``np.partition`` per region and motion, numpy's arccos); it lives only here, as
the yardstick. Sums may differ by rounding (summation order, and the pass's own arccos,
within 1 ulp of numpy's), to 1e-9 relative; counts, quantiles and histograms must be
identical. Every comparison scores the pair twice, with the truth prepared once
(``prepare_pair_truth``, as the runner shares it between estimates) and without, and
asks for identical rows.
"""

from __future__ import annotations

import math
import os
from types import SimpleNamespace

import numpy as np
import pytest

import harness.metrics as M
from scenes.ground_truth import PairTruth

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


# --------------------------------------------------------------------------- the reference


def _ref_hist(epe):
    idx = np.minimum(np.floor(np.asarray(epe, np.float64).ravel() / M.HIST_BIN_PX), M.HIST_NBINS - 1)
    return np.bincount(idx.astype(np.int64), minlength=M.HIST_NBINS)


def _ref_error_rows(epe, ae, mag, *, region, motion, frame):
    n = int(epe.size)
    nan = float("nan")
    out = {}
    hist = _ref_hist(epe)
    if n:
        k50, k95 = max(1, math.ceil(0.5 * n)) - 1, max(1, math.ceil(0.95 * n)) - 1
        part = np.partition(epe, (k50, k95))
        med, p95 = float(part[k50]), float(part[k95])
    else:
        med = p95 = nan
    s_epe, s_sq, s_ae = float(epe.sum()), float(epe @ epe), float(ae.sum())
    mean = (lambda s: s / n) if n else (lambda s: nan)
    out["epe_mean"] = (mean(s_epe), s_epe, n, "")
    out["epe_rms"] = (math.sqrt(s_sq / n) if n else nan, s_sq, n, "")
    out["epe_median"] = (med, nan, n, hist)
    out["epe_p95"] = (p95, nan, n, hist)
    out["ae_mean"] = (mean(s_ae), s_ae, n, "")
    for thr in (1, 3, 5):
        k = int(np.count_nonzero(epe > thr))
        out[f"outlier_{thr}px"] = (100.0 * mean(k), k, n, "")
    k = int(np.count_nonzero((epe > 3.0) & (epe > 0.05 * mag)))
    out["fl_all"] = (100.0 * mean(k), k, n, "")
    return {(m, region, motion, frame): v for m, v in out.items()}


def _ref_score_flow(flow_est, flow_true, valid_true, *, valid_est, instances, motion, frame):
    t = np.asarray(flow_true, np.float32)
    e = np.asarray(flow_est, np.float32)
    vt = np.asarray(valid_true, bool) & np.isfinite(t).all(-1)
    ve = np.ones(vt.shape, bool) if valid_est is None else np.asarray(valid_est, bool)
    masks = M.region_masks(vt, instances)
    e64, t64 = e[vt].astype(np.float64), t[vt].astype(np.float64)
    epe = np.hypot(e64[:, 0] - t64[:, 0], e64[:, 1] - t64[:, 1])
    num = e64[:, 0] * t64[:, 0] + e64[:, 1] * t64[:, 1] + 1.0
    den = np.sqrt((e64[:, 0] ** 2 + e64[:, 1] ** 2 + 1.0) * (t64[:, 0] ** 2 + t64[:, 1] ** 2 + 1.0))
    ae = np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0)))
    mag = np.hypot(t64[:, 0], t64[:, 1])
    out = {}
    for r, m in masks.items():
        sel = m[vt]
        out.update(_ref_error_rows(epe[sel], ae[sel], mag[sel], region=r, motion=motion, frame=frame))
        n, k = int(m.sum()), int((m & ve).sum())
        out[("coverage", r, motion, frame)] = (100.0 * k / n if n else float("nan"), k, n, "")
    return out


def reference_score_pair(estimate, truth, *, frame):
    """Flow rows of a pair as the per-region scoring computed them: key -> (value, sum, count, hist)."""
    kw = {"valid_est": estimate.valid, "instances": truth.instances, "frame": frame}
    out = _ref_score_flow(estimate.flow_total, truth.flow, truth.valid, motion="total", **kw)
    est_local = np.asarray(estimate.flow_total, np.float32) - np.asarray(estimate.flow_global, np.float32)
    true_local = np.asarray(truth.flow, np.float32) - np.asarray(truth.flow_camera, np.float32)
    out.update(_ref_score_flow(est_local, true_local, truth.valid, motion="local", **kw))
    return out


# --------------------------------------------------------------------------- comparison


def _same(a, b):
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-9, abs=1e-12)


def _identical(a, b):
    """Rows equal field by field, NaN equal to NaN."""
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra.keys() == rb.keys()
        for k in ra:
            x, y = ra[k], rb[k]
            same = x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))
            assert same, (ra["metric"], ra["region"], ra["motion"], k, x, y)


def assert_same_scores(estimate, truth, frame):
    """The fused rows equal the reference's, with and without a prepared truth; returns the rows."""
    all_rows = M.score_pair(estimate, truth, frame=frame)
    prepared = M.prepare_pair_truth(truth)
    _identical(all_rows, M.score_pair(estimate, None, frame=frame, prepared=prepared))
    _identical(all_rows, M.score_pair(estimate, truth, frame=frame, prepared=prepared))
    rows = [r for r in all_rows if r["kind"] == "accuracy"]
    new = {(r["metric"], r["region"], r["motion"], r["frame"]): (r["value"], r["sum"], r["count"], r["hist"])
           for r in rows}
    old = reference_score_pair(estimate, truth, frame=frame)
    assert new.keys() == old.keys()
    for key, (v, s, n, h) in old.items():
        nv, ns, nn, nh = new[key]
        assert nn == n, key
        if isinstance(h, str):  # no histogram on this row
            assert nh == b"", key
        else:  # the stored bytes decode to the reference's counts
            np.testing.assert_array_equal(M.decode_hist(nh), h, err_msg=str(key))
        assert _same(nv, v) and _same(ns, s), (key, (nv, ns), (v, s))
        if key[0] in ("epe_median", "epe_p95") or key[0].startswith(("outlier", "fl_", "coverage")):
            assert nv == v or (math.isnan(nv) and math.isnan(v)), key  # exact: ranks and counts
    # every metric of every region and both motions
    assert {(m, r, mo) for m, r, mo, _ in new} == {
        (m, r, mo) for m in ("epe_mean", "epe_rms", "epe_median", "epe_p95", "ae_mean", "outlier_1px", "outlier_3px",
                             "outlier_5px", "fl_all", "coverage") for r in M.REGIONS for mo in M.MOTIONS}
    return all_rows


def _synthetic_pair(rng, h=90, w=120, *, scale=1.0, speed=1.0):
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    cam = (np.stack([2.0 + 0.01 * xs, -1.0 + 0.02 * ys], -1) * speed).astype(np.float32)
    flow = cam.copy()
    instances = np.zeros((h, w), np.uint16)
    instances[20:35, 30:60] = 1
    instances[60:70, 90:110] = 2
    flow[instances > 0] += np.float32([3.0, -1.5])
    valid = rng.random((h, w)) > 0.05
    est = flow + rng.standard_t(2, size=flow.shape).astype(np.float32) * np.float32(scale)
    est[5:9, 5:9] += np.float32(150.0)  # past the histogram's last edge: the overflow bin
    glob = np.broadcast_to(np.float32([2.2, -0.8]), flow.shape).copy()
    truth = PairTruth(flow=flow, flow_camera=cam, valid=valid, instances=instances)
    estimate = SimpleNamespace(flow_total=est, flow_global=glob, valid=rng.random((h, w)) > 0.2, stage_ms={})
    return estimate, truth


@pytest.mark.parametrize("scale", [0.01, 0.5, 5.0])
def test_fused_scoring_equals_the_reference_on_synthetic_fields(scale):
    rng = np.random.default_rng(7)
    estimate, truth = _synthetic_pair(rng, scale=scale)
    assert_same_scores(estimate, truth, 3)


def test_fused_scoring_equals_the_reference_when_one_bin_holds_most_pixels():
    """An almost constant error, as real estimates have on the background: one bin holds the median and
    the p95 of every region and motion, over several membership patterns each."""
    rng = np.random.default_rng(16)
    estimate, truth = _synthetic_pair(rng)
    noise = np.float32(0.0123) + rng.uniform(0.0, 0.004, truth.flow.shape[:2]).astype(np.float32)
    estimate.flow_total = truth.flow + np.stack([noise, np.zeros_like(noise)], -1)
    estimate.flow_global = truth.flow_camera.copy()
    rows = assert_same_scores(estimate, truth, 2)
    for r in rows:
        if r["metric"] == "epe_median":
            hist = M.decode_hist(r["hist"])
            assert hist[1] > 0.9 * hist.sum(), (r["region"], r["motion"])
            assert 0.01 <= r["value"] and next(q["value"] for q in rows if q["metric"] == "epe_p95" and q["region"]
                                               == r["region"] and q["motion"] == r["motion"]) < 0.02


def test_fused_scoring_equals_the_reference_on_fast_motion():
    """Flows of 60 to 200 px: the Fl limit (5 % of |w_true|) is above 3 px and decides."""
    rng = np.random.default_rng(9)
    estimate, truth = _synthetic_pair(rng, scale=3.0, speed=40.0)
    assert np.nanmax(np.hypot(truth.flow[..., 0], truth.flow[..., 1])) > 120
    rows = assert_same_scores(estimate, truth, 1)
    fl = next(r for r in rows if r["metric"] == "fl_all" and r["region"] == "all" and r["motion"] == "total")
    o3 = next(r for r in rows if r["metric"] == "outlier_3px" and r["region"] == "all" and r["motion"] == "total")
    assert 0 < fl["sum"] < o3["sum"]  # some pixels over 3 px are within 5 % of their flow


def test_huge_errors_go_to_the_overflow_bin():
    """A diverged estimate (1e30 px, an exact multiple of the bin) lands in the last bin, as the reference has it."""
    rng = np.random.default_rng(15)
    estimate, truth = _synthetic_pair(rng)
    estimate.flow_total[30:32, 40:44] = np.float32(1e30)
    estimate.flow_total[60, 10] = np.float32(-3e38)
    rows = assert_same_scores(estimate, truth, 0)
    hist = M.decode_hist(next(r["hist"] for r in rows if r["metric"] == "epe_median" and r["region"] == "all"))
    assert hist[-1] >= 9


def test_perfect_estimate_scores_zero_exactly():
    """Zero error: EPE and angular error 0 in every region (arccos of exactly 1), both motions."""
    rng = np.random.default_rng(10)
    _, truth = _synthetic_pair(rng)
    estimate = SimpleNamespace(flow_total=truth.flow.copy(), flow_global=truth.flow_camera.copy(), valid=None,
                               stage_ms={})
    estimate.flow_total[~np.isfinite(estimate.flow_total)] = 0.0
    rows = assert_same_scores(estimate, truth, 0)
    for r in rows:
        if r["metric"] in ("epe_mean", "ae_mean", "epe_p95") and r["count"]:
            assert r["value"] == 0.0, (r["metric"], r["region"], r["motion"])


def test_own_arccos_is_within_one_ulp_of_numpys():
    """The pass's arccos (series, SIMD) against numpy's over [-1, 1], densest near 1 (small angles)."""
    from harness._flow_kernels import acos_array

    rng = np.random.default_rng(11)
    c = np.concatenate([np.linspace(-1.0, 1.0, 200_001), 1.0 - rng.uniform(0, 1e-3, 100_000),
                        1.0 - rng.uniform(0, 1e-12, 10_000), -1.0 + rng.uniform(0, 1e-6, 10_000),
                        np.nextafter([0.5, -0.5], [1.0, -1.0]), [0.5, -0.5, 0.0, -0.0]])
    got = np.empty_like(c)
    acos_array(c, got)
    want = np.arccos(c)
    assert np.all(np.abs(got - want) <= np.spacing(want)), np.max(np.abs(got - want) / np.spacing(want))
    assert got[c == 1.0].tolist() == [0.0] * int((c == 1.0).sum())


def test_prepared_truth_must_match_the_call():
    rng = np.random.default_rng(12)
    estimate, truth = _synthetic_pair(rng)
    prepared = M.prepare_pair_truth(truth, regions=("all", "interior"), boundary_px=2)
    rows = M.score_pair(estimate, truth, frame=0, prepared=prepared, timings=False)
    assert {r["region"] for r in rows} == {"all", "interior"}
    assert not prepared.flow.flags.writeable and not prepared.bits.flags.writeable
    with pytest.raises(ValueError, match="regions: expected those of prepared"):
        M.score_pair(estimate, truth, frame=0, prepared=prepared, regions=M.REGIONS)
    with pytest.raises(ValueError, match=r"boundary_px: expected that of prepared \(2\), got 3"):
        M.score_pair(estimate, truth, frame=0, prepared=prepared, boundary_px=3)
    small = PairTruth(flow=truth.flow[:10], flow_camera=truth.flow_camera[:10], valid=truth.valid[:10],
                      instances=truth.instances[:10])
    with pytest.raises(ValueError, match="truth: expected the size of prepared"):
        M.score_pair(estimate, small, frame=0, prepared=prepared)
    with pytest.raises(ValueError, match="flow_est: expected size"):
        M.score_pair(SimpleNamespace(flow_total=estimate.flow_total[:10], flow_global=estimate.flow_global[:10],
                                     valid=None, stage_ms={}), None, frame=0, prepared=prepared)


@pytest.mark.parametrize("where", ["flow_total", "flow_global"])
def test_a_non_finite_estimate_is_rejected_in_either_motion(where):
    rng = np.random.default_rng(13)
    estimate, truth = _synthetic_pair(rng)
    bad = getattr(estimate, where).copy()
    bad[50, 60, 1] = np.inf
    setattr(estimate, where, bad)
    with pytest.raises(ValueError, match=r"flow_est: 1 value\(s\) are NaN or infinite"):
        M.score_pair(estimate, truth, frame=0)


def test_valid_est_of_the_wrong_size_is_rejected():
    rng = np.random.default_rng(14)
    estimate, truth = _synthetic_pair(rng)
    estimate.valid = estimate.valid[:, :-1]
    with pytest.raises(ValueError, match=r"valid_est: expected shape \(90, 120\), got \(90, 119\)"):
        M.score_pair(estimate, truth, frame=0)


def test_fused_scoring_equals_the_reference_with_nan_truth_and_empty_regions():
    rng = np.random.default_rng(8)
    estimate, truth = _synthetic_pair(rng)
    cam = truth.flow_camera.copy()
    cam[40:50, :] = np.nan  # unknown camera flow: the local motion scores fewer pixels
    flow = truth.flow.copy()
    flow[:3] = np.nan
    truth = PairTruth(flow=flow, flow_camera=cam, valid=truth.valid, instances=np.zeros_like(truth.instances))
    assert_same_scores(estimate, truth, 0)
    empty = PairTruth(flow=flow, flow_camera=cam, valid=np.zeros_like(truth.valid), instances=truth.instances)
    assert_same_scores(estimate, empty, 0)


@pytest.mark.gl
@pytest.mark.slow
def test_fused_scoring_equals_the_reference_on_the_smoke_run(render_cache):
    """Every pair of the smoke suite's cells of seed 1 (both scenes, with and without jitter, every
    pipeline), scored both ways (fused with and without a prepared truth, and the reference): every
    metric, region and motion. Seed 2 is another world of the same scenes: twice the time, no other code."""
    from algorithms.pipeline import PairEstimate, Pipeline
    from harness.cell_scoring import point_seeds
    from harness.suites import expand, load_suite
    from scenes import cached_sequence, open_sequence

    cells = [c for c in expand(load_suite("smoke")) if c.variant.seed == 1]
    assert len(cells) == 10
    pairs = 0
    for cell in cells:
        seq = open_sequence(cached_sequence(cell.variant.spec, render_cache))
        for est in Pipeline.from_dict(cell.pipeline_spec).run(seq, seeds=point_seeds(seq.tracks)):
            if isinstance(est, PairEstimate):
                assert_same_scores(est, seq.pair_truth(est.index), est.index)
                pairs += 1
    assert pairs == 10 * 5
