"""benchmarks/tracking_quality.py, KIT AIS part: the moving/parked call of labelled boxes and the point scoring."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "tracking_quality.py"
_spec = importlib.util.spec_from_file_location("tracking_quality_benchmark", _PATH)
tq = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tq
_spec.loader.exec_module(tq)


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
