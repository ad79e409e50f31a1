"""Cast shadows taken off detection boxes (algorithms.detection.trim_cast_shadows, shadow_bands)."""

import numpy as np
import pytest

from algorithms.detection import Detection, detect_vehicles, shadow_bands, trim_cast_shadows
from algorithms.pipeline import Pipeline, PipelineError

H, W = 160, 220
# bodies (x0, y0, x1, y1), inclusive, 24 x 12 px: cars lying along x, far enough apart for their rings of ground
BODIES = [(20, 20, 43, 31), (90, 24, 113, 35), (150, 18, 173, 29), (30, 90, 53, 101), (110, 100, 133, 111)]
SHADOW_PX = 5


def _scene(rng, *, shadow=None, body_grey=(190.0, 150.0)):
    """Frame t: textured grey ground, cars with a brighter roof and darker windscreens, each with its cast
    shadow (the body's silhouette shifted by ``shadow`` (dx, dy) px, ground darkened to half) or none.
    Returns the frame and, per car, the box of body and shadow together (what the motion test boxes)."""
    g = 100.0 + rng.normal(0.0, 4.0, size=(H, W))
    boxes = []
    for x0, y0, x1, y1 in BODIES:
        if shadow is not None:
            dx, dy = shadow
            g[y0 + dy:y1 + dy + 1, x0 + dx:x1 + dx + 1] *= 0.5  # eq. of a cast shadow: irradiance ratio k = 0.5
        paint, roof = body_grey
        g[y0:y1 + 1, x0:x1 + 1] = paint + rng.normal(0.0, 3.0, size=(y1 - y0 + 1, x1 - x0 + 1))
        g[y0 + 3:y1 - 2, x0 + 7:x1 - 6] = roof
        g[y0 + 2:y1 - 1, x0 + 4:x0 + 7] = 40.0   # windscreen
        g[y0 + 2:y1 - 1, x1 - 5:x1 - 3] = 45.0   # rear window
        if shadow is None:
            boxes.append((x0, y0, x1, y1))
        else:
            boxes.append((min(x0, x0 + dx), min(y0, y0 + dy), max(x1, x1 + dx), max(y1, y1 + dy)))
    return g.astype(np.float32), boxes


MOTIONS = [(1.5, 0.2), (-2.0, 0.0), (0.1, 1.0), (0.0, -1.2), (-1.0, 0.3)]  # px/frame: traffic both ways, both axes


def _dets(boxes, motions=MOTIONS):
    return [Detection((x0 + x1) / 2, (y0 + y1) / 2, 100, float(x0), float(y0), float(x1), float(y1), u, v)
            for (x0, y0, x1, y1), (u, v) in zip(boxes, motions)]


@pytest.mark.parametrize("shadow", [(-SHADOW_PX, 2), (SHADOW_PX, -1), (1, SHADOW_PX), (-2, -SHADOW_PX)])
def test_the_box_ends_at_the_body_whichever_way_the_sun_casts(shadow):
    rng = np.random.default_rng(3)
    g, boxes = _scene(rng, shadow=shadow)
    out = trim_cast_shadows(g, _dets(boxes))
    dx, dy = shadow
    big = 0 if abs(dx) == SHADOW_PX else 1  # the side (axis) the shadow reaches out on by SHADOW_PX
    for d, body, box in zip(out, BODIES, boxes):
        got = np.array([d.x0_px, d.y0_px, d.x1_px, d.y1_px])
        # the shadow's side ends at the body within 1 px; the box never cuts into the body by more than 1 px
        side = (0 if dx < 0 else 2) if big == 0 else (1 if dy < 0 else 3)
        assert abs(got[side] - body[side]) <= 1, (shadow, got, body)
        assert all(got[s] <= body[s] + 1 for s in (0, 1)) and all(got[s] >= body[s] - 1 for s in (2, 3)), got
        # the opposite side is left alone
        opp = (side + 2) % 4
        assert got[opp] == box[opp]
        assert (d.x_px, d.y_px) == ((got[0] + got[2]) / 2, (got[1] + got[3]) / 2)
        assert d.area_px == 100 and (d.u_px, d.v_px) in MOTIONS


def test_a_box_grown_ahead_of_dark_cars_that_all_drive_one_way_is_not_trimmed():
    # a box that holds the ground a fast vehicle covers next: the body at its rear end, dark, on the same side for
    # every car driving that way; no shadow, so nothing may be cut
    rng = np.random.default_rng(7)
    g, boxes = _scene(rng, body_grey=(48.0, 60.0))
    grown = [(x0, y0, x1 + 12, y1) for x0, y0, x1, y1 in boxes]
    dets = _dets(grown, [(14.0, 0.5)] * len(grown))
    assert trim_cast_shadows(g, dets) == dets
    # traffic both ways gives each end a dark body in turn: no side is darker for movers either way
    both = [(x0, y0, x1 + 12, y1) if i % 2 == 0 else (x0 - 12, y0, x1, y1) for i, (x0, y0, x1, y1) in enumerate(boxes)]
    dets = _dets(both, [(14.0, 0.5) if i % 2 == 0 else (-14.0, 0.5) for i in range(len(both))])
    assert trim_cast_shadows(g, dets) == dets


def test_no_shadow_no_change_and_dark_cars_keep_their_bodies():
    rng = np.random.default_rng(4)
    for body_grey in ((190.0, 150.0), (48.0, 60.0)):  # light cars; dark cars, as dark as a shadow
        g, boxes = _scene(rng, body_grey=body_grey)
        dets = _dets(boxes)
        assert trim_cast_shadows(g, dets) == dets


def test_too_few_detections_do_not_decide_the_sun():
    rng = np.random.default_rng(5)
    g, boxes = _scene(rng, shadow=(-SHADOW_PX, 2))
    dets = _dets(boxes[:2])
    assert trim_cast_shadows(g, dets, min_votes=3) == dets
    assert trim_cast_shadows(g, dets, min_votes=2) != dets


def test_shadow_bands_sees_the_dark_band_on_its_side_only():
    rng = np.random.default_rng(6)
    g, boxes = _scene(rng, shadow=(-SHADOW_PX, 0))
    widths, outer = shadow_bands(g, boxes[0])
    assert widths[0] == pytest.approx(SHADOW_PX, abs=1)
    assert widths[2] == 0
    assert outer[0] > outer[2] + 0.2
    widths, outer = shadow_bands(g, (0, 0, 10, 10))  # no ring of ground around it: nothing said
    assert not widths.any() and np.isnan(outer).all()


@pytest.mark.parametrize("key, value, match", [
    ("shadow_trim_rel", 0.5, r"shadow_trim_rel: expected a fraction in \[0, 0.5\), got 0.5"),
    ("shadow_trim_rel", -0.1, r"shadow_trim_rel: expected a finite number >= 0, got -0.1"),
    ("shadow_ratio_lo", 0.9, r"shadow_ratio_lo: expected below shadow_ratio_hi \(0.8\), got 0.9"),
    ("shadow_ratio_hi", 1.2, r"shadow_ratio_hi: expected a fraction in \[0, 1\], got 1.2"),
    ("shadow_vote", 2.0, r"shadow_vote: expected a fraction in \[0, 1\], got 2.0"),
    ("shadow_min_votes", 0, r"shadow_min_votes: expected an integer >= 1, got 0"),
    ("shadow_min_votes", 2.5, r"shadow_min_votes: expected an integer >= 1, got 2.5"),
])
def test_bad_shadow_keys_are_rejected_naming_them(key, value, match):
    with pytest.raises(ValueError, match=match):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), **{key: value})
    with pytest.raises(PipelineError, match=rf"detection\.{key}"):
        Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": {key: value}})


def test_trim_rejects_a_colour_frame_and_a_bad_vote():
    with pytest.raises(ValueError, match=r"gray: expected an \(H, W\) frame, got shape \(4, 4, 3\)"):
        trim_cast_shadows(np.zeros((4, 4, 3)), [])
    with pytest.raises(ValueError, match=r"vote: expected a fraction in \[0, 1\], got -1"):
        trim_cast_shadows(np.zeros((4, 4)), [], vote=-1)


def _moving_scene(rng, t: int, motions, shadow):
    """Frame t of cars driving at ``motions`` (px/frame, integers) over a static textured ground, each with its
    cast shadow (the body shifted by ``shadow``, the ground darkened to half); the same ground in every frame."""
    ground = 100.0 + np.random.default_rng(11).normal(0.0, 6.0, size=(H, W))
    g = ground.copy()
    dx, dy = shadow
    bodies = [(x0 + u * t, y0 + v * t, x1 + u * t, y1 + v * t) for (x0, y0, x1, y1), (u, v) in zip(BODIES, motions)]
    for x0, y0, x1, y1 in bodies:
        g[y0 + dy:y1 + dy + 1, x0 + dx:x1 + dx + 1] *= 0.5
    for i, (x0, y0, x1, y1) in enumerate(bodies):
        car = np.random.default_rng(20 + i).normal(170.0, 25.0, size=(y1 - y0 + 1, x1 - x0 + 1))  # paint, moves along
        g[y0:y1 + 1, x0:x1 + 1] = car
    return g.astype(np.float32), bodies


def test_detect_vehicles_with_shadow_trim_boxes_the_body_not_its_shadow():
    motions = [(2, 0), (-2, 0), (0, 2), (0, -2), (2, 0)]
    shadow = (-SHADOW_PX, 1)
    rng = np.random.default_rng(12)
    (g0, bodies), (g1, _) = _moving_scene(rng, 0, motions, shadow), _moving_scene(rng, 1, motions, shadow)
    flow = np.zeros((H, W, 2), np.float32)
    for (x0, y0, x1, y1), (u, v) in zip(bodies, motions):  # body and shadow move together: the flow holds both
        flow[y0 - 1:y1 + 3, x0 - SHADOW_PX - 1:x1 + 2] = (u, v)
    kw = dict(frames=(g0, g1), min_area_m2=None, max_area_m2=None, min_box_m2=None)
    off = detect_vehicles(flow, np.ones((H, W), bool), **kw)
    on = detect_vehicles(flow, np.ones((H, W), bool), shadow_trim_rel=0.35, **kw)
    assert len(off) == len(on) == len(BODIES)
    for body in bodies:
        (a,) = [d for d in off if abs(d.y_px - (body[1] + body[3]) / 2) < 4 and abs(d.x1_px - body[2]) <= 3]
        (b,) = [d for d in on if abs(d.y_px - (body[1] + body[3]) / 2) < 4 and abs(d.x1_px - body[2]) <= 3]
        assert a.x0_px <= body[0] - SHADOW_PX + 2            # without the trim the box holds the shadow
        assert abs(b.x0_px - body[0]) <= 1.5, (b, body)      # with it, it ends at the body
        assert b.x1_px == a.x1_px
