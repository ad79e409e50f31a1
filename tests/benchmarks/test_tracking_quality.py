"""benchmarks/tracking_quality.py: the breakdown of misses and false positives names each one's cause; the KIT AIS
part's moving/parked call of labelled boxes and its point scoring."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from algorithms.detection import Detection

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "tracking_quality.py"
_spec = importlib.util.spec_from_file_location("tracking_quality_benchmark", _PATH)
tq = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tq
_spec.loader.exec_module(tq)

BOX = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]


def _truth_row(vid, x0, y0, x1, y1, parked=0):
    return {"frame": 0, "vehicle_id": vid, "x_px": (x0 + x1) / 2, "y_px": (y0 + y1) / 2, "bbox_x0_px": x0,
            "bbox_y0_px": y0, "bbox_x1_px": x1, "bbox_y1_px": y1, "visible": 1, "class": "car", "parked": parked}


def _det(x0, y0, x1, y1):
    """A detection whose continuous box is (x0, y0, x1, y1) (inclusive pixel box half a pixel in)."""
    return Detection((x0 + x1) / 2, (y0 + y1) / 2, 1, x0 + 0.5, y0 + 0.5, x1 - 0.5, y1 - 0.5)


def test_each_miss_gets_its_cause_and_each_false_positive_the_vehicle_it_lay_on():
    truth = pd.DataFrame([
        _truth_row(1, 10, 10, 30, 20),    # tracked: no miss
        _truth_row(2, 40, 10, 60, 20),    # a detection boxes it short (IoU 0.25)
        _truth_row(3, -30, 40, 10, 50),   # a quarter of it in the image
        _truth_row(4, 40, 40, 60, 50),    # detected, never tracked
        _truth_row(5, 70, 70, 90, 80),    # nothing there
    ])
    parked = pd.DataFrame([_truth_row(9, 10, 70, 30, 80, parked=1)])
    dets = [[_det(10, 10, 30, 20), _det(40, 10, 45, 20), _det(40, 40, 60, 50)]]
    tracks = pd.DataFrame([
        {"frame": 0, "track_id": 7, "x_filt_px": 20.0, "y_filt_px": 15.0, "bbox_x0_px": 10.0, "bbox_y0_px": 10.0,
         "bbox_x1_px": 30.0, "bbox_y1_px": 20.0},
        {"frame": 0, "track_id": 8, "x_filt_px": 20.0, "y_filt_px": 75.0, "bbox_x0_px": 12.0, "bbox_y0_px": 70.0,
         "bbox_x1_px": 30.0, "bbox_y1_px": 80.0},   # on the parked car
    ])
    fn, fp = tq.error_breakdown(tracks, dets, truth, frame_shape=(100, 100),
                                everything=pd.concat([truth, parked], ignore_index=True))
    causes = dict(zip(fn["vehicle_id"], fn["cause"]))
    assert causes == {2: "detection box", 3: "out of frame", 4: "tracker", 5: "no detection"}
    assert fn.set_index("vehicle_id").loc[3, "in_image"] == 0.25
    assert fn.set_index("vehicle_id").loc[2, "det_iou"] == 0.25
    assert list(fp["track_id"]) == [8] and fp["vehicle_id"].iat[0] == 9 and fp["parked"].iat[0] == 1
    assert abs(fp["best_iou"].iat[0] - 0.9) < 1e-9


def _box(x, y):
    return [x, y, x + 30, y + 15]


def _frames():
    """10 frames, a still camera: a parked car at x 20, a car that drives 20 px a frame then stops (frames 0-3
    driving, then at rest), and one that drives 12 px a frame throughout."""
    stop_x = [100, 120, 140, 160, 170, 170, 170, 170, 170, 170]
    return [np.array([_box(20, 20), _box(stop_x[t], 100), _box(300 + 12 * t, 200)], float) for t in range(10)]


def test_a_car_that_stops_half_way_is_parked_by_the_median_and_moving_at_some_time_by_the_harness_rule():
    boxes, path = _frames(), np.zeros((10, 2))
    median, chains = tq.moving_chains(boxes, path, link_px=40.0, move_px=8.0)
    ever, chains_ever = tq.moving_chains(boxes, path, link_px=40.0, move_px=8.0, rule="ever")
    assert all(list(lab) == [0, 0, 1] for lab in median)  # the stopping car's median step is 0
    assert all(list(lab) == [0, 1, 1] for lab in ever)  # it drove 20 px a frame for three steps
    assert all((a == b).all() for a, b in zip(chains, chains_ever)) and len({c[1] for c in chains}) == 1
    with pytest.raises(ValueError, match="rule: expected median or ever, got 'max'"):
        tq.moving_chains(boxes, path, link_px=40.0, move_px=8.0, rule="max")


def test_points_are_scored_once_per_moving_box_and_parked_hits_counted_apart():
    boxes = [np.array([[0, 0, 10, 10], [20, 0, 30, 10], [40, 0, 50, 10]], float)]
    labels = [np.array([1, 0, -1])]
    # two points in the moving box (one true, one false), one on the parked car, one in the unknown box (not
    # counted), one on nothing
    points = [[(5, 5), (6, 6), (25, 5), (45, 5), (80, 80)]]
    assert tq.score_points(points, boxes, labels) == (1, 3, 1)
