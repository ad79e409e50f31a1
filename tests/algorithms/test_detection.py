"""Moving-vehicle detection (algorithms.detection) and the box tracker over it."""

import math

import cv2
import numpy as np
import pytest

from algorithms.detection import DETECTION_DEFAULTS, Detection, detect_vehicles, ground_residual
from algorithms.kalman import BoxKalman
from algorithms.pipeline import Pipeline, PipelineError
from algorithms.tracking import MultiTargetTracker
from tests.algorithms.synthetic import box_iou

H, W = 120, 160


def _field(rng, blocks, *, sigma_noise=0.05, blur=1.0):
    """A local flow field: ground noise plus blocks (y0, y1, x0, x1, (u, v)), smoothed as a flow method would."""
    f = rng.normal(0.0, sigma_noise, size=(H, W, 2)).astype(np.float32)
    for y0, y1, x0, x1, uv in blocks:
        f[y0:y1, x0:x1] = uv
    return cv2.GaussianBlur(f, (0, 0), blur) if blur else f


def _near(dets, x, y, tol=2.5):
    return [d for d in dets if abs(d.x_px - x) <= tol and abs(d.y_px - y) <= tol]


def test_adjacent_cars_with_different_velocities_split_and_a_bus_stays_whole():
    rng = np.random.default_rng(0)
    flow = _field(rng, [(40, 48, 40, 60, (3.0, 0.0)),     # car A, 20 x 8 px
                        (48, 56, 40, 60, (-3.0, 0.0)),    # car B, touching A, driving the other way
                        (90, 102, 30, 90, (2.5, 0.5))])   # a bus, 60 x 12 px
    dets = detect_vehicles(flow, np.ones((H, W), bool))
    assert all(isinstance(d, Detection) for d in dets)
    assert len(dets) == 3, dets
    (a,), (b,) = _near(dets, 49.5, 43.5), _near(dets, 49.5, 51.5)
    assert (a.u_px, b.u_px) == pytest.approx((3.0, -3.0), abs=0.5)
    (bus,) = _near(dets, 59.5, 95.5)
    assert (bus.u_px, bus.v_px) == pytest.approx((2.5, 0.5), abs=0.3)
    # the bus's box is the bus (the smoothing's halo below half its speed left out), within 2 px
    assert (bus.x0_px, bus.y0_px, bus.x1_px, bus.y1_px) == pytest.approx((30, 90, 89, 101), abs=2)
    # the same pair at one velocity is one rigid mover: no split
    one = detect_vehicles(_field(rng, [(40, 56, 40, 60, (3.0, 0.0))]), np.ones((H, W), bool))
    assert len(one) == 1
    assert (one[0].x0_px, one[0].y0_px, one[0].x1_px, one[0].y1_px) == pytest.approx((40, 40, 59, 55), abs=1)


def test_parallax_along_the_global_motion_is_rejected_and_motion_across_it_is_not():
    rng = np.random.default_rng(1)
    valid = np.ones((H, W), bool)
    shift = (0.0, 5.0)  # the ground's image motion of the pair
    # a roof 15 % of the flight height up: residual 0.18 x the ground's motion, along it and in its sense
    roof = _field(rng, [(30, 60, 30, 60, (0.0, 0.9))])
    assert detect_vehicles(roof, valid, global_flow_px=shift) == []
    # the same residual across the global motion is no parallax of a static point: a vehicle
    across = _field(rng, [(30, 60, 30, 60, (0.9, 0.0))])
    assert len(detect_vehicles(across, valid, global_flow_px=shift)) == 1
    # against the flight, or faster than any roof's parallax, along it: vehicles
    for uv in ((0.0, -0.9), (0.0, 3.0)):
        assert len(detect_vehicles(_field(rng, [(30, 60, 30, 60, uv)]), valid, global_flow_px=shift)) == 1
    # without the global motion the test is off
    assert len(detect_vehicles(roof, valid)) == 1
    # a parallax field over a whole textured scene (a field of roofs and trees) after the affine ground fit
    yy = np.linspace(0, 1, H, dtype=np.float32)[:, None]
    scene = np.zeros((H, W, 2), np.float32)
    scene[..., 1] = 0.3 + 0.4 * yy   # a tilted view: the residual grows smoothly down the frame
    scene[50:70, 100:130, 1] += 0.8  # a building
    assert detect_vehicles(scene, valid, global_flow_px=shift) == []


def test_a_bus_moving_along_its_length_slower_than_a_roofs_parallax_is_kept_with_parallax_lengthwise_rel():
    # a bus (12 x 50 px) pulling into a stop along the flight line, at 0.18 times the ground's image motion: from
    # the flow alone the parallax of a roof 15 % of the flight height up, rejected by default; a roof's parallax
    # points along the flight whatever its shape, a vehicle drives along its length
    rng = np.random.default_rng(4)
    valid = np.ones((H, W), bool)
    shift = (0.0, 5.0)
    bus = _field(rng, [(30, 80, 70, 82, (0.0, 0.9))])
    assert detect_vehicles(bus, valid, global_flow_px=shift) == []
    (d,) = detect_vehicles(bus, valid, global_flow_px=shift, parallax_lengthwise_rel=2.5)
    assert (d.x0_px, d.y0_px, d.x1_px, d.y1_px) == pytest.approx((70, 30, 81, 79), abs=2)
    # a square roof and a bar across the motion (a roof's edge) are still parallax with the key on
    for block in ((30, 60, 30, 60), (40, 52, 30, 90)):
        field = _field(rng, [(*block, (0.0, 0.9))])
        assert detect_vehicles(field, valid, global_flow_px=shift, parallax_lengthwise_rel=2.5) == []
    with pytest.raises(ValueError, match="parallax_lengthwise_rel: expected a finite number >= 0"):
        detect_vehicles(bus, valid, parallax_lengthwise_rel=-1.0)


def test_ground_residual_removes_a_smooth_field_and_keeps_a_block():
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    f = np.stack([0.5 + 0.01 * xx - 0.005 * yy, -0.3 + 0.004 * xx + 0.008 * yy], axis=-1)
    f[20:30, 20:40] += (3.0, 1.0)
    r = ground_residual(f, np.ones((H, W), bool))
    outside = np.ones((H, W), bool)
    outside[20:30, 20:40] = False
    assert np.abs(r[outside]).max() < 1e-3
    np.testing.assert_allclose(r[20:30, 20:40], np.broadcast_to((3.0, 1.0), (10, 20, 2)), atol=1e-3)


def test_a_region_whose_flow_does_not_move_the_texture_is_rejected():
    rng = np.random.default_rng(2)
    g0 = cv2.GaussianBlur(rng.uniform(0, 255, (H, W)).astype(np.float32), (0, 0), 1.5)
    flow = _field(rng, [(40, 60, 60, 90, (2.0, 0.0))], blur=0)
    valid = np.ones((H, W), bool)
    # an illumination change: the block brightens, nothing moves
    lit = g0.copy()
    lit[40:60, 60:90] += 25.0
    assert detect_vehicles(flow, valid, frames=(g0, lit)) == []
    # the block's texture moved 2 px right: found, at its velocity
    moved = g0.copy()
    moved[40:60, 62:92] = g0[40:60, 60:90]
    (d,) = detect_vehicles(flow, valid, frames=(g0, moved))
    assert (d.u_px, d.v_px) == pytest.approx((2.0, 0.0), abs=0.25)
    # its box from the frames: the block in frame t (not the place it moves to), within 2 px
    assert (d.x0_px, d.y0_px, d.x1_px, d.y1_px) == pytest.approx((60, 40, 89, 59), abs=2)
    # block matching recovers a motion the flow saw only in part (a fast vehicle)
    fast = g0.copy()
    fast[40:60, 69:99] = g0[40:60, 60:90]
    slow_flow = _field(rng, [(40, 60, 60, 90, (3.0, 0.0))], blur=0)
    (d,) = detect_vehicles(slow_flow, valid, frames=(g0, fast))
    assert (d.u_px, d.v_px) == pytest.approx((9.0, 0.0), abs=0.25)


def test_area_in_square_metres_and_its_limits():
    rng = np.random.default_rng(3)
    flow = _field(rng, [(40, 48, 40, 60, (3.0, 0.0))], blur=0)
    valid = np.ones((H, W), bool)
    (d,) = detect_vehicles(flow, valid, gsd_m_per_px=0.25)
    assert d.area_m2 == pytest.approx(d.area_px * 0.0625)
    assert math.isnan(detect_vehicles(flow, valid)[0].area_m2)
    # 160 px at 0.1 m/px are 1.6 m^2: under the default minimum of a vehicle's top view
    assert detect_vehicles(flow, valid, gsd_m_per_px=0.1) == []


def test_box_tracker_keeps_identity_through_a_five_frame_occlusion():
    n = 30
    a = np.array([[20.0 + 3.0 * t, 50.0] for t in range(n)])           # hidden in frames 10..14
    b = np.array([[140.0 - 2.0 * t, 70.0 + 0.5 * t] for t in range(n)])
    occluded = set(range(10, 15))
    rng = np.random.default_rng(4)

    def det(c, uv):
        x, y = c + rng.normal(0, 0.3, 2)
        return Detection(x, y, 160, x - 9.5, y - 3.5, x + 9.5, y + 3.5, *uv)

    runs = {}
    for coasting in (False, True):
        trk = MultiTargetTracker(report_coasting=coasting)
        for t in range(n):
            dets = [det(b[t], (-2.0, 0.5))] + ([] if t in occluded else [det(a[t], (3.0, 0.0))])
            trk.step(t, dets)
        runs[coasting] = trk.rows()
    rows = runs[False]
    ids = {r["track_id"] for r in rows}
    assert len(ids) == 2
    for tid in ids:
        mine = sorted((r for r in rows if r["track_id"] == tid), key=lambda r: r["frame"])
        assert [r["frame"] for r in mine] == list(range(n))  # one id from birth to the end, through the gap
        truth = a if abs(mine[0]["x_filt_px"] - a[0, 0]) < 3 else b
        xy = np.array([[r["x_filt_px"], r["y_filt_px"]] for r in mine])
        seen = np.isfinite(xy[:, 0])
        assert np.abs(xy[seen] - truth[seen]).max() < 1.5
        if truth is a:
            assert not seen[10:15].any()  # a hidden vehicle is not reported by default
            assert mine[0]["bbox_x1_px"] - mine[0]["bbox_x0_px"] == pytest.approx(19.0, abs=1.0)
    # reported, the coasting frames carry the constant-velocity prediction
    coast = [r for r in runs[True] if r["frame"] in occluded and abs(r["y_filt_px"] - 50.0) < 5]
    assert len(coast) == 5
    for r in coast:
        assert (r["x_filt_px"], r["y_filt_px"]) == pytest.approx(tuple(a[r["frame"]]), abs=1.5)
        assert math.isnan(r["x_px"])


def test_box_kalman_recovers_a_constant_velocity_and_growth():
    kf = BoxKalman((10.0, 20.0, 8.0, 4.0))
    for k in range(1, 40):
        kf.predict()
        kf.update((10.0 + 2.0 * k, 20.0 - 1.0 * k, 8.0 + 0.1 * k, 4.0))
    np.testing.assert_allclose(kf.x[4:8], (2.0, -1.0, 0.1, 0.0), atol=0.02)
    with pytest.raises(ValueError, match=r"box: expected a finite \(cx, cy, w, h\)"):
        kf.update((1.0, 2.0, 3.0))



def test_box_kalman_restarted_size_follows_the_new_size_at_once_and_keeps_the_motion():
    # a filter that learned a 40 x 10 px box (two cars abreast) restarts its size at 20 x 10: the centre and its
    # motion are kept, the size is the new one with its rate 0, and an update at that size stays there, where the
    # filter alone is still halfway
    runs = {}
    for restart in (False, True):
        kf = BoxKalman((10.0, 20.0, 40.0, 10.0))
        for k in range(1, 30):
            kf.predict()
            kf.update((10.0 + 2.0 * k, 20.0, 40.0, 10.0))
        before = kf.x.copy()
        if restart:
            kf.restart_size(20.0, 10.0)
            np.testing.assert_array_equal(kf.x[[0, 1, 4, 5]], before[[0, 1, 4, 5]])
            np.testing.assert_array_equal(kf.x[[2, 3, 6, 7]], [20.0, 10.0, 0.0, 0.0])
        kf.predict()
        kf.update((70.0, 20.0, 20.0, 10.0))
        runs[restart] = kf.x.copy()
    assert abs(runs[True][2] - 20.0) < 0.5 and runs[False][2] > 25.0
    assert runs[True][4] == pytest.approx(2.0, abs=0.05)
    with pytest.raises(ValueError, match=r"w, h: expected finite sizes > 0"):
        BoxKalman((0.0, 0.0, 4.0, 4.0)).restart_size(0.0, 4.0)


BASE = {"name": "t", "flow": {"method": "dis"}}


@pytest.mark.parametrize("section, match", [
    ({"detection": {"bogus": 1}}, r"detection.bogus: unknown key; valid: field, px_scale, min_magnitude_px"),
    ({"detection": {"split_px": -1.0}}, r"detection.split_px: expected a finite number >= 0, got -1.0"),
    ({"detection": {"ground_model": "cubic"}}, r"detection.ground_model: expected affine, quadratic or none"),
    ({"detection": {"field": "total"}}, r"detection.field: expected local or filtered, got 'total'"),
    ({"detection": {"min_explained": 1.5}}, r"detection.min_explained: expected a fraction in \[0, 1\]"),
    ({"detection": {"gsd_m_per_px": 0}}, r"detection.gsd_m_per_px: expected null or a finite number > 0"),
    ({"tracking": {"multi": {"bogus": 1}}}, r"tracking.multi.bogus: unknown key; valid: gate_px"),
    ({"tracking": {"multi": {"min_iou": 0.0}}}, r"tracking.multi.min_iou: expected a number in \(0, 1\], got 0.0"),
    ({"tracking": {"multi": {"death_misses": 0}}}, r"tracking.multi.death_misses: expected an integer >= 1"),
    ({"tracking": {"multi": {"sigma_meas_px": 0.0}}}, r"tracking.multi.sigma_meas_px: expected a finite number > 0"),
])
def test_bad_detection_and_tracker_keys_are_rejected_naming_them(section, match):
    with pytest.raises(PipelineError, match=match):
        Pipeline.from_dict({**BASE, **section})


def test_every_detection_key_is_a_pipeline_key_and_unknown_function_keys_fail():
    d = Pipeline.from_dict(BASE).config["detection"]
    assert {k: d[k] for k in DETECTION_DEFAULTS} == DETECTION_DEFAULTS
    with pytest.raises(ValueError, match=r"detection: unknown key\(s\) \['bogus'\]"):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), bogus=1)
    with pytest.raises(ValueError, match=r"valid: expected \(4, 4\) bool"):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 5), bool))


def test_a_parallax_field_of_registered_frames_is_rejected_and_traffic_across_it_is_not():
    # frames registered before they came: no global motion to compare with, but the crowns of trees all
    # keep the parallax of the translation that was removed, one direction and sense
    rng = np.random.default_rng(5)
    crowns = [(y, y + 25, x, x + 25, (1.5 + 0.2 * k, 0.1)) for k, (y, x) in enumerate([(10, 10), (10, 70), (70, 20),
                                                                                         (75, 110)])]
    cars = [(50, 58, 60, 80, (0.0, 3.0)), (95, 103, 40, 60, (-3.0, 0.0))]
    flow = _field(rng, crowns + cars)
    dets = detect_vehicles(flow, np.ones((H, W), bool))
    assert sorted((round(d.u_px), round(d.v_px)) for d in dets) == [(-3, 0), (0, 3)]
    # off, the crowns are moving regions too
    assert len(detect_vehicles(flow, np.ones((H, W), bool), parallax_min_fraction=0.0)) == 6


def _ground(rng, h=H, w=W):
    """Textured ground: smoothed noise, grey levels about 60..200."""
    return cv2.GaussianBlur(rng.uniform(40, 220, (h, w)).astype(np.float32), (0, 0), 1.2)


def _paint_car(img, x0, y0, length, width, *, roof=150.0, outline=30.0):
    """A car seen from above at integer (x0, y0): a 2 px dark outline around a uniform roof."""
    out = img.copy()
    out[y0:y0 + width, x0:x0 + length] = outline
    out[y0 + 2:y0 + width - 2, x0 + 2:x0 + length - 2] = roof
    return out


def _textured(g, cars):
    """Frames t-1, t, t+1 (``frames``, ``prev_frame``) of ground ``g`` with textured ``roof`` patches at ``(x, y)`` in
    frame t, each moving ``speed`` (integer px) a frame to the right: ``cars`` ``(x, y, speed, roof)``."""
    out = []
    for k in (-1, 0, 1):
        f = g.copy()
        for x, y, speed, roof in cars:
            f[y:y + roof.shape[0], x + speed * k:x + speed * k + roof.shape[1]] = roof
        out.append(f)
    return dict(frames=(out[1], out[2]), prev_frame=out[0])


def test_a_slow_car_with_a_uniform_roof_gets_its_whole_box_not_one_edge():
    # 40 x 16 px, 1.5 px a frame to the right: only its front and rear edges change, the roof between does not
    rng = np.random.default_rng(6)
    g = _ground(rng)
    frames = [_paint_car(g, 60 + 2 * k - 2, 50, 40, 16) for k in range(3)]  # t-1, t, t+1: 2 px a frame
    flow = _field(rng, [(48, 68, 56, 104, (2.0, 0.0))])  # the flow's region: the car and a halo
    valid = np.ones((H, W), bool)
    car = (60, 50, 99, 65)
    (d,) = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=frames[0])
    assert (d.u_px, d.v_px) == pytest.approx((2.0, 0.0), abs=0.3)
    assert box_iou(d, car) >= 0.8, d
    # the front and rear edge parts joined: the largest part alone is about half the car
    (one,) = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=frames[0], box_join=0.0)
    assert box_iou(one, car) < 0.6, one
    # two frames only: the ground the car covers next is taken off, the box still the car within 2 px
    (d2,) = detect_vehicles(flow, valid, frames=(frames[1], frames[2]))
    assert (d2.x0_px, d2.y0_px, d2.x1_px, d2.y1_px) == pytest.approx(car, abs=2)


def _paint_diagonal_car(img, cx, cy, length, width, *, roof=150.0, outline=30.0):
    """A car seen from above driving at 45 degrees, centred at (cx, cy): a 2 px dark outline, a uniform roof."""
    out = img.copy()
    along, across = np.array([1.0, 1.0]) / math.sqrt(2), np.array([-1.0, 1.0]) / math.sqrt(2)
    for ln, wd, grey in ((length, width, outline), (length - 4, width - 4, roof)):
        corners = [np.array([cx, cy]) + a * ln / 2 * along + b * wd / 2 * across for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        cv2.fillConvexPoly(out, np.round(np.array(corners)).astype(np.int32), grey)
    return out


def test_a_diagonal_car_with_a_uniform_roof_gets_its_whole_box_and_a_diagonal_follower_stays_out():
    # 40 x 16 px at 45 degrees, (2, 2) px a frame: its front and rear edges change, the roof between does not, and
    # the axis-aligned box of the two parts holds the ground beside the car: the parts join over their convex hull
    rng = np.random.default_rng(7)
    g = _ground(rng)
    frames = [_paint_diagonal_car(g, 70 + 2 * k - 2, 60 + 2 * k - 2, 40, 16) for k in range(3)]  # t-1, t, t+1
    flow = _field(rng, [(36, 86, 46, 96, (2.0, 2.0))])
    valid = np.ones((H, W), bool)
    ys, xs = np.nonzero(np.abs(frames[1] - g) > 1)
    car = (xs.min(), ys.min(), xs.max(), ys.max())
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], box_reach_px=0)
    (d,) = detect_vehicles(flow, valid, **kw)
    assert box_iou(d, car) >= 0.8, (d, car)
    (one,) = detect_vehicles(flow, valid, box_join=0.0, **kw)   # the largest part alone: the front or the rear
    assert box_iou(one, car) < 0.6, one
    # a follower 15 px behind on the same diagonal: textured ground between them, so it stays out of the box
    frames = [_paint_diagonal_car(_paint_diagonal_car(g, 70 + 2 * k - 2, 60 + 2 * k - 2, 40, 16),
                                  70 + 2 * k - 2 - 32, 60 + 2 * k - 2 - 32, 20, 12) for k in range(3)]
    flow = _field(rng, [(14, 86, 24, 96, (2.0, 2.0))])
    dets = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=frames[0], box_reach_px=0)
    lead = max(dets, key=lambda q: box_iou(q, car))
    assert box_iou(lead, car) >= 0.8, (dets, car)


def test_a_bus_whose_flow_found_its_front_alone_gets_its_whole_box_within_reach_and_no_follower():
    # 56 x 16 px bus with a uniform roof, 1 px a frame to the right: a window flow method reaches the threshold
    # at its front alone (a 20 px region), and the rear edge, 40 px behind that region, is the rest of it
    rng = np.random.default_rng(10)
    g = _ground(rng)
    frames = [_paint_car(g, 40 + k - 1, 50, 56, 16) for k in range(3)]  # t-1, t, t+1
    flow = _field(rng, [(48, 68, 80, 100, (1.0, 0.0))])
    valid = np.ones((H, W), bool)
    bus = (40, 50, 95, 65)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0])
    (front,) = detect_vehicles(flow, valid, box_reach_px=0, **kw)
    assert box_iou(front, bus) < 0.5, front
    (d,) = detect_vehicles(flow, valid, box_reach_px=48, **kw)
    assert box_iou(d, bus) >= 0.8, d
    # too short a reach: the rear edge stays out
    (short,) = detect_vehicles(flow, valid, box_reach_px=20, **kw)
    assert box_iou(short, bus) < 0.5, short
    # a car 12 px behind another at the same speed: textured ground lies between them, so the follower stays
    # out of the leader's box, and a follower in the next lane (not across the motion's path) does too
    for x_rear, y_rear in ((40, 50), (66, 30)):
        frames = [_paint_car(_paint_car(g, x_rear + k - 1, y_rear, 24, 16), 76 + k - 1, 50, 24, 16) for k in range(3)]
        (lead,) = detect_vehicles(flow, valid, box_reach_px=48, frames=(frames[1], frames[2]), prev_frame=frames[0])
        assert lead.x0_px >= 74 and lead.y0_px >= 48, (x_rear, y_rear, lead)


def _paint_at(img, cx, cy, length, width, angle_deg, *, roof=150.0, outline=30.0):
    """A vehicle seen from above centred at (cx, cy), driving at ``angle_deg`` (image axes, y down): a 2 px dark
    outline around a uniform roof, painted with sub-pixel corners."""
    out = img.copy()
    a = math.radians(angle_deg)
    along, across = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    for ln, wd, grey in ((length, width, outline), (length - 4, width - 4, roof)):
        corners = [np.array([cx, cy]) + s * ln / 2 * along + t * wd / 2 * across
                   for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        cv2.fillConvexPoly(out, np.round(np.array(corners) * 16).astype(np.int32), grey, shift=4)
    return out


def _truck_at(img, cx, cy, angle_deg, *, length=72, width=18, cab=20):
    """A truck centred at (cx, cy) driving at ``angle_deg``: a uniform light trailer and, ahead of it, a cab."""
    e = np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))])
    out = _paint_at(img, *(np.array([cx, cy]) - e * (cab + 2) / 2), length - cab - 2, width, angle_deg, roof=200.0)
    return _paint_at(out, *(np.array([cx, cy]) + e * (length - cab) / 2), cab, width - 2, angle_deg, roof=235.0)


@pytest.mark.parametrize("step", [(2, 1), (3, 2), (2, 2)])
def test_a_diagonal_truck_whose_flow_found_its_cab_alone_gets_its_whole_box_with_box_reach_parts(step):
    # a 72 x 18 px truck at 27, 34 and 45 degrees whose flow reached the threshold on its cab alone (the city-wide
    # world's truck 202: its uniform trailer moves along its own sides). The trailer's rear edge lies in the lane
    # within reach, but the hull of the cab's axis-aligned box and that edge sweeps the ground beside the trailer:
    # the box's corners keep the cab alone, the parts' own pixels join the whole truck
    du, dv = step
    angle = math.degrees(math.atan2(dv, du))
    rng = np.random.default_rng(11)
    g = _ground(rng)
    frames = [_truck_at(g, 76 + (k - 1) * du, 60 + (k - 1) * dv, angle) for k in range(3)]  # t-1, t, t+1
    ys, xs = np.nonzero(np.abs(frames[1] - g) > 1)
    truck = (xs.min(), ys.min(), xs.max(), ys.max())
    cx, cy = np.array([76.0, 60.0]) + 26 * np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    flow = _field(rng, [(int(cy) - 13, int(cy) + 13, int(cx) - 13, int(cx) + 13, (float(du), float(dv)))])
    valid = np.ones((H, W), bool)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], box_reach_px=48)
    (cab,) = detect_vehicles(flow, valid, box_reach_parts=False, **kw)
    assert box_iou(cab, truck) < 0.3, (cab, truck)
    (d,) = detect_vehicles(flow, valid, box_reach_parts=True, **kw)
    assert box_iou(d, truck) >= 0.9, (d, truck)
    assert (d.u_px, d.v_px) == pytest.approx((du, dv), abs=0.3)


@pytest.mark.parametrize("gap_px", [10, 16])
def test_with_box_reach_parts_a_diagonal_follower_behind_a_band_of_ground_stays_out(gap_px):
    # two 26 x 14 px cars at 34 degrees, one gap_px behind the other at the same velocity, the flow found on the
    # leader alone: the ground between them is a band of static texture across the lane, so the follower's edges,
    # in the lane and within reach, stay out of the leader's box
    du, dv = 3, 2
    angle = math.degrees(math.atan2(dv, du))
    e = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    rng = np.random.default_rng(12)
    g = _ground(rng)
    lead_c = np.array([90.0, 66.0])
    follow_c = lead_c - e * (26 + gap_px)
    frames = [_paint_at(_paint_at(g, *(follow_c + (k - 1) * np.array([du, dv])), 26, 14, angle),
                        *(lead_c + (k - 1) * np.array([du, dv])), 26, 14, angle) for k in range(3)]
    ys, xs = np.nonzero(np.abs(_paint_at(g, *lead_c, 26, 14, angle) - g) > 1)
    lead = (xs.min(), ys.min(), xs.max(), ys.max())
    flow = _field(rng, [(54, 78, 78, 102, (float(du), float(dv)))])
    dets = detect_vehicles(flow, np.ones((H, W), bool), frames=(frames[1], frames[2]), prev_frame=frames[0],
                           box_reach_px=48, box_reach_parts=True)
    assert max(box_iou(d, lead) for d in dets) >= 0.85, (dets, lead)


@pytest.mark.parametrize("gap_px", [6, 8, 10])
def test_with_box_reach_parts_a_follower_nose_to_tail_over_untextured_asphalt_stays_out(gap_px):
    # two 26 x 14 px cars at 34 degrees, gap_px apart nose to tail at one velocity, on untextured asphalt (the
    # synthetic city: warping it by the motion changes nothing, so it is no static texture), the flow found on the
    # leader alone: without the road test the band between them is no ground and the follower joins the leader's
    # box; with it the asphalt's grey (the ring around the leader's box) makes that band ground, the follower stays out
    # (the asphalt next to the moving edges is marked by the motion, so it must count as ground marked or not)
    du, dv = 3, 2
    angle = math.degrees(math.atan2(dv, du))
    e = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    rng = np.random.default_rng(13)
    g = 90.0 + rng.normal(0.0, 0.4, (H, W)).astype(np.float32)
    lead_c = np.array([90.0, 66.0])
    follow_c = lead_c - e * (26 + gap_px)
    frames = [_paint_at(_paint_at(g, *(follow_c + (k - 1) * np.array([du, dv])), 26, 14, angle),
                        *(lead_c + (k - 1) * np.array([du, dv])), 26, 14, angle) for k in range(3)]
    lead, follow = ((xs.min(), ys.min(), xs.max(), ys.max()) for ys, xs in
                    (np.nonzero(np.abs(_paint_at(g, *c, 26, 14, angle) - g) > 2) for c in (lead_c, follow_c)))
    flow = _field(rng, [(54, 78, 78, 102, (float(du), float(dv)))])
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], box_reach_px=48, box_reach_parts=True)

    def covered(d):  # the share of the follower's box inside the detection's
        w = min(d.x1_px, follow[2]) - max(d.x0_px, follow[0]) + 1
        h = min(d.y1_px, follow[3]) - max(d.y0_px, follow[1]) + 1
        return max(0, w) * max(0, h) / ((follow[2] - follow[0] + 1) * (follow[3] - follow[1] + 1))

    (joined,) = detect_vehicles(flow, np.ones((H, W), bool), box_reach_road_k=0.0, **kw)
    assert covered(joined) > 0.8, (joined, follow)
    (d,) = detect_vehicles(flow, np.ones((H, W), bool), **kw)
    assert covered(d) < 0.25 and box_iou(d, lead) >= 0.7, (d, lead, follow)


def test_static_band_counts_road_coloured_pixels_as_ground_only_with_the_road_mask():
    # a hull 40 px along the motion (+x) and 12 px across, nothing static: a 4 px band of road-coloured asphalt
    # across the lane is ground with the road mask, a uniform roof that is not road-coloured is not
    from algorithms.detection import _road_grey, _static_band

    grey = np.full((30, 60), 200.0)  # a uniform trailer roof
    grey[:, 24:28] = 90.0            # asphalt between two vehicles
    ring = np.full(40, 90.0)
    ring[::2] += 1.0                 # the ground around the box: 90-91
    road_grey, sigma = _road_grey(ring)
    road = np.abs(grey - road_grey) <= 1.0 * sigma
    moved = np.zeros(grey.shape, np.uint8)
    static = np.zeros(grey.shape, bool)
    pts = np.array([[5, 8], [44, 8], [44, 21], [5, 21]])
    assert _static_band(pts, moved, static, 1.0, 0.0) == 0.0
    assert _static_band(pts, moved, static, 1.0, 0.0, road=road) == pytest.approx(1.0)
    grey[:, 24:28] = 200.0
    assert _static_band(pts, moved, static, 1.0, 0.0, road=np.abs(grey - road_grey) <= sigma) == 0.0
    assert _road_grey(ring[:15]) is None


def test_static_band_finds_a_band_of_ground_across_the_lane_not_static_pixels_along_its_sides():
    # a hull 40 px along the motion (+x) and 12 px across: static pixels along both sides (the ground beside a
    # trailer) give no line a majority; a 4 px band of static ground across the lane gives a line of it
    from algorithms.detection import _static_band

    moved = np.zeros((30, 60), np.uint8)
    static = np.zeros(moved.shape, bool)
    pts = np.array([[5, 8], [44, 8], [44, 21], [5, 21]])
    static[8:11, :], static[19:22, :] = True, True  # the sides, 3 px each (eroded to 1 px inside the hull)
    assert _static_band(pts, moved, static, 1.0, 0.0) < 0.5
    static[:, 24:28] = True
    assert _static_band(pts, moved, static, 1.0, 0.0) == pytest.approx(1.0)
    # the same band where the motion marks it (the changed edges of one vehicle) is no ground
    moved[:, 24:28] = 1
    assert _static_band(pts, moved, static, 1.0, 0.0) < 0.5


def test_a_part_ahead_in_the_lane_joins_only_where_the_whole_motion_explains_it_better_than_half():
    # a bus's front part (the box) and, 20 px ahead in its lane over uniform road (nothing static between), a part
    # that is a bus's rear edge when the whole motion explains its change better than half of it does, and a slower
    # vehicle's edge ahead in a queue when half the motion explains it as well (city: a van's box took in the rear
    # of the car creeping ahead of it)
    from algorithms.detection import _join_in_lane

    moved = np.zeros((40, 80), np.uint8)
    moved[10:26, 10:20] = 1   # the box's own part
    moved[10:26, 40:44] = 1   # the part ahead
    static = np.zeros(moved.shape, bool)
    box = (10, 10, 19, 25)
    full = np.ones(moved.shape, bool)
    assert _join_in_lane(moved, static, box, 1.0, 0.0, 0.2, full)[:4] == (10, 10, 43, 25)
    full[:, 40:44] = False
    assert _join_in_lane(moved, static, box, 1.0, 0.0, 0.2, full)[:4] == (10, 10, 19, 25)
    # static texture between keeps them apart whatever the motion says
    static[:, 25:35] = True
    assert _join_in_lane(moved, static, box, 1.0, 0.0, 0.2, np.ones(moved.shape, bool))[:4] == (10, 10, 19, 25)


def test_a_car_faster_than_its_length_whose_flow_broke_in_two_is_one_detection_at_its_motion():
    # 24 x 12 px car moving 30 px a frame; the flow found a third of that on its rear half and all of it on its
    # front half (a flow method that cannot follow such a motion)
    rng = np.random.default_rng(7)
    g = _ground(rng)
    frames = [_paint_car(g, 70 + 30 * k - 30, 60, 24, 12, roof=200.0) for k in range(3)]
    flow = _field(rng, [(58, 74, 68, 82, (10.0, 0.0)), (58, 74, 82, 96, (30.0, 0.0))], blur=0.7)
    valid = np.ones((H, W), bool)
    for prev in (frames[0], None):
        dets = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=prev)
        assert len(dets) == 1, dets
        (d,) = dets
        assert (d.u_px, d.v_px) == pytest.approx((30.0, 0.0), abs=0.5)
        assert box_iou(d, (70, 60, 93, 71)) >= 0.7, (prev is None, d)


def test_the_frames_are_compared_about_the_residual_the_ground_keeps():
    # a shift compensation that left the ground 1.5 px of motion (a rotation, a tilt): the ground fit removes it
    # from the flow, and the frame tests take it as the ground's motion; a car moving 2 px over it is found
    # with its box, and a static textured patch whose flow is the ground's is no detection
    rng = np.random.default_rng(8)
    big = _ground(rng, H + 8, W + 8)
    car_t = _paint_car(big, 60, 50, 30, 14)
    shift = lambda img, dx: cv2.warpAffine(img, np.float32([[1, 0, dx], [0, 1, 0]]), (img.shape[1], img.shape[0]),  # noqa: E731
                                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    g0 = car_t[:H, :W]
    # frame t+1: the ground 1.5 px to the right (sampled at x - 1.5), the car 3.5 px
    g1 = shift(big, -1.5)
    g1 = _paint_car(g1, 60 + 3, 50, 30, 14)[:H, :W]  # 3 px over the ground's 0 (integer painting), 1.5 + 2 ~ 3.5
    flow = _field(rng, [(46, 68, 56, 96, (3.0 - 1.5, 0.0))])
    flow[..., 0] += 1.5  # the local flow carries the ground's residual
    (d,) = detect_vehicles(flow, np.ones((H, W), bool), frames=(g0, g1))
    assert d.u_px == pytest.approx(1.5, abs=0.4)  # relative to the ground
    assert box_iou(d, (60, 50, 89, 63)) >= 0.7, d


def test_a_flow_region_over_texture_that_did_not_move_is_rejected():
    # flow noise: a blob of 1.5 px flow over a patch of ground that is the same in both frames
    rng = np.random.default_rng(9)
    g = _ground(rng)
    noisy = g + rng.normal(0, 2.0, g.shape).astype(np.float32)
    flow = _field(rng, [(40, 60, 60, 80, (1.5, 0.5))])
    assert detect_vehicles(flow, np.ones((H, W), bool), frames=(g, noisy), prev_frame=g) == []
    # the same flow where the patch did move: found
    moved = g.copy()
    moved[40:60, 62:82] = g[40:60, 60:80]
    assert len(detect_vehicles(flow, np.ones((H, W), bool), frames=(g, moved))) == 1
    # where only a 4 x 4 px spot moved inside the flow's 20 x 20 px region (a pole's top, a pedestrian): the
    # region is min_area_px large, the pixels its motion explains (about 46 after the 3 x 3 average) decide
    g0, g1 = g.copy(), g.copy()
    g0[50:54, 68:72], g1[50:54, 70:74] = 255.0, 255.0
    flow = _field(rng, [(40, 60, 60, 80, (2.0, 0.0))])
    (d,) = detect_vehicles(flow, np.ones((H, W), bool), frames=(g0, g1), min_area_px=40)
    assert (d.x0_px, d.y0_px, d.x1_px, d.y1_px) == pytest.approx((68, 50, 71, 53), abs=1)
    assert detect_vehicles(flow, np.ones((H, W), bool), frames=(g0, g1), min_area_px=60) == []


@pytest.mark.parametrize("kwargs, match", [
    ({"box_join": 1.5}, r"box_join: expected a fraction in \[0, 1\], got 1.5"),
    ({"box_reach_join": -0.1}, r"box_reach_join: expected a finite number >= 0, got -0.1"),
    ({"box_reach_px": 2.5}, r"box_reach_px: expected an integer >= 0, got 2.5"),
    ({"box_three_frames": 1}, r"box_three_frames: expected true/false, got 1"),
    ({"box_reach_parts": 1}, r"box_reach_parts: expected true/false, got 1"),
    ({"gap_split_moved": 1}, r"gap_split_moved: expected true/false, got 1"),
    ({"box_reach_road_k": -1.0}, r"box_reach_road_k: expected a finite number >= 0, got -1.0"),
    ({"prev_frame": np.zeros((4, 5), np.float32)}, r"prev_frame: expected a gray frame of shape \(4, 4\)"),
])
def test_bad_box_keys_and_a_misshapen_previous_frame_are_rejected(kwargs, match):
    z = np.zeros((4, 4), np.float32)
    with pytest.raises(ValueError, match=match):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), frames=(z, z), **kwargs)


def _patch_frames(rng, step_px, *, contrast=40.0, noise=3.0, gain=(1.0, 1.0, 1.0), offset=(0.0, 0.0, 0.0)):
    """Frames t-1, t, t+1 of textured ground with a low-contrast textured patch (a tree crown in shade, a dark car)
    whose content moves ``step_px`` to the right a frame, each frame with its own sensor noise; ``gain`` and
    ``offset`` change the patch's contrast and brightness per frame (light)."""
    g = _ground(rng)
    tex = cv2.GaussianBlur(rng.uniform(-1, 1, (H, W)).astype(np.float32), (0, 0), 1.0) * contrast
    out = []
    for k, (a, b) in zip((-1, 0, 1), zip(gain, offset)):
        moved = cv2.warpAffine(tex, np.float32([[1, 0, -step_px * k], [0, 1, 0]]), (W, H),
                               flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
        f = g.copy()
        f[40:70, 50:90] = 100 + b + a * moved[40:70, 50:90]
        out.append(f + rng.normal(0, noise, f.shape).astype(np.float32))
    return out


def test_a_patch_that_changes_at_its_place_as_noise_does_is_rejected_and_a_steady_mover_is_kept():
    valid = np.ones((H, W), bool)
    flow = lambda rng: _field(rng, [(38, 72, 48, 92, (1.5, 0.0))])  # noqa: E731  the flow's claim
    # the crown's content sways 1 px a frame under noise of 3 grey levels: the flow's motion explains part of the
    # change (the tests before pass it), but its box changes at its place by less than 5x what noise does
    for seed in range(3):
        rng = np.random.default_rng(20 + seed)
        f = _patch_frames(rng, 1.0)
        fl = flow(rng)
        assert detect_vehicles(fl, valid, frames=(f[1], f[2]), prev_frame=f[0]) == []
        assert len(detect_vehicles(fl, valid, frames=(f[1], f[2]), prev_frame=f[0], change_noise_k=0.0)) == 1
    # the same patch carried 3 px a frame over three frames (a vehicle): its content leaves its place, kept;
    # also when the light changes its brightness and contrast from frame to frame (NCC leaves that out)
    for gain, offset in (((1.0, 1.0, 1.0), (0.0, 0.0, 0.0)), ((0.8, 1.0, 1.3), (-20.0, 0.0, 25.0))):
        rng = np.random.default_rng(30)
        f = _patch_frames(rng, 3.0, gain=gain, offset=offset)
        fl = _field(rng, [(38, 72, 48, 92, (3.0, 0.0))])
        (d,) = detect_vehicles(fl, valid, frames=(f[1], f[2]), prev_frame=f[0])
        assert d.u_px > 1.5 and 50 <= d.x_px <= 89 and 40 <= d.y_px <= 69, d
        if gain == (1.0, 1.0, 1.0):
            assert box_iou(d, (50, 40, 89, 69)) >= 0.6, d


def test_the_change_noise_alone_gives_a_static_patch_is_what_the_test_expects():
    # sigma_d^2 / (2 var) is the expected 1 - NCC of a static patch under independent noise in both frames
    from algorithms.detection import _changed_at_rest, _difference_variance

    rng = np.random.default_rng(40)
    g = _ground(rng, 240, 320)
    for sigma in (2.0, 6.0):
        a = g + rng.normal(0, sigma, g.shape).astype(np.float32)
        b = g + rng.normal(0, sigma, g.shape).astype(np.float32)
        dv = _difference_variance(a, b)
        assert dv == pytest.approx(2 * sigma**2, rel=0.1)
        c, null = _changed_at_rest(a, b, (100, 80, 159, 119), (0.0, 0.0), dv)
        assert c == pytest.approx(null, rel=0.25)
        # the same patch moved by 3 px decorrelates far beyond it
        moved, _ = _changed_at_rest(a, np.roll(b, 3, axis=1), (100, 80, 159, 119), (0.0, 0.0), dv)
        assert moved > max(4 * null, 0.8)
    # a flat patch (a box on a car's uniform outline) has nothing to tell
    flat = np.full((40, 40), 90.0, np.float32)
    assert _changed_at_rest(flat, flat + rng.normal(0, 2, flat.shape), (5, 5, 30, 30), (0.0, 0.0), 8.0) is None


@pytest.mark.parametrize("kwargs, match", [
    ({"change_noise_k": -1.0}, r"change_noise_k: expected a finite number >= 0, got -1.0"),
    ({"change_noise_k": math.nan}, r"change_noise_k: expected a finite number >= 0, got nan"),
    ({"change_enough": 1.5}, r"change_enough: expected a fraction in \[0, 1\], got 1.5"),
    ({"box_margin_rel": -0.5}, r"box_margin_rel: expected a finite number >= 0, got -0.5"),
])
def test_bad_change_keys_are_rejected_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), **kwargs)
    (key,) = kwargs
    with pytest.raises(PipelineError, match=rf"detection\.{key}: expected a (finite number|fraction)"):
        Pipeline.from_dict({**BASE, "detection": kwargs})


def test_a_fast_car_whose_flow_covers_part_of_it_gets_its_whole_box():
    # 30 x 14 px car with a textured roof (racks, windows), 8 px a frame to the right; the flow (TV-L1, a method
    # that follows part of a fast car) found its motion on its front 16 px only
    rng = np.random.default_rng(11)
    g = _ground(rng)
    roof = cv2.GaussianBlur(rng.uniform(0, 255, (14, 30)).astype(np.float32), (0, 0), 1.0)
    frames = []
    for k in range(3):
        f = g.copy()
        f[50:64, 52 + 8 * k:82 + 8 * k] = roof
        frames.append(f)
    flow = _field(rng, [(50, 64, 74, 90, (8.0, 0.0))], blur=0.7)
    valid = np.ones((H, W), bool)
    car = (60, 50, 89, 63)
    (d,) = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=frames[0])
    assert d.u_px == pytest.approx(8.0, abs=0.5)
    assert box_iou(d, car) >= 0.8, d
    # sought within 4 px of the region alone, the box stops short of the car's rear
    (part,) = detect_vehicles(flow, valid, frames=(frames[1], frames[2]), prev_frame=frames[0], box_margin_rel=0.0)
    assert box_iou(part, car) < 0.7, part


def test_the_size_limit_judges_the_box_from_the_frames_not_the_flow_halo():
    # 20 x 12 px car, 8 px a frame to the right; the flow (Farneback at its default window) spread its motion
    # over a 60 x 44 px halo around it. At 0.2 m/px the halo is 106 m^2, over a max_area_m2 of 80, the car 9.6 m^2
    rng = np.random.default_rng(12)
    g = _ground(rng)
    frames = [_paint_car(g, 62 + 8 * k - 8, 52, 20, 12) for k in range(3)]  # t-1, t, t+1
    flow = _field(rng, [(36, 80, 42, 102, (8.0, 0.0))], blur=0.7)
    valid = np.ones((H, W), bool)
    car = (62, 52, 81, 63)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], gsd_m_per_px=0.2, max_area_m2=80.0)
    (d,) = detect_vehicles(flow, valid, **kw)
    assert d.u_px == pytest.approx(8.0, abs=0.5)
    assert box_iou(d, car) >= 0.7, d
    # the same limit in px judges the box too
    assert len(detect_vehicles(flow, valid, **{**kw, "max_area_px": 2000})) == 1
    # a limit under the car's box rejects it, in m^2 and in px
    assert detect_vehicles(flow, valid, **{**kw, "max_area_m2": 6.0}) == []
    assert detect_vehicles(flow, valid, **{**kw, "max_area_px": 150}) == []
    # without the frames there is no box but the region's: the halo is judged, and is too large
    assert detect_vehicles(flow, valid, gsd_m_per_px=0.2, max_area_m2=80.0) == []


def test_two_cars_one_smoothed_flow_region_joined_are_split_by_box_split_rel():
    # two 20 x 12 px cars with textured roofs 14 px apart in one lane, both 3 px a frame to the right: a smoothing
    # flow (Farneback's window) gave them one region with the ground between them, which is textured
    rng = np.random.default_rng(13)
    g = _ground(rng)
    roofs = [cv2.GaussianBlur(rng.uniform(0, 255, (12, 20)).astype(np.float32), (0, 0), 1.0) for _ in range(2)]

    def scene(cars):
        return _textured(g, [(x, y, 3, roof) for (x, y), roof in zip(cars, roofs)])

    flow = _field(rng, [(44, 72, 32, 102, (3.0, 0.0))], blur=1.5)
    valid = np.ones((H, W), bool)
    rear, front = (40, 52, 59, 63), (74, 52, 93, 63)
    kw = dict(parallax_min_fraction=0.0, **scene([(40, 52), (74, 52)]))  # three movers of one direction: no field
    (one,) = detect_vehicles(flow, valid, **kw)  # the default: the part holding most of the region alone
    assert max(box_iou(one, rear), box_iou(one, front)) >= 0.7, one
    two = detect_vehicles(flow, valid, box_split_rel=0.8, **kw)
    assert len(two) == 2, two
    for car in (rear, front):
        (d,) = [d for d in two if box_iou(d, car) >= 0.7]
        assert (d.u_px, d.v_px) == pytest.approx((3.0, 0.0), abs=0.5)
    # a second part much smaller than the first (a 6 x 6 px thing ahead) is no second vehicle at 0.8
    roofs[1] = roofs[1][:6, :6]
    kw = dict(parallax_min_fraction=0.0, **scene([(40, 52), (78, 55)]))
    assert len(detect_vehicles(flow, valid, box_split_rel=0.8, **kw)) == 1
    with pytest.raises(ValueError, match="box_split_rel"):
        detect_vehicles(flow, valid, box_split_rel=-0.5)


def test_a_second_car_split_off_a_region_gets_one_box_not_its_two_edges():
    # a 20 x 12 px car with a textured roof and, in the next lane, a 36 x 16 px car with a uniform roof, both 3 px a
    # frame to the right and joined by a smoothing flow into one region: the uniform car's front and rear edges change
    # and its roof does not, so the frames mark it as two parts with no static texture between them
    rng = np.random.default_rng(21)
    g = _ground(rng)
    roof = cv2.GaussianBlur(rng.uniform(0, 255, (12, 20)).astype(np.float32), (0, 0), 1.0)
    kw = _textured(g, [(30, 52, 3, roof)])
    prev, (t0, t1) = kw["prev_frame"], kw["frames"]
    prev, t0, t1 = (_paint_car(f, 56 + 3 * k, 70, 36, 16) for f, k in ((prev, -1), (t0, 0), (t1, 1)))
    flow = _field(rng, [(44, 92, 22, 98, (3.0, 0.0))], blur=1.5)
    valid = np.ones((H, W), bool)
    first, second = (30, 52, 49, 63), (56, 70, 91, 85)
    kw = dict(frames=(t0, t1), prev_frame=prev, parallax_min_fraction=0.0)
    (one,) = detect_vehicles(flow, valid, **kw)
    assert box_iou(one, first) >= 0.8, one
    two = detect_vehicles(flow, valid, box_split_rel=0.3, **kw)
    assert len(two) == 2, two
    for car in (first, second):
        (d,) = [d for d in two if box_iou(d, car) >= 0.8]
        assert (d.u_px, d.v_px) == pytest.approx((3.0, 0.0), abs=0.5)


def test_a_region_beyond_max_area_halo_rel_is_rejected_before_its_box():
    # the halo test's car (test_the_size_limit_judges_the_box_from_the_frames_not_the_flow_halo): its 106 m^2
    # region is 1.3 times a max_area_m2 of 80, inside the default 4 and beyond 1.2
    rng = np.random.default_rng(12)
    g = _ground(rng)
    frames = [_paint_car(g, 62 + 8 * k - 8, 52, 20, 12) for k in range(3)]
    flow = _field(rng, [(36, 80, 42, 102, (8.0, 0.0))], blur=0.7)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], gsd_m_per_px=0.2, max_area_m2=80.0)
    valid = np.ones((H, W), bool)
    assert len(detect_vehicles(flow, valid, **kw)) == 1
    assert detect_vehicles(flow, valid, max_area_halo_rel=1.2, **kw) == []
    with pytest.raises(ValueError, match="max_area_halo_rel"):
        detect_vehicles(flow, valid, max_area_halo_rel=0.5)


def test_a_cyclist_whose_flow_halo_passes_the_region_minimum_is_rejected_on_its_box_and_a_car_is_not():
    # at 0.2 m/px: a cyclist of 10 x 5 px (2 x 1 m, 2 m^2 boxed) 4 px a frame to the right, whose motion a smoothing
    # flow spread over a 26 x 20 px halo (about 20 m^2, over min_area_m2), and a 20 x 12 px car (9.6 m^2) beside it
    rng = np.random.default_rng(21)
    g = _ground(rng)
    frames = []
    for k in range(3):  # t-1, t, t+1
        f = _paint_car(g, 40 + 4 * k - 4, 40, 10, 5, roof=90.0)
        frames.append(_paint_car(f, 90 + 4 * k - 4, 80, 20, 12))
    flow = _field(rng, [(32, 52, 32, 58, (4.0, 0.0)), (74, 98, 84, 114, (4.0, 0.0))], blur=1.0)
    valid = np.ones((H, W), bool)
    cyclist, car = (40, 40, 49, 44), (90, 80, 109, 91)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], gsd_m_per_px=0.2, parallax_min_fraction=0.0)
    (d,) = detect_vehicles(flow, valid, **kw)  # the default min_box_m2, 4 m^2
    assert box_iou(d, car) >= 0.7, d
    both = detect_vehicles(flow, valid, min_box_m2=None, **kw)
    assert len(both) == 2 and max(box_iou(x, cyclist) for x in both) >= 0.5, both
    # the car is rejected by a limit over its box alone; without the ground sampling distance there is no limit
    assert detect_vehicles(flow, valid, min_box_m2=10.0, **kw) == []
    assert len(detect_vehicles(flow, valid, **{**kw, "gsd_m_per_px": None})) == 2
    with pytest.raises(ValueError, match="min_box_m2"):
        detect_vehicles(flow, valid, min_box_m2=-1.0)


def test_a_small_box_at_the_image_border_is_a_cut_vehicle_and_not_judged_by_min_box_m2():
    # the cyclist-sized mover of the test above, 6 px from the top edge (within border_px): a car the frame cuts
    # looks the same
    rng = np.random.default_rng(22)
    g = _ground(rng)
    frames = [_paint_car(g, 40 + 4 * k - 4, 6, 10, 5, roof=90.0) for k in range(3)]
    flow = _field(rng, [(3, 19, 32, 58, (4.0, 0.0))], blur=1.0)
    valid = np.ones((H, W), bool)
    kw = dict(frames=(frames[1], frames[2]), prev_frame=frames[0], gsd_m_per_px=0.2, parallax_min_fraction=0.0)
    (d,) = detect_vehicles(flow, valid, **kw)
    assert box_iou(d, (40, 6, 49, 10)) >= 0.5, d
    # 9 px further into the frame it is judged, and rejected
    frames = [_paint_car(g, 40 + 4 * k - 4, 15, 10, 5, roof=90.0) for k in range(3)]
    flow = _field(rng, [(8, 28, 32, 58, (4.0, 0.0))], blur=1.0)
    kw = dict(kw, frames=(frames[1], frames[2]), prev_frame=frames[0])
    assert detect_vehicles(flow, valid, **kw) == []
    assert len(detect_vehicles(flow, valid, min_box_m2=None, **kw)) == 1


def _road(rng, h=H, w=W, grey=120.0):
    """Asphalt: a grey level with a few levels of fine grain."""
    return (grey + cv2.GaussianBlur(rng.normal(0, 4, (h, w)), (0, 0), 1.0)).astype(np.float32)


def _moving(rng, cars, uv, *, road=None):
    """Frames t-1, t, t+1 of ``cars`` ``(x0, y0, length, width, roof)`` all moving ``uv`` (integer px) a frame."""
    g = _road(rng) if road is None else road
    out = []
    for k in range(3):
        f = g
        for x0, y0, length, width, roof in cars:
            f = _paint_car(f, x0 + (k - 1) * uv[0], y0 + (k - 1) * uv[1], length, width, roof=roof)
        out.append(f)
    return dict(frames=(out[1], out[2]), prev_frame=out[0])


def test_two_cars_nose_to_tail_at_one_speed_are_two_boxes_and_a_bus_of_their_length_is_one():
    # a queue moving off: two 30 x 14 px cars 6 px apart in one lane, both 2 px a frame to the right; the flow gave
    # them one region (its window bridged the gap). A bus of the same length (66 px, one uniform roof) beside them
    rng = np.random.default_rng(21)
    flow = _field(rng, [(38, 56, 18, 90, (2.0, 0.0))], blur=1.5)
    valid = np.ones((H, W), bool)
    rear, front = (20, 40, 49, 53), (56, 40, 85, 53)
    kw = dict(parallax_min_fraction=0.0, **_moving(rng, [(20, 40, 30, 14, 190.0), (56, 40, 30, 14, 60.0)], (2, 0)))
    (one,) = detect_vehicles(flow, valid, **kw)  # the default: no cut, one box around both
    assert box_iou(one, (20, 40, 85, 53)) >= 0.8, one
    two = detect_vehicles(flow, valid, gap_split_length_px=16, **kw)
    assert len(two) == 2, two
    for car in (rear, front):
        (d,) = [d for d in two if box_iou(d, car) >= 0.7]
        assert (d.x0_px, d.y0_px, d.x1_px, d.y1_px) == pytest.approx(car, abs=2)
        assert (d.u_px, d.v_px) == pytest.approx((2.0, 0.0), abs=0.5)
    # the bus: no band of road inside it, one box whatever the keys allow
    bus = _moving(rng, [(20, 40, 66, 14, 190.0)], (2, 0))
    (b,) = detect_vehicles(flow, valid, gap_split_length_px=16, gap_split_width_px=6, parallax_min_fraction=0.0, **bus)
    assert box_iou(b, (20, 40, 85, 53)) >= 0.8, b
    # a bus whose roof is the road's grey: its dark outline and ends still cross no band of road from side to side
    bus = _moving(rng, [(20, 40, 66, 14, 120.0)], (2, 0))
    (b,) = detect_vehicles(flow, valid, gap_split_length_px=16, parallax_min_fraction=0.0, **bus)
    assert box_iou(b, (20, 40, 85, 53)) >= 0.8, b
    # parts shorter than the key asks stay one: 40 px each is no car behind another at 16 px a car
    (one,) = detect_vehicles(flow, valid, gap_split_length_px=40, **kw)
    assert box_iou(one, (20, 40, 85, 53)) >= 0.8, one


def _driving_down(g, lefts, *, top=32, length=30, width=14) -> dict:
    """Frames t-1, t, t+1 on the ground ``g`` of vehicles ``width`` px wide (a dark outline, a light roof) whose left
    columns are ``lefts``, ``length`` px long from row ``top`` at frame t, driving 1 px a frame down the image."""
    frames = []
    for k in range(3):
        f = g.copy()
        for x0 in lefts:
            f[top + k - 1:top + length + k - 1, x0:x0 + width] = 30.0
            f[top + 2 + k - 1:top + length - 2 + k - 1, x0 + 2:x0 + width - 2] = 200.0
        frames.append(f)
    return dict(frames=(frames[1], frames[2]), prev_frame=frames[0])


def _one_box_each(detections, cars):
    assert len(detections) == len(cars), detections
    for car in cars:
        (d,) = [d for d in detections if box_iou(d, car) >= 0.7]
        assert (d.x0_px, d.y0_px, d.x1_px, d.y1_px) == pytest.approx(car, abs=2)


def test_two_cars_side_by_side_at_one_speed_are_two_boxes():
    # cars leaving a parking row together: two 30 x 14 px cars 4 px apart across their motion, 1 px a frame down
    # the image (the cars lie along it), one flow region
    rng = np.random.default_rng(22)
    flow = _field(rng, [(30, 72, 48, 86, (0.0, 1.0))], blur=1.5)
    valid = np.ones((H, W), bool)
    kw = dict(parallax_min_fraction=0.0, **_driving_down(_road(rng), (50, 68)))
    (one,) = detect_vehicles(flow, valid, **kw)
    assert box_iou(one, (50, 32, 81, 61)) >= 0.7, one
    _one_box_each(detect_vehicles(flow, valid, gap_split_width_px=8, **kw), [(50, 32, 63, 61), (68, 32, 81, 61)])
    # a box two narrow cars wide is not cut into parts narrower than the key
    assert len(detect_vehicles(flow, valid, gap_split_width_px=16, **kw)) == 1


def test_two_cars_abreast_with_a_marking_between_them_are_cut_where_nothing_moves():
    # the cars of the side-by-side test, but a white marking fills the 4 px between them (a zebra crossing's
    # stripe along their motion): no band of road grey crosses the box, yet the marking does not move with them
    rng = np.random.default_rng(22)
    flow = _field(rng, [(30, 72, 48, 86, (0.0, 1.0))], blur=1.5)
    valid = np.ones((H, W), bool)
    g = _road(rng)
    g[:, 64:68] = 220.0
    kw = dict(parallax_min_fraction=0.0, gap_split_width_px=8)
    (one,) = detect_vehicles(flow, valid, **_driving_down(g, (50, 68)), **kw)  # the road's grey finds no band
    assert box_iou(one, (50, 32, 81, 61)) >= 0.7, one
    _one_box_each(detect_vehicles(flow, valid, gap_split_moved=True, **_driving_down(g, (50, 68)), **kw),
                  [(50, 32, 63, 61), (68, 32, 81, 61)])
    # one vehicle as wide as both, its roof uniform: its moving ends span its width, and it stays whole
    (d,) = detect_vehicles(flow, valid, gap_split_moved=True, **_driving_down(g, (50,), width=32), **kw)
    assert box_iou(d, (50, 32, 81, 61)) >= 0.7, d
    # two blobs as wide as long (a tree's crowns that flicker): no vehicle drives across its length, no cut
    blobs = _driving_down(g, (50, 68), top=40, length=14)
    assert len(detect_vehicles(flow, valid, gap_split_moved=True, **blobs, **kw)) == 1
    # a marking as wide as a narrow car, a band of road on each side of it: the road's grey cuts out three parts, and
    # the marking's, which holds no moving pixel, fails; the band that does not move still parts the two cars
    flow = _field(rng, [(30, 72, 48, 94, (0.0, 1.0))], blur=1.5)
    g = _road(rng)
    g[:, 66:74] = 220.0
    (one,) = detect_vehicles(flow, valid, **_driving_down(g, (50, 76)), **kw)
    assert box_iou(one, (50, 32, 89, 61)) >= 0.7, one
    _one_box_each(detect_vehicles(flow, valid, gap_split_moved=True, **_driving_down(g, (50, 76)), **kw),
                  [(50, 32, 63, 61), (76, 32, 89, 61)])


def test_gap_split_cuts_only_where_a_band_of_road_crosses_the_box():
    from algorithms.detection import _gap_split

    rng = np.random.default_rng(23)
    g = _road(rng)
    # two cars nose to tail along the motion are cut; the cut boxes hold each car
    f = _paint_car(_paint_car(g, 20, 40, 30, 14, roof=200.0), 58, 40, 30, 14, roof=60.0)
    cut = _gap_split(f, (20, 40, 87, 53), 2.0, 0.0, width_px=0, length_px=16)
    assert [q[:4] for q in cut] == [(20, 40, 49, 53), (58, 40, 87, 53)]
    # the same box across the motion (the two cars abreast for a vertical motion) is cut by the width key alone
    assert _gap_split(f, (20, 40, 87, 53), 0.0, 2.0, width_px=0, length_px=16) == []
    assert sorted(q[:4] for q in _gap_split(f, (20, 40, 87, 53), 0.0, 2.0, width_px=16, length_px=0)) == \
        [(20, 40, 49, 53), (58, 40, 87, 53)]
    # a uniform vehicle of the whole length is not cut
    bus = _paint_car(g, 20, 40, 68, 14, roof=200.0)
    assert _gap_split(bus, (20, 40, 87, 53), 2.0, 0.0, width_px=8, length_px=16) == []


@pytest.mark.parametrize("kwargs, match", [
    ({"gap_split_width_px": -1}, r"gap_split_width_px: expected a finite number >= 0, got -1"),
    ({"gap_split_length_px": 2.5}, r"gap_split_length_px: expected an integer >= 0, got 2.5"),
    ({"gap_split_valley": 1.5}, r"gap_split_valley: expected a fraction in \[0, 1\], got 1.5"),
    ({"gap_split_road_k": math.inf}, r"gap_split_road_k: expected a finite number >= 0, got inf"),
])
def test_bad_gap_split_keys_are_rejected_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), **kwargs)
    (key,) = kwargs
    with pytest.raises(PipelineError, match=rf"detection\.{key}"):
        Pipeline.from_dict({**BASE, "detection": kwargs})


def test_a_car_beyond_the_flow_s_reach_gets_its_motion_and_box_from_the_wide_search():
    # 2-3 frames a second: a 30 x 14 px car moves 20-30 px a frame, and the flow (a method that cannot follow it)
    # gave its region a fifth of that, or a third backwards, as on KIT AIS. The refinement within refine_px of that
    # falls short, and the box the frames give with it misses the car
    rng = np.random.default_rng(3)
    car = (40, 50, 69, 63)
    valid = np.ones((H, W), bool)
    for speed, flow_u in ((30, 6.0), (20, -6.0)):
        m = _moving(rng, [(40, 50, 30, 14, 200.0)], (speed, 0))
        flow = _field(rng, [(48, 66, 38, 72, (flow_u, 0.0))], blur=0.7)
        (short,) = detect_vehicles(flow, valid, **m)
        assert short.u_px < speed - 5 and box_iou(short, car) < 0.5, short
        for prev in (m["prev_frame"], None):
            (d,) = detect_vehicles(flow, valid, frames=m["frames"], prev_frame=prev, refine_wide_px=48)
            assert (d.u_px, d.v_px) == pytest.approx((speed, 0.0), abs=0.5)
            assert box_iou(d, car) >= 0.8, (speed, prev is None, d)


def test_the_wide_search_finds_no_mover_in_static_texture_or_a_row_of_parked_cars():
    # flow noise over ground that did not move, and over a row of identical parked cars 36 px apart (the search
    # reaches the next car, one period on, and the one before it as well: no margin over the opposite motion)
    rng = np.random.default_rng(11)
    g = _ground(rng)
    noisy = g + rng.normal(0, 2.0, g.shape).astype(np.float32)
    flow = _field(rng, [(40, 60, 60, 80, (1.5, 0.5))])
    valid = np.ones((H, W), bool)
    assert detect_vehicles(flow, valid, frames=(g, noisy), prev_frame=g, refine_wide_px=48) == []
    row = _road(rng)
    for x0 in range(8, W - 30, 36):
        row = _paint_car(row, x0, 50, 30, 14, roof=190.0)
    noisy = row + rng.normal(0, 2.0, row.shape).astype(np.float32)
    flow = _field(rng, [(48, 66, 42, 76, (3.0, 0.0))], blur=0.7)
    assert detect_vehicles(flow, valid, frames=(row, noisy), prev_frame=row, refine_wide_px=48) == []


def test_a_bad_wide_search_radius_is_rejected_naming_it():
    z = np.zeros((4, 4), np.float32)
    with pytest.raises(ValueError, match=r"refine_wide_px: expected an integer >= 0, got 4.5"):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), frames=(z, z), refine_wide_px=4.5)
    with pytest.raises(PipelineError, match=r"detection.refine_wide_px"):
        Pipeline.from_dict({**BASE, "detection": {"refine_wide_px": -1}})


def test_a_slow_car_close_behind_a_fast_one_is_found_by_leftover_rel_and_a_halo_is_not():
    # a queue: a 24 x 12 px car 3 px a frame to the right and, 4 px behind it in its lane, one at 1 px a frame. The
    # flow's smoothing joins them into one region; its 2-means does not split 1 from 3 px a frame (split_px +
    # split_rel * 3 = 2.8), and core_rel leaves the slow car out as the fast one's halo
    rng = np.random.default_rng(31)
    g = _ground(rng)
    roofs = [cv2.GaussianBlur(rng.uniform(0, 255, (12, 24)).astype(np.float32), (0, 0), 1.0) for _ in range(2)]

    def scene(cars):
        return dict(parallax_min_fraction=0.0, **_textured(g, cars))

    rear, front = (52, 54, 75, 65), (80, 54, 103, 65)
    flow = _field(rng, [(54, 66, 52, 76, (1.0, 0.0)), (54, 66, 80, 104, (3.0, 0.0))], blur=2.0)
    valid = np.ones((H, W), bool)
    kw = scene([(52, 54, 1, roofs[0]), (80, 54, 3, roofs[1])])
    (one,) = detect_vehicles(flow, valid, **kw)  # the default: the fast car alone
    assert box_iou(one, front) >= 0.7, one
    two = detect_vehicles(flow, valid, leftover_rel=0.2, **kw)
    assert len(two) == 2, two
    for car, speed in ((rear, 1.0), (front, 3.0)):
        (d,) = [d for d in two if box_iou(d, car) >= 0.7]
        assert (d.u_px, d.v_px) == pytest.approx((speed, 0.0), abs=0.5)
    # the fast car alone, its motion spread by the flow over the ground behind it at 1 px a frame: that halo moved
    # nothing, and stays no mover
    alone = scene([(80, 54, 3, roofs[1])])
    (d,) = detect_vehicles(flow, valid, leftover_rel=0.2, **alone)
    assert box_iou(d, front) >= 0.7, d
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="leftover_rel"):
            detect_vehicles(flow, valid, leftover_rel=bad)


def test_left_over_keeps_the_parts_in_the_lane_of_the_mover_found():
    from algorithms.detection import _left_over, _Region

    def block(x0, y0, x1, y1):
        ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1]
        return ys.ravel(), xs.ravel()

    # a region: a mover's box (20..43 x 50..61, moving +x), 200 px behind it in its lane, 200 px beside it (no lane)
    parts = [block(20, 50, 43, 61), block(0, 52, 15, 63), block(24, 70, 43, 79)]
    ys, xs = (np.concatenate(a) for a in zip(*parts))
    region = _Region(ys, xs, np.zeros((len(ys), 2), np.float32))
    found = [(20, 50, 43, 61, 3.0, 0.0)]
    (behind,) = _left_over(region, found, 0.1, 50)
    assert (behind.box(), len(behind.ys)) == ((0, 52, 15, 63), 192)
    # the same parts beside a mover that moves along y: now the one at x 24..43 lies in its lane
    (below,) = _left_over(region, [(20, 50, 43, 61, 0.0, 2.0)], 0.1, 50)
    assert below.box() == (24, 70, 43, 79)
    # a part under the fraction of the region, or a region no box overlaps, gives none
    assert _left_over(region, found, 0.5, 50) == []
    assert _left_over(region, [(120, 50, 143, 61, 3.0, 0.0)], 0.1, 50) == []
