"""A box that holds a uniform roof's edge grows along its lane over the body (algorithms.detection.fill_lane;
the pipeline's detection.lane_fill_rel), and a part that ends inside another box is dropped (detection.nms_inside)."""

import math

import cv2
import numpy as np
import pytest

from algorithms.detection import DETECTION_DEFAULTS, Detection, detect_vehicles, drop_parts_inside, fill_lane
from algorithms.pipeline import Pipeline, PipelineError

H, W = 160, 240


def _ground(seed=0):
    rng = np.random.default_rng(seed)
    return (90.0 + rng.normal(0.0, 3.0, size=(H, W))).astype(np.float32)


def _paint(img, cx, cy, length, width, angle_deg, grey):
    """A uniform body seen from above centred at (cx, cy), its length along ``angle_deg`` (image axes, y down)."""
    a = math.radians(angle_deg)
    along, across = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    corners = [np.array([cx, cy]) + s * length / 2 * along + t * width / 2 * across
               for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    out = img.copy()
    cv2.fillConvexPoly(out, np.round(np.array(corners) * 16).astype(np.int32), float(grey), shift=4)
    return out


def _extent(img, ground):
    ys, xs = np.nonzero(np.abs(img - ground) > 20)
    return xs.min(), ys.min(), xs.max(), ys.max()


def _det(box, u, v):
    x0, y0, x1, y1 = box
    return Detection((x0 + x1) / 2, (y0 + y1) / 2, 100, float(x0), float(y0), float(x1), float(y1), u, v)


def _iou(d, box):
    x0, y0, x1, y1 = box
    w = min(d.x1_px, x1) - max(d.x0_px, x0) + 1
    h = min(d.y1_px, y1) - max(d.y0_px, y0) + 1
    inter = max(0, w) * max(0, h)
    area = (d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1) + (x1 - x0 + 1) * (y1 - y0 + 1) - inter
    return inter / area


@pytest.mark.parametrize("u, v", [(2.0, 0.0), (-1.5, 0.0), (0.0, 1.0)])
def test_a_box_on_a_buss_front_edge_grows_over_its_uniform_roof_and_stops_at_the_road(u, v):
    # a 60 x 16 px bus, its roof one grey: the flow and the frames' change saw its front edge alone (a 12 px box at the
    # end it drives towards); a car of the same grey follows 8 px of road behind it in the lane
    angle = math.degrees(math.atan2(v, u))
    e = np.array([u, v]) / math.hypot(u, v)
    g0 = _ground()
    centre = np.array([120.0, 80.0])
    bus_only = _paint(g0, *centre, 60, 16, angle, 200)
    bus = _extent(bus_only, g0)
    frame = _paint(bus_only, *(centre - e * (30 + 8 + 12)), 24, 14, angle, 200)
    front = centre + e * 24
    x0, y0 = np.floor(np.minimum(front - 6 * np.abs(e) - 8 * np.abs(e[::-1]), front)).astype(int)
    x1, y1 = np.ceil(np.maximum(front + 6 * np.abs(e) + 8 * np.abs(e[::-1]), front)).astype(int)
    edge = _det((x0, y0, x1, y1), u, v)
    assert _iou(edge, bus) < 0.4
    (grown,) = fill_lane(frame, [edge], max_rel=4.0)  # the edge is 16 px wide: up to 64 px long
    assert _iou(grown, bus) >= 0.9, (grown, bus)
    assert (grown.x_px, grown.y_px) == ((grown.x0_px + grown.x1_px) / 2, (grown.y0_px + grown.y1_px) / 2)
    # however far it may grow, the road behind the bus ends it: the follower stays out
    (far,) = fill_lane(frame, [edge], max_rel=8.0)
    assert far == grown
    # off, or no motion: the box as it was
    assert fill_lane(frame, [edge], max_rel=0.0) == [edge]
    assert fill_lane(frame, [_det((x0, y0, x1, y1), 0.0, 0.0)]) == [_det((x0, y0, x1, y1), 0.0, 0.0)]


def test_a_diagonal_buss_edge_grows_within_its_lane():
    # 56 x 16 px at 34 degrees: the lane is the body's extent across the motion, so the ground beside the bus, inside
    # its axis-aligned box, is no reason to stop and none of a parked car beside the lane is taken in
    angle = 34.0
    e = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    g0 = _ground(1)
    centre = np.array([110.0, 80.0])
    frame = _paint(g0, *centre, 56, 16, angle, 60)
    bus = _extent(frame, g0)
    frame = _paint(frame, *(centre + np.array([-e[1], e[0]]) * 22), 24, 12, angle, 60)  # beside it, the next lane
    front = _extent(_paint(g0, *(centre + e * 22), 12, 16, angle, 60), g0)
    (grown,) = fill_lane(frame, [_det(front, *(1.5 * e))])
    assert _iou(grown, bus) >= 0.85, (grown, bus)


def test_with_the_next_frame_the_new_end_must_move_with_the_vehicle():
    # a 60 x 16 px bus found by its front edge grows over its roof: its rear edge moves with it. A 30 x 14 px car found
    # but for its front 6 px, its nose on a white stop line (no road either, as a crosswalk's stripes blurred together
    # are): the line's far edge does not move with the car, so the box does not grow over it; without the next frame
    # nothing tells the line from a roof
    u, v = 2.0, 0.0
    g0 = _ground(4)
    bus = [_paint(g0, 120 + k * u, 50, 60, 16, 0.0, 200) for k in range(2)]
    line = g0.copy()
    line[96:116, 156:162] = 230.0
    car = [_paint(line, 140 + k * u, 106, 30, 14, 0.0, 200) for k in range(2)]
    whole = _extent(bus[0], g0)
    edge = _det((whole[2] - 11, whole[1], whole[2], whole[3]), u, v)
    (grown,) = fill_lane(bus[0], [edge], next_gray=bus[1], max_rel=4.0)
    assert _iou(grown, whole) >= 0.9, (grown, whole)
    body = _extent(_paint(g0, 140, 106, 30, 14, 0.0, 200), g0)
    rear = _det((body[0], body[1], body[2] - 6, body[3]), u, v)  # its front 6 px short, as a box can be
    (blind,) = fill_lane(car[0], [rear])
    assert blind.x1_px >= 161, blind  # over the car's front and on over the stop line
    (checked,) = fill_lane(car[0], [rear], next_gray=car[1])
    assert checked.x1_px <= body[2] + 1, (checked, body)
    with pytest.raises(ValueError, match=r"next_gray: expected the shape of gray \(160, 240\), got \(4, 4\)"):
        fill_lane(car[0], [rear], next_gray=np.zeros((4, 4)))


def test_a_box_that_holds_its_whole_car_stays_as_it_is():
    g0 = _ground(2)
    frame = _paint(g0, 120, 80, 30, 14, 0.0, 190)
    car = _extent(frame, g0)
    d = _det(car, 2.0, 0.0)
    assert fill_lane(frame, [d]) == [d]


def test_the_growth_is_at_most_max_rel_times_the_body():
    # a wall of no-road grey runs on along the lane (a kerb of light stone, a building's edge): the box grows max_rel
    # times the body's size at most, not along the whole wall
    g0 = _ground(3)
    frame = g0.copy()
    frame[74:87, 20:230] = 200.0
    d = _det((150, 74, 161, 86), 1.0, 0.0)  # 12 x 13 px of it
    (grown,) = fill_lane(frame, [d], max_rel=2.0)
    assert 12 < grown.x1_px - grown.x0_px + 1 <= 2 * 13 + 1, grown  # ahead first, then behind, 26 px in all
    assert (grown.y0_px, grown.y1_px) == (74, 86)
    (longer,) = fill_lane(frame, [d], max_rel=4.0)
    assert 2 * 13 + 1 < longer.x1_px - longer.x0_px + 1 <= 4 * 13 + 1, longer


def test_bad_inputs_are_rejected_naming_them():
    with pytest.raises(ValueError, match=r"gray: expected an \(H, W\) frame, got shape \(4, 4, 3\)"):
        fill_lane(np.zeros((4, 4, 3)), [])
    with pytest.raises(ValueError, match=r"max_rel: expected a number >= 0, got -1"):
        fill_lane(np.zeros((4, 4)), [], max_rel=-1)
    with pytest.raises(ValueError, match=r"lane_fill_line: expected a fraction in \(0, 1\], got 1.5"):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), lane_fill_line=1.5)
    with pytest.raises(PipelineError, match=r"detection\.lane_fill_rel"):
        Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": {"lane_fill_rel": -2}})


def test_two_edges_of_one_roof_grown_into_one_box_are_one_detection_with_nms_inside():
    # a 60 x 16 px bus whose uniform roof showed the flow its front and its rear edge, two boxes that share no pixel;
    # each grows over the roof (fill_lane) and they end as one box twice: the smaller goes, the car behind stays
    g0 = _ground(2)
    frame = _paint(g0, 120.0, 80.0, 60, 16, 0.0, 200)
    bus = _extent(frame, g0)
    frame = _paint(frame, 120.0 - 30 - 8 - 12, 80.0, 24, 14, 0.0, 200)  # 8 px of road behind
    car = _extent(_paint(g0, 120.0 - 30 - 8 - 12, 80.0, 24, 14, 0.0, 200), g0)
    front, rear = (_det((bus[2] - 11, bus[1], bus[2], bus[3]), 2.0, 0.0),
                   _det((bus[0], bus[1], bus[0] + 11, bus[3]), 2.0, 0.0))
    grown = fill_lane(frame, [front, rear, _det(car, 2.0, 0.0)], max_rel=4.0)
    assert [round(_iou(d, bus), 1) >= 0.9 for d in grown] == [True, True, False], grown
    assert grown[0][3:7] == grown[1][3:7]                   # one box twice, though nms_iou in the detector saw two
    kept = drop_parts_inside(grown, 0.5)
    assert len(kept) == 2 and _iou(kept[1], car) >= 0.9 and _iou(kept[0], bus) >= 0.9, kept


def test_a_part_inside_a_larger_box_goes_and_a_neighbour_overlapping_it_less_stays():
    bus = _det((466, 635, 527, 719), 0.0, 1.0)                 # 62 x 85 px
    rear = _det((509, 630, 527, 646), 0.0, 1.0)                # its rear edge: 12 of its 17 rows inside, IoU 0.04
    car = _det((520, 700, 552, 738), 0.0, 1.0)                 # the car behind: under a fifth inside
    assert _iou(rear, bus[3:7]) < DETECTION_DEFAULTS["nms_iou"]
    assert drop_parts_inside([bus, rear, car], 0.5) == [bus, car]
    assert drop_parts_inside([rear, car, bus], 0.7) == [car, bus]         # 71 % inside, in any order
    assert drop_parts_inside([bus, rear, car], 0.75) == [bus, rear, car]
    twin = bus._replace(x_px=bus.x_px + 1, x0_px=bus.x0_px + 1, x1_px=bus.x1_px + 1)
    assert drop_parts_inside([bus, twin], 0.5) == [bus]                   # the same size: the later goes
    assert drop_parts_inside([twin, bus], 0.5) == [twin]
    assert drop_parts_inside([], 0.5) == []
    # inside a larger box of another motion it is another mover (merge_px + merge_rel x the faster speed: 1.3-1.5 px)
    assert drop_parts_inside([bus, rear._replace(v_px=-1.0)], 0.5) == [bus, rear._replace(v_px=-1.0)]
    assert drop_parts_inside([bus, rear._replace(u_px=1.2)], 0.5) == [bus]
    with pytest.raises(ValueError, match=r"nms_inside: expected a fraction in \[0, 1\], got 1.5"):
        detect_vehicles(np.zeros((4, 4, 2), np.float32), np.ones((4, 4), bool), nms_inside=1.5)
    with pytest.raises(PipelineError, match=r"detection\.nms_inside"):
        Pipeline.from_dict({"name": "t", "flow": {"method": "dis"}, "detection": {"nms_inside": -1}})
