"""The run folder and cell artifacts: one schema each, written and read back, other versions refused."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from algorithms.pipeline import PIPELINES
from harness import cell_artifacts as A
from harness.run_folder import RUN_FORMAT, RunFolderFormatError, cell_entry, read_run, write_run


def _info(tmp_path, **changes):
    info = {"suite": "s", "suite_source": "s.yaml", "resolved_suite": {}, "config_hash": "h",
            "pipelines": [PIPELINES["thesis-hs"], {**PIPELINES["thesis-lk"], "name": "mine"}],
            "provenance": {"machine": "box", "git_commit": "abc"}, "cache_dir": str(tmp_path / "cache"),
            "cells": [cell_entry(cell_id="c1", scene="tiny", seed=3, pipeline="mine", config_hash="x",
                                 sequence=tmp_path / "seq")],
            "status": "ok", "started": "t0", "finished": "t1"}
    info.update(changes)
    return info


def test_run_json_round_trip_keeps_pipeline_order_and_flow_methods(tmp_path):
    (tmp_path / "seq").mkdir()
    write_run(tmp_path, _info(tmp_path))
    assert json.loads((tmp_path / "run.json").read_text())["format"] == RUN_FORMAT
    run = read_run(tmp_path)
    assert run.suite == "s" and run.provenance["machine"] == "box"
    assert list(run.pipelines) == ["thesis-hs", "mine"], "suite order, though run.json sorts its keys"
    assert run.flow_method("mine") == "lucas_kanade" and run.flow_method("thesis-hs") == "horn_schunck"
    assert run.flow_method("absent") is None
    assert run.sequence_dir("tiny", 3) == tmp_path / "seq" and run.sequence_dir("tiny", 4) is None
    assert run.cache_dir == tmp_path / "cache" and run.cell_dir("c1") == tmp_path / "cells" / "c1"


def test_run_json_of_another_format_or_incomplete_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"run.json: missing key\(s\) \['pipelines'\]"):
        write_run(tmp_path, {k: v for k, v in _info(tmp_path).items() if k != "pipelines"})
    (tmp_path / "run.json").write_text(json.dumps({"format": "aerobench-run/9"}))
    with pytest.raises(RunFolderFormatError, match="run format 'aerobench-run/9', this aerobench reads 'aerobench-run/1'"):
        read_run(tmp_path)
    with pytest.raises(FileNotFoundError, match="not a run folder"):
        read_run(tmp_path / "nowhere")


def _estimate(n=4):
    t = np.arange(n, dtype=float)[:, None]
    tracks = pd.DataFrame({"frame": [0, 1, 0], "track_id": [0, 0, 0], "x_px": [1.0, 2.0, 9.0],
                           "y_px": [1.0, 1.5, 9.0], "x_filt_px": [1.0, 2.0, 9.0], "y_filt_px": [1.0, 1.5, 9.0],
                           "x_pred_px": [np.nan, 2.0, np.nan], "y_pred_px": [np.nan, 1.5, np.nan],
                           "source": ["point", "point", "multi"], "seed_vehicle_id": [7, 7, np.nan]})
    return SimpleNamespace(cumulative_px=np.hstack([2 * t, -t]), flight_line_px=np.hstack([2 * t, -t]),
                           correction_px=np.zeros((n, 2)), jitter_px=np.zeros((n, 2)), tracks=tracks)


def _camera(n=4):
    return pd.DataFrame({"frame": range(n), "global_dx_px": [2.0] * (n - 1) + [np.nan],
                         "global_dy_px": [-1.0] * (n - 1) + [np.nan], "jitter_x_px": 0.0, "jitter_y_px": 0.0})


def test_cell_files_round_trip(tmp_path):
    est = _estimate()
    A.write_stabilisation(tmp_path, A.stabilisation_table(est, _camera()))
    stab = A.read_stabilisation(tmp_path)
    assert list(stab.columns) == list(A.STABILISATION_COLUMNS)
    # true cumulative shift of frame i: the sum of the true pair shifts before it
    assert stab["true_cumulative_x_px"].tolist() == [0.0, 2.0, 4.0, 6.0]
    truth = pd.DataFrame({"frame": [0, 1], "vehicle_id": [7, 7], "x_px": [1.5, 2.5], "y_px": [1.0, 1.0],
                          "visible": [1, 1]})
    A.write_tracks(tmp_path, A.tracks_table(est, truth))
    tr = A.read_tracks(tmp_path)
    assert list(tr.columns) == list(A.TRACK_COLUMNS)
    point = tr[tr["source"] == "point"]
    assert point["true_x_px"].tolist() == [1.5, 2.5] and tr[tr["source"] == "multi"]["true_x_px"].isna().all()
    assert tr[["bbox_x0_px", "bbox_y1_px"]].isna().all().all()  # no tracker of this estimate has a box
    # a multi-target track's box goes through; a tracks.csv written before boxes existed reads them as NaN
    est.tracks = est.tracks.assign(bbox_x0_px=[np.nan, np.nan, 5.0], bbox_y0_px=[np.nan, np.nan, 6.0],
                                   bbox_x1_px=[np.nan, np.nan, 13.0], bbox_y1_px=[np.nan, np.nan, 12.0])
    A.write_tracks(tmp_path, A.tracks_table(est, truth))
    multi = A.read_tracks(tmp_path).query("source == 'multi'")
    assert multi[["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]].values.tolist() == [[5.0, 6.0, 13.0, 12.0]]
    old = pd.read_csv(tmp_path / A.TRACKS_FILE).drop(columns=["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"])
    old.to_csv(tmp_path / A.TRACKS_FILE, index=False)
    assert A.read_tracks(tmp_path)["bbox_x1_px"].isna().all()
    total = np.full((3, 4, 2), 2.0, np.float32)
    glob = np.full((3, 4, 2), 1.5, np.float32)
    A.write_pair_flows(tmp_path, 5, total, glob)
    assert A.picture_pairs(tmp_path) == [5]
    np.testing.assert_array_equal(A.read_flow(tmp_path, 5), total)
    np.testing.assert_array_equal(A.read_flow(tmp_path, 5, local=True), total - glob)
    assert A.read_flow(tmp_path, 6) is None and A.read_error(tmp_path) == ""
    A.write_error(tmp_path, "Traceback ...\nValueError: x\n")
    assert A.read_error(tmp_path).endswith("ValueError: x")


def test_cell_json_is_versioned(tmp_path):
    assert A.read_cell_info(tmp_path) is None  # a partial cell
    info = dict.fromkeys(A.CELL_INFO_KEYS, "")
    with pytest.raises(ValueError, match=r"cell.json: missing key\(s\) \['seed'\]"):
        A.write_cell_info(tmp_path, {k: v for k, v in info.items() if k != "seed"})
    A.write_cell_info(tmp_path, {**info, "status": "ok"})
    assert A.read_cell_info(tmp_path)["format"] == A.CELL_FORMAT
    (tmp_path / "cell.json").write_text(json.dumps({**info, "format": "aerobench-cell/0"}))
    with pytest.raises(A.CellArtifactError, match="cell format 'aerobench-cell/0', this aerobench reads"):
        A.read_cell_info(tmp_path)
