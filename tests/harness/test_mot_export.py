"""The MOTChallenge export of a cell's tracks, and box-aware CLEAR-MOT / IDF1 / HOTA against py-motmetrics
on the same files (its IoU matching for boxed tracks; its accumulator fed the point-in-box rule for points)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest

import harness.metrics as M
from harness import cell_artifacts as A

mm = pytest.importorskip("motmetrics")


def _boxed_scenario(rng: np.random.Generator, n_frames: int = 30, n_vehicles: int = 5, *, boxes: bool = True):
    """Vehicles with boxes on straight lines (one leaves); tracks with box noise, a swap, a gap, a late
    birth, a takeover and clutter. Tracks carry boxes (``boxes``) or only their centre."""
    truth, est = [], []
    start = rng.uniform(40, 300, size=(n_vehicles, 2))
    vel = rng.uniform(-3, 3, size=(n_vehicles, 2))
    size = rng.uniform([14, 8], [40, 20], size=(n_vehicles, 2))
    for f in range(n_frames):
        for v in range(n_vehicles):
            x, y = start[v] + vel[v] * f
            w, h = size[v]
            visible = int(not (v == 4 and f > 22))
            truth.append({"frame": f, "vehicle_id": v + 1, "x_px": x, "y_px": y, "bbox_x0_px": x - w / 2,
                          "bbox_y0_px": y - h / 2, "bbox_x1_px": x + w / 2, "bbox_y1_px": y + h / 2,
                          "visible": visible})
            if not visible or (v == 1 and 8 <= f < 12) or (v == 2 and f < 4):
                continue
            tid = 100 + v
            if v in (0, 1) and f >= 18:
                tid = 101 if v == 0 else 100  # an identity swap (the boxes stay on their vehicles)
            if v == 2 and f >= 15:
                tid = 200
            # noise up to a few px: some boxes fall under IoU 0.5, some points leave their box
            nx, ny = rng.normal(0, 0.25 * min(w, h), 2)
            sw, sh = rng.uniform(0.7, 1.3, 2) * (w, h)
            row = {"frame": f, "track_id": tid, "x_filt_px": x + nx, "y_filt_px": y + ny, "source": "multi"}
            if boxes:
                row.update(bbox_x0_px=x + nx - sw / 2, bbox_y0_px=y + ny - sh / 2, bbox_x1_px=x + nx + sw / 2,
                           bbox_y1_px=y + ny + sh / 2)
            est.append(row)
        if f % 5 == 2:  # clutter
            cx, cy = rng.uniform(0, 350, 2)
            row = {"frame": f, "track_id": 900 + f, "x_filt_px": cx, "y_filt_px": cy, "source": "multi"}
            if boxes:
                row.update(bbox_x0_px=cx - 10, bbox_y0_px=cy - 6, bbox_x1_px=cx + 10, bbox_y1_px=cy + 6)
            est.append(row)
    return pd.DataFrame(est), pd.DataFrame(truth)


def _mm_load(path):
    """py-motmetrics' reader (its ``df[["X", "Y"]] -= (1, 1)`` warns under pandas 3: not ours to fix)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", FutureWarning)
        return mm.io.loadtxt(str(path))


def _truth_from_mot(path) -> pd.DataFrame:
    """A MOTChallenge ground-truth file as tracks.csv rows (every row visible, centre = box centre)."""
    g = A.read_mot(path).rename(columns={"id": "vehicle_id"})
    g["x_px"] = (g["bbox_x0_px"] + g["bbox_x1_px"]) / 2
    g["y_px"] = (g["bbox_y0_px"] + g["bbox_y1_px"]) / 2
    g["visible"] = 1
    return g


def _export(tmp_path, est, truth, source):
    gt_path = A.write_mot(tmp_path / "gt.txt", A.mot_truth_table(truth))
    (path,) = A.write_mot_tracks(tmp_path, est.assign(source=source))
    assert path.name == f"mot_{source}.txt"
    return gt_path, path


_MM = ["num_objects", "num_predictions", "num_detections", "num_misses", "num_false_positives", "num_switches",
       "mota", "idtp", "idf1"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_boxed_tracks_score_as_py_motmetrics_scores_the_exported_files_by_iou(tmp_path, seed):
    est, truth = _boxed_scenario(np.random.default_rng(seed))
    gt_path, path = _export(tmp_path, est, truth, "multi")
    # py-motmetrics on the files: its own reader, its IoU and its rule (a pair only at 1 - IoU <= 0.5)
    acc = _oracle(gt_path, path, _iou_distance)
    s = mm.metrics.create().compute(acc, metrics=_MM, name="x").iloc[0]
    # ours on the same files
    c = M.mot_counts(A.read_mot_tracks(tmp_path), _truth_from_mot(gt_path))
    assert (c.objects, c.predictions, c.matches, c.misses, c.false_positives, c.switches, c.idtp) == (
        s.num_objects, s.num_predictions, s.num_detections, s.num_misses, s.num_false_positives, s.num_switches,
        s.idtp)
    assert c.mota == pytest.approx(s.mota, abs=1e-9) and c.idf1 == pytest.approx(s.idf1, abs=1e-9)
    # the scenario exercises every count, and IoU decides: a distance gate of 20 px would match more
    assert c.switches >= 1 and c.false_positives > 0 and c.misses > 0
    gate_only = M.mot_counts(est.drop(columns=list(M.BOX_COLUMNS)), truth.drop(columns=list(M.BOX_COLUMNS)))
    assert gate_only.matches > c.matches


def _oracle(gt_path, path, distance):
    """py-motmetrics' accumulator over the files as its own reader gives them, frame by frame
    (``utils.compare_to_groundtruth``'s loop: its ``iou_matrix`` calls ``np.asfarray``, gone in numpy 2)."""
    gt, dt = _mm_load(gt_path), _mm_load(path)
    acc = mm.MOTAccumulator(auto_id=False)
    fg, fd = set(gt.index.get_level_values(0)), set(dt.index.get_level_values(0))
    for f in sorted(fg | fd):
        g = gt.loc[f] if f in fg else gt.iloc[:0].droplevel(0)
        d = dt.loc[f] if f in fd else dt.iloc[:0].droplevel(0)
        D = distance(g[["X", "Y", "Width", "Height"]].to_numpy(float), d[["X", "Y", "Width", "Height"]].to_numpy(float))
        acc.update(g.index.tolist(), d.index.tolist(), D, frameid=int(f))
    return acc


def _iou_distance(objs, hyps):
    """py-motmetrics' IoU distance: 1 - boxiou, NaN (do not pair) above 0.5."""
    dist = 1 - mm.distances.boxiou(objs[:, None], hyps[None, :])
    return np.where(dist > 0.5, np.nan, dist)


def _point_in_box_distance(objs, hyps):
    """The point-in-box rule from the files: the point (carrier box centre) inside the vehicle's box."""
    cx, cy = objs[:, 0] + objs[:, 2] / 2, objs[:, 1] + objs[:, 3] / 2
    px, py = hyps[:, 0] + hyps[:, 2] / 2, hyps[:, 1] + hyps[:, 3] / 2
    n = np.maximum(np.abs(px[None] - cx[:, None]) / (objs[:, 2:3] / 2), np.abs(py[None] - cy[:, None]) / (objs[:, 3:4] / 2))
    return np.where(n <= 1, n, np.nan)


@pytest.mark.parametrize("seed", [0, 3])
def test_point_tracks_match_when_inside_the_box_as_py_motmetrics_counts_them(tmp_path, seed):
    est, truth = _boxed_scenario(np.random.default_rng(seed), boxes=False)
    gt_path, path = _export(tmp_path, est, truth, "point")
    back = A.read_mot_tracks(tmp_path)
    assert back["bbox_x0_px"].isna().all()  # the carrier box is not a box: scored as points
    np.testing.assert_allclose(back["x_filt_px"], est.sort_values(["frame", "track_id"])["x_filt_px"], atol=1e-9)
    s = mm.metrics.create().compute(_oracle(gt_path, path, _point_in_box_distance), metrics=_MM, name="x").iloc[0]
    c = M.mot_counts(back, _truth_from_mot(gt_path))
    assert (c.objects, c.predictions, c.matches, c.switches, c.idtp) == (
        s.num_objects, s.num_predictions, s.num_detections, s.num_switches, s.idtp)
    assert c.mota == pytest.approx(s.mota, abs=1e-9) and c.idf1 == pytest.approx(s.idf1, abs=1e-9)
    assert 0 < c.matches < c.predictions  # some points fall outside their box


def test_the_export_is_motchallenge_text_and_reads_back(tmp_path):
    est = pd.DataFrame({"frame": [0, 0, 1, 2], "track_id": [3, 4, 3, 3], "x_filt_px": [10.0, 50.5, 12.0, np.nan],
                        "y_filt_px": [20.0, 60.0, 21.0, 1.0], "bbox_x0_px": [5.0, np.nan, 7.0, 0.0],
                        "bbox_y0_px": [15.0, np.nan, 16.0, 0.0], "bbox_x1_px": [15.0, np.nan, 17.0, 1.0],
                        "bbox_y1_px": [25.0, np.nan, 26.0, 1.0], "source": "multi"})
    (path,) = A.write_mot_tracks(tmp_path, est)
    lines = path.read_text().splitlines()
    # frames 1-based, bb_left = x0 + 1.5 (the box [5, 15] covers pixels 5.5 .. 14.5, 1-based 6.5 ..: its left
    # edge is 6.5); the row without a box gets the 4 px carrier; a NaN position is no row
    assert lines == ["1,3,6.5,16.5,10.0,10.0,1.0,-1,-1,-1", "1,4,50.0,59.5,4.0,4.0,1.0,-1,-1,-1",
                     "2,3,8.5,17.5,10.0,10.0,1.0,-1,-1,-1"]
    back = A.read_mot(path)
    assert back["frame"].tolist() == [0, 0, 1] and back["id"].tolist() == [3, 4, 3]
    np.testing.assert_array_equal(back[list(M.BOX_COLUMNS)].to_numpy()[0], [5.0, 15.0, 15.0, 25.0])
    loaded = _mm_load(path)  # py-motmetrics reads the file
    assert len(loaded) == 3 and loaded["Width"].tolist() == [10.0, 4.0, 10.0]


@pytest.mark.parametrize("text, match", [
    ("1,2,3,4,5\n", r"f\.txt:1: expected at least 6 fields"),
    ("1,2,3,4,5,6\n0,2,3,4,5,6\n", r"f\.txt:2: expected a 1-based integer frame, got '0'"),
    ("1,2,3,4,5,6\n\n2,2,x,4,5,6\n", r"f\.txt:3: expected numbers"),
])
def test_a_bad_motchallenge_file_is_refused_naming_file_and_line(tmp_path, text, match):
    (tmp_path / "f.txt").write_text(text)
    with pytest.raises(A.CellArtifactError, match=match):
        A.read_mot(tmp_path / "f.txt")


def test_hota_with_boxes_uses_iou_as_the_similarity():
    # One vehicle, box [0, 10] x [0, 10], 2 frames; track 7 with box [0, 10] x [0, 5] (IoU 0.5) then
    # [0, 10] x [0, 8] (IoU 0.8). Every alpha has one pair per frame to match (Luiten 2021, eq. 4-12):
    #   alpha <= 0.5 (10 alphas): TP 2, A(c) = 2 / (2 + 2 - 2) = 1: DetA 1, AssA 1, HOTA 1, LocA 0.65
    #   0.5 < alpha <= 0.8 (6): TP 1, FN 1, FP 1: DetA 1/3, A = 1/(2 + 2 - 1) = 1/3, HOTA = sqrt(1/9) = 1/3
    #   alpha > 0.8 (3): no TP: DetA 0, AssA 0 (TrackEval), HOTA 0
    truth = pd.DataFrame({"frame": [0, 1], "vehicle_id": 1, "x_px": 5.0, "y_px": 5.0, "bbox_x0_px": 0.0,
                          "bbox_y0_px": 0.0, "bbox_x1_px": 10.0, "bbox_y1_px": 10.0, "visible": 1})
    est = pd.DataFrame({"frame": [0, 1], "track_id": 7, "x_filt_px": 5.0, "y_filt_px": [2.5, 4.0],
                        "bbox_x0_px": 0.0, "bbox_y0_px": 0.0, "bbox_x1_px": 10.0, "bbox_y1_px": [5.0, 8.0],
                        "source": "multi"})
    c = M.hota_counts(est, truth)
    np.testing.assert_allclose(c.tp, [2] * 10 + [1] * 6 + [0] * 3)
    np.testing.assert_allclose(c.loc_sum, [1.3] * 10 + [0.8] * 6 + [0] * 3)
    rows = {r["metric"]: r for r in M.hota_rows(est, truth)}
    assert rows["hota"]["value"] == pytest.approx((10 + 6 / 3) / 19)
    assert rows["deta"]["value"] == pytest.approx((10 + 6 / 3) / 19)
    assert rows["assa"]["value"] == pytest.approx((10 + 6 / 3) / 19)
    assert rows["loca"]["value"] == pytest.approx((10 * 0.65 + 6 * 0.8) / 16)  # alphas with a TP only
    assert rows["hota"]["region"] == "multi" and rows["hota"]["count"] == 2


def test_hota_rows_pool_over_sequences_from_summed_per_alpha_counts():
    from harness.results import rows_to_frame

    seqs = [_boxed_scenario(np.random.default_rng(k), n_frames=12 + 6 * k) for k in range(3)]
    frames = [rows_to_frame(M.hota_rows(e, t), seed=k) for k, (e, t) in enumerate(seqs)]
    agg = M.aggregate(pd.concat(frames), by=[]).set_index("metric")["value"]
    pooled = M.hota_counts(*seqs[0])
    for e, t in seqs[1:]:
        pooled = pooled + M.hota_counts(e, t)
    assert agg["hota"] == pytest.approx(pooled.hota, abs=1e-12)
    assert agg["deta"] == pytest.approx(float(np.mean(pooled.deta)), abs=1e-12)
    per_seq = [M.hota_counts(e, t).hota for e, t in seqs]
    assert not math.isclose(np.mean(per_seq), agg["hota"], rel_tol=1e-9)  # not an average of averages
