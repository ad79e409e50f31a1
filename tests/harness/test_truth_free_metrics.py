"""Metrics without ground truth (photometric residual, ITF) and detection precision / recall: known motion
scores as it should, occlusion is left out, bad input is refused, and the rows pool from totals."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pandas as pd
import pytest

import harness.metrics as M
from harness.results import rows_to_frame


def _texture(h=96, w=128, seed=0):
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur((rng.random((h + 40, w + 40)) * 255).astype(np.float32), (0, 0), 2.0)


def _pair(dx=3, dy=2, h=96, w=128):
    """Frame 1 is frame 0's content moved by (dx, dy) px: the true flow is (dx, dy) everywhere."""
    big = _texture(h, w)
    g0 = big[20:20 + h, 20:20 + w]
    g1 = big[20 - dy:20 - dy + h, 20 - dx:20 - dx + w]
    return np.ascontiguousarray(g0), np.ascontiguousarray(g1)


def _by(rows, metric):
    (r,) = [r for r in rows if r["metric"] == metric]
    return r


def test_the_true_flow_has_a_residual_near_zero_and_a_wrong_flow_a_larger_one():
    g0, g1 = _pair()
    prep = M.prepare_photometric(g0, g1)
    assert prep.consistent.mean() > 0.8  # the reference (DIS) agrees with itself on a translation
    true = np.broadcast_to(np.array([3, 2], np.float32), g0.shape + (2,))
    rows = M.photometric_rows(true, prep, frame=4)
    assert _by(rows, "photo_residual")["value"] < 0.05 and _by(rows, "photo_residual")["frame"] == 4
    assert _by(rows, "photo_residual")["motion"] == "photometric"
    off = [M.photometric_rows(true + np.float32(e), prep, frame=4) for e in (0.5, 1.0, 2.0)]
    res = [_by(r, "photo_residual")["value"] for r in off]
    assert 0.05 < res[0] < res[1] < res[2]  # the residual grows with the flow error
    # the residual is the Charbonnier mean over the scored pixels: sum / count
    r = _by(off[0], "photo_residual")
    assert r["value"] == pytest.approx(r["sum"] / r["count"])
    assert _by(off[0], "photo_coverage")["count"] == g0.size


def test_a_flow_that_leaves_the_frame_is_not_scored_there():
    g0, g1 = _pair()
    prep = M.prepare_photometric(g0, g1)
    far = np.zeros(g0.shape + (2,), np.float32)
    far[..., 0] = 200.0  # every pixel lands outside frame 1
    rows = M.photometric_rows(far, prep, frame=0)
    assert _by(rows, "photo_coverage")["value"] == 0.0 and math.isnan(_by(rows, "photo_residual")["value"])


def test_the_forward_backward_check_takes_an_occluding_square_out():
    # a square moves 8 px right over a static background: the background strip it covers in frame 1
    # (columns 70-77 of frame 0) has no match there
    bg = _texture(seed=1)[20:116, 20:148]
    sq = _texture(seed=2)[:30, :30]
    g0, g1 = bg.copy(), bg.copy()
    g0[30:60, 40:70] = sq
    g1[30:60, 48:78] = sq
    prep = M.prepare_photometric(g0, g1)
    covered = np.zeros_like(prep.consistent)
    covered[34:56, 71:77] = True
    # DIS (the reference) smooths over the edge: about two thirds of the strip go, 1-2 % elsewhere
    assert prep.consistent[covered].mean() < 0.5 and prep.consistent[:, 90:].mean() > 0.95


def test_photometric_input_is_checked():
    g0, g1 = _pair()
    with pytest.raises(ValueError, match=r"gray frames: expected two \(H, W\) arrays of one shape"):
        M.prepare_photometric(g0, g1[:, :-1])
    prep = M.prepare_photometric(g0, g1)
    with pytest.raises(ValueError, match="flow_total"):
        M.photometric_rows(np.zeros((5, 5, 2), np.float32), prep, frame=0)


def test_itf_is_the_psnr_of_the_stabilised_pair():
    g0, g1 = _pair(dx=3, dy=2)
    # a perfect correction moves frame 1 back onto frame 0: delta = c1 - c0 = -(3, 2)
    good = M.psnr_shifted(g0, g1, (-3.0, -2.0))
    assert math.isinf(good) or good > 60
    bad = M.psnr_shifted(g0, g1, (0.0, 0.0))
    # by hand: no displacement, nothing to interpolate, the overlap is every pixel
    assert bad == pytest.approx(10 * math.log10(255 ** 2 / np.mean((g1.astype(np.float64) - g0) ** 2)))
    assert bad < good
    rows = M.itf_rows([30.0, math.inf, 20.0])
    assert [r["frame"] for r in rows] == [0, 2] and [r["value"] for r in rows] == [30.0, 20.0]
    agg = M.aggregate(rows_to_frame(rows), by=[]).set_index("metric")["value"]
    assert agg["stab_itf"] == 25.0


def _truth_frame():
    return pd.DataFrame({"frame": 0, "vehicle_id": [1, 2, 3, 4], "x_px": [20.0, 60.0, 100.0, 140.0],
                         "y_px": 20.0, "bbox_x0_px": [10.0, 50.0, 90.0, 130.0], "bbox_y0_px": 15.0,
                         "bbox_x1_px": [30.0, 70.0, 110.0, 150.0], "bbox_y1_px": 25.0,
                         "visible": [1, 1, 1, 0], "speed_mps": [10.0, 0.0, 10.0, 10.0], "parked": [0, 1, 0, 0]})


def test_detection_precision_and_recall_count_moving_vehicles_only():
    truth = _truth_frame()  # moving and visible: vehicles 1 and 3 (2 is parked, 4 hidden)
    # detections as tuples: (x, y, area) without a box, (x, y, area, x0, y0, x1, y1) with an inclusive pixel box
    dets = [(21.0, 19.0, 40.0),                 # a point inside vehicle 1's box
            (60.0, 20.0, 40.0),                 # on the parked vehicle 2: a false positive
            (22.0, 21.0, 30.0),                 # a second point in vehicle 1: one-to-one, a false positive
            (100.0, 20.0, 200.0, 91, 15, 109, 25)]  # pixels 91..109 x 15..25: [90.5, 109.5] x [14.5, 25.5]
    tp, n_det, n_true, region = M.detection_counts(dets, truth)
    assert (tp, n_det, n_true, region) == (2, 4, 2, "moving")
    rows = M.detection_rows(dets, truth, frame=0)
    assert {r["metric"]: r["value"] for r in rows} == {"det_precision": 50.0, "det_recall": 100.0}
    # a box that overlaps vehicle 3 by less than IoU 0.5 does not match, though its centre is inside
    thin = [(100.0, 20.0, 10.0, 99, 15, 101, 25)]
    assert M.detection_counts(thin, truth)[0] == 0
    assert M.detection_counts([(100.0, 20.0, 10.0)], truth)[0] == 1


def test_detection_does_not_count_a_pedestrian_as_a_moving_vehicle():
    truth = _truth_frame().assign(**{"class": ["car", "car", "pedestrian", "car"]})
    tp, n_det, n_true, region = M.detection_counts([(100.0, 20.0, 40.0)], truth)
    assert (tp, n_det, n_true, region) == (0, 1, 1, "moving")


def test_a_detection_on_a_vehicle_of_low_visibility_is_neither_true_nor_false():
    # vehicle 3 mostly outside the image (its box the part inside): not counted, and a detection on it left out
    truth = _truth_frame().assign(visible_fraction=[1.0, 1.0, 0.2, 1.0])
    dets = [(21.0, 19.0, 40.0), (100.0, 20.0, 40.0), (200.0, 200.0, 4.0)]  # on 1, on 3, on nothing
    assert M.detection_counts(dets, truth) == (1, 2, 1, "moving")
    # without the column vehicle 3 counts and the detection on it is a true one
    assert M.detection_counts(dets, _truth_frame()) == (2, 3, 2, "moving")


def test_without_a_moving_column_every_visible_vehicle_counts_and_without_boxes_there_are_no_rows():
    truth = _truth_frame().drop(columns=["parked", "speed_mps"])
    assert M.detection_counts([(60.0, 20.0, 1.0)], truth) == (1, 1, 3, "all")
    assert M.detection_rows([(60.0, 20.0, 1.0)], truth.drop(columns=list(M.BOX_COLUMNS)), frame=0) == []
    # no detection: precision has no items (NaN, adds nothing), recall 0
    rows = {r["metric"]: r for r in M.detection_rows([], truth, frame=0)}
    assert math.isnan(rows["det_precision"]["value"]) and rows["det_recall"]["value"] == 0.0


def test_detection_rows_pool_from_summed_matches():
    truth = _truth_frame()
    a = M.detection_rows([(21.0, 19.0, 1.0)], truth, frame=0)                      # 1 of 1, recall 1 of 2
    b = M.detection_rows([(0.0, 0.0, 1.0), (1.0, 1.0, 1.0), (2.0, 2.0, 1.0)], truth, frame=1)  # 0 of 3
    agg = M.aggregate(rows_to_frame(a + b), by=[]).set_index("metric")["value"]
    assert agg["det_precision"] == pytest.approx(100 * 1 / 4) and agg["det_recall"] == pytest.approx(100 * 1 / 4)
