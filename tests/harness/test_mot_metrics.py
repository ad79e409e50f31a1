"""CLEAR-MOT and identity metrics against py-motmetrics on the same data, and their summed-count aggregates."""

import math

import numpy as np
import pandas as pd
import pytest

import harness.metrics as M
from harness.results import rows_to_frame

mm = pytest.importorskip("motmetrics")


def _scenario(rng: np.random.Generator, n_frames: int = 40, n_vehicles: int = 4):
    """Vehicles on straight lines (some leave), noisy tracks with a swap, a gap, a late birth and clutter."""
    truth, est = [], []
    start = rng.uniform(20, 200, size=(n_vehicles, 2))
    vel = rng.uniform(-2, 2, size=(n_vehicles, 2))
    for f in range(n_frames):
        for v in range(n_vehicles):
            x, y = start[v] + vel[v] * f
            visible = int(not (v == 3 and f > 30))
            truth.append({"frame": f, "vehicle_id": v + 1, "x_px": x, "y_px": y, "visible": visible})
            if not visible or (v == 1 and 10 <= f < 14) or (v == 2 and f < 5):
                continue
            tid = 100 + v
            if v in (0, 1) and f >= 25:  # vehicles 1 and 2 exchange track ids
                tid = 101 if v == 0 else 100
            if v == 2 and f >= 20:
                tid = 200                # a new track takes over vehicle 3
            nx, ny = rng.normal(0, 1.5, 2)
            est.append({"frame": f, "track_id": tid, "x_filt_px": x + nx, "y_filt_px": y + ny, "source": "multi"})
        if f % 7 == 3:                   # clutter
            est.append({"frame": f, "track_id": 900 + f, "x_filt_px": rng.uniform(0, 250),
                        "y_filt_px": rng.uniform(0, 250), "source": "multi"})
    est.append({"frame": n_frames, "track_id": 999, "x_filt_px": 5.0, "y_filt_px": 5.0, "source": "multi"})
    return pd.DataFrame(est), pd.DataFrame(truth)


def _oracle(est: pd.DataFrame, truth: pd.DataFrame, gate_px: float):
    acc = mm.MOTAccumulator(auto_id=False)
    vis = truth[truth["visible"] == 1]
    for f in sorted(set(vis["frame"]) | set(est["frame"])):
        g, e = vis[vis["frame"] == f], est[est["frame"] == f]
        P, Q = g[["x_px", "y_px"]].to_numpy(float), e[["x_filt_px", "y_filt_px"]].to_numpy(float)
        D = np.hypot(P[:, None, 0] - Q[None, :, 0], P[:, None, 1] - Q[None, :, 1]).reshape(len(P), len(Q))
        acc.update(g["vehicle_id"].tolist(), e["track_id"].tolist(), np.where(D <= gate_px, D, np.nan), frameid=int(f))
    return acc


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clear_mot_and_idf1_equal_py_motmetrics(seed):
    est, truth = _scenario(np.random.default_rng(seed))
    gate = 5.0
    c = M.mot_counts(est, truth, gate_px=gate)
    s = mm.metrics.create().compute(
        _oracle(est, truth, gate),
        metrics=["num_objects", "num_predictions", "num_detections", "num_misses", "num_false_positives",
                 "num_switches", "mota", "motp", "idtp", "idfn", "idfp", "idf1"], name="x").iloc[0]
    # motmetrics' num_detections = its MATCH + SWITCH events: every corresponding pair, our ``matches``
    assert (c.objects, c.predictions, c.matches, c.misses, c.false_positives, c.switches) == (
        s.num_objects, s.num_predictions, s.num_detections, s.num_misses, s.num_false_positives, s.num_switches)
    assert (c.idtp, c.idfn, c.idfp) == (s.idtp, s.idfn, s.idfp)
    assert c.mota == pytest.approx(s.mota, abs=1e-12)
    assert c.motp_px == pytest.approx(s.motp, rel=1e-12)   # Euclidean distances given: MOTP in px
    assert c.idf1 == pytest.approx(s.idf1, rel=1e-12)
    assert c.switches >= 2 and c.false_positives > 0 and c.misses > 0  # the scenario exercises every count


def test_mot_rows_aggregate_from_summed_counts_like_motmetrics_overall():
    seqs = [_scenario(np.random.default_rng(k), n_frames=20 + 10 * k) for k in range(3)]
    gate = 5.0
    frames = [rows_to_frame(M.mot_rows(e, t, gate_px=gate), seed=k) for k, (e, t) in enumerate(seqs)]
    agg = M.aggregate(pd.concat(frames), by=[]).set_index("metric")
    mh = mm.metrics.create()
    overall = mh.compute_many([_oracle(e, t, gate) for e, t in seqs], names=["a", "b", "c"],
                              metrics=["mota", "motp", "idf1", "num_misses", "num_false_positives"],
                              generate_overall=True).loc["OVERALL"]
    assert agg.loc["mota", "value"] == pytest.approx(overall.mota, abs=1e-12)
    assert agg.loc["motp", "value"] == pytest.approx(overall.motp, rel=1e-12)
    assert agg.loc["idf1", "value"] == pytest.approx(overall.idf1, rel=1e-12)
    assert agg.loc["mot_misses", "value"] == overall.num_misses
    assert agg.loc["mot_false_positives", "value"] == overall.num_false_positives
    # an average of per-sequence MOTAs is not the pooled MOTA here (sequences differ in length)
    per_seq = [M.mot_counts(e, t, gate_px=gate).mota for e, t in seqs]
    assert not math.isclose(np.mean(per_seq), agg.loc["mota", "value"], rel_tol=1e-9)


def test_perfect_tracks_score_one_and_an_empty_gate_is_refused():
    est, truth = _scenario(np.random.default_rng(3))
    vis = truth[truth["visible"] == 1]
    perfect = pd.DataFrame({"frame": vis["frame"], "track_id": vis["vehicle_id"], "x_filt_px": vis["x_px"],
                            "y_filt_px": vis["y_px"], "source": "multi"})
    c = M.mot_counts(perfect, truth, gate_px=1.0)
    assert (c.mota, c.motp_px, c.idf1, c.switches) == (1.0, 0.0, 1.0, 0)
    with pytest.raises(ValueError, match="gate_px: expected > 0"):
        M.mot_counts(est, truth, gate_px=0.0)


def test_frames_are_grouped_as_pandas_groupby_groups_them():
    """The numpy frame grouping under every CLEAR-MOT / HOTA count gives groupby's groups: shuffled
    rows, invisible vehicles, NaN estimates, frames with only vehicles or only tracks."""
    est, truth = _scenario(np.random.default_rng(3))
    est = est.sample(frac=1.0, random_state=4).reset_index(drop=True)
    truth = truth.sample(frac=1.0, random_state=5).reset_index(drop=True)
    est.loc[est.index[:6], "x_filt_px"] = np.nan  # not predictions
    est = pd.concat([est, pd.DataFrame([{"frame": 77, "track_id": 5, "x_filt_px": 1.0, "y_filt_px": 2.0,
                                         "source": "multi"}])], ignore_index=True)
    vis = truth[truth["visible"].astype(bool)]
    fin = est[np.isfinite(est["x_filt_px"]) & np.isfinite(est["y_filt_px"])]
    vg, eg = dict(list(vis.groupby("frame"))), dict(list(fin.groupby("frame")))
    got = list(M._points_by_frame(est, truth))
    assert [int(f) for f, *_ in got] == sorted(set(vg) | set(eg))
    for f, vids, P, tids, Q in got:
        g, e = vg.get(f), eg.get(f)
        np.testing.assert_array_equal(vids, [] if g is None else g["vehicle_id"].to_numpy())
        np.testing.assert_array_equal(P.reshape(-1, 2), np.zeros((0, 2)) if g is None else g[["x_px", "y_px"]])
        np.testing.assert_array_equal(tids, [] if e is None else e["track_id"].to_numpy())
        np.testing.assert_array_equal(Q.reshape(-1, 2), np.zeros((0, 2)) if e is None else e[["x_filt_px", "y_filt_px"]])
    # and the counts still equal py-motmetrics on the shuffled table
    c = M.mot_counts(est, truth, gate_px=5.0)
    s = mm.metrics.create().compute(_oracle(fin, truth, 5.0), metrics=["num_switches", "mota", "idf1"],
                                    name="x").iloc[0]
    assert c.switches == s["num_switches"]
    assert c.mota == pytest.approx(s["mota"], abs=1e-12) and c.idf1 == pytest.approx(s["idf1"], abs=1e-12)


def _boxed(rows):
    """tracks.csv rows ``(frame, vehicle_id, x, y, half_width, extra...)``: square boxes around the centre."""
    out = []
    for f, v, x, y, h, extra in rows:
        out.append({"frame": f, "vehicle_id": v, "x_px": x, "y_px": y, "bbox_x0_px": x - h, "bbox_y0_px": y - h,
                    "bbox_x1_px": x + h, "bbox_y1_px": y + h, "visible": 1, **extra})
    return pd.DataFrame(out)


def _points(rows):
    return pd.DataFrame([{"frame": f, "track_id": t, "x_filt_px": x, "y_filt_px": y, "x_px": x, "y_px": y,
                          "x_pred_px": np.nan, "y_pred_px": np.nan, "source": "multi"} for f, t, x, y in rows])


def test_a_track_on_a_parked_car_is_a_false_positive_and_the_parked_car_no_miss():
    # two frames: car 1 moves, car 2 is parked; one point track inside each box
    truth = _boxed([(f, v, x + (3.0 * f if v == 1 else 0.0), 20.0, 6.0, {"parked": p, "class": "car"})
                    for f in (0, 1) for v, x, p in ((1, 20.0, 0), (2, 80.0, 1))])
    est = _points([(f, t, x + (3.0 * f if t == 10 else 0.0), 21.0)
                   for f in (0, 1) for t, x in ((10, 20.0), (11, 80.0))])
    c = M.mot_counts(est, truth, gate_px=5.0)
    assert (c.objects, c.predictions, c.matches, c.misses, c.false_positives) == (2, 4, 2, 0, 2)
    assert c.mota == pytest.approx(1 - 2 / 2)
    # the parked car has no track rows; the moving one is complete
    rows = [r for r in M.track_rows(est, truth, gate_px=5.0) if r["metric"] == "track_completeness"]
    assert [(r["track_id"], r["value"]) for r in rows] == [(1, 100.0)]
    # a car queued at a light (not parked, speed 0 in a frame) stays an object in that frame when it moves in another
    queued = truth.assign(speed_mps=np.where(truth["frame"] == 0, 0.0, 6.0))
    assert M.mot_counts(est, queued, gate_px=5.0).objects == 2
    # one that stands still through the whole sequence is a distractor: neither a miss nor its track a false positive
    static = truth.assign(speed_mps=0.3)
    c = M.mot_counts(est, static, gate_px=5.0)
    assert (c.objects, c.misses, c.false_positives) == (0, 0, 2)   # the parked car's track is still one
    assert M.mot_counts(est[est["track_id"] == 11], static, gate_px=5.0).misses == 0
    assert M.static_vehicles(static).tolist() == [True, False, True, False]
    # a speed at or over the limit in one visible row makes it a moving vehicle, counted in every frame
    once = static.assign(speed_mps=np.where(static["frame"] == 1, M.STATIC_SPEED_MPS, 0.0))
    assert M.mot_counts(est, once, gate_px=5.0).objects == 2
    # a moving column, where present, decides over parked
    moving = truth.assign(moving=1)
    assert M.mot_counts(est, moving, gate_px=5.0).objects == 4


def test_a_track_on_a_pedestrian_is_neither_a_false_positive_nor_the_pedestrian_a_miss():
    truth = _boxed([(0, 1, 20.0, 20.0, 6.0, {"parked": 0, "class": "car"}),
                    (0, 2, 60.0, 20.0, 2.0, {"parked": 0, "class": "pedestrian"}),
                    (0, 3, 100.0, 20.0, 3.0, {"parked": 0, "class": "cyclist"})])
    est = _points([(0, 10, 20.5, 20.0), (0, 11, 60.5, 20.0), (0, 12, 100.0, 21.0), (0, 13, 200.0, 200.0)])
    c = M.mot_counts(est, truth, gate_px=5.0)
    # only the car is an object; the tracks on the pedestrian and the cyclist are removed; 13 is clutter
    assert (c.objects, c.predictions, c.matches, c.misses, c.false_positives) == (1, 2, 1, 0, 1)
    h = M.hota_counts(est, truth, gate_px=5.0)
    assert (h.tp[0], h.fn[0], h.fp[0]) == (1, 0, 1)
    # no track on the pedestrian: still no miss
    assert M.mot_counts(est[est["track_id"] == 10], truth, gate_px=5.0).misses == 0
    # older truth without class and parked: every visible row is an object, the same numbers as before
    old = truth.drop(columns=["class", "parked"])
    c_old = M.mot_counts(est, old, gate_px=5.0)
    assert (c_old.objects, c_old.matches, c_old.false_positives) == (3, 3, 1)


def test_a_row_of_low_visibility_is_neither_a_miss_nor_a_track_on_it_a_false_positive():
    # car 1 in full view; car 2 shows 30 % of itself in frame 0 (most of it beyond the border, its box the part in the
    # image) and all of itself in frame 1; one boxed track on each car in both frames
    truth = _boxed([(f, v, x, 20.0, 6.0, {"parked": 0, "class": "car", "visible_fraction": vf, "speed_mps": 5.0})
                    for f, v, x, vf in ((0, 1, 20.0, 1.0), (0, 2, 80.0, 0.3), (1, 1, 23.0, 1.0), (1, 2, 83.0, 1.0))])
    est = _points([(f, t, x, 20.0) for f, t, x in ((0, 10, 20.0), (0, 11, 80.0), (1, 10, 23.0), (1, 11, 83.0))])
    est = est.assign(bbox_x0_px=est["x_filt_px"] - 6.0, bbox_y0_px=14.0, bbox_x1_px=est["x_filt_px"] + 6.0,
                     bbox_y1_px=26.0)
    assert M.low_visibility(truth).tolist() == [False, True, False, False]
    assert M.counted_objects(truth).tolist() == [True, False, True, True]
    assert M.distractor_objects(truth).tolist() == [False, True, False, False]
    c = M.mot_counts(est, truth, gate_px=5.0)
    # frame 0: car 2 is a distractor, track 11 on it removed; frame 1: both counted and matched
    assert (c.objects, c.predictions, c.matches, c.misses, c.false_positives, c.switches) == (3, 3, 3, 0, 0, 0)
    assert c.mota == 1.0
    # without a track on car 2 in frame 0 it is still no miss
    c = M.mot_counts(est[~((est["frame"] == 0) & (est["track_id"] == 11))], truth, gate_px=5.0)
    assert (c.objects, c.misses, c.false_positives) == (3, 0, 0)
    # at the threshold itself the row counts; a threshold of 0 (the MOTChallenge devkit's default) counts every row
    edge = truth.assign(visible_fraction=np.where(truth["visible_fraction"] < 1, M.MIN_VISIBLE_FRACTION, 1.0))
    assert M.mot_counts(est, edge, gate_px=5.0).objects == 4
    assert M.counted_objects(truth, min_visible_fraction=0.0).all()
    # a parked car of low visibility stays no object and no distractor: a track on it is a false positive
    parked = truth.assign(parked=np.where(truth["vehicle_id"] == 2, 1, 0))
    assert not M.distractor_objects(parked).any()
    assert M.mot_counts(est, parked, gate_px=5.0).false_positives == 2
    # without the column (older folders, a gt.txt without visibility) no row is low; real annotation (no speed_mps:
    # a gt.txt) is scored by its flags alone, its visibility not cut on (TrackEval's and the MOT devkit's minvis 0)
    assert not M.low_visibility(truth.drop(columns=["visible_fraction"])).any()
    real = truth.drop(columns=["speed_mps"])
    assert not M.low_visibility(real).any() and M.counted_objects(real).all()
    assert M.mot_counts(est, real, gate_px=5.0).objects == 4
    with pytest.raises(ValueError, match="min_visible_fraction: expected 0..1, got 1.5"):
        M.counted_objects(truth, min_visible_fraction=1.5)


def test_a_track_in_an_ignore_region_is_no_false_positive():
    truth = _boxed([(f, 1, 20.0, 20.0, 6.0, {}) for f in (0, 1)])
    # a large ignored region (a parking lot) in frame 0 only, holding two tracks
    ignore = pd.DataFrame({"frame": [0], "bbox_x0_px": [50.0], "bbox_y0_px": [0.0], "bbox_x1_px": [150.0],
                           "bbox_y1_px": [60.0], "class": ["car"]})
    est = _points([(0, 10, 20.0, 20.0), (0, 11, 70.0, 30.0), (0, 12, 120.0, 40.0),
                   (1, 10, 20.0, 20.0), (1, 11, 70.0, 30.0)])
    c = M.mot_counts(est, truth, gate_px=5.0, ignore=ignore)
    assert (c.objects, c.predictions, c.false_positives) == (2, 3, 1)   # frame 1's track 11 is outside any region
    assert M.mot_counts(est, truth, gate_px=5.0).false_positives == 3
    rows = {r["metric"]: r for r in M.mot_rows(est, truth, gate_px=5.0, ignore=ignore)}
    assert rows["mot_false_positives"]["value"] == 1
    # a region does not take a track from the vehicle it lies on
    over = ignore.assign(bbox_x0_px=0.0)
    assert M.mot_counts(est, truth, gate_px=5.0, ignore=over).matches == 2
    with pytest.raises(ValueError, match="ignore regions: expected columns"):
        M.mot_counts(est, truth, gate_px=5.0, ignore=ignore.drop(columns=["bbox_x1_px"]))


def _with_distractors(rng: np.random.Generator):
    """The scenario plus a parked car, a pedestrian, tracks on both, and a track beside the pedestrian."""
    est, truth = _scenario(rng)
    truth["class"], truth["parked"] = "car", 0
    n = truth["frame"].max() + 1
    extra = [{"frame": f, "vehicle_id": 50, "x_px": 300.0, "y_px": 300.0, "visible": 1, "class": "car",
              "parked": 1} for f in range(n)]
    extra += [{"frame": f, "vehicle_id": 60, "x_px": 400.0 + f, "y_px": 50.0, "visible": 1, "class": "pedestrian",
               "parked": 0} for f in range(n)]
    est_extra = [{"frame": f, "track_id": 500, "x_filt_px": 301.0, "y_filt_px": 300.0, "source": "multi"}
                 for f in range(0, n, 2)]
    est_extra += [{"frame": f, "track_id": 600, "x_filt_px": 400.0 + f, "y_filt_px": 51.0, "source": "multi"}
                  for f in range(n)]
    return (pd.concat([est, pd.DataFrame(est_extra)], ignore_index=True),
            pd.concat([truth, pd.DataFrame(extra)], ignore_index=True))


@pytest.mark.parametrize("seed", [0, 1])
def test_clear_mot_with_distractors_equals_py_motmetrics_after_removal_by_hand(seed):
    est, truth = _with_distractors(np.random.default_rng(seed))
    gate = 5.0
    c = M.mot_counts(est, truth, gate_px=gate)
    # on the oracle's side, by hand: the pedestrian is no object and the one track on it (600, always within
    # the gate of it and of no car) is removed; the parked car stays out of the objects, its track stays in
    oracle_truth = truth[truth["class"] != "pedestrian"]
    oracle_truth = oracle_truth.assign(visible=np.where(oracle_truth["parked"] == 1, 0, oracle_truth["visible"]))
    oracle_est = est[est["track_id"] != 600]
    s = mm.metrics.create().compute(
        _oracle(oracle_est, oracle_truth, gate),
        metrics=["num_objects", "num_predictions", "num_misses", "num_false_positives", "num_switches", "mota",
                 "idf1"], name="x").iloc[0]
    assert (c.objects, c.predictions, c.misses, c.false_positives, c.switches) == (
        s.num_objects, s.num_predictions, s.num_misses, s.num_false_positives, s.num_switches)
    assert c.mota == pytest.approx(s.mota, abs=1e-12) and c.idf1 == pytest.approx(s.idf1, abs=1e-12)
    n_parked_track = int((est["track_id"] == 500).sum())
    assert c.false_positives >= n_parked_track > 0   # the track on the parked car counts against MOTA


def test_score_sequence_passes_real_footages_ignore_regions_to_every_tracking_metric():
    from types import SimpleNamespace

    truth = _boxed([(f, 1, 20.0, 20.0, 6.0, {}) for f in (0, 1)])
    ignore = pd.DataFrame({"frame": [0, 1], "bbox_x0_px": 50.0, "bbox_y0_px": 0.0, "bbox_x1_px": 150.0,
                           "bbox_y1_px": 60.0, "class": "car"})
    est = _points([(f, t, x, 20.0) for f in (0, 1) for t, x in ((10, 20.0), (11, 90.0))])
    seq = SimpleNamespace(tracks=est)
    plain = {(r["metric"], r["region"]): r["value"] for r in M.score_sequence(seq, None, truth)}
    kept = {(r["metric"], r["region"]): r["value"] for r in M.score_sequence(seq, None, truth, ignore_df=ignore)}
    assert plain[("mot_false_positives", "multi")] == 2 and kept[("mot_false_positives", "multi")] == 0
    assert kept[("mota", "multi")] == 1.0 and kept[("idf1", "multi")] == 1.0 and kept[("hota", "multi")] > plain[
        ("hota", "multi")]


def test_a_tracker_that_ran_and_output_no_track_is_scored_as_missing_every_vehicle():
    # the metric set of a cell must not depend on whether a track was confirmed: the gate compares sets
    from types import SimpleNamespace

    truth = _boxed([(f, 1, 20.0, 20.0, 6.0, {}) for f in (0, 1, 2)])
    point = _points([(f, 10, 20.0, 20.0) for f in (0, 1, 2)]).assign(source="point", seed_vehicle_id=1)
    seq = SimpleNamespace(tracks=point, trackers=("point", "multi"))
    rows = {(r["metric"], r["region"]): r for r in M.score_sequence(seq, None, truth)}
    assert rows[("mota", "point")]["value"] == 1.0
    assert rows[("mota", "multi")]["value"] == 0.0 and rows[("mot_misses", "multi")]["sum"] == 3
    assert rows[("hota", "multi")]["value"] == 0.0 and rows[("track_completeness", "multi")]["value"] == 0.0
    # without the trackers named, as before: only the tracker that output rows
    bare = {r["region"] for r in M.score_sequence(SimpleNamespace(tracks=point), None, truth)}
    assert bare == {"point"}
    # no rows at all from either tracker: both still scored
    empty = SimpleNamespace(tracks=point.iloc[0:0], trackers=("point", "multi"))
    assert {r["region"] for r in M.score_sequence(empty, None, truth) if r["metric"] == "mota"} == {"point", "multi"}
