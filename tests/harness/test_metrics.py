"""Metrics against hand-computed values, and aggregation from totals equal to whole-set computation."""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from harness import metrics as M
from harness.results import rows_to_frame


def _by(rows, metric, region="all", motion="total"):
    found = [r for r in rows if r["metric"] == metric and r["region"] == region and r["motion"] == motion]
    assert len(found) == 1, (metric, region, motion, len(found))
    return found[0]


def _field(*uv) -> np.ndarray:
    return np.asarray(uv, np.float32).reshape(1, -1, 2)


# --------------------------------------------------------------------------- per-pixel errors

def test_endpoint_error_is_the_euclidean_distance():
    assert M.endpoint_error(_field(3, 4), _field(0, 0))[0, 0] == pytest.approx(5.0)
    assert M.endpoint_error(_field(1, -2), _field(1, -2))[0, 0] == 0.0


def test_angular_error_uses_the_unit_third_component():
    # (0,0,1) vs (1,0,1): cos = 1/sqrt(2) -> 45 deg; (1,0,1) vs (-1,0,1): orthogonal -> 90 deg
    ae = M.angular_error_deg(_field(0, 0, 1, 0), _field(1, 0, -1, 0))
    np.testing.assert_allclose(ae[0], [45.0, 90.0], atol=1e-9)
    assert M.angular_error_deg(_field(2.5, -1), _field(2.5, -1))[0, 0] == pytest.approx(0.0, abs=1e-5)


def test_flow_rows_match_hand_computed_values():
    # EPE 0.5, 2, 4, 6 px; true magnitudes 0, 0, 100 (5 % = 5 px > 4: not Fl), 10 (5 % = 0.5 < 6: Fl)
    true = _field(0, 0, 0, 0, 100, 0, 10, 0)
    est = _field(0.5, 0, 0, 2, 104, 0, 10, 6)
    rows = M.flow_rows(est, true, np.ones((1, 4), bool))
    get = {r["metric"]: r for r in rows}
    assert get["epe_mean"]["value"] == pytest.approx(12.5 / 4)
    assert get["epe_mean"]["sum"] == pytest.approx(12.5) and get["epe_mean"]["count"] == 4
    assert get["epe_rms"]["value"] == pytest.approx(math.sqrt((0.25 + 4 + 16 + 36) / 4))
    assert get["epe_median"]["value"] == 2.0      # nearest rank: the 2nd of 4
    assert get["epe_p95"]["value"] == 6.0         # nearest rank: the 4th of 4
    assert get["outlier_1px"]["value"] == 75.0
    assert get["outlier_3px"]["value"] == 50.0
    assert get["outlier_5px"]["value"] == 25.0 and get["outlier_5px"]["sum"] == 1
    assert get["fl_all"]["value"] == 25.0
    assert get["epe_mean"]["unit"] == "px" and get["outlier_1px"]["unit"] == "%"
    assert get["ae_mean"]["unit"] == "deg" and not get["ae_mean"]["higher_is_better"]


def test_an_empty_region_adds_nothing():
    rows = M.flow_rows(_field(1, 0), _field(0, 0), np.zeros((1, 1), bool))
    assert all(r["count"] == 0 for r in rows)
    assert all(math.isnan(r["value"]) for r in rows)


# --------------------------------------------------------------------------- regions

def test_boundary_mask_of_a_one_pixel_vehicle_and_an_invalid_corner():
    valid = np.ones((9, 9), bool)
    inst = np.zeros((9, 9), np.uint16)
    inst[4, 4] = 1
    b = M.boundary_mask(valid, inst, boundary_px=1)
    # the edge is the plus (4,4) +- 1; dilated by 3x3 it is the 5x5 box without its corners
    assert b.sum() == 21
    assert b[2:7, 3:6].all() and b[3:6, 2:7].all() and not b[2, 2] and not b[6, 6]
    valid[0, 0] = False
    regions = M.region_masks(valid, inst, boundary_px=1)
    assert regions["all"].sum() == 80
    assert regions["vehicles"].sum() == 1 and regions["background"].sum() == 79
    assert regions["interior"].sum() == 81 - 21 - 4   # the invalid corner takes its 2x2 neighbourhood
    assert not regions["interior"][1, 1] and regions["interior"][2, 0]


def test_unknown_region_is_rejected():
    with pytest.raises(ValueError, match="unknown region 'sky'"):
        M.region_masks(np.ones((3, 3), bool), regions=("sky",))


# --------------------------------------------------------------------------- score_pair

def _pair(h=12, w=16):
    cam = np.zeros((h, w, 2), np.float32)
    cam[..., 0] = 2.0
    inst = np.zeros((h, w), np.uint16)
    inst[4:8, 5:10] = 7
    flow = cam.copy()
    flow[inst == 7] += (1.0, 0.0)
    truth = SimpleNamespace(flow=flow, flow_camera=cam, valid=np.ones((h, w), bool), instances=inst)
    return truth


def test_total_and_local_motion_separate_a_stabilisation_error():
    truth = _pair()
    glob = np.full_like(truth.flow, 0.0)
    glob[..., 0] = 2.5  # the global model is 0.5 px off; the total flow is exact
    est = SimpleNamespace(flow_total=truth.flow.copy(), flow_global=glob, valid=np.ones(truth.valid.shape, bool),
                          stage_ms={"global_motion": 2.0, "flow": 8.0})
    rows = M.score_pair(est, truth, frame=3)
    assert _by(rows, "epe_mean", motion="total")["value"] == 0.0
    assert _by(rows, "epe_mean", motion="local")["value"] == pytest.approx(0.5)
    assert _by(rows, "epe_mean", "vehicles", "local")["count"] == 20
    assert _by(rows, "time_flow_ms", motion="cost")["value"] == 8.0
    assert _by(rows, "time_total_ms", motion="cost")["value"] == 10.0
    assert _by(rows, "time_flow_ms", motion="cost")["kind"] == "timing"
    assert all(r["frame"] == 3 for r in rows)


def test_declined_pixels_lower_coverage_and_are_still_scored():
    truth = _pair()
    ft = truth.flow.copy()
    ft[0, :] = 0.0                      # the method gives up on the first row: zero flow there
    ve = np.ones(truth.valid.shape, bool)
    ve[0, :] = False
    est = SimpleNamespace(flow_total=ft, flow_global=truth.flow_camera, valid=ve, stage_ms={})
    rows = M.score_pair(est, truth, frame=0)
    row = _by(rows, "epe_mean")
    declined = truth.valid[0, :] & np.isfinite(truth.flow[0, :]).all(-1)
    expected = np.hypot(truth.flow[0, declined, 0], truth.flow[0, declined, 1]).sum() / row["count"]
    assert row["count"] == int(truth.valid.sum())  # dense: every truth-valid pixel counts
    assert row["value"] == pytest.approx(expected) and row["value"] > 0
    assert _by(rows, "coverage")["value"] == pytest.approx(100 * 11 / 12)


def test_a_nan_estimate_is_an_error_not_a_skipped_pixel():
    truth = _pair()
    ft = truth.flow.copy()
    ft[0, 0] = np.nan
    est = SimpleNamespace(flow_total=ft, flow_global=truth.flow_camera, valid=truth.valid, stage_ms={})
    with pytest.raises(ValueError, match="flow_est: 2 value"):
        M.score_pair(est, truth, frame=0)


def test_wrong_flow_layout_is_rejected():
    with pytest.raises(ValueError, match=r"expected \(H, W, 2\)"):
        M.score_flow(np.zeros((2, 4, 5), np.float32), np.zeros((4, 5, 2), np.float32), np.ones((4, 5), bool))


# --------------------------------------------------------------------------- aggregation

def _frames(rng, n=5):
    out = []
    for i in range(n):
        h, w = rng.integers(6, 20, size=2)
        true = rng.normal(scale=3, size=(h, w, 2)).astype(np.float32)
        est = (true + rng.standard_cauchy(size=(h, w, 2)) * 0.3).astype(np.float32)
        valid = rng.random((h, w)) > 0.2
        out.append((est, true, valid))
    return out


def test_aggregate_equals_the_whole_set_and_ignores_order():
    rng = np.random.default_rng(4)
    frames = _frames(rng)
    rows = []
    for i, (e, t, v) in enumerate(frames):
        rows += M.flow_rows(e, t, v, frame=i)
    df = rows_to_frame(rows, cell_id="c", scene="s", pipeline="p")
    agg = M.aggregate(df, by=["pipeline"]).set_index("metric")["value"]
    shuffled = M.aggregate(df.sample(frac=1.0, random_state=1), by=["pipeline"]).set_index("metric")["value"]
    pd.testing.assert_series_equal(agg, shuffled)

    e = np.concatenate([f[0][f[2]] for f in frames])
    t = np.concatenate([f[1][f[2]] for f in frames])
    whole = {r["metric"]: r["value"] for r in M.flow_rows(e[None], t[None], np.ones((1, len(e)), bool))}
    for m in ("epe_mean", "epe_rms", "ae_mean", "outlier_1px", "outlier_3px", "outlier_5px", "fl_all"):
        assert agg[m] == pytest.approx(whole[m], rel=1e-9), m
    # quantiles come from the summed histogram: within half a bin of the pooled value
    for m in ("epe_median", "epe_p95"):
        assert abs(agg[m] - whole[m]) <= M.HIST_BIN_PX / 2 + 1e-9, m
    # and the average of per-frame means is not what aggregate returns
    per_frame = df[df["metric"] == "epe_mean"]["value"].mean()
    assert per_frame != pytest.approx(agg["epe_mean"], rel=1e-6)


def test_aggregate_leaves_failed_rows_out():
    rows = M.flow_rows(_field(1, 0), _field(0, 0), np.ones((1, 1), bool))
    ok = rows_to_frame(rows, cell_id="a", status="ok")
    bad = rows_to_frame([{"metric": "epe_mean", "value": 99.0, "sum": 99.0, "count": 1.0}], cell_id="b",
                        status="failed")
    agg = M.aggregate(pd.concat([ok, bad]), by=[]).set_index("metric")
    assert agg.loc["epe_mean", "value"] == 1.0


def test_histogram_round_trip_and_overflow():
    epe = np.array([0.0, 0.004, 0.015, 2.5, 250.0])
    h = M.epe_histogram(epe)
    assert h.sum() == 5 and h[0] == 2 and h[1] == 1 and h[250] == 1 and h[-1] == 1
    np.testing.assert_array_equal(M.decode_hist(M.encode_hist(h)), h)
    assert M.hist_quantile(h, 0.5) == pytest.approx(0.015)  # the 3rd of 5, at its bin centre
    assert M.hist_quantile(h, 1.0) == M.HIST_MAX_PX           # overflow reads as the floor
    assert math.isnan(M.hist_quantile(np.zeros_like(h), 0.5))



def _overflow_frames():
    """Two frames of 1-D EPEs (px) whose pooled 95th percentile and median lie above 100 px."""
    return [np.r_[np.full(90, 1.0), np.full(10, 182.3)], np.r_[np.full(5, 0.5), np.full(95, 250.0)]]


def _nearest_rank(x, q):
    return np.sort(x)[max(1, math.ceil(q * x.size)) - 1]


@pytest.mark.parametrize("path", ["flow_rows", "score_flow"])
def test_an_aggregated_quantile_in_the_overflow_bin_is_read_from_its_samples_not_floored(path):
    # issue 23: eval-flow printed epe_p95 100.0000 on KITTI where the pooled p95 is 182.3 px
    frames = []
    for f, epe in enumerate(_overflow_frames()):
        flow_true = np.zeros((1, epe.size, 2), np.float32)
        flow_est = np.stack([epe, np.zeros_like(epe)], -1).astype(np.float32)[None]
        valid = np.ones((1, epe.size), bool)
        rows = (M.flow_rows(flow_est, flow_true, valid, frame=f) if path == "flow_rows"
                else M.score_flow(flow_est, flow_true, valid, regions=("all",), frame=f))
        frames.append(rows_to_frame(rows, cell_id="c", status="ok"))
    pooled = np.concatenate([np.float64(np.float32(e)) for e in _overflow_frames()])
    agg = M.aggregate(pd.concat(frames), by=[]).set_index("metric")["value"]
    for metric, q in (("epe_p95", 0.95), ("epe_median", 0.5)):
        assert _nearest_rank(pooled, q) > M.HIST_MAX_PX
        assert agg[metric] == pytest.approx(_nearest_rank(pooled, q), abs=M.HIST_BIN_PX / 2), metric
    # a histogram that lost its overflow samples (written before they were kept) still reads the floor
    h = M.epe_histogram(pooled)
    assert M.hist_quantile(h, 0.95) == M.HIST_MAX_PX
    assert M.hist_quantile(h, 0.5, tail=M.overflow_tail(pooled)) == pytest.approx(182.305)


@pytest.mark.parametrize("bins", [[], [0], [M.HIST_NBINS - 1], [0, M.HIST_NBINS - 1], [7, 8, 300]])
def test_encoded_histogram_stores_its_first_to_last_non_empty_bin(bins):
    h = np.zeros(M.HIST_NBINS, np.int64)
    h[bins] = np.arange(1, len(bins) + 1)
    data = M.encode_hist(h)
    if not bins:
        assert data == b""
        return
    fmt, width, lo, n = struct.unpack_from("<BBII", data)
    assert (fmt, width, lo, n) == (1, 4, min(bins), max(bins) - min(bins) + 1)
    np.testing.assert_array_equal(M.decode_hist(data), h)




def test_a_row_written_before_tails_were_kept_leaves_a_pooled_quantile_above_100_px_at_the_floor():
    # a format-1 histogram (overflow count, no samples) pooled with a format-2 one: the tail is incomplete
    epe = np.full(10, 150.0)
    old = {"metric": "epe_p95", "value": 150.0, "sum": float("nan"), "count": 10.0, "hist": M.encode_hist(
        M.epe_histogram(epe))}
    new = {**old, "hist": M.encode_hist(M.epe_histogram(epe), tail=M.overflow_tail(epe))}
    assert old["hist"][0] == 1 and new["hist"][0] == 2
    agg = M.aggregate(rows_to_frame([old, new]), by=[]).set_index("metric")
    assert agg.loc["epe_p95", "value"] == M.HIST_MAX_PX
    assert M.aggregate(rows_to_frame([new, new]), by=[]).set_index("metric").loc["epe_p95", "value"] == \
        pytest.approx(150.005)


def test_a_histogram_with_a_tail_round_trips_and_a_tail_that_is_not_the_overflow_is_refused():
    epe = np.array([0.5, 100.0, 100.004, 250.0, 250.001, 3e20])
    h, tail = M.epe_histogram(epe), M.overflow_tail(epe)
    np.testing.assert_array_equal(tail[0], [10000, 25000, 2 ** 62])  # 100.004 shares 100's bin; 3e20 clamped
    np.testing.assert_array_equal(tail[1], [2, 2, 1])
    data = M.encode_hist(h, tail=tail)
    assert data[0] == 2 and M.encode_hist(h)[0] == 1  # format 2 only with a tail: old bytes unchanged
    np.testing.assert_array_equal(M.decode_hist(data), h)
    for a, b in zip(M.decode_tail(data), tail):
        np.testing.assert_array_equal(a, b)
    assert M.decode_tail(M.encode_hist(h))[0].size == 0
    merged = M.merge_tails([tail, M.overflow_tail(np.array([250.0, 400.0]))])
    np.testing.assert_array_equal(merged[0], [10000, 25000, 40000, 2 ** 62])
    np.testing.assert_array_equal(merged[1], [2, 3, 1, 1])
    with pytest.raises(ValueError, match="tail: expected the 5 samples of the overflow bin, got 4"):
        M.encode_hist(h, tail=(tail[0], tail[1] - np.array([0, 1, 0])))
    with pytest.raises(ValueError, match="tail: expected ascending unique bins >= 10000"):
        M.encode_hist(h, tail=(tail[0][::-1], tail[1]))


def test_registry_describes_every_metric():
    table = M.describe_metrics()
    assert {"epe_mean", "fl_all", "jitter_residual_rms", "id_switches", "time_flow_ms"} <= set(table["metric"])
    assert (table["weighting"].str.len() > 0).all()
    with pytest.raises(KeyError, match="unknown metric 'epe'.*epe_mean"):
        M.metric_def("epe")


# --------------------------------------------------------------------------- global motion, jitter

def _camera(n, *, jitter):
    return pd.DataFrame({"frame": np.arange(n), "jitter_x_px": jitter[:, 0], "jitter_y_px": jitter[:, 1],
                         "global_dx_px": [1.0] * (n - 1) + [np.nan], "global_dy_px": [0.0] * (n - 1) + [np.nan]})


def test_shift_error_per_pair_skips_the_last_frame():
    cam = _camera(4, jitter=np.zeros((4, 2)))
    rows = M.shift_rows(np.array([[1.0, 0.0], [4.0, 4.0], [1.0, 0.0]]), cam)
    assert [r["value"] for r in rows] == [0.0, 5.0, 0.0]
    assert [r["frame"] for r in rows] == [0, 1, 2]


def test_shift_error_pairs_the_shifts_with_the_camera_rows_in_frame_order():
    cam = _camera(4, jitter=np.zeros((4, 2)))
    cam["global_dx_px"] = [1.0, 2.0, 3.0, np.nan]
    shuffled = cam.iloc[[2, 0, 3, 1]]  # camera.csv in any order: pair i is frame i's row
    rows = M.shift_rows(np.array([[1.0, 0.0], [2.0, 3.0], [0.0, 4.0]]), shuffled)
    assert [(r["frame"], r["value"]) for r in rows] == [(0, 0.0), (1, 3.0), (2, 5.0)]


def test_jitter_residual_absorbs_the_truths_linear_trend():
    i = np.arange(20.0)
    wobble = np.stack([np.sin(i), np.cos(2 * i)], axis=1)
    truth = wobble + np.stack([0.3 * i + 5, -0.1 * i], axis=1)  # drift and offset are flight line, not jitter
    cam = _camera(20, jitter=truth)
    exact = M.detrend(wobble)
    rows = M.jitter_rows(exact, cam)
    assert max(r["value"] for r in rows) < 1e-9
    off = M.jitter_rows(exact + [1.0, 0.0], cam)
    agg = M.aggregate(rows_to_frame(off), by=[]).set_index("metric")
    assert agg.loc["jitter_residual_rms", "value"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="expected 20 frames"):
        M.jitter_rows(exact[:5], cam)


# --------------------------------------------------------------------------- trajectories

def _truth_tracks():
    rows = []
    for f in range(4):
        rows.append({"frame": f, "vehicle_id": 1, "x_px": 10.0 + f, "y_px": 10.0, "visible": 1})
        rows.append({"frame": f, "vehicle_id": 2, "x_px": 100.0, "y_px": 50.0 + f, "visible": 1})
        rows.append({"frame": f, "vehicle_id": 3, "x_px": 200.0, "y_px": 200.0, "visible": int(f < 2)})
    return pd.DataFrame(rows)


def _est(frame, track_id, x, y, source, seed=np.nan, pred=None):
    px, py = pred if pred is not None else (x, y)
    return {"frame": frame, "track_id": track_id, "x_px": x, "y_px": y, "x_filt_px": x, "y_filt_px": y,
            "x_pred_px": px, "y_pred_px": py, "source": source, "seed_vehicle_id": seed}


def test_point_tracker_errors_ate_fde_and_completeness():
    est = pd.DataFrame([_est(0, 0, 10.0, 13.0, "point", 1, pred=(10.0, 10.0)),
                        _est(1, 0, 11.0, 14.0, "point", 1),
                        _est(2, 0, 12.0, 10.0, "point", 1)])  # lost after frame 2
    rows = M.track_rows(est, _truth_tracks())
    errs = [r["value"] for r in rows if r["metric"] == "track_error"]
    assert errs == [3.0, 4.0, 0.0]
    assert _by(rows, "track_ate_rmse", "point", "track")["value"] == pytest.approx(math.sqrt(25 / 3))
    assert _by(rows, "track_fde", "point", "track")["value"] == 0.0
    assert [r["value"] for r in rows if r["metric"] == "track_pred_error"][0] == 0.0
    comp = {r["track_id"]: r["value"] for r in rows if r["metric"] == "track_completeness"}
    assert comp == {1: 75.0, 2: 0.0, 3: 0.0}
    assert not [r for r in rows if r["metric"] == "id_switches"]  # seeded tracks map by id


def test_multi_target_identity_switch_counted_once():
    est = []
    for f in range(4):
        est.append(_est(f, 7 if f < 2 else 8, 10.0 + f, 10.5, "multi"))   # vehicle 1 changes track id
        est.append(_est(f, 9, 100.5, 50.0 + f, "multi"))                   # vehicle 2 kept
    rows = M.track_rows(pd.DataFrame(est), _truth_tracks(), gate_px=5.0)
    sw = {r["track_id"]: r["value"] for r in rows if r["metric"] == "id_switches"}
    assert sw == {1: 1.0, 2: 0.0, 3: 0.0}
    comp = {r["track_id"]: r["value"] for r in rows if r["metric"] == "track_completeness"}
    assert comp == {1: 100.0, 2: 100.0, 3: 0.0}


def test_association_keeps_a_correspondence_within_the_gate():
    truth = _truth_tracks()
    truth = truth[truth["vehicle_id"] == 1]
    est = pd.DataFrame([_est(0, 1, 11.0, 10.0, "multi"),
                        _est(1, 1, 14.0, 10.0, "multi"), _est(1, 2, 11.2, 10.0, "multi")])
    a = M.associate_tracks(est, truth, gate_px=5.0)
    assert a["track_id"].tolist() == [1, 1]   # CLEAR-MOT: no switch while the old match stays in the gate
    assert not a["switch"].any()
    tight = M.associate_tracks(est, truth, gate_px=0.5)  # frame 0 (1 px off) falls outside the gate
    assert tight["frame"].tolist() == [1] and tight["track_id"].tolist() == [2]


def test_score_flow_per_region_equals_flow_rows_on_the_region_mask():
    rng = np.random.default_rng(7)
    truth = _pair(16, 20)
    est = (truth.flow + rng.normal(scale=0.7, size=truth.flow.shape)).astype(np.float32)
    valid = rng.random(truth.valid.shape) > 0.1
    rows = M.score_flow(est, truth.flow, valid, instances=truth.instances, boundary_px=2)
    masks = M.region_masks(valid, truth.instances, boundary_px=2)
    for region, mask in masks.items():
        direct = {r["metric"]: r for r in M.flow_rows(est, truth.flow, mask, region=region)}
        for metric, r in direct.items():
            got = _by(rows, metric, region)
            assert got["count"] == r["count"] and got["hist"] == r["hist"], (metric, region)
            assert got["value"] == pytest.approx(r["value"], rel=1e-12, nan_ok=True), (metric, region)


# --------------------------------------------------------------------------- stabilisation (Liu et al. 2013)

def test_stabilisation_identity_correction_of_a_steady_flight_scores_one_one_one():
    n = 30
    steady = np.tile([0.0, 2.0], (n - 1, 1))   # constant flight: the output does not shake
    sc = M.stabilisation_scores(np.zeros((n, 2)), steady, (120, 160))
    assert sc == {"cropping_ratio": 1.0, "distortion": 1.0, "stability": 1.0}


def test_stabilisation_crop_follows_the_correction_extent_and_removed_shake_is_stable():
    rng = np.random.default_rng(4)
    n = 64
    i = np.arange(n)
    shake = np.stack([3.0 * np.sin(2.9 * i), rng.normal(0, 1.0, n)], axis=1)   # high-frequency jitter
    true_shifts = np.diff(shake, axis=0) + [0.0, 2.0]
    raw = M.stabilisation_scores(np.zeros((n, 2)), true_shifts, (100, 200))
    fixed = M.stabilisation_scores(-shake, true_shifts, (100, 200))   # the correction removes it exactly
    assert raw["stability"] < 0.3 and fixed["stability"] == 1.0
    extent = shake.max(axis=0) - shake.min(axis=0)
    assert fixed["cropping_ratio"] == pytest.approx(min((200 - extent[0]) / 200, (100 - extent[1]) / 100))
    slow = np.stack([5.0 * np.sin(2 * np.pi * i / n), np.zeros(n)], axis=1)  # one slow sway: low frequency
    assert M.stabilisation_scores(np.zeros((n, 2)), np.diff(slow, axis=0), (100, 200))["stability"] > 0.9
    assert math.isnan(M.stabilisation_scores(np.zeros((8, 2)), np.ones((7, 2)), (100, 200))["stability"])
    with pytest.raises(ValueError, match="expected 63 pair shifts for 64 frames"):
        M.stabilisation_scores(np.zeros((n, 2)), true_shifts[:-1], (100, 200))
