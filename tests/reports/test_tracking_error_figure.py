"""The point tracker's per-frame error figure shows what track_error scores (issue 23, item 1)."""

from __future__ import annotations

import numpy as np

from harness import cell_artifacts as artifacts
from harness.results import read_table
from reports import html, plots
from reports.load import load_run


def test_the_figure_plots_the_mean_of_the_scored_track_error_rows_per_frame(tiny_run, monkeypatch):
    data = load_run(tiny_run)
    cells = html.cell_index(data)
    # the case the figure got wrong: a seed vehicle leaves the view, the point tracker goes on following it
    unseen = [t[(t["source"] == "point") & (t["true_visible"] == 0) & t["true_x_px"].notna()]
              for t in (artifacts.read_tracks(tiny_run / "cells" / c) for c in cells["cell_id"])]
    assert all(len(u) for u in unseen), "fixture: tiny seed 1 has a seed vehicle out of view"

    drawn = {}

    def capture(errors, **kw):
        drawn.update(errors)
        return "<svg></svg>"

    monkeypatch.setattr(plots, "tracking_error_figure", capture)
    html.scene_block(data, cells, "tracking", "tiny")
    assert set(drawn) == set(data.pipelines)

    table = read_table(tiny_run / "results.parquet")
    for pipe, curve in drawn.items():
        for metric, column in (("track_error", "err_kalman"), ("track_raw_error", "err_raw")):
            rows = table[(table["pipeline"] == pipe) & (table["metric"] == metric) & (table["region"] == "point")]
            scored = rows.groupby("frame")["value"].mean()
            got = curve.set_index("frame")[column]
            assert list(got.index) == [int(f) for f in scored.index], (pipe, metric)
            np.testing.assert_allclose(got.to_numpy(float), scored.to_numpy(float), rtol=1e-9, atol=1e-12,
                                       err_msg=f"{pipe} {metric}")
