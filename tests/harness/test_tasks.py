"""harness.tasks and harness.cell_scoring: what a worker does with a cell, from plain data to a cell folder."""

from __future__ import annotations

import copy

import pandas as pd

from harness import cell_artifacts as artifacts
from harness.cell_scoring import point_seeds
from harness.results import ROWS_FILE, read_table
from harness.suites import expand, parse_suite
from harness.tasks import cell_payload, cell_task
from tests.harness.harness_testdata import TINY_SUITE


def test_point_seeds_are_the_vehicles_visible_in_frame_0_in_id_order():
    tracks = pd.DataFrame({"frame": [0, 0, 0, 1], "vehicle_id": [5, 2, 9, 2], "x_px": [1.0, 2.0, 3.0, 4.0],
                           "y_px": [10.0, 20.0, 30.0, 40.0], "visible": [1, 1, 0, 1]})
    assert point_seeds(tracks) == [(2, 2.0, 20.0), (5, 1.0, 10.0)]
    assert point_seeds(tracks.iloc[:0]) == [] and point_seeds(None) == []


def test_point_seeds_are_the_counted_vehicles_only_no_parked_car_no_pedestrian():
    tracks = pd.DataFrame({"frame": 0, "vehicle_id": [1, 2, 3, 4, 5], "x_px": [1.0, 2.0, 3.0, 4.0, 5.0],
                           "y_px": 0.0, "visible": 1, "parked": [0, 1, 0, 0, 0],
                           "class": ["car", "car", "pedestrian", "bus", "cyclist"], "speed_mps": [5.0, 0, 1, 0, 3]})
    # vehicle 4 is a bus queued at a light in frame 0 (speed 0, not parked) that drives off in frame 1: seeded
    later = tracks.assign(frame=1, speed_mps=[5.0, 0, 1, 4.0, 3])
    assert point_seeds(pd.concat([tracks, later])) == [(1, 1.0, 0.0), (4, 4.0, 0.0)]
    # one that stands still through the whole clip is a distractor, not a counted vehicle: not seeded
    assert point_seeds(tracks) == [(1, 1.0, 0.0)]


def test_a_cell_whose_scene_failed_to_render_is_recorded_as_failed_in_its_folder(tmp_path):
    (cell,) = expand(parse_suite({**copy.deepcopy(TINY_SUITE), "pipelines": ["dis"]}))
    payload = cell_payload(cell, tmp_path / "cells", {"git_commit": "abc", "git_dirty": False, "machine": "m"}, [])
    assert payload["pipeline_spec"] == cell.pipeline_spec and payload["config_hash"] == cell.config_hash
    payload.update(sequence=None, render_error="rendering failed: RuntimeError: no GL", render_traceback="tb\n")
    out = cell_task(payload)
    assert out == {"cell_id": cell.cell_id, "status": "failed", "error": "RuntimeError: rendering failed: "
                   "RuntimeError: no GL", "rows": 1}
    folder = tmp_path / "cells" / cell.cell_id
    info = artifacts.read_cell_info(folder)
    assert info["status"] == "failed" and info["config_hash"] == cell.config_hash
    table = read_table(folder / ROWS_FILE)
    assert list(table["metric"]) == ["cell_failed"] and table["git_commit"].iloc[0] == "abc"
    assert "tb" in (folder / "error.txt").read_text()
    assert [p.name for p in (tmp_path / "cells").iterdir()] == [cell.cell_id]  # no temporary folder left
