"""What the scoring of a cell adds beside the flow rows: the truth-free, detection and HOTA rows of every
cell, and each tracker's MOTChallenge export, which scores as the run's own rows do."""

from __future__ import annotations

import pytest

import harness.metrics as M
from harness import cell_artifacts as A
from harness.results import read_results, read_run_json
from scenes import open_sequence


@pytest.mark.gl
@pytest.mark.slow
def test_every_cell_has_truth_free_detection_and_hota_rows(reference_run):
    table = read_results(reference_run.run_dir)
    n_pairs = 3  # the tiny preset's 4 frames
    for _cell, rows in table.groupby("cell_id"):
        photo = rows[rows["metric"] == "photo_residual"]
        assert sorted(photo["frame"]) == list(range(n_pairs)) and set(photo["motion"]) == {"photometric"}
        assert (photo["value"] >= 0).all() and (photo["count"] > 0).all()
        assert len(rows[rows["metric"] == "stab_itf"]) == n_pairs
        det = rows[rows["metric"].isin(["det_precision", "det_recall"])]
        assert len(det) == 2 * n_pairs and set(det["region"]) == {"moving"}
        hota = rows[rows["metric"] == "hota"]
        assert set(hota["region"]) == set(rows.loc[rows["metric"] == "mota", "region"]) and len(hota)


@pytest.mark.gl
@pytest.mark.slow
def test_the_motchallenge_export_scores_as_the_run_did(reference_run):
    run_dir = reference_run.run_dir
    meta = read_run_json(run_dir)
    table = read_results(run_dir)
    for cell in meta["cells"]:
        folder = run_dir / "cells" / cell["cell_id"]
        tracks = A.read_tracks(folder)
        back = A.read_mot_tracks(folder)
        assert sorted(back["source"].unique()) == sorted(tracks["source"].unique())
        truth = open_sequence(cell["sequence"]).tracks
        rows = table[(table["cell_id"] == cell["cell_id"]) & table["metric"].isin(["mota", "idf1"])]
        for source, est in back.groupby("source"):
            # the trackers have no box yet: exported with a carrier box, read back as points
            assert est["bbox_x0_px"].isna().all()
            c = M.mot_counts(est, truth)
            got = rows[rows["region"] == source].set_index("metric")["value"]
            assert c.mota == pytest.approx(got["mota"], abs=1e-9) and c.idf1 == pytest.approx(got["idf1"], abs=1e-9)
