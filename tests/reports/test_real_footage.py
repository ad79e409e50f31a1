"""The real-footage pictures and table: truth boxes from tracks or YOLO boxes, tracks drawn where they are."""

from __future__ import annotations

import types

import numpy as np
import pandas as pd
import pytest

from reports.real_footage import TRUTH_RGB, draw_boxes_and_tracks, truth_boxes


def _seq(tracks=None, boxes=None):
    return types.SimpleNamespace(tracks=tracks, boxes=boxes, source="real")


def _box_row(frame, x0, y0, x1, y1, **kw):
    return dict(frame=frame, bbox_x0_px=x0, bbox_y0_px=y0, bbox_x1_px=x1, bbox_y1_px=y1, **kw)


def test_truth_boxes_come_from_tracks_with_ids_and_skip_the_invisible():
    tracks = pd.DataFrame([_box_row(3, 10, 10, 20, 18, vehicle_id=7, visible=1),
                           _box_row(3, 40, 40, 50, 48, vehicle_id=8, visible=0),
                           _box_row(4, 12, 10, 22, 18, vehicle_id=7, visible=1)])
    b = truth_boxes(_seq(tracks=tracks), 3)
    assert b[["x0", "y0", "x1", "y1"]].to_numpy().tolist() == [[10, 10, 20, 18]]
    assert b["id"].tolist() == [7]


def test_truth_boxes_fall_back_to_yolo_boxes_without_ids_and_are_empty_without_either():
    boxes = pd.DataFrame([_box_row(0, 1, 2, 3, 4, **{"class": "car"}), _box_row(1, 5, 6, 7, 8, **{"class": "bus"})])
    b = truth_boxes(_seq(boxes=boxes), 1)
    assert b[["x0", "y0", "x1", "y1"]].to_numpy().tolist() == [[5, 6, 7, 8]] and b["id"].tolist() == [-1]
    assert truth_boxes(_seq(), 0).empty


def test_boxes_and_crosses_are_drawn_where_they_are_and_nowhere_else():
    rgb = np.zeros((60, 80, 3), np.uint8)
    # boxes over pixels 5..25 x 5..20 and 40..58 x 32..48 (continuous: half a pixel out)
    truth = pd.DataFrame({"x0": [4.5], "y0": [4.5], "x1": [25.5], "y1": [20.5], "id": [1]})
    tracks = pd.DataFrame({"source": ["multi", "point"], "track_id": [3, 0], "x": [50.0, 60.0], "y": [40.0, 12.0],
                           "x0": [39.5, np.nan], "y0": [31.5, np.nan], "x1": [58.5, np.nan], "y1": [48.5, np.nan]})
    out = draw_boxes_and_tracks(rgb, truth, tracks, color_rgb=(255, 0, 0))
    assert rgb.max() == 0  # the input is not drawn on
    assert tuple(out[5, 15]) == TRUTH_RGB and tuple(out[12, 5]) == TRUTH_RGB  # the truth box's edges
    assert tuple(out[20, 15]) == TRUTH_RGB and tuple(out[12, 25]) == TRUTH_RGB
    assert out[4, 15].max() == 0 and out[12, 26].max() == 0  # on its pixels, not beside them
    assert out[12, 15].max() == 0  # its inside stays as it was
    assert out[40, 40, 0] > 200 and out[40, 40, 1] < 60  # the track's box edge in its colour
    assert out[40, 49].max() == 0  # inside the track box
    assert out[12, 60, 0] > 200  # the point track's cross at its position
    # nothing drawn far from every box and point
    assert out[50:, :30].max() == 0


def test_drawing_refuses_what_is_not_an_rgb_frame():
    with pytest.raises(ValueError, match=r"expected \(H, W, 3\) uint8, got \(4, 4\) float64"):
        draw_boxes_and_tracks(np.zeros((4, 4)), pd.DataFrame(columns=["x0", "y0", "x1", "y1"]),
                              pd.DataFrame(columns=["source", "track_id", "x", "y", "x0", "y0", "x1", "y1"]),
                              color_rgb=(0, 0, 0))
