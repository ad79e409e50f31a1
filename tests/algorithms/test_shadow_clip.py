"""One sun over a clip: the clip-level cast-shadow vote (algorithms.detection.shadow_lean, clip_shadow_direction,
trim_toward, image_yaw_rad, turn; the pipeline's detection.shadow_scope clip)."""

import math

import numpy as np
import pytest

from algorithms.detection import (Detection, clip_shadow_direction, detect_vehicles, image_yaw_rad, shadow_lean,
                                  trim_cast_shadows, trim_toward, turn)
from algorithms.pipeline import Pipeline, PipelineError

H, W = 160, 220
# bodies (x0, y0, x1, y1), inclusive, 24 x 12 px, cars lying along x, apart enough for their rings of ground
BODIES = [(20, 20, 43, 31), (90, 24, 113, 35), (150, 18, 173, 29), (30, 90, 53, 101), (110, 100, 133, 111)]
MOTIONS = [(1.5, 0.2), (-2.0, 0.0), (0.1, 1.0), (0.0, -1.2), (-1.0, 0.3)]  # px/frame: both ways, both axes
SHADOW_PX = 5


def _frame(seed, *, shadow=None, bodies=BODIES, paint=190.0, side_face=0, fronts=None):
    """Textured ground, light cars (dark windscreen and rear window), each with its cast shadow (the body shifted
    by ``shadow`` (dx, dy) px, the ground darkened to half) or none; ``side_face`` rows along each body's top painted dark (a
    tall vehicle's side in its own shade: part of the body); with ``fronts`` (per car +1 or -1, the way it drives
    along x) a wide dark windscreen at its front instead of both windows. Returns the frame and the boxes."""
    rng = np.random.default_rng(seed)
    g = 100.0 + rng.normal(0.0, 4.0, size=(H, W))
    boxes = []
    for x0, y0, x1, y1 in bodies:
        dx, dy = shadow if shadow is not None else (0, 0)
        if shadow is not None:
            g[y0 + dy:y1 + dy + 1, x0 + dx:x1 + dx + 1] *= 0.5
        g[y0:y1 + 1, x0:x1 + 1] = paint + rng.normal(0.0, 3.0, size=(y1 - y0 + 1, x1 - x0 + 1))
        if fronts is None:
            g[y0 + 2:y1 - 1, x0 + 4:x0 + 7] = 40.0  # windscreen
            g[y0 + 2:y1 - 1, x1 - 5:x1 - 3] = 45.0  # rear window
        elif fronts[len(boxes)] > 0:
            g[y0 + 1:y1, x1 - 7:x1 - 1] = 35.0
        else:
            g[y0 + 1:y1, x0 + 2:x0 + 8] = 35.0
        if side_face:
            g[y0:y0 + side_face, x0:x1 + 1] = 35.0
        boxes.append((min(x0, x0 + dx), min(y0, y0 + dy), max(x1, x1 + dx), max(y1, y1 + dy)))
    return g.astype(np.float32), boxes


def _dets(boxes, motions=MOTIONS):
    return [Detection((x0 + x1) / 2, (y0 + y1) / 2, 100, float(x0), float(y0), float(x1), float(y1), u, v)
            for (x0, y0, x1, y1), (u, v) in zip(boxes, motions)]


def _votes(frames_dets):
    """The leans and motions of several frames' detections, stacked (no camera turn)."""
    leans, motions = [], []
    for g, dets in frames_dets:
        leans.append(shadow_lean(g, dets)[1])
        motions.append([(d.u_px, d.v_px) for d in dets])
    return np.concatenate(leans), np.concatenate(motions).astype(float)


@pytest.mark.parametrize("shadow", [(-SHADOW_PX, 1), (SHADOW_PX, -1), (1, SHADOW_PX), (-1, -SHADOW_PX)])
def test_the_clip_recovers_the_suns_side_and_boxes_end_at_the_body(shadow):
    clip = [(g, _dets(b)) for g, b in (_frame(s, shadow=shadow) for s in range(6))]
    direction = clip_shadow_direction(*_votes(clip), min_votes=15)
    dx, dy = shadow
    axis = 0 if abs(dx) == SHADOW_PX else 1
    # the shadow's axis and sense; on the axis it reaches out 1 px along, its sense or nothing, and less
    assert np.sign(direction[axis]) == np.sign(shadow[axis]) and abs(direction[axis]) >= 0.1
    assert direction[1 - axis] * shadow[1 - axis] >= 0 and abs(direction[1 - axis]) < abs(direction[axis])
    side = (0 if dx < 0 else 2) if axis == 0 else (1 if dy < 0 else 3)
    g, dets = clip[0]
    bands, _ = shadow_lean(g, dets)
    for d, body, box in zip(trim_toward(dets, bands, direction), BODIES, _frame(0, shadow=shadow)[1]):
        got = np.array([d.x0_px, d.y0_px, d.x1_px, d.y1_px])
        assert abs(got[side] - body[side]) <= 1, (shadow, got, body)
        assert got[(side + 2) % 4] == box[(side + 2) % 4]
        assert (d.x_px, d.y_px) == ((got[0] + got[2]) / 2, (got[1] + got[3]) / 2)


def test_an_overcast_clip_casts_no_shadow_and_no_box_is_trimmed():
    for paint in (190.0, 48.0):  # light cars; dark cars, as dark as a shadow
        clip = [(g, _dets(b)) for g, b in (_frame(s, paint=paint) for s in range(6))]
        direction = clip_shadow_direction(*_votes(clip), min_votes=15)
        assert not direction.any()
        g, dets = clip[0]
        assert trim_toward(dets, shadow_lean(g, dets)[0], direction) == dets


def test_too_few_votes_decide_nothing():
    clip = [(g, _dets(b)) for g, b in (_frame(s, shadow=(-SHADOW_PX, 0)) for s in range(6))]
    lean, motion = _votes(clip)  # along x: 18 votes of cars driving right or across, 24 left or across
    assert clip_shadow_direction(lean, motion, min_votes=19)[0] == 0
    assert clip_shadow_direction(lean, motion, min_votes=18)[0] < -0.1


def test_a_frame_the_per_frame_vote_gets_wrong_is_outvoted_by_the_clip():
    # eight frames of cars with their shadows on the left; then a frame of three tall vehicles whose shaded side
    # face (4 dark rows along the top of each body, inside the truth box) and shadows on the left: the frame alone
    # votes top a shadow side and cuts into the bodies; the clip's 43 votes hold too little top lean
    clip = [(g, _dets(b)) for g, b in (_frame(s, shadow=(-SHADOW_PX, 0)) for s in range(8))]
    tall = BODIES[:3]
    g, boxes = _frame(9, shadow=(-SHADOW_PX, 0), bodies=tall, side_face=4)
    dets = _dets(boxes, [(2.0, 0.0), (-2.0, 0.0), (1.5, 0.1)])
    frame_vote = trim_cast_shadows(g, dets)
    assert any(d.y0_px > body[1] + 1 for d, body in zip(frame_vote, tall))  # the frame alone: into the bodies
    direction = clip_shadow_direction(*_votes(clip + [(g, dets)]), min_votes=20)
    assert direction[0] < -0.1 and direction[1] == 0
    for d, body in zip(trim_toward(dets, shadow_lean(g, dets)[0], direction), tall):
        assert d.y0_px == body[1] and abs(d.x0_px - body[0]) <= 1, (d, body)


def test_dark_fronts_lean_with_the_traffic_and_the_shadow_is_what_both_ways_share():
    # wide dark windscreens at each car's front lean its box the way it drives, more than its 3 px shadow on the left
    # leans it: the frame's rule (both ways past the vote) sees no shadow; the clip's mean of both ways does
    motions = [(2.0, 0.0), (-2.0, 0.0), (2.0, 0.1), (-1.5, 0.0), (1.8, 0.0)]
    fronts = [1, -1, 1, -1, 1]
    clip = [(g, _dets(b, motions)) for g, b in (_frame(s, shadow=(-3, 0), fronts=fronts) for s in range(8))]
    lean, motion = _votes(clip)
    right = lean[motion[:, 0] > 0, 0].mean()
    assert right > 0.1  # the cars driving right lean right: their fronts outweigh the shadow
    g, dets = clip[0]
    assert trim_cast_shadows(g, dets) == dets
    direction = clip_shadow_direction(lean, motion, min_votes=15)
    assert direction[0] < -0.1 and direction[1] == 0
    # no sun: the fronts alone cancel
    calm = [(g, _dets(b, motions)) for g, b in (_frame(s, fronts=fronts) for s in range(8))]
    assert not clip_shadow_direction(*_votes(calm), min_votes=15).any()
    # traffic one way only: front and shadow cannot be told apart, nothing is said along x
    one_way = [(g, _dets(b, [(2.0, 0.0)] * 5)) for g, b in (_frame(s, shadow=(-3, 0), fronts=[1] * 5)
                                                            for s in range(8))]
    assert clip_shadow_direction(*_votes(one_way), min_votes=15)[0] == 0


def test_a_camera_turned_a_quarter_sees_the_same_sun_once_its_yaw_is_taken_off():
    # frame 1 is frame 0 turned a quarter (np.rot90: x' = y, y' = W - 1 - x); M maps frame 0's pixels to frame 1's
    M = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, W - 1.0], [0.0, 0.0, 1.0]])
    yaw = image_yaw_rad(M)
    assert yaw == pytest.approx(-math.pi / 2)
    g0, boxes0 = _frame(1, shadow=(-SHADOW_PX, 1))
    g1 = np.ascontiguousarray(np.rot90(g0))
    boxes1 = [(y0, W - 1 - x1, y1, W - 1 - x0) for x0, y0, x1, y1 in boxes0]
    bodies1 = [(y0, W - 1 - x1, y1, W - 1 - x0) for x0, y0, x1, y1 in BODIES]
    motions1 = [(v, -u) for u, v in MOTIONS]
    lean0, lean1 = shadow_lean(g0, _dets(boxes0))[1], shadow_lean(g1, _dets(boxes1, motions1))[1]
    np.testing.assert_allclose(turn(lean1, -yaw), lean0, atol=1e-9)  # the frame-1 votes in frame 0's axes
    d0 = clip_shadow_direction(np.concatenate([lean0, turn(lean1, -yaw)]),
                               np.concatenate([MOTIONS, turn(motions1, -yaw)]), min_votes=6)
    assert d0[0] < -0.1 and 0 <= d0[1] < -d0[0]  # left in frame 0 (and the 1 px down, less)
    d1 = turn(d0, yaw)  # frame 0's left is frame 1's bottom
    np.testing.assert_allclose(d1, (d0[1], -d0[0]), atol=1e-12)
    dets1 = _dets(boxes1, motions1)
    for d, body in zip(trim_toward(dets1, shadow_lean(g1, dets1)[0], d1), bodies1):
        assert abs(d.y1_px - body[3]) <= 1 and d.y0_px == body[1], (d, body)


def test_a_diagonal_shadow_faces_two_sides_an_axis_one():
    dets = _dets([(10, 10, 40, 30)], [(1.0, 0.0)])
    bands = np.array([[4, 3, 5, 6]])
    left_top = trim_toward(dets, bands, (-1.0, -1.0))[0]
    assert (left_top.x0_px, left_top.y0_px, left_top.x1_px, left_top.y1_px) == (14, 13, 40, 30)
    right = trim_toward(dets, bands, (1.0, 0.3))[0]
    assert (right.x0_px, right.y0_px, right.x1_px, right.y1_px) == (10, 10, 35, 30)
    assert trim_toward(dets, bands, (0.0, 0.0)) == dets


def test_a_box_moving_diagonally_keeps_its_sides_and_its_bands_do_not_set_the_cut():
    # three boxes with a 6 px band on the left: one driving along x, one along y, one at 40 degrees off x (its axis-
    # aligned box's left band is a corner of its body); the diagonal one's 12 px band would raise the median cut
    dets = _dets([(10, 10, 40, 30), (60, 10, 80, 40), (100, 10, 140, 40)],
                 [(2.0, 0.0), (0.0, -1.5), (1.5, 1.26)])
    bands = np.array([[6, 0, 0, 0], [6, 0, 0, 0], [12, 0, 0, 0]])
    along_x, along_y, diagonal = trim_toward(dets, bands, (-1.0, 0.0), diagonal_deg=20.0)
    assert (along_x.x0_px, along_y.x0_px) == (16.0, 66.0)
    assert diagonal == dets[2]
    # off (0), every box is trimmed, the diagonal one at most 1.5 times the median band, 6 px: 9 px
    assert trim_toward(dets, bands, (-1.0, 0.0))[2].x0_px == 109.0
    # 20 degrees off an axis is along it (and a box without a motion is trimmed)
    near_axis = _dets([(10, 10, 40, 30), (60, 10, 80, 40)], [(1.0, 0.35), (0.0, 0.0)])
    assert [d.x0_px for d in trim_toward(near_axis, bands[:2], (-1.0, 0.0), diagonal_deg=20.0)] == [16.0, 66.0]


def test_bad_inputs_are_rejected_naming_them():
    with pytest.raises(ValueError, match=r"motion_px: expected 2 rows \(one per lean\), got 1"):
        clip_shadow_direction(np.zeros((2, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"vote: expected a fraction in \[0, 1\], got 1.5"):
        clip_shadow_direction(np.zeros((2, 2)), np.zeros((2, 2)), vote=1.5)
    with pytest.raises(ValueError, match=r"bands: expected 1 rows \(one per detection\), got 2"):
        trim_toward(_dets([(10, 10, 40, 30)]), np.zeros((2, 4)), (1.0, 0.0))
    with pytest.raises(ValueError, match=r"diagonal_deg: expected degrees in \[0, 45\], got 50"):
        trim_toward(_dets([(10, 10, 40, 30)]), np.zeros((1, 4)), (1.0, 0.0), diagonal_deg=50)
    with pytest.raises(ValueError, match=r"matrix: expected a \(3, 3\) model, got shape \(2, 3\)"):
        image_yaw_rad(np.eye(3)[:2])
    with pytest.raises(ValueError, match=r"gray: expected an \(H, W\) frame, got shape \(4, 4, 3\)"):
        shadow_lean(np.zeros((4, 4, 3)), [])


@pytest.mark.parametrize("key, value, match", [
    ("shadow_scope", "sequence", r"shadow_scope: expected frame or clip, got 'sequence'"),
    ("shadow_clip_min_votes", 0, r"shadow_clip_min_votes: expected an integer >= 1, got 0"),
    ("shadow_diagonal_deg", 60.0, r"shadow_diagonal_deg: expected degrees in \[0, 45\], got 60.0"),
])
def test_bad_clip_keys_are_rejected_naming_them(key, value, match):
    with pytest.raises(ValueError, match=match):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), **{key: value})
    with pytest.raises(PipelineError, match=rf"detection\.{key}"):
        Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": {key: value}})


# a pipeline run: six cars 24 x 12 px driving 2 px a frame both ways along x over a blurred textured ground, their
# shadows 5 px to the left (the ground darkened to half)
RUN_BODIES = [(30, 30, 53, 41), (120, 34, 143, 45), (200, 28, 223, 39), (40, 120, 63, 131), (150, 130, 173, 141),
              (210, 160, 233, 171)]
RUN_MOTIONS = [(2, 0), (-2, 0), (2, 0), (-2, 0), (2, 0), (-2, 0)]


def _run_frame(t, shadow):
    import cv2

    g = cv2.GaussianBlur((100.0 + np.random.default_rng(5).normal(0.0, 8.0, size=(200, 280))).astype(np.float32),
                         (0, 0), 1.0)
    bodies = [(x0 + u * t, y0 + v * t, x1 + u * t, y1 + v * t)
              for (x0, y0, x1, y1), (u, v) in zip(RUN_BODIES, RUN_MOTIONS)]
    if shadow is not None:
        dx, dy = shadow
        for x0, y0, x1, y1 in bodies:
            g[y0 + dy:y1 + dy + 1, x0 + dx:x1 + dx + 1] *= 0.5
    for i, (x0, y0, x1, y1) in enumerate(bodies):
        g[y0:y1 + 1, x0:x1 + 1] = np.random.default_rng(20 + i).normal(175.0, 20.0, size=(y1 - y0 + 1, x1 - x0 + 1))
    return np.clip(g, 0, 255).astype(np.uint8), bodies


def _left_offsets(det, frames, shadow):
    """Per pair, each detection's left side less its car's (the car its centre lies on)."""
    from algorithms.pipeline import SequenceEstimate

    out = []
    det = {"min_area_m2": None, "max_area_m2": None, "min_box_m2": None, **det}
    p = Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": det})
    for e in p.run(frames):
        if isinstance(e, SequenceEstimate):
            continue
        bodies = _run_frame(e.index, shadow)[1]
        row = []
        for d in e.detections:
            (b,) = [b for b in bodies if b[0] - 8 <= d.x_px <= b[2] and b[1] <= d.y_px <= b[3]]
            row.append(d.x0_px - b[0])
        out.append(sorted(row))
    return out


def test_the_pipeline_votes_once_over_the_clip_and_trims_from_when_it_has_decided():
    shadow = (-SHADOW_PX, 0)
    frames = [_run_frame(t, shadow)[0] for t in range(6)]
    clip = {"shadow_trim_rel": 0.35, "shadow_scope": "clip", "shadow_clip_min_votes": 6}
    off = _left_offsets({}, frames, shadow)
    on = _left_offsets(clip, frames, shadow)
    assert all(len(r) == len(RUN_BODIES) for r in off + on)
    assert all(x <= -SHADOW_PX + 1 for r in off for x in r)  # the boxes hold the shadow
    # pair 0 holds 3 votes of each way along x, under 6: nothing decided; from pair 1 on, the boxes end at the body
    assert on[0] == off[0]
    assert all(abs(x) <= 1 for r in on[1:] for x in r), on
    # detect_vehicles alone leaves the boxes to the pipeline with the clip's scope
    assert _left_offsets({"shadow_trim_rel": 0.35, "shadow_scope": "clip", "shadow_clip_min_votes": 10 ** 6},
                         frames, shadow) == off



def test_the_clip_trims_the_boxes_the_long_pair_merged_in(monkeypatch):
    # a slow mover's box from the long pair (algorithms.long_baseline) holds its shadow as the pair's box does; the
    # merge is made to return the pair's boxes as the detector found them, shadow and all (what a long-pair box that
    # replaced one would be): what leaves the detection stage is trimmed all the same once the clip has decided
    import algorithms.pipeline as P
    from algorithms.pipeline import SequenceEstimate

    found = {}

    def lean(gray, dets, **kw):  # a pair's vote (its first call) sees its boxes as detected, before any trim
        found["dets"] = list(dets)
        return shadow_lean(gray, dets, **kw)

    def merge(dets, slow, **kw):
        return found.pop("dets")

    monkeypatch.setattr(P, "shadow_lean", lean)
    monkeypatch.setattr(P, "merge_detections", merge)
    shadow = (-SHADOW_PX, 0)
    frames = [_run_frame(t, shadow)[0] for t in range(6)]
    det = {"min_area_m2": None, "max_area_m2": None, "min_box_m2": None, "shadow_trim_rel": 0.35,
           "shadow_scope": "clip", "shadow_clip_min_votes": 6, "long_baseline": {"frames": 2}}
    checked = 0
    for e in Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": det}).run(frames):
        if isinstance(e, SequenceEstimate) or e.index < 2:  # the long pair from pair 2 on; the shadow from pair 1
            continue
        bodies = _run_frame(e.index, shadow)[1]
        assert len(e.detections) == len(RUN_BODIES)
        for d in e.detections:
            (b,) = [b for b in bodies if b[0] - 8 <= d.x_px <= b[2] and b[1] <= d.y_px <= b[3]]
            assert abs(d.x0_px - b[0]) <= 1, (e.index, d, b)
        checked += 1
    assert checked >= 2
