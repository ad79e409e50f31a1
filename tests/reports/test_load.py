"""reports.load: a run folder read through the harness readers, reshaped for the report."""

from __future__ import annotations

import numpy as np
import pytest

from harness import cell_artifacts as artifacts
from reports.load import (load_run, open_scene_sequence, picture_frames, pooled, primary_rows, read_cell_flow,
                          read_stabilisation, read_tracks, read_true_tracks, scene_base)
from tests.reports.conftest import FAILED, PICTURE_FRAME, PIPELINES, SCENES


def test_load_run_orders_pipelines_as_the_suite_and_sets_failed_cells_apart(run_dir):
    data = load_run(run_dir)
    assert data.pipelines == PIPELINES  # run.json's order, not the table's alphabetical one
    assert [scene_base(s) for s in data.scenes] == [s for s in SCENES for _ in range(3)]
    assert data.seeds == [0]
    assert list(data.failed["pipeline"]) == [FAILED[2]]
    failed_id = data.failed["cell_id"].iloc[0]
    assert failed_id not in set(data.ok["cell_id"]) and (data.ok["status"] == "ok").all()
    assert "cell_failed" not in data.metrics and "epe_mean" in data.metrics
    assert data.run["suite"] == "fixture_suite"


def test_pooled_values_are_sums_over_counts_never_a_mean_of_means(run_dir):
    data = load_run(run_dir)
    rows = data.ok[(data.ok["metric"] == "epe_mean") & (data.ok["region"] == "all")
                   & (data.ok["motion"] == "total") & (data.ok["pipeline"] == "dis")]
    value = pooled(rows, ["pipeline"])["value"].iloc[0]
    assert value == pytest.approx(rows["sum"].sum() / rows["count"].sum(), rel=1e-12)
    assert value != pytest.approx(rows["value"].mean(), rel=1e-6)  # the pixel counts differ per pair


def test_primary_rows_keep_each_metrics_headline_view(run_dir):
    data = load_run(run_dir)
    prim = primary_rows(data.ok)
    epe = prim[prim["metric"] == "epe_mean"]
    assert set(epe["motion"]) == {"total"} and len(epe) == len(
        data.ok[(data.ok["metric"] == "epe_mean") & (data.ok["region"] == "all") & (data.ok["motion"] == "total")])
    track = prim[prim["metric"] == "track_error"]  # no region "all": every region pooled, relabelled
    assert set(track["region"]) == {"all"} and set(track["motion"]) == {"track"}
    assert set(prim[prim["metric"] == "time_total_ms"]["motion"]) == {"cost"}


def test_scene_base_drops_the_sweep_suffix():
    assert scene_base("urban[jitter_px=2]") == "urban" and scene_base("rural") == "rural"


def test_sequences_and_cell_artifacts_come_back_as_the_harness_wrote_them(run_dir):
    data = load_run(run_dir)
    first = data.scenes[0]
    seq = open_scene_sequence(data, scene=first, seed=0)
    assert seq is not None and len(seq) == 5
    assert open_scene_sequence(data, scene=data.scenes[1], seed=0) is None  # run.json names no folder
    truth = read_true_tracks(seq)
    assert list(truth.columns) == ["frame", "vehicle_id", "x", "y", "parked"] and len(truth) == 5
    assert read_true_tracks(None) is None

    cell = run_dir / "cells" / f"{first.split('[')[0]}-jitter_px=0-s0-dis"
    stab = read_stabilisation(cell)
    raw = artifacts.read_stabilisation(cell)
    np.testing.assert_array_equal(stab["cum_x"], raw["cumulative_x_px"])
    np.testing.assert_array_equal(stab["jit_true_y"], raw["true_jitter_y_px"])
    assert picture_frames(cell) == [PICTURE_FRAME]
    total, local = read_cell_flow(cell, PICTURE_FRAME), read_cell_flow(cell, PICTURE_FRAME, local=True)
    assert total.shape == local.shape and total.dtype == np.float32
    assert read_cell_flow(cell, PICTURE_FRAME + 1) is None
    tracks = read_tracks(cell)
    assert {"source", "track_id", "x_true", "y_true"} <= set(tracks.columns)
