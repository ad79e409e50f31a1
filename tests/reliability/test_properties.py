"""Property tests over the algorithms, metrics and formats (hypothesis, derandomized for CI).

Random shapes, dtypes, constant and extreme images: no crash other than the documented
TypeError / ValueError with a message; finite flow of the right shape and dtype with a bool
valid mask; endpoint error non-negative and zero for identical fields; aggregates independent
of row order; filters keep constant fields; Kalman covariances stay symmetric positive definite.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import algorithms.pipeline  # noqa: F401  (fills the flow registry with every built-in method)
from algorithms.filters import spatial_filter, temporal_filter, threshold_flow
from algorithms.kalman import ConstantVelocityKalman, kalman_cv_filter, scalar_kalman
from algorithms.registry import get_flow_method
from harness.metrics import (
    HIST_NBINS, aggregate, angular_error_deg, encode_hist, endpoint_error, epe_histogram, score_flow,
)
from scenes.formats import read_flo, read_png, write_flo, write_png

FAST = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
BUILT_IN_FLOW = ("lucas_kanade", "horn_schunck", "farneback", "dis", "tvl1", "ilk", "tv_l1")
DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)
DIS_SAFE_SIDE_PX = 16  # below, cv2 5.0 DIS crashes the process on some shapes (15x48) or raises cv2.error


@st.composite
def frame_pairs(draw, min_side=2, max_side=48):
    h = draw(st.integers(min_side, max_side))
    w = draw(st.integers(min_side, max_side))
    dtype = np.dtype(draw(st.sampled_from(DTYPES)))
    kind = draw(st.sampled_from(("random", "constant", "extreme", "shifted")))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    hi = float(np.iinfo(dtype).max) if dtype.kind in "ui" else 255.0
    lo = float(np.iinfo(dtype).min) if dtype.kind == "i" else 0.0
    if kind == "constant":
        v = draw(st.sampled_from((lo, hi, 0.0, 77.0)))
        return np.full((h, w), v, dtype), np.full((h, w), v, dtype)
    if kind == "extreme":  # a checkerboard of the dtype's extremes (floats: +-1e6)
        if dtype.kind == "f":
            lo, hi = -1e6, 1e6
        board = (np.indices((h, w)).sum(0) % 2).astype(bool)
        f0 = np.where(board, hi, lo).astype(dtype)
        return f0, np.where(~board, hi, lo).astype(dtype)
    f0 = rng.uniform(lo, hi, (h, w))
    f1 = np.roll(f0, 1, axis=1) if kind == "shifted" else rng.uniform(lo, hi, (h, w))
    return f0.astype(dtype), f1.astype(dtype)


@FAST
@given(method=st.sampled_from(BUILT_IN_FLOW), pair=frame_pairs())
def test_flow_methods_return_finite_flow_or_a_documented_error(method, pair):
    f0, f1 = pair
    if method == "dis":  # OpenCV's DIS segfaults on short frames: see the test below
        assume(min(f0.shape) >= DIS_SAFE_SIDE_PX)
    try:
        flow, valid = get_flow_method(method)(f0, f1)
    except (TypeError, ValueError) as exc:
        assert str(exc), "an error without a message"
        return
    h, w = f0.shape
    assert flow.shape == (h, w, 2) and flow.dtype == np.float32
    assert valid.shape == (h, w) and valid.dtype == bool
    assert np.isfinite(flow).all(), f"{method}: {np.count_nonzero(~np.isfinite(flow))} non-finite vectors"


@FAST
@given(method=st.sampled_from(BUILT_IN_FLOW), h=st.integers(32, 48), w=st.integers(32, 48),
       v=st.sampled_from((0, 1, 128, 255)))
def test_identical_constant_frames_give_no_motion(method, h, w, v):
    f = np.full((h, w), v, np.uint8)
    flow, valid = get_flow_method(method)(f, f)
    # no texture: nothing to measure; what is reported valid must be zero motion
    assert np.all(np.abs(flow[valid]) < 1e-3)
    assert np.isfinite(flow).all()


@pytest.mark.parametrize("shape", [(15, 48), (8, 48), (20, 7), (2, 2)])
def test_dis_on_small_frames_is_refused_not_a_crash(shape):
    # OpenCV 5.0's DIS segfaults on 15x48 and 8x48 frames: run it in a child so a crash fails the test
    import subprocess
    import sys

    from tests.reliability.rel_support import ROOT

    code = (f"import numpy as np\nfrom algorithms.reference import dis\n"
            f"f0 = (np.random.default_rng(0).random({shape}) * 255).astype(np.uint8)\n"
            f"try:\n    dis(f0, np.roll(f0, 1, 1))\nexcept ValueError as exc:\n    print('refused:', exc)\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"exit {done.returncode}: {done.stderr[-300:]}"
    assert "refused: dis: expected frames of at least" in done.stdout


finite_flows = st.integers(1, 24).flatmap(lambda h: st.integers(1, 24).flatmap(lambda w: arrays(
    np.float32, (h, w, 2), elements=st.floats(-300, 300, width=32, allow_nan=False))))


@FAST
@given(a=finite_flows, data=st.data())
def test_endpoint_and_angular_error_are_metrics(a, data):
    b = data.draw(arrays(np.float32, a.shape, elements=st.floats(-300, 300, width=32, allow_nan=False)))
    e = endpoint_error(a, b)
    assert e.shape == a.shape[:2] and (e >= 0).all()
    assert (endpoint_error(a, a) == 0).all()
    np.testing.assert_array_equal(e, endpoint_error(b, a))
    ae = angular_error_deg(a, b)
    assert ((ae >= 0) & (ae <= 180)).all() and (angular_error_deg(a, a) < 1e-3).all()


@FAST
@given(a=finite_flows, data=st.data())
def test_scoring_a_field_against_itself_gives_zero_error(a, data):
    valid = data.draw(arrays(bool, a.shape[:2]))
    rows = {(r["metric"], r["region"]): r for r in score_flow(a, a, valid)}
    n = int(valid.sum())
    for m in ("epe_mean", "epe_rms", "outlier_1px"):
        r = rows[(m, "all")]
        assert r["count"] == n
        assert (r["value"] == 0.0) if n else math.isnan(r["value"]), (m, r)


_AGG_METRICS = ("epe_mean", "epe_rms", "outlier_3px", "epe_median", "id_switches")


@st.composite
def metric_rows(draw):
    n = draw(st.integers(1, 40))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    out = []
    for i in range(n):
        metric = _AGG_METRICS[int(rng.integers(len(_AGG_METRICS)))]
        count = float(rng.integers(0, 5000))
        epe = rng.exponential(2.0, int(min(count, 300)))
        hist = encode_hist(epe_histogram(epe)) if metric == "epe_median" else b""
        total = float(np.nan if metric == "epe_median" else rng.lognormal(0, 4) * (count > 0))
        out.append({"pipeline": "p", "scene": f"s{i % 3}", "metric": metric, "region": "all", "motion": "total",
                    "kind": "accuracy", "value": 0.0, "sum": total, "count": count, "unit": "px",
                    "higher_is_better": False, "hist": hist, "status": "ok" if i % 7 else "failed"})
    return pd.DataFrame(out)


@FAST
@given(rows=metric_rows(), seed=st.integers(0, 2**31 - 1), by=st.sampled_from(([], ["pipeline"], ["scene"])))
def test_aggregate_does_not_depend_on_row_order(rows, seed, by):
    ref = aggregate(rows, by=by)
    got = aggregate(rows.sample(frac=1.0, random_state=seed), by=by)
    pd.testing.assert_frame_equal(got.reset_index(drop=True), ref.reset_index(drop=True), check_exact=True)
    assert got["value"].to_numpy().tobytes() == ref["value"].to_numpy().tobytes()
    assert (got["count"] >= 0).all() and len(got) == len(rows[rows["status"] == "ok"].groupby(
        [*by, "metric", "region", "motion"]))


@FAST
@given(h=st.integers(1, 32), w=st.integers(1, 32), u=st.floats(-50, 50, width=32), v=st.floats(-50, 50, width=32),
       border=st.sampled_from(("replicate", "reflect")))
def test_filters_keep_a_constant_field(h, w, u, v, border):
    f = np.empty((h, w, 2), np.float32)
    f[..., 0], f[..., 1] = u, v
    tol = 1e-6 * max(1.0, abs(u), abs(v))
    np.testing.assert_allclose(spatial_filter(f, border=border), f, rtol=0, atol=tol)
    for prev, nxt in ((f, f), (None, f), (f, None), (None, None)):
        np.testing.assert_allclose(temporal_filter(prev, f, nxt), f, rtol=0, atol=tol)
    kept, mask = threshold_flow(f)  # no direction, no magnitude limits: everything stays
    assert mask.dtype == bool and mask.all()
    np.testing.assert_array_equal(kept, f)


positions = arrays(np.float64, st.tuples(st.integers(1, 40), st.just(2)),
                   elements=st.one_of(st.floats(-1e4, 1e4), st.just(np.nan)))


@FAST
@given(z=positions, sa=st.floats(0, 20), sm=st.floats(0.01, 50), sv=st.floats(0, 100))
def test_kalman_covariance_stays_symmetric_positive_definite(z, sa, sm, sv):
    kf = ConstantVelocityKalman((0.0, 0.0), sigma_accel_px=sa, sigma_meas_px=sm, sigma_pos0_px=sm, sigma_vel0_px=sv)
    for zk in z:
        kf.predict()
        kf.update(zk)
        P = kf.P
        assert np.isfinite(P).all() and np.isfinite(kf.x).all()
        np.testing.assert_allclose(P, P.T, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(P).max()))
        # positive semi-definite (eigenvalues may reach 0 for a noise-free axis, never below)
        assert np.linalg.eigvalsh((P + P.T) / 2).min() >= -1e-9 * max(1.0, np.abs(P).max())
    out = kalman_cv_filter(z, sigma_accel_px=sa, sigma_meas_px=sm, sigma_vel0_px=sv)
    seen = np.isfinite(z).all(axis=1)
    if seen.any():
        first = int(np.argmax(seen))
        assert np.isfinite(out.filtered_px[first:]).all()
        for P in out.covariances[first:]:
            assert np.linalg.eigvalsh((P + P.T) / 2).min() >= -1e-9 * max(1.0, np.abs(P).max())


@FAST
@given(z=arrays(np.float64, st.integers(1, 50), elements=st.one_of(st.floats(-1e4, 1e4), st.just(np.nan))),
       q=st.floats(0, 10), r=st.floats(1e-3, 10))
def test_scalar_kalman_stays_between_prediction_and_measurement(z, q, r):
    x = scalar_kalman(z, x0=-1.0, p0=1.0, q=q, r=r)  # thesis start X(1|1) = -1
    assert x.shape == z.shape and np.isfinite(x).all()
    for k in range(1, len(z)):  # eq. 4.8 with 0 <= Kg <= 1: a convex combination
        if not math.isnan(z[k]):
            lo, hi = sorted((x[k - 1], z[k]))
            assert lo - 1e-9 * max(1, abs(lo)) <= x[k] <= hi + 1e-9 * max(1, abs(hi))


@FAST
@given(flow=arrays(np.float32, st.tuples(st.integers(1, 16), st.integers(1, 16), st.just(2)),
                   elements=st.one_of(st.floats(-1e6, 1e6, width=32), st.just(np.nan))))
def test_flo_round_trip_is_exact(tmp_path_factory, flow):
    path = tmp_path_factory.mktemp("flo") / "f.flo"
    write_flo(path, flow)
    back = read_flo(path)
    assert back.dtype == np.float32 and back.shape == flow.shape
    np.testing.assert_array_equal(back, flow)  # NaN (unknown) where NaN, the same bits elsewhere


@FAST
@given(img=st.one_of(
    arrays(np.uint8, st.tuples(st.integers(1, 16), st.integers(1, 16), st.just(3))),
    arrays(np.uint8, st.tuples(st.integers(1, 16), st.integers(1, 16))),
    arrays(np.uint16, st.tuples(st.integers(1, 16), st.integers(1, 16)))))
def test_png_round_trip_is_exact(tmp_path_factory, img):
    path = tmp_path_factory.mktemp("png") / "i.png"
    write_png(path, img)
    back = read_png(path)
    assert back.dtype == img.dtype
    np.testing.assert_array_equal(back, img)


def test_the_histogram_has_the_documented_bins():
    assert epe_histogram(np.array([0.0, 0.004, 99.999, 1e9])).sum() == 4 and HIST_NBINS > 10_000


@settings(max_examples=15, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(name=st.sampled_from(("thesis-lk", "thesis-hs", "pyramidal-lk", "dis", "farneback")),
       n=st.integers(2, 4), h=st.integers(41, 56), w=st.integers(41, 56),
       kind=st.sampled_from(("random", "constant", "black", "drifting")), seed=st.integers(0, 2**32 - 1))
def test_pipelines_give_finite_estimates_on_degenerate_sequences(name, n, h, w, kind, seed):
    from algorithms.pipeline import PIPELINES, Pipeline

    rng = np.random.default_rng(seed)
    base = (rng.random((h + 8, w + 8, 3)) * 255).astype(np.uint8)
    frames = {"random": [(rng.random((h, w, 3)) * 255).astype(np.uint8) for _ in range(n)],
              "constant": [np.full((h, w, 3), 120, np.uint8)] * n,
              "black": [np.zeros((h, w, 3), np.uint8)] * n,
              "drifting": [base[i:i + h, 2 * i:2 * i + w] for i in range(n)]}[kind]
    spec = PIPELINES[name]
    pipeline = spec if isinstance(spec, Pipeline) else Pipeline.from_dict(spec)
    *pairs, seq = list(pipeline.run(frames, seeds=[(1, w / 2, h / 2)]))
    assert [p.index for p in pairs] == list(range(n - 1))
    for p in pairs:
        for a in (p.flow_global, p.flow_total, p.flow_local, p.flow_filtered):
            assert a.shape == (h, w, 2) and np.isfinite(a).all()
        assert p.valid.dtype == bool and p.motion_mask.dtype == bool and np.isfinite(p.global_shift_px).all()
    for a in (seq.shifts_px, seq.cumulative_px, seq.flight_line_px, seq.correction_px, seq.jitter_px):
        assert np.isfinite(a).all()
    assert seq.shifts_px.shape == (n - 1, 2) and seq.cumulative_px.shape == (n, 2)
