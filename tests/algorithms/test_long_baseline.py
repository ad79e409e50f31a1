"""Slow movers over a longer time baseline (algorithms.long_baseline) and its pipeline keys."""

import math
import sys

import cv2
import numpy as np
import pytest

from algorithms.detection import Detection, detect_vehicles, explained_in_box, ground_fit_at
from algorithms.long_baseline import (LONG_BASELINE_DEFAULTS, ParallaxChains, check_long_baseline, compose_models,
                                      long_baseline_detections, merge_detections, register_into, registration_fix)
from algorithms.pipeline import Pipeline, PipelineError
from algorithms.reference import dis
from tests.algorithms.synthetic import box_iou

H, W = 120, 160
CAR = (26, 14)  # length, width px (364 px: above min_box_px)
SPEED_PX = 0.4  # px a frame, to the right: under the one-pair threshold (0.5 px)
X0, Y0 = 60.0, 54.0  # the car's top-left at frame 0


def _ground(rng):
    """Textured ground: smoothed noise, grey levels about 60..200."""
    return cv2.GaussianBlur(rng.uniform(40, 220, (H, W)).astype(np.float32), (0, 0), 1.2)


def _car_layer(rng):
    """A car seen from above at (0, 0) of an (H, W) layer: dark outline, a roof with a few light patches."""
    img = np.zeros((H, W), np.float32)
    alpha = np.zeros((H, W), np.float32)
    length, width = CAR
    img[:width, :length], alpha[:width, :length] = 25.0, 1.0
    img[2:width - 2, 2:length - 2] = 150.0
    for _ in range(4):
        x, y = int(rng.integers(3, length - 6)), int(rng.integers(3, width - 5))
        img[y:y + 2, x:x + 3] = 235.0
    return img, alpha


def _sequence(n, *, speed_px=SPEED_PX, seed=0, at=(X0, Y0)):
    """``n`` gray frames (float32, 0..255) of a still camera over textured ground and one car at ``speed_px``, its
    top-left at ``at`` in frame 0."""
    rng = np.random.default_rng(seed)
    g = _ground(rng)
    car, alpha = _car_layer(rng)
    frames = []
    for t in range(n):
        M = np.float32([[1, 0, at[0] + speed_px * t], [0, 1, at[1]]])
        c = cv2.warpAffine(car, M, (W, H), flags=cv2.INTER_LINEAR)
        a = cv2.warpAffine(alpha, M, (W, H), flags=cv2.INTER_LINEAR)
        frames.append((g * (1 - a) + c).astype(np.float32))
    return frames


def _car_box(t, speed_px=SPEED_PX, at=(X0, Y0)):
    x = at[0] + speed_px * t
    return x, at[1], x + CAR[0] - 1, at[1] + CAR[1] - 1


def _u8(a):
    return np.clip(a, 0, 255).astype(np.uint8)


def test_a_car_at_0_4_px_a_frame_is_found_over_six_frames_and_not_over_one():
    k = 6
    frames = _sequence(k + 2)
    t = k
    valid = np.ones((H, W), bool)
    # one pair: the car's 0.4 px stays under the detector's threshold
    w1, v1 = dis(_u8(frames[t]), _u8(frames[t + 1]))
    assert detect_vehicles(w1, v1 & valid, frames=(frames[t], frames[t + 1])) == []
    # frame t against frame t-k (a still camera: the composed model is the identity)
    C = compose_models([np.eye(3)] * k)
    old, inside = register_into(frames[t - k], C)
    assert inside.all()
    wk, vk = dis(_u8(frames[t]), _u8(old))
    (d,) = long_baseline_detections(wk, vk & inside, baseline_frames=k, frames=(frames[t], old), composed=C)
    assert (d.u_px, d.v_px) == pytest.approx((SPEED_PX, 0.0), abs=0.12)  # the per-frame velocity
    assert box_iou(d, _car_box(t)) >= 0.6, d
    # a box that small is no vehicle: a walking pedestrian over k frames
    assert long_baseline_detections(wk, vk & inside, baseline_frames=k, frames=(frames[t], old), composed=C,
                                    min_box_px=2 * 26 * 14) == []


def test_a_static_textured_scene_gives_nothing_over_the_long_baseline():
    frames = _sequence(7, speed_px=0.0)
    rng = np.random.default_rng(1)
    noisy = [f + rng.normal(0, 2.0, f.shape).astype(np.float32) for f in frames]  # sensor noise, frame by frame
    C = compose_models([np.eye(3)] * 6)
    old, inside = register_into(noisy[0], C)
    wk, vk = dis(_u8(noisy[6]), _u8(old))
    assert long_baseline_detections(wk, vk & inside, baseline_frames=6, frames=(noisy[6], old), composed=C) == []


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_car_creeping_at_0_25_px_a_frame_needs_the_lower_floor_and_static_noise_passes_neither(seed):
    # 1.5 px over six frames, which the flow under-estimates: under the default floor (min_displacement_px 1.5), over
    # dis's 1.0; the long pair's own noise (noise_k times its median residual) still keeps a static noisy scene out
    k, speed = 6, 0.25
    frames = _sequence(k + 2, speed_px=speed, seed=seed)
    C = compose_models([np.eye(3)] * k)
    old, inside = register_into(frames[0], C)
    wk, vk = dis(_u8(frames[k]), _u8(old))
    run = lambda w, v, f, o, md: long_baseline_detections(w, v & inside, baseline_frames=k, frames=(f, o),  # noqa: E731
                                                          composed=C, min_displacement_px=md)
    assert run(wk, vk, frames[k], old, 1.5) == []
    (d,) = run(wk, vk, frames[k], old, 1.0)
    assert (d.u_px, d.v_px) == pytest.approx((speed, 0.0), abs=0.08)
    assert box_iou(d, _car_box(k, speed)) >= 0.8, d
    still = _sequence(k + 1, speed_px=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    noisy = [f + rng.normal(0, 2.0, f.shape).astype(np.float32) for f in still]
    old_n, _ = register_into(noisy[0], C)
    wn, vn = dis(_u8(noisy[k]), _u8(old_n))
    assert run(wn, vn, noisy[k], old_n, 1.0) == []


def test_models_compose_oldest_first_and_registration_undoes_them():
    A = np.array([[1.0, 0, 2.0], [0, 1.0, -1.0], [0, 0, 1.0]])
    B = np.array([[np.cos(0.01), -np.sin(0.01), 0.5], [np.sin(0.01), np.cos(0.01), 0.25], [0, 0, 1.0]])
    np.testing.assert_allclose(compose_models([A, B]), B @ A)
    np.testing.assert_allclose(compose_models([]), np.eye(3))
    # frame t-2 of a ground that moved (3, -2) px in two frames, registered into frame t: the same pixels
    rng = np.random.default_rng(2)
    g = _ground(rng)
    shift = np.eye(3)
    shift[:2, 2] = (1.5, -1.0)
    C = compose_models([shift, shift])
    moved = cv2.warpAffine(g, np.float32([[1, 0, 3.0], [0, 1, -2.0]]), (W, H))  # frame t: content 3 px right, 2 up
    old, inside = register_into(g, C)
    assert not inside[:, :3].any() and not inside[-2:, :].any() and inside[10:-10, 10:-10].all()
    np.testing.assert_allclose(old[10:-10, 10:-10], moved[10:-10, 10:-10], atol=1e-3)
    with pytest.raises(ValueError, match=r"matrices: expected finite \(3, 3\) arrays"):
        compose_models([np.eye(2)])


def _det(x0, y0, x1, y1, u, v, area=None):
    return Detection((x0 + x1) / 2, (y0 + y1) / 2, area or (x1 - x0 + 1) * (y1 - y0 + 1), x0, y0, x1, y1, u, v)


def test_merge_adds_where_nothing_lies_replaces_a_slow_part_and_drops_a_fast_vehicles_trail():
    long_car = _det(100, 50, 123, 61, 0.4, 0.0)
    # nothing there: added
    assert merge_detections([], [long_car], baseline_frames=6) == [long_car]
    # a slow one-pair detection of the car's front edge (a quarter of its box): the long one takes its place
    edge = _det(118, 50, 123, 61, 0.45, 0.0)
    assert merge_detections([edge], [long_car], baseline_frames=6) == [long_car]
    # ... unless replacing is off, or the one-pair detection is the car's whole box
    assert merge_detections([edge], [long_car], baseline_frames=6, replace_rel=0.0) == [edge]
    whole = _det(101, 50, 123, 61, 0.45, 0.0)
    assert merge_detections([whole], [long_car], baseline_frames=6) == [whole]
    # a car at 10 px a frame now at x 200..223: six frames back it was at x 140..163; the long pair's region
    # there is its trail, not a mover
    fast = _det(200, 50, 223, 61, 10.0, 0.0)
    trail = _det(140, 50, 163, 61, 0.3, 0.0)
    assert merge_detections([fast], [trail], baseline_frames=6) == [fast]
    assert len(merge_detections([fast], [trail], baseline_frames=2)) == 2  # two frames back it was elsewhere


def _pipeline(**long_baseline):  # long_baseline {}: the defaults (the stage off)
    return Pipeline.from_dict({
        "name": "slow", "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 4}},
        "jitter": None, "compensation": "shift", "flow": {"method": "dis"}, "threshold": None,
        "spatial": False, "temporal": False,
        "detection": {"long_baseline": long_baseline} if long_baseline else {},
        "tracking": {"point": False, "multi": None}})


def test_the_pipeline_finds_the_slow_car_with_the_long_baseline_and_not_without_it():
    frames = _sequence(10)
    k = 6
    on = [e.detections for e in _pipeline(frames=k).run(frames) if hasattr(e, "detections")]
    off = [e.detections for e in _pipeline().run(frames) if hasattr(e, "detections")]
    assert LONG_BASELINE_DEFAULTS["frames"] == 0 and all(d == [] for d in off)
    found = [t for t, ds in enumerate(on) if any(box_iou(d, _car_box(t)) >= 0.5 for d in ds)]
    assert set(range(k, len(on))) <= set(found), found  # every pair with k frames behind it
    assert all(len(ds) <= 1 for ds in on)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_car_creeping_at_0_1_px_a_frame_is_found_over_the_slow_baseline_alone(seed):
    """slow_frames: 0.6 px over six frames stays under dis's 1.0 px floor; over 18 frames the car moved 1.8 px and is
    found in every pair from the 18th on, once (the six-frame stage finds nothing to join it), and a still scene gives
    nothing over either baseline. Before the 18th the slow baseline runs over the frames there are (from 8): the car
    is found in most pairs once it has moved past the floor over them, never before."""
    speed, k, k2 = 0.1, 6, 18
    frames = _sequence(k2 + 5, speed_px=speed, seed=seed)

    def found(pipeline, seq):
        return [e.detections for e in pipeline.run(seq) if hasattr(e, "detections")]

    six = found(_pipeline(frames=k, min_displacement_px=1.0), frames)
    both = found(_pipeline(frames=k, slow_frames=k2, min_displacement_px=1.0), frames)
    assert all(ds == [] for ds in six)
    hit = {t for t, ds in enumerate(both) if any(box_iou(d, _car_box(t, speed)) >= 0.7 for d in ds)}
    floor = round(1.0 / speed)  # the pair with the car 1.0 px from where it was in frame 0
    assert set(range(k2, len(both))) <= hit <= set(range(floor, len(both))), hit
    assert len(hit & set(range(floor, k2))) >= (k2 - floor) // 2, hit
    assert all(len(ds) <= 1 for ds in both)
    (d,) = both[-1]
    assert (d.u_px, d.v_px) == pytest.approx((speed, 0.0), abs=0.04)  # the per-frame velocity, not the 18-frame one
    rng = np.random.default_rng(seed)
    still = [f + rng.normal(0, 2.0, f.shape).astype(np.float32) for f in _sequence(k2 + 5, speed_px=0.0, seed=seed)]
    assert all(ds == [] for ds in found(_pipeline(frames=k, slow_frames=k2, min_displacement_px=1.0), still))


def _turn(deg):
    """The map of a camera turned by ``deg`` about the image centre, (3, 3): frame-0 points to the turned frame's."""
    return np.vstack([cv2.getRotationMatrix2D(((W - 1) / 2, (H - 1) / 2), deg, 1.0), [0.0, 0.0, 1.0]])


def test_registration_fix_is_the_ground_fit_of_a_turn_and_nothing_within_the_tolerance():
    """The long pair's flow of ground turned by 4 degrees (up to 7 px at the corners) with a car's patch moving
    otherwise: the fix maps each corner where the turn does, within 0.05 px; a turn of 0.5 degree (under 1 px) is
    no fix at 3 px."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    corners = np.array([[0.0, 0.0, 1.0], [W - 1.0, 0.0, 1.0], [0.0, H - 1.0, 1.0], [W - 1.0, H - 1.0, 1.0]])
    valid = np.ones((H, W), bool)
    for deg, expect_fix in ((4.0, True), (0.5, False)):
        T = _turn(deg)
        flow = np.stack([T[0, 0] * xs + T[0, 1] * ys + T[0, 2] - xs, T[1, 0] * xs + T[1, 1] * ys + T[1, 2] - ys], -1)
        flow[50:64, 60:86] = (5.0, -2.0)  # a vehicle
        fix = registration_fix(flow.astype(np.float32), valid, tol_px=3.0)
        assert (fix is not None) == expect_fix, deg
        if expect_fix:
            np.testing.assert_allclose(corners @ fix.T, corners @ T.T, atol=0.05)
    with pytest.raises(ValueError, match=r"tol_px: expected a number > 0, got 0"):
        registration_fix(np.zeros((H, W, 2), np.float32), valid, tol_px=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_slow_car_under_a_turning_camera_is_found_once_the_long_pair_is_registered_again(seed):
    """A camera turning 0.6 degree a frame, under a shift model: over the 18-frame pair the ground near the car moves
    6 px and the corners 16 px. A car creeping at 0.1 px a frame near the left edge is found in three or more of
    the five pairs from the 18th on with the pair registered again (reregister_px, the default 3 px), and nothing
    else; without it the car is found in none of them (only over the shorter slow pairs before, which the turn moved
    less), and the ground the turn moved is taken for movers."""
    speed, k, k2, deg, at = 0.1, 6, 18, 0.6, (30.0, 53.0)
    frames, boxes = [], []
    for t, f in enumerate(_sequence(k2 + 5, speed_px=speed, seed=seed, at=at)):
        T = _turn(deg * t)
        frames.append(cv2.warpAffine(f, T[:2], (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT101))
        x0, y0, x1, y1 = _car_box(t, speed, at=at)
        c = np.array([[x0, y0, 1.0], [x1, y0, 1.0], [x0, y1, 1.0], [x1, y1, 1.0]]) @ T[:2].T
        boxes.append((c[:, 0].min(), c[:, 1].min(), c[:, 0].max(), c[:, 1].max()))

    def found(**keys):  # the pairs that find the car, and the detections elsewhere
        dets = [e.detections for e in _pipeline(frames=k, slow_frames=k2, min_displacement_px=1.0, **keys).run(frames)
                if hasattr(e, "detections")]
        return ({t for t, ds in enumerate(dets) if any(box_iou(d, boxes[t]) >= 0.5 for d in ds)},
                sum(box_iou(d, boxes[t]) < 0.1 for t, ds in enumerate(dets) for d in ds))

    assert LONG_BASELINE_DEFAULTS["reregister_px"] == 3.0
    hits, elsewhere = found()
    assert len(hits & set(range(k2, k2 + 5))) >= 3 and elsewhere == 0
    hits, elsewhere = found(reregister_px=0.0)
    assert not hits & set(range(k2, k2 + 5)) and elsewhere > 0  # the ground that the turn moved, taken for movers


@pytest.mark.parametrize("seed", [0, 1])
def test_the_long_pair_runs_the_flow_with_its_own_parameters(seed, monkeypatch):
    """flow_params: DIS from full resolution on the long pair alone; a 26 x 14 px car at 0.8 px a frame is found in
    every pair from the first long one (pair 2) on, which the medium preset's half-resolution flow misses."""
    monkeypatch.setattr(sys.modules[__name__], "CAR", (26, 14))
    frames = _sequence(12, speed_px=0.8, seed=seed)
    calls = []
    import algorithms.registry as registry

    real = registry.STAGES["flow"]["dis"]

    def recording(f0, f1, **kw):
        calls.append(kw)
        return real(f0, f1, **kw)

    def found(pipeline):
        on = [e.detections for e in pipeline.run(frames) if hasattr(e, "detections")]
        return {t for t, ds in enumerate(on) if any(box_iou(d, _car_box(t, 0.8)) >= 0.5 for d in ds)}

    full = _pipeline(frames=6, flow_params={"finest_scale": 0})
    monkeypatch.setitem(registry.STAGES["flow"], "dis", recording)
    assert set(range(1, 11)) <= found(full)
    assert {"finest_scale": 0} in calls and {} in calls  # the long pair's and the pair's own
    assert 2 not in found(_pipeline(frames=6))


@pytest.mark.parametrize("section, match", [
    ({"flow_params": {"finest_scal": 0}},
     r"detection.long_baseline.flow_params.finest_scal: unknown parameter of dis; valid: preset, finest_scale"),
    ({"flow_params": 3}, r"detection.long_baseline.flow_params: expected a mapping"),
    ({"frames": 1}, r"detection.long_baseline.frames: expected 0 \(off\) or an integer >= 2, got 1"),
    ({"frames": 2.5}, r"detection.long_baseline.frames: expected an integer"),
    ({"max_speed_px": 0}, r"detection.long_baseline.max_speed_px: expected a finite number > 0"),
    ({"min_displacement_px": -1.0}, r"detection.long_baseline.min_displacement_px: expected a finite number > 0"),
    ({"ground_model": "cubic"}, r"detection.long_baseline.ground_model: expected affine, quadratic or none"),
    ({"replace_rel": -0.5}, r"detection.long_baseline.replace_rel: expected a finite number >= 0"),
    ({"min_box_px": 10.5}, r"detection.long_baseline.min_box_px: expected an integer"),
    ({"parallax_max_ratio": -1.0}, r"detection.long_baseline.parallax_max_ratio: expected a finite number >= 0"),
    ({"reregister_px": -1.0}, r"detection.long_baseline.reregister_px: expected a finite number >= 0"),
    ({"parallax_trend": -0.1}, r"detection.long_baseline.parallax_trend: expected a finite number >= 0"),
    ({"parallax_trend_snr": math.inf}, r"detection.long_baseline.parallax_trend_snr: expected a finite number"),
    ({"parallax_trend_frames": 2}, r"detection.long_baseline.parallax_trend_frames: expected an integer >= 3"),
    ({"bogus": 1}, r"detection.long_baseline.bogus: unknown key; valid: frames"),
    ({"frames": 6, "slow_frames": 6}, r"detection.long_baseline.slow_frames: expected 0 \(off\) or an integer over "
                                      r"frames \(6, which must be on\), got 6"),
    ({"slow_frames": 18}, r"slow_frames: expected 0 \(off\) or an integer over frames \(0, which must be on\)"),
    ({"frames": 6, "slow_frames": True}, r"detection.long_baseline.slow_frames: expected an integer"),
])
def test_bad_long_baseline_keys_are_rejected_naming_them(section, match):
    with pytest.raises(PipelineError, match=match):
        _pipeline(**section)


def test_the_defaults_are_the_pipeline_keys_and_the_function_checks_refuse_bad_input():
    assert _pipeline().config["detection"]["long_baseline"] == LONG_BASELINE_DEFAULTS
    assert check_long_baseline({}) == LONG_BASELINE_DEFAULTS
    with pytest.raises(ValueError, match=r"long_baseline: unknown key\(s\) \['bogus'\]"):
        check_long_baseline({"bogus": 1})
    f, v = np.zeros((8, 8, 2), np.float32), np.ones((8, 8), bool)
    fr = (np.zeros((8, 8), np.float32),) * 2
    with pytest.raises(ValueError, match=r"baseline_frames: expected an integer >= 1, got 0"):
        long_baseline_detections(f, v, baseline_frames=0, frames=fr, composed=np.eye(3))
    with pytest.raises(ValueError, match=r"composed: expected a finite \(3, 3\) matrix"):
        long_baseline_detections(f, v, baseline_frames=2, frames=fr, composed=np.eye(2))
    with pytest.raises(ValueError, match=r"flow: expected \(H, W, 2\)"):
        long_baseline_detections(f[..., 0], v, baseline_frames=2, frames=fr, composed=np.eye(3))


def test_the_inside_mask_leaves_a_margin_at_the_edge_frame_t_k_covers_and_not_at_the_image_border():
    g = np.zeros((H, W), np.float32)
    shift = np.eye(3)
    shift[0, 2] = 5.0  # the ground moved 5 px right: frame t's first 5 columns were outside frame t-k
    _, inside = register_into(g, shift, margin_px=3)
    assert not inside[:, :8].any() and inside[:, 8:].all()  # 5 px uncovered + 3 px margin; other edges kept
    _, plain = register_into(g, shift)
    assert not plain[:, :5].any() and plain[:, 5:].all()
    with pytest.raises(ValueError, match=r"margin_px: expected an integer >= 0, got -1"):
        register_into(g, shift, margin_px=-1)


def test_a_long_baseline_region_where_the_pair_flow_is_fast_is_no_slow_mover():
    k = 6
    frames = _sequence(k + 2)
    t = k
    C = compose_models([np.eye(3)] * k)
    old, inside = register_into(frames[t - k], C)
    wk, vk = dis(_u8(frames[t]), _u8(old))
    kw = dict(baseline_frames=k, frames=(frames[t], old), composed=C)
    still = np.zeros((H, W, 2), np.float32)
    assert len(long_baseline_detections(wk, vk & inside, pair_flow=still, **kw)) == 1
    # the pair's flow says the same place moves 8 px a frame: a fast vehicle the long pair lost
    fast = still.copy()
    fast[50:70, 55:90] = (8.0, 0.0)
    assert long_baseline_detections(wk, vk & inside, pair_flow=fast, **kw) == []
    with pytest.raises(ValueError, match=r"pair_flow, pair_valid: expected"):
        long_baseline_detections(wk, vk & inside, pair_flow=still[:10], **kw)


def _flight(n, *, camera_px=1.0, gamma=0.5, car_px=(0.4, 0.0), car_accel_px=0.0, seam_deg=30.0, seed=3):
    """``n`` gray frames (float32) of a camera flying ``camera_px`` a frame (the ground moves down the image) over
    textured ground, a car driving ``car_px`` a frame over it (speeding up by ``car_accel_px`` a frame each frame
    down the image), and a building's roof whose parallax is ``gamma``
    times the ground's motion (``gamma = h / (Z - h)``: 0.5 is a building a third of the flight height), light
    grey with dark seams every 6 px at ``seam_deg`` from the x axis (one-dimensional texture, as roofs have).
    Returns the frames, the car's box at each frame ``(x0, y0, x1, y1)`` and the roof's."""
    h, w = 160, 220
    rng = np.random.default_rng(seed)
    pad = 40 + int(math.ceil(n * camera_px * (1 + gamma)))
    ground = cv2.GaussianBlur(rng.uniform(40, 220, (h + 2 * pad, w + 2 * pad)).astype(np.float32), (0, 0), 1.2)
    yy, xx = np.mgrid[0:34, 0:44]
    a = math.radians(seam_deg)
    roof = np.where(np.mod(-math.sin(a) * xx + math.cos(a) * yy, 6.0) < 1.2, 90.0, 170.0).astype(np.float32)
    roof[:2], roof[-2:], roof[:, :2], roof[:, -2:] = 60.0, 60.0, 60.0, 60.0
    rng_car = np.random.default_rng(0)
    _ground(rng_car)
    car, alpha = _car_layer(rng_car)  # the car of _sequence
    car, alpha = car[:CAR[1], :CAR[0]], alpha[:CAR[1], :CAR[0]]
    frames, car_boxes, roof_boxes = [], [], []
    for t in range(n):
        dy = camera_px * t
        img = cv2.warpAffine(ground, np.float32([[1, 0, -pad], [0, 1, -pad + dy]]), (w, h), flags=cv2.INTER_LINEAR)
        for layer, mask, x, y, boxes in (
                (roof, np.ones_like(roof), 150.0, 30.0 + (1 + gamma) * dy, roof_boxes),
                (car, alpha, 30.0 + car_px[0] * t, 80.0 + dy + car_px[1] * t + 0.5 * car_accel_px * t * t,
                 car_boxes)):
            M = np.float32([[1, 0, x], [0, 1, y]])
            lay = cv2.warpAffine(layer, M, (w, h), flags=cv2.INTER_LINEAR)
            al = cv2.warpAffine(mask, M, (w, h), flags=cv2.INTER_LINEAR)
            img = img * (1 - al) + lay
            boxes.append((x, y, x + layer.shape[1] - 1, y + layer.shape[0] - 1))
        frames.append(img.astype(np.float32))
    return frames, car_boxes, roof_boxes


def _long_pair(frames, t, k, camera_px):
    shift = np.eye(3)
    shift[1, 2] = camera_px  # every pair's model: the ground moved camera_px down the image
    C = compose_models([shift] * k)
    old, inside = register_into(frames[t - k], C, margin_px=8)
    wk, vk = dis(_u8(frames[t]), _u8(old))
    return dict(flow=wk, valid=vk & inside, baseline_frames=k, frames=(frames[t], old), composed=C)


@pytest.mark.parametrize("seam_deg", [0.0, 30.0, 90.0])
def test_a_roofs_parallax_is_no_slow_mover_and_a_creeping_car_beside_it_is(seam_deg):
    k = 6
    frames, cars, roofs = _flight(k + 1, seam_deg=seam_deg)
    pair = _long_pair(frames, k, k, 1.0)
    flow, valid = pair.pop("flow"), pair.pop("valid")
    # without the parallax test the roof, 0.5 px a frame along the flight, is a slow mover too (the detector's own
    # parallax test stops at a quarter of the ground's motion)
    off = long_baseline_detections(flow, valid, parallax_max_ratio=0.0, **pair)
    assert any(box_iou(d, roofs[k]) >= 0.5 for d in off), off
    (d,) = long_baseline_detections(flow, valid, **pair)
    assert box_iou(d, cars[k]) >= 0.5, d
    assert (d.u_px, d.v_px) == pytest.approx((0.4, 0.0), abs=0.12)


def test_a_car_creeping_along_the_flight_slower_than_a_building_is_given_up_and_a_faster_one_kept():
    # from frames t and t-k a car moving with the camera's motion, in its sense, at gamma times it is a roof's
    # parallax: parallax_max_ratio says how tall a building the test covers, and what it gives up
    k = 6
    for car_px, found in (((0.0, 0.6), False), ((0.0, -0.6), True)):
        frames, cars, _ = _flight(k + 1, car_px=car_px, gamma=0.0)
        pair = _long_pair(frames, k, k, 1.0)
        flow, valid = pair.pop("flow"), pair.pop("valid")
        dets = long_baseline_detections(flow, valid, **pair)
        assert any(box_iou(d, cars[k]) >= 0.5 for d in dets) == found, (car_px, dets)
        # either is found without the test
        dets = long_baseline_detections(flow, valid, parallax_max_ratio=0.0, **pair)
        assert any(box_iou(d, cars[k]) >= 0.5 for d in dets), (car_px, dets)


def test_a_car_speeding_up_along_the_flight_is_kept_once_its_ratio_changes_and_the_roof_never_is():
    # 0.25 -> 0.55 px a frame along the flight, in its sense: at every frame the long pair alone takes it for a roof
    # (its ratio to the camera's motion under parallax_max_ratio); over the frames its ratio changes, the roof's
    # (gamma 0.5) does not
    k, n = 6, 30
    frames, cars, roofs = _flight(n, car_px=(0.0, 0.25), car_accel_px=0.01)
    chains = ParallaxChains(min_change=0.1, min_frames=8, snr=5.0)
    with_chains, without = [], []
    for t in range(k, n):
        pair = _long_pair(frames, t, k, 1.0)
        flow, valid = pair.pop("flow"), pair.pop("valid")
        without.append(long_baseline_detections(flow, valid, **pair))
        with_chains.append(long_baseline_detections(flow, valid, parallax_chains=chains, frame=t, **pair))
    car_found = [any(box_iou(d, cars[t]) >= 0.5 for d in dets) for t, dets in zip(range(k, n), with_chains)]
    assert not any(any(box_iou(d, cars[t]) >= 0.5 for d in dets) for t, dets in zip(range(k, n), without))
    # released once its chain holds min_frames and its ratio changed by 0.1 (0.01 a frame: about frame 16, ten
    # after the first long pair), and kept from then on
    first = car_found.index(True) + k
    assert 15 <= first <= 21, car_found
    assert all(car_found[first - k:]), car_found
    assert not any(box_iou(d, roofs[t]) >= 0.3 for t, dets in zip(range(k, n), with_chains) for d in dets)


def test_the_pipeline_with_parallax_trend_finds_the_speeding_car_and_adds_nothing_on_the_roof():
    from algorithms.pipeline import PairEstimate

    n = 30
    frames, cars, roofs = _flight(n, car_px=(0.0, 0.25), car_accel_px=0.01)

    def frames_on(pipeline):
        car, roof = set(), set()
        for e in pipeline.run(frames):
            if isinstance(e, PairEstimate):
                car |= {e.index} if any(box_iou(d, cars[e.index]) >= 0.5 for d in e.detections) else set()
                roof |= {e.index} if any(box_iou(d, roofs[e.index]) >= 0.3 for d in e.detections) else set()
        return car, roof

    car_off, roof_off = frames_on(_pipeline(frames=6))
    car_on, roof_on = frames_on(_pipeline(frames=6, parallax_trend=0.1))
    # off: the pair detector finds it in a frame or two once it passes 0.5 px a frame; on: from its chain's release
    assert len(car_off) <= 3 and car_off <= car_on, (car_off, car_on)
    assert len(car_on - car_off) >= 6 and min(car_on - car_off) >= 15, (car_off, car_on)
    # the roof (gamma 0.5) is the pair detector's business (over its bound 0.25); the chains add no frame of it
    assert roof_on == roof_off


def _rejected(x, y, gamma, g=(0.0, -6.0), size=(20, 12)):
    """A detection at ``(x, y)`` whose motion over the pair is ``gamma`` times the pair's global motion ``g``."""
    return Detection(x + size[0] / 2, y + size[1] / 2, size[0] * size[1], x, y, x + size[0] - 1, y + size[1] - 1,
                     gamma * g[0], gamma * g[1], math.nan)


@pytest.mark.parametrize("gammas, released_at", [
    ([0.3] * 30, None),  # a roof: its ratio stays
    ([0.3 + 0.004 * (i % 3 - 1) for i in range(30)], None),  # a roof, the flow's noise about its ratio
    ([0.1 + 0.015 * i for i in range(30)], 7),  # a car speeding up: 0.1 along the chain from its 8th detection
    ([0.5 - 0.012 * i for i in range(30)], 9),  # one slowing down: 0.1 along it at its 10th (0.108)
    ([0.1 + 0.004 * i + 0.08 * (i % 2) for i in range(30)], None),  # 0.12 along it, under 5 times its scatter 0.04
])
def test_a_chain_is_released_when_its_ratio_changes_beyond_its_scatter_and_stays_released(gammas, released_at):
    g, k = np.array([0.0, -6.0]), 6  # the pair's global motion: the ground 1 px a frame down the image
    chains = ParallaxChains(min_change=0.1, min_frames=8, snr=5.0)
    out = []
    for i, gamma in enumerate(gammas):
        chains.begin(i, g, k)
        # the point moves (1 + gamma) px a frame down the image
        y = 20.0 + sum(1.0 + a for a in gammas[:i])
        out.append(chains.exempt(_rejected(40.0, y, gamma, g)))
    assert out == [released_at is not None and i >= released_at for i in range(len(gammas))]


def test_chains_link_across_a_short_gap_only_and_one_detection_is_added_once_a_frame():
    g, k = np.array([0.0, -6.0]), 6
    rising = [0.1 + 0.02 * i for i in range(12)]

    def run(skip):
        chains = ParallaxChains(min_change=0.1, min_frames=8, snr=5.0)
        said = False
        for i, gamma in enumerate(rising):
            chains.begin(i, g, k)
            if i in skip:
                continue
            d = _rejected(40.0, 20.0 + sum(1.0 + a for a in rising[:i]), gamma, g)
            said = chains.exempt(d)
            assert chains.exempt(d) == said  # judged by both tests: one point of the chain
        return said

    assert run(skip=set()) is True
    assert run(skip={4, 5}) is True  # two frames missed: still one chain (10 points, 0.22 along it)
    assert run(skip={3, 4, 5}) is False  # three: two chains, the second too short
    chains = ParallaxChains(min_change=0.1)
    chains.begin(3, g, k)
    with pytest.raises(ValueError, match=r"frame: expected frames in order, got 3 after 3"):
        chains.begin(3, g, k)
    with pytest.raises(ValueError, match=r"parallax_trend_frames: expected an integer >= 3"):
        ParallaxChains(min_change=0.1, min_frames=2)
    f, v = np.zeros((8, 8, 2), np.float32), np.ones((8, 8), bool)
    with pytest.raises(ValueError, match=r"frame: expected the index of frame t with parallax_chains"):
        long_baseline_detections(f, v, baseline_frames=2, frames=(np.zeros((8, 8), np.float32),) * 2,
                                 composed=np.eye(3), parallax_chains=ParallaxChains(min_change=0.1))


def test_explained_in_box_tells_the_true_motion_from_others_and_the_ground_fit_is_read_where_asked():
    rng = np.random.default_rng(5)
    a = _ground(rng)
    # frame t's content at x is the other frame's at x + (2, 1): that motion explains the change, its opposite not
    b = cv2.warpAffine(a, np.float32([[1, 0, 2.0], [0, 1, 1.0]]), (W, H), flags=cv2.INTER_LINEAR)
    e = explained_in_box((a, b), (40, 30, 100, 80), [(2.0, 1.0), (-2.0, -1.0), (0.0, 0.0)])
    assert e[0] > 0.9 and e[1] < 0.2 and e[2] == pytest.approx(0.0)
    # the ground's motion taken out first: the rest of (2, 1) is (1, 0)
    assert explained_in_box((a, b), (40, 30, 100, 80), [(1.0, 0.0)], ground_px=(1.0, 1.0))[0] > 0.9
    with pytest.raises(ValueError, match=r"box: expected \(x0, y0, x1, y1\) overlapping the 160 x 120 frame"):
        explained_in_box((a, b), (200, 10, 220, 20), [(0.0, 0.0)])
    # an affine ground flow is read back at the points asked, an outlier region (a vehicle) left out of the fit
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    flow = np.dstack([0.5 + 0.01 * xs, -0.3 + 0.02 * ys])
    flow[50:60, 70:90] = (6.0, 0.0)
    pts = [(10.0, 20.0), (150.0, 100.0), (80.0, 55.0)]
    fit = ground_fit_at(flow, np.ones((H, W), bool), pts)
    np.testing.assert_allclose(fit, [(0.5 + 0.01 * x, -0.3 + 0.02 * y) for x, y in pts], atol=0.02)


def test_the_mid_frame_must_show_the_creep_too():
    # frames 0..3: the car creeps 0.8 px a frame; 3..6: it stands. Over frames 0 -> 6 it moved 2.4 px (0.4 px a
    # frame), but from frame 3 to frame 6 its place did not change: what the long pair sees happened before
    k, t, m = 6, 6, 3
    rng = np.random.default_rng(0)
    g = _ground(rng)
    car, alpha = _car_layer(rng)

    def at(x):
        M = np.float32([[1, 0, x], [0, 1, Y0]])
        a = cv2.warpAffine(alpha, M, (W, H), flags=cv2.INTER_LINEAR)
        return (g * (1 - a) + cv2.warpAffine(car, M, (W, H), flags=cv2.INTER_LINEAR)).astype(np.float32)

    stopped = [at(X0 + 0.8 * min(s, 3)) for s in range(k + 1)]
    creeping = _sequence(k + 1)
    for frames, kept in ((creeping, True), (stopped, False)):
        C = compose_models([np.eye(3)] * k)
        old, inside = register_into(frames[t - k], C)
        mid, _ = register_into(frames[t - m], compose_models([np.eye(3)] * m))
        wk, vk = dis(_u8(frames[t]), _u8(old))
        kw = dict(baseline_frames=k, frames=(frames[t], old), composed=C)
        assert len(long_baseline_detections(wk, vk & inside, **kw)) == 1  # the long pair alone finds either
        found = long_baseline_detections(wk, vk & inside, mid_frame=(mid, m), **kw)
        assert len(found) == int(kept), found
    with pytest.raises(ValueError, match=r"mid_frame: expected \(frame, m\) with 0 < m < 6, got m = 6"):
        long_baseline_detections(wk, vk & inside, mid_frame=(mid, 6), **kw)
    with pytest.raises(PipelineError, match=r"detection.long_baseline.mid_check: expected"):
        _pipeline(mid_check="yes")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_dis_pipelines_long_pair_follows_a_small_cars_six_frame_motion(seed):
    """The built-in dis runs its long pair with DIS from full resolution: a 24 x 12 px car's motion over six frames at
    0.8 px a frame, (4.8, 1.2) px, within 0.3 px; its pair flow's parameters (half resolution) give under 65 % of it."""
    from algorithms.pipeline import PIPELINES
    from tests.algorithms.test_reference import _small_car_pair

    cfg = PIPELINES["dis"]
    assert cfg["flow"]["method"] == "dis"
    f0, f1, inner = _small_car_pair(seed, (4.8, 1.2))
    long_params = {**cfg["flow"]["params"], **cfg["detection"]["long_baseline"]["flow_params"]}
    np.testing.assert_allclose(np.median(dis(f0, f1, **long_params)[0][inner].reshape(-1, 2), axis=0), [4.8, 1.2],
                               atol=0.3)
    assert np.median(dis(f0, f1, **cfg["flow"]["params"])[0][inner][..., 0]) < 0.65 * 4.8


def test_the_dis_pipeline_takes_the_long_box_over_a_slow_pair_box_of_part_of_the_car():
    """dis's pair flow (half resolution) boxes a small slow car in part: a pair box of 15 of the car's 24 px (0.63 of
    the long pair's box) gives way to the long one under dis's replace_rel (0.8), not under the default 0.5."""
    from algorithms.pipeline import PIPELINES

    rr = PIPELINES["dis"]["detection"]["long_baseline"]["replace_rel"]
    long_car = _det(100, 50, 123, 62, 0.9, 0.2)
    part = _det(109, 50, 123, 62, 1.0, 0.2)
    assert merge_detections([part], [long_car], baseline_frames=6, replace_rel=rr) == [long_car]
    assert merge_detections([part], [long_car], baseline_frames=6,
                            replace_rel=LONG_BASELINE_DEFAULTS["replace_rel"]) == [part]
