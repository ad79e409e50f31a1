"""benchmarks/difficulty_calibration.py: the earlier tracker's point rows get the boxes of their regions."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "difficulty_calibration.py"
_spec = importlib.util.spec_from_file_location("difficulty_calibration_benchmark", _PATH)
calib = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = calib
_spec.loader.exec_module(calib)


def _mask():
    m = np.zeros((60, 80), bool)
    m[10:20, 5:35] = True     # 30 x 10 px, centroid (19.5, 14.5)
    m[40:52, 60:68] = True    # 8 x 12 px, centroid (63.5, 45.5)
    m[0:3, 70:73] = True      # 9 px: under min_area_px
    return m


def test_mask_regions_are_the_connected_regions_with_inclusive_boxes():
    rows = calib.mask_regions(_mask(), 4, min_area_px=20)
    df = pd.DataFrame(rows, columns=calib.REGION_COLUMNS).sort_values("area_px", ascending=False)
    assert len(df) == 2
    big, small = df.iloc[0], df.iloc[1]
    assert (big["frame"], big["x0_px"], big["y0_px"], big["x1_px"], big["y1_px"]) == (4, 5, 10, 34, 19)
    assert big["area_px"] == 300
    assert big["x_px"] == pytest.approx(19.5) and big["y_px"] == pytest.approx(14.5)
    assert (small["x0_px"], small["y0_px"], small["x1_px"], small["y1_px"]) == (60, 40, 67, 51)
    assert small["x_px"] == pytest.approx(63.5) and small["y_px"] == pytest.approx(45.5)


def test_a_row_takes_its_regions_size_centred_on_the_filtered_position_and_keeps_it_while_coasting():
    rows = calib.mask_regions(_mask(), 0, min_area_px=20) + calib.mask_regions(_mask(), 1, min_area_px=20)
    regions = pd.DataFrame(rows, columns=calib.REGION_COLUMNS)
    tracks = pd.DataFrame({
        "frame": [0, 0, 1, 2],
        "track_id": [7, 3, 7, 7],
        # the detections as the tracker hands them back (path subtracted and added: equal up to rounding)
        "x_px": [19.5 + 1e-9, 63.5, 19.5, np.nan],
        "y_px": [14.5, 45.5 - 1e-9, 14.5, np.nan],
        "x_filt_px": [20.0, 63.0, 21.0, 22.5],
        "y_filt_px": [15.0, 45.0, 14.0, 13.5],
    })
    out = calib.boxes_from_regions(tracks, regions)
    assert list(out["frame"]) == [0, 0, 1, 2] and list(out["track_id"]) == [3, 7, 7, 7]
    b = out[calib.BOXES].to_numpy()
    np.testing.assert_allclose(b[0], [63.0 - 4, 45.0 - 6, 63.0 + 4, 45.0 + 6])      # 8 x 12
    np.testing.assert_allclose(b[1], [20.0 - 15, 15.0 - 5, 20.0 + 15, 15.0 + 5])    # 30 x 10
    np.testing.assert_allclose(b[2], [21.0 - 15, 14.0 - 5, 21.0 + 15, 14.0 + 5])
    np.testing.assert_allclose(b[3], [22.5 - 15, 13.5 - 5, 22.5 + 15, 13.5 + 5])    # coasting: last size


def test_a_row_on_no_region_and_missing_columns_are_refused():
    regions = pd.DataFrame(calib.mask_regions(_mask(), 0, min_area_px=20), columns=calib.REGION_COLUMNS)
    off = pd.DataFrame({"frame": [0], "track_id": [1], "x_px": [30.0], "y_px": [30.0], "x_filt_px": [30.0],
                        "y_filt_px": [30.0]})
    with pytest.raises(ValueError, match=r"frame 0 row at \(30.000, 30.000\) px lies on no region"):
        calib.boxes_from_regions(off, regions)
    with pytest.raises(ValueError, match=r"frame 5 row .* no region"):
        calib.boxes_from_regions(off.assign(frame=5), regions)
    with pytest.raises(ValueError, match="tracks: expected columns"):
        calib.boxes_from_regions(off.drop(columns=["x_filt_px"]), regions)
    with pytest.raises(ValueError, match="regions: expected columns"):
        calib.boxes_from_regions(off, regions.drop(columns=["area_px"]))


def test_a_box_on_the_vehicle_matches_by_iou_and_a_blob_twice_its_size_does_not():
    """Why the two scorings differ: a track box from a flow blob twice a car's size fails IoU >= 0.5
    though its point lies on the car (today's metrics, both rules)."""
    truth = pd.DataFrame({"frame": [0], "vehicle_id": [1], "x_px": [50.0], "y_px": [50.0], "visible": [1],
                          "bbox_x0_px": [40.0], "bbox_y0_px": [45.0], "bbox_x1_px": [60.0], "bbox_y1_px": [55.0]})
    track = pd.DataFrame({"frame": [0], "track_id": [0], "x_filt_px": [51.0], "y_filt_px": [50.0]})
    tight = track.assign(bbox_x0_px=41.0, bbox_y0_px=45.0, bbox_x1_px=61.0, bbox_y1_px=55.0)
    blob = track.assign(bbox_x0_px=31.0, bbox_y0_px=40.0, bbox_x1_px=71.0, bbox_y1_px=60.0)
    assert calib.score(tight, truth, gate_px=20.0)["mota_box"] == 1.0
    s = calib.score(blob, truth, gate_px=20.0)
    assert s["mota_box"] == -1.0 and s["fp_box/obj"] == 1.0
    assert s["mota_pt"] == 1.0 and s["objects"] == 1
    assert s["mota_c"] == 1.0  # the centre rule: 1 px from the centre, within the 20 px gate
    far = track.assign(x_filt_px=75.0)  # 25 px off: outside the box and beyond the gate
    assert calib.score(far, truth, gate_px=20.0)["mota_c"] == -1.0
    assert calib.score(far, truth, gate_px=30.0)["mota_c"] == 1.0
