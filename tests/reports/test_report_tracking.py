"""Tracking section: one polyline per (tracker, track), truth per vehicle, Table 4.1 with both axes."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from reports.load import read_tracks
from reports.plots import track_polylines


def section(html_text: str, sid: str) -> str:
    start = html_text.index(f'<section id="{sid}">')
    return html_text[start:html_text.index("</section>", start)]


@pytest.fixture(scope="module")
def tracking(fixture_report) -> str:
    """The tracking section, each figure it shows from a file (the trajectories) put in its place."""
    text = section(fixture_report["html"].read_text(), "tracking")
    return re.sub(r'<img class="svg" src="([^"]+)"[^>]*>',
                  lambda m: (fixture_report["html"].parent / m.group(1)).read_text(), text)


def test_point_and_multi_tracks_with_the_same_id_are_separate_lines(run_dir):
    cell = next(p for p in sorted((run_dir / "cells").iterdir()) if (p / "tracks.csv").is_file())
    tr = read_tracks(cell)
    assert set(tr["track_id"]) == {0}, "fixture: both trackers use track id 0"
    lines = track_polylines(tr)
    assert set(lines) == {("point", 0), ("multi", 0)}
    # joined by track_id alone, one line would run from the multi track (x < 3) to the point track (x > 12)
    assert np.ptp(tr["x"]) > 10
    for key, g in lines.items():
        assert np.ptp(g["x"]) < 3 if key[0] == "multi" else g["x"].min() > 5
        assert g["frame"].is_monotonic_increasing


def test_a_tracks_file_of_another_schema_is_refused_by_name(tmp_path):
    from harness.cell_artifacts import CellArtifactError

    pd.DataFrame({"frame": [1, 0], "track_id": [0, 0], "x_px": [2.0, 1.0], "y_px": [1.0, 1.0]}).to_csv(
        tmp_path / "tracks.csv", index=False)
    with pytest.raises(CellArtifactError, match=r"tracks.csv: lacks the column\(s\) \['source', 'seed_vehicle_id'"):
        read_tracks(tmp_path)


def test_figure_names_truth_raw_kalman_per_tracker(tracking):
    for text in ("ground truth (true vehicle centre)", "point tracker (thesis 4.1): raw",
                 "point tracker (thesis 4.1): Kalman", "multi-target tracker: raw", "multi-target tracker: Kalman",
                 ">v1<", ">m0<"):
        assert text in tracking, text


def test_table41_says_which_track_and_shows_both_axes(tracking):
    table = tracking[tracking.index('<table class="t41"'):]
    table = table[:table.index("</table>")]
    assert "point tracker seeded on vehicle 1 (track 0)" in table
    assert "distance [px] from the track to the vehicle&#x27;s true projected centre in the same frame" in table
    assert "\u0394x [px]" in table and "\u0394y [px]" in table
    # fixture truth: the vehicle moves 5 px right and 0.5 px down per frame
    row = re.search(r"<th scope=\"row\">Frame 1</th>(.*?)</tr>", table).group(1)
    cells = re.findall(r'<td class="num"[^>]*>([^<]*)</td>', row)
    assert len(cells) == 8
    assert cells[2] == "5.000" and cells[5] == "0.5000"
    assert 'data-label="\u0394x true"' in row, "under 600 px each value keeps its column name"
