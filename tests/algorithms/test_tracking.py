"""Detections from a motion mask, the thesis point tracker, the multi-target tracker."""

import numpy as np
import pytest

from algorithms.kalman import THESIS_KALMAN, scalar_kalman
from algorithms.tracking import MultiTargetTracker, PointTracker, detect_moving_objects


def test_detection_finds_known_blobs_with_centroids_and_areas():
    m = np.zeros((40, 60), bool)
    m[5:10, 10:20] = True        # 5 x 10 block, centroid (14.5, 7)
    m[30:34, 40:44] = True       # 4 x 4 block, centroid (41.5, 31.5)
    m[20, 5] = True              # single noisy pixel
    det = detect_moving_objects(m, min_area_px=4)
    assert det == [(14.5, 7.0, 50), (41.5, 31.5, 16)]
    with pytest.raises(ValueError, match=r"mask: expected \(H, W\) bool"):
        detect_moving_objects(m.astype(np.uint8))


def test_point_tracker_follows_global_plus_local_and_filters_flow():
    h, w = 50, 80
    tracker = PointTracker(10.0, 40.0, track_id=7, seed_vehicle_id=3, kalman=THESIS_KALMAN)
    shifts = [(1.0, 0.0), (2.0, -1.0), (1.0, 0.0)]
    local = (0.5, -2.0)
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0], flow[..., 1] = local
    for s in shifts:
        tracker.step(s, flow)
    rows = tracker.rows()
    assert [r["frame"] for r in rows] == [0, 1, 2, 3]
    # p(t+1) = p(t) + s + w
    assert (rows[3]["x_px"], rows[3]["y_px"]) == (10 + 4 + 1.5, 40 - 1 - 6.0)
    assert rows[0]["seed_vehicle_id"] == 3 and rows[0]["source"] == "point"
    # filtered path integrates the thesis-filtered flow: X(1|1) = -1 for the first pair
    wv = scalar_kalman([-2.0] * 3, **THESIS_KALMAN)
    assert rows[3]["y_filt_px"] == pytest.approx(40 - 1 + wv.sum())


def test_point_tracker_outside_the_image_only_moves_with_the_camera():
    tracker = PointTracker(1.0, 1.0)
    flow = np.ones((4, 4, 2), np.float32)
    tracker.step((-5.0, 0.0), flow)   # moves to (-3, 2): outside from now on
    tracker.step((1.0, 1.0), flow)
    rows = tracker.rows()
    assert (rows[2]["x_px"], rows[2]["y_px"]) == (-2.0, 3.0)


def _crossing(rng: np.random.Generator, n=30):
    t = np.arange(n, dtype=float)
    a = np.column_stack([10 + 2.0 * t, 50 + 0.3 * t])       # right, slightly down
    b = np.column_stack([70 - 2.0 * t, 56 - 0.3 * t])       # left, slightly up: paths cross at t = 15
    noise = lambda: rng.normal(0, 0.3, size=(n, 2))  # noqa: E731
    return a + noise(), b + noise()


def test_multi_target_tracker_keeps_identities_through_a_crossing():
    a, b = _crossing(np.random.default_rng(0))
    trk = MultiTargetTracker(gate_px=5.0, birth_hits=3, death_misses=2, sigma_accel_px=0.1, sigma_meas_px=0.3)
    for t in range(len(a)):
        dets = [(a[t, 0], a[t, 1], 30), (b[t, 0], b[t, 1], 30)]
        if t % 2:
            dets.reverse()  # the order of detections must not matter
        if t == 12:
            dets = dets[:1]  # one missed detection: the missing track coasts
        trk.step(t, dets)
    rows = trk.rows()
    ids = sorted({r["track_id"] for r in rows})
    assert len(ids) == 2
    for tid in ids:
        mine = [r for r in rows if r["track_id"] == tid]
        assert [r["frame"] for r in mine] == list(range(len(a)))  # rows from birth, incl. tentative frames
        xy = np.array([[r["x_filt_px"], r["y_filt_px"]] for r in mine])
        truth = a if abs(xy[0, 0] - a[0, 0]) < 2 else b
        assert np.abs(xy - truth).max() < 2.0  # never jumps to the other target


def test_multi_target_tracker_birth_death_and_ground_frame():
    trk = MultiTargetTracker(gate_px=3.0, birth_hits=2, death_misses=2)
    trk.step(0, [(5.0, 5.0, 10), (40.0, 40.0, 10)])
    trk.step(1, [(6.0, 5.0, 10)])           # the second one was a one-frame blip
    trk.step(2, [])
    trk.step(3, [])
    rows = trk.rows()
    assert {r["track_id"] for r in rows} == {0}
    assert [r["frame"] for r in rows] == [0, 1, 2]  # coasts one frame, deleted at the second miss
    assert np.isnan(rows[2]["x_px"])
    # a target fixed on the ground seen by a camera panning 4 px/frame: in the
    # ground frame it does not move, so a tight gate still holds it
    pan = MultiTargetTracker(gate_px=1.0, birth_hits=1, death_misses=1)
    for t in range(6):
        pan.step(t, [(20.0 + 4 * t, 10.0, 5)], offset_px=(4.0 * t, 0.0))
    assert {r["track_id"] for r in pan.rows()} == {0}
    with pytest.raises(ValueError, match="birth_hits: expected an integer >= 1"):
        MultiTargetTracker(birth_hits=0)


def test_recentre_on_region_finds_the_vehicle_that_moves_like_the_point():
    from algorithms.tracking import recentre_on_region

    flow = np.zeros((60, 80, 2), np.float32)
    flow[20:30, 30:50] = (2.0, 0.5)      # a vehicle, centroid (39.5, 24.5)
    flow[20:30, 52:70] = (-2.0, 0.0)     # its neighbour drives the other way
    assert recentre_on_region(flow, 41.0, 27.0, radius_px=12.0) == (39.5, 24.5)
    # the window (half-side 12) clips the vehicle from x = 47: a second round, as the tracker runs, gets it whole
    once = recentre_on_region(flow, 47.0, 28.0, radius_px=12.0)
    assert once == (42.0, 24.5) and recentre_on_region(flow, *once, radius_px=12.0) == (39.5, 24.5)
    assert recentre_on_region(flow, 10.0, 10.0, radius_px=12.0) == (10.0, 10.0)   # on the ground: stays
    with pytest.raises(ValueError, match="radius_px: expected a finite number > 0"):
        recentre_on_region(flow, 47.0, 28.0, radius_px=0.0)


def test_point_tracker_with_underestimated_flow_drifts_open_loop_and_holds_when_recentred():
    h, w = 60, 200
    truth = [(20.0 + 3.0 * t, 30.0) for t in range(12)]
    trackers = [PointTracker(*truth[0]), PointTracker(*truth[0], recentre_px=12.0)]
    for t in range(11):
        flow = np.zeros((h, w, 2), np.float32)
        cx = round(truth[t][0])
        flow[26:35, cx - 6:cx + 7] = (2.4, 0.0)   # the flow method sees 80 % of the vehicle's 3 px/frame
        for trk in trackers:
            trk.step((0.0, 0.0), flow)
    err = [np.hypot(*(np.array([r["x_px"], r["y_px"]]) - truth[r["frame"]])) for r in trackers[0].rows()]
    assert err[-1] > 6.0                                    # 0.6 px/frame, integrated open loop
    err_rc = [np.hypot(*(np.array([r["x_px"], r["y_px"]]) - truth[r["frame"]])) for r in trackers[1].rows()]
    assert max(err_rc[:-1]) <= 0.51 and err_rc[-1] <= 1.2   # re-centred every frame (the last one is a step ahead)


def test_position_filter_smooths_noisy_recentred_positions_in_the_ground_frame():
    rng = np.random.default_rng(5)
    n, h, w = 40, 80, 260
    pan = np.array([0.0, 0.4])                                    # the camera pans; its path is removed first
    truth = np.array([[20.0 + 5.0 * t, 20.0 + 0.4 * t] for t in range(n)])
    trk = PointTracker(*truth[0], recentre_px=12.0, position_filter={"sigma_accel_px": 0.05, "sigma_meas_px": 1.0})
    for t in range(n - 1):
        flow = np.zeros((h, w, 2), np.float32)
        cx, cy = np.round(truth[t] + rng.normal(0, 1.0, 2)).astype(int)   # the moving region is found 1 px off
        flow[cy - 4:cy + 5, cx - 8:cx + 9] = (5.0, 0.0)
        trk.step(pan, flow)
    rows = trk.rows()[5:-1]                                       # after the filter settles; last frame unmeasured
    raw = np.array([[r["x_px"], r["y_px"]] for r in rows])
    filt = np.array([[r["x_filt_px"], r["y_filt_px"]] for r in rows])
    ref = truth[5:-1]
    raw_err, filt_err = np.hypot(*(raw - ref).T), np.hypot(*(filt - ref).T)
    assert np.abs(filt - raw).max() > 0.5                         # the Kalman output is not the raw track
    assert filt_err.mean() < 0.7 * raw_err.mean()
    with pytest.raises(ValueError, match="position_filter: unknown key"):
        PointTracker(0.0, 0.0, position_filter={"q": 1.0})
