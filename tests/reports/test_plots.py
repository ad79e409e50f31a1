"""reports.plots: fixed colours, reproducible inline SVG, what each figure draws."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from reports.plots import (difficulty_curves, pipeline_colors, stabilisation_figure, track_polylines,
                           tracking_figure)


def test_each_pipeline_keeps_one_colour_and_neighbours_differ():
    colors = pipeline_colors(["a", "b", "c"])
    assert len(set(colors.values())) == 3
    assert pipeline_colors(["a", "b", "c", "d"])["b"] == colors["b"]  # adding a pipeline moves no colour


def _stab(with_truth: bool) -> pd.DataFrame:
    t = np.arange(6, dtype=float)
    cum = np.stack([2.0 * t + np.sin(t), -t], 1)
    df = pd.DataFrame({"frame": t.astype(int)})
    for j, a in enumerate("xy"):
        df[f"cum_{a}"], df[f"line_{a}"], df[f"corr_{a}"] = cum[:, j], cum[:, j] * 0.9, cum[:, j] * 0.1
        df[f"jit_{a}"] = cum[:, j] * 0.1
        df[f"cum_true_{a}"] = cum[:, j] if with_truth else np.nan
        df[f"jit_true_{a}"] = 0.0 if with_truth else np.nan
    return df


def test_the_stabilisation_figure_draws_the_after_row_only_with_ground_truth():
    svg, truth = stabilisation_figure(_stab(True), title="cell x")
    assert truth and "after stabilisation (fig. 3.2), x [px]" in svg and svg.startswith("<svg")
    svg, truth = stabilisation_figure(_stab(False), title="cell x")
    assert not truth and "fig. 3.2" not in svg and "before (fig. 3.1), y [px]" in svg


def test_svg_is_reproducible_inline_text_without_namespaces_or_metadata():
    curves = pd.DataFrame({"pipeline": ["p1", "p1", "p2", "p2"], "sweep_value": [0.0, 1.0, 0.0, 1.0],
                           "metric": "epe_mean", "value": [0.5, 0.8, 0.4, 1.2]})
    args = dict(param="jitter_px", metrics=[("epe_mean", "EPE [px] lower is better")],
                colors=pipeline_colors(["p1", "p2"]))
    a, b = difficulty_curves(curves, **args), difficulty_curves(curves, **args)
    assert a == b  # same data, same bytes: reports can be diffed
    assert "xmlns" not in a and "<metadata>" not in a and 'style="width:100%' in a
    assert "p1" in a and "p2" in a and "EPE [px] lower is better" in a  # text stays text


def test_a_track_is_its_source_and_id_and_runs_in_frame_order():
    tr = pd.DataFrame({"frame": [2, 0, 1, 0, 1], "source": ["point", "point", "point", "multi", "multi"],
                       "track_id": [0, 0, 0, 0, 0], "x": [3.0, 1.0, 2.0, 50.0, 51.0], "y": 0.0})
    lines = track_polylines(tr)
    assert set(lines) == {("point", 0), ("multi", 0)}  # the same id in two trackers is two tracks
    assert list(lines[("point", 0)]["x"]) == [1.0, 2.0, 3.0]


def _tracks() -> dict[str, pd.DataFrame]:
    frame = np.arange(4)
    t = pd.DataFrame({"frame": frame, "source": "point", "track_id": 0, "seed_vehicle_id": 1.0,
                      "x": 10.0 + 5 * frame, "y": 20.0 + 2 * frame, "x_filt": 10.0 + 5 * frame,
                      "y_filt": 20.0 + 2 * frame, "x_true": 10.0 + 5 * frame, "y_true": 20.0 + 2 * frame})
    return {"a": t, "b": t.copy()}


def test_tracking_figures_of_different_frames_name_their_frame_pictures_apart():
    """Several figures share one HTML page, where ids are global: each frame picture needs its own id,
    every panel of a figure shows that figure's picture, and the picture keeps the frame's own pixels."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (60, 80, 3), dtype=np.uint8) for _ in range(2)]
    svgs = [tracking_figure(f, _tracks(), title="t") for f in frames]
    ids = [re.findall(r'<image id="([^"]+)"', s) for s in svgs]
    assert all(len(i) == 1 for i in ids) and ids[0] != ids[1]
    for s, (i,) in zip(svgs, ids):
        assert s.count(f'<use xlink:href="#{i}"/>') == 2  # one per panel
        w, h = (int(v) for v in re.search(r'<image id="[^"]+" x="[^"]+" y="[^"]+" width="([\d.]+)" '
                                          r'height="([\d.]+)"', s).groups())
        assert w <= 80 and h <= 60  # the frame's pixels (cropped to the view), not resampled upwards
