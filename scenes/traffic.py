"""City traffic: road-user classes and their shapes, a car-following simulation with traffic lights,
parked cars, pedestrians, cyclists, and the street furniture that hides them (street trees, footbridges).

Everything is drawn from explicit ``numpy.random.Generator``s, so a seed gives the same traffic.

Classes and sizes (length x width x height, metres; the ranges are drawn from uniformly):
:data:`CLASS_SIZES_M`. A road user's shape is a few boxes in its own frame (x forward, y left, z up,
origin on the ground under its centre): :func:`vehicle_parts` (boxes with their colours, for the
renderer) and :func:`vehicle_shape` (the boxes alone, for the ground truth): one home, so the truth
sees exactly what is drawn. A ``car`` is :func:`scenes.world.vehicle_boxes`.

Motion (:func:`place_traffic`): each moving road user follows a route of directed road *legs*
through junctions (right-hand traffic, lanes counted from the centre line, a parking lane along the
kerb where the road is wide enough: :func:`lane_layout`). The simulation steps ``SIM_DT_S`` from
``-warmup_s`` to the last frame; each step every vehicle takes one constant acceleration from the
Intelligent Driver Model (Treiber, Hennecke, Helbing 2000)::

    a = a_max [1 - (v / v0)^4 - (s* / s)^2],   s* = s0 + max(0, v T + v dv / (2 sqrt(a_max b)))

against the nearest of: the vehicle ahead in its lane (on its leg or the next one of its route),
the stop line of a red light (a standing leader). Then a hard limit: nobody advances past the
old position of its leader minus ``HARD_GAP_M``, braking as hard as it takes (leaders never move
back, so the bumper-to-bumper gap never falls below it). A vehicle that would stop inside a step
gets a knot where it stops. The steps are the knots of a ``profile``
:class:`scenes.motion.VehiclePath`: its positions at *any* time are the closed form of the
simulation itself, so the truth between frames (rolling shutter, motion blur) is exact.

Traffic lights: at every junction of three or more roads the approaches along one axis have
green together (``green_s``), then ``clearance_s`` of amber and all-red, then the other axis. A
left turn gives way: it waits at the line while oncoming traffic is within LEFT_YIELD_M of its own
line or in the junction. A vehicle that cannot stop at the line with ``HARD_BRAKE_MPS2`` when the light turns goes on. Turning
vehicles slow to ``turn_speed_mps`` through the corner. Lane changes happen on legs with two or more
lanes (to the lane a turn needs, or at random with ``lane_change_fraction``), along a smooth
S-curve of the lane offset over ``LANE_CHANGE_M``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from scenes.car_paint import GLASS_RGB, colour_by_share
from scenes.formats import TRUTH_CLASSES
from scenes.motion import CameraPath, VehiclePath, polyline_arc_lengths
from scenes.vegetation import CONIFER_VARIANTS, CROWN_BASES, crown_lobes
from scenes.world import (Box, Building, Tree, World, _bezier, _offset_right, _rect_corners,
                          _trim, distance_to_polyline, ground_footprint, point_rect_distance, rects_overlap,
                          sun_direction, vehicle_boxes)

__all__ = [
    "CLASSES",
    "VEHICLE_CLASSES",
    "PAINTED_CLASSES",
    "CLASS_SIZES_M",
    "HARD_GAP_M",
    "vehicle_parts",
    "vehicle_shape",
    "lane_layout",
    "place_traffic",
    "street_furniture",
    "overpass_shadow_polygons",
    "max_height_m",
]

CLASSES = TRUTH_CLASSES  # the class names of tracks.csv, synthetic and real (one home: scenes.formats)
VEHICLE_CLASSES = ("car", "van", "truck", "bus", "motorbike")
PAINTED_CLASSES = ("car", "van", "truck", "bus")  # glossy paint with a sky highlight (scenes.car_paint)
# (length, width, height) ranges in metres: European cars, vans (Sprinter-like), rigid trucks,
# 12 m city buses, motorbikes; a cyclist with the bicycle, a pedestrian seen from above (depth x shoulders)
CLASS_SIZES_M = {
    "car": ((3.8, 4.9), (1.7, 1.9), (1.4, 1.6)),
    "van": ((4.8, 6.0), (1.9, 2.1), (2.0, 2.6)),
    "truck": ((7.0, 10.0), (2.45, 2.55), (3.0, 3.8)),
    "bus": ((10.5, 12.2), (2.5, 2.55), (3.0, 3.3)),
    "motorbike": ((1.9, 2.3), (0.7, 0.9), (1.2, 1.4)),
    "cyclist": ((1.6, 1.9), (0.55, 0.7), (1.65, 1.85)),
    "pedestrian": ((0.28, 0.4), (0.45, 0.58), (1.55, 1.9)),
}
BUS_RGB = ((214, 190, 60), (226, 226, 222), (170, 44, 40), (48, 86, 150))
CARGO_RGB = ((228, 228, 224), (200, 202, 206), (150, 152, 156))
CLOTHES_RGB = ((40, 42, 48), (70, 72, 80), (120, 118, 112), (160, 60, 50), (52, 74, 120), (190, 184, 170),
               (90, 110, 70), (200, 160, 60))
DARK_RGB = (34, 34, 36)
HAIR_RGB = ((40, 32, 26), (70, 54, 40), (150, 120, 80), (30, 30, 30))

SIM_DT_S = 0.1
HARD_GAP_M = 0.8  # bumper to bumper, never less, whatever it costs in braking
HARD_BRAKE_MPS2 = 6.0  # a vehicle that cannot stop at the line with this goes on through amber
LANE_W_M = 3.5  # a lane's nominal width
PARKING_LANE_M = 2.4
MIN_LANE_M = 2.8
LANE_CHANGE_M = 30.0
JUNCTION_CLEAR_M = 0.7  # corners start this many road widths before the junction (scenes.world._join)
FOOTPATH_M = 0.9  # a footpath's centre beyond the kerb; walkers keep right of it by WALK_SIDE_M
WALK_SIDE_M = 0.25
STREET_TREE_M = 1.9  # a street tree's trunk beyond the kerb
CROWN_CLEAR_M = 4.8  # a street tree's crown starts this high: above every vehicle class


def max_height_m() -> float:
    """The tallest road user's height (the renderer's near plane and street-tree crowns keep above it)."""
    return max(h[1] for _, _, h in CLASS_SIZES_M.values())


# -- shapes ----------------------------------------------------------------------------------

def vehicle_parts(v: VehiclePath) -> list[tuple[Box, tuple[int, int, int]]]:
    """The boxes of road user ``v`` in its own frame with their colours, by its class and ``size_m``."""
    L, W, H = v.size_m
    body, glass = tuple(v.body_rgb), tuple(v.cabin_rgb)
    cls = v.vclass
    if cls == "car":
        return list(zip(vehicle_boxes(L, W, H), (body, glass, body)))
    if cls == "van":
        hl = 0.5 * H
        return [(Box((0.0, 0.0, hl / 2), (L, W, hl)), body),
                (Box((-0.08 * L, 0.0, hl + 0.5 * (H - hl)), (0.84 * L, 0.97 * W, H - hl)), body),
                (Box((0.36 * L, 0.0, hl + 0.01 + 0.4 * (H - hl)), (0.08 * L, 0.9 * W, 0.8 * (H - hl))), glass)]
    if cls == "truck":
        # no two boxes share a visible face (coplanar faces would flicker between frames): the
        # windscreen stands 4 cm proud of the cab, the chassis 20 cm short of the cargo's back
        cab_l, cab_h = 2.2, 0.8 * H
        cargo = tuple(int(c) for c in CARGO_RGB[int(v.vehicle_id) % len(CARGO_RGB)])
        cargo_l = L - cab_l - 0.3
        return [(Box((L / 2 - 0.04 - (cab_l - 0.04) / 2, 0.0, cab_h / 2), (cab_l - 0.04, W, cab_h)), body),
                (Box((L / 2 - 0.15, 0.0, 0.6 * cab_h), (0.3, 0.92 * W, 0.45 * cab_h)), glass),
                (Box((-L / 2 + cargo_l / 2, 0.0, 0.55 * H), (cargo_l, W, 0.9 * H)), cargo),
                (Box((-L / 2 + 0.2 + (cargo_l - 0.2) / 2, 0.0, 0.06 * H), (cargo_l - 0.2, 0.9 * W, 0.12 * H)),
                 DARK_RGB)]
    if cls == "bus":
        hb = 0.92 * H
        light = tuple(int(min(255, 1.12 * c)) for c in body)
        return [(Box((-0.02, 0.0, hb / 2), (L - 0.04, W, hb)), body),
                (Box((L / 2 - 0.15, 0.0, 0.55 * hb), (0.3, 0.94 * W, 0.6 * hb)), glass),
                (Box((-0.05 * L, 0.0, hb + 0.04 * H), (0.3 * L, 0.6 * W, 0.08 * H)), light),
                (Box((0.3 * L, 0.0, hb + 0.03 * H), (0.08 * L, 0.4 * W, 0.06 * H)), (180, 182, 186))]
    if cls == "motorbike":
        return [(Box((0.0, 0.0, 0.35), (L, 0.35 * W, 0.7)), DARK_RGB),
                (Box((-0.1 * L, 0.0, 0.75), (0.3 * L, 0.9 * W, 0.2)), body),
                (Box((-0.05 * L, 0.0, (H - 0.3 + 0.85) / 2), (0.26, 0.55 * W, H - 0.3 - 0.85)), glass),
                (Box((0.0, 0.0, H - 0.15), (0.3, 0.28, 0.3)), body)]
    if cls == "cyclist":
        return [(Box((0.0, 0.0, 0.45), (L, 0.1, 0.9)), DARK_RGB),
                (Box((-0.05 * L, 0.0, 0.9 + (H - 1.15) / 2), (0.42, W, H - 1.15)), body),
                (Box((0.05 * L, 0.0, H - 0.125), (0.24, 0.22, 0.25)), glass)]
    if cls == "pedestrian":
        legs = 0.5 * H
        return [(Box((0.0, 0.0, legs / 2), (0.8 * L, 0.6 * W, legs)), DARK_RGB),
                (Box((0.0, 0.0, legs + (0.86 * H - legs) / 2), (L, W, 0.86 * H - legs)), body),
                (Box((0.0, 0.0, 0.93 * H), (0.2, 0.19, 0.14 * H)), glass)]
    raise ValueError(f"vclass: expected one of {', '.join(CLASSES)}, got {cls!r}")


def vehicle_shape(v: VehiclePath) -> list[Box]:
    """The boxes the ground truth intersects for road user ``v`` (the renderer draws the same)."""
    return [b for b, _ in vehicle_parts(v)]


def _draw_size(cls: str, rng: np.random.Generator) -> tuple[float, float, float]:
    return tuple(float(rng.uniform(lo, hi)) for lo, hi in CLASS_SIZES_M[cls])


def _draw_colours(cls: str, rng: np.random.Generator) -> tuple[tuple, tuple]:
    if cls == "bus":
        body = BUS_RGB[int(rng.integers(0, len(BUS_RGB)))]
    elif cls in ("cyclist", "pedestrian", "motorbike"):
        body = CLOTHES_RGB[int(rng.integers(0, len(CLOTHES_RGB)))]
    else:  # cars, vans and trucks' cabs by the colours' shares on the road (scenes.car_paint); one
        # integer drawn, as for the other classes, so the traffic's stream does not depend on the palette
        body = colour_by_share(int(rng.integers(0, 1000)) / 1000.0)
    head = HAIR_RGB[int(rng.integers(0, len(HAIR_RGB)))] if cls in ("cyclist", "pedestrian") else GLASS_RGB
    if cls == "motorbike":
        head = CLOTHES_RGB[int(rng.integers(0, len(CLOTHES_RGB)))]
    jitter = rng.uniform(0.92, 1.06)
    return tuple(int(min(255, c * jitter)) for c in body), tuple(int(c) for c in head)


# -- lanes and legs ----------------------------------------------------------------------------

def lane_layout(road_width_m: float, *, kerb_parking: bool) -> tuple[int, float, float]:
    """(lanes per direction, lane width, parking lane width) of a two-way road.

    Lanes fill the half road from the centre line; a parking lane of PARKING_LANE_M runs along
    the kerb when asked and when the lanes left are at least MIN_LANE_M wide.
    """
    half = road_width_m / 2
    park = PARKING_LANE_M if kerb_parking and half - PARKING_LANE_M >= MIN_LANE_M else 0.0
    n = max(1, int(round((half - park) / LANE_W_M)))
    return n, (half - park) / n, park


@dataclass
class _Leg:
    """A road driven from ``entry`` to ``leave``: its centre line in driving order and its lanes."""

    k: int
    entry: int
    leave: int
    centre: np.ndarray
    length: float
    width: float
    n_lanes: int
    lane_w: float
    park_w: float
    stop_c: float  # the stop line's distance along the centre line from the entry node
    index: int = -1  # in _Network.legs (a key that does not depend on memory addresses)
    approach: int = -1  # the phase of the leave node's traffic lights this leg belongs to, -1 = none
    oncoming: list = field(default_factory=list)  # legs (indices) green together from the other side

    def offset(self, lane: float) -> float:
        return (lane + 0.5) * self.lane_w


@dataclass
class _RouteLeg:
    leg: _Leg
    lane_in: int
    lane_out: int
    change_c: tuple[float, float]  # lane change from lane_in to lane_out between these leg coordinates
    cut_in: float  # the leg's part starts this far along its centre line (after the corner)
    s_corner: float  # route arc length where the corner into this leg starts (-inf for the first)
    s_part: float  # route arc length where the leg's part starts
    turn_deg: float  # the turn from this leg into the next (0 for the last)


@dataclass
class _Route:
    legs: list[_RouteLeg]
    polyline: np.ndarray
    s_end: float

    def leg_at(self, s: float) -> int:
        i = 0
        for j, rl in enumerate(self.legs):
            if s >= rl.s_corner:
                i = j
            else:
                break
        return i

    def coord(self, i: int, s: float) -> float:
        rl = self.legs[i]
        return rl.cut_in + (s - rl.s_part)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


class _Network:
    """Directed legs of the roads near the view, their lanes, junction approaches and signal timing."""

    def __init__(self, world: World, ts, area: tuple[float, float, float, float], rng: np.random.Generator):
        self.world = world
        x0, y0, x1, y1 = area
        self.area = area
        nodes = world.nodes_m
        self.inside = (nodes[:, 0] > x0) & (nodes[:, 0] < x1) & (nodes[:, 1] > y0) & (nodes[:, 1] < y1)
        pad = 400.0
        self.legs: list[_Leg] = []
        self.by_entry: dict[int, list[int]] = {}
        degree = np.bincount(np.array([r.nodes for r in world.roads]).ravel(), minlength=len(nodes))
        widest = np.zeros(len(nodes))
        for r in world.roads:
            for n in r.nodes:
                widest[n] = max(widest[n], r.width_m)
        for k, r in enumerate(world.roads):
            c = r.centre_m
            if (c[:, 0].max() < x0 - pad or c[:, 0].min() > x1 + pad or c[:, 1].max() < y0 - pad
                    or c[:, 1].min() > y1 + pad):
                continue
            n, lw, pw = lane_layout(r.width_m, kerb_parking=ts.kerb_parking_per_km > 0)
            for entry, leave, line in ((r.nodes[0], r.nodes[1], c), (r.nodes[1], r.nodes[0], c[::-1])):
                length = float(polyline_arc_lengths(line)[-1])
                stop = length - (JUNCTION_CLEAR_M * widest[leave] + 1.0) if degree[leave] >= 3 else length
                leg = _Leg(k=k, entry=int(entry), leave=int(leave), centre=np.ascontiguousarray(line), length=length,
                           width=r.width_m, n_lanes=n, lane_w=lw, park_w=pw, stop_c=max(0.5 * length, stop),
                           index=len(self.legs))
                self.by_entry.setdefault(int(entry), []).append(len(self.legs))
                self.legs.append(leg)
        # traffic lights, two phases as most city junctions have: the approaches along one axis green
        # together (straight on and turns; a left turn gives way to oncoming traffic), then the other
        # axis, each green followed by clearance_s of amber and all-red
        self.degree = degree
        self.signals: dict[int, tuple[int, float]] = {}  # node -> (number of phases, offset in the cycle)
        approaches: dict[int, list[int]] = {}
        for i, leg in enumerate(self.legs):
            if degree[leg.leave] >= 3:
                approaches.setdefault(leg.leave, []).append(i)
        for node, idx in approaches.items():
            axes: list[float] = []
            for i in idx:
                d = self.legs[i].centre[-1] - self.legs[i].centre[-2]
                ang = math.atan2(d[1], d[0]) % math.pi
                for g, a in enumerate(axes):
                    diff = abs(ang - a) % math.pi
                    if min(diff, math.pi - diff) < math.radians(45.0):
                        break
                else:
                    g = len(axes)
                    axes.append(ang)
                self.legs[i].approach = g
            for i in idx:  # oncoming: the approaches of the same phase from the other side
                a = self.legs[i]
                da = a.centre[-1] - a.centre[-2]
                a.oncoming = [j for j in idx if j != i and self.legs[j].approach == a.approach
                              and float(da @ (self.legs[j].centre[-1] - self.legs[j].centre[-2])) < 0]
            if ts.junctions == "lights":
                cycle = len(axes) * (ts.green_s + ts.clearance_s)
                self.signals[node] = (len(axes), float(rng.uniform(0, cycle)))
        self.green_s, self.clear_s = ts.green_s, ts.clearance_s

    def green(self, leg: _Leg, t_s: float) -> bool:
        sig = self.signals.get(leg.leave)
        if sig is None or leg.approach < 0:
            return True
        n, off = sig
        slot = self.green_s + self.clear_s
        phase = (t_s + off) % (n * slot)
        return int(phase // slot) == leg.approach and phase % slot < self.green_s

    def turn_deg(self, a: _Leg, b: _Leg) -> float:
        d_in = a.centre[-1] - a.centre[-2]
        d_out = b.centre[1] - b.centre[0]
        return math.degrees(math.atan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], float(d_in @ d_out)))

    def next_legs(self, i: int) -> list[tuple[float, int]]:
        """(turn angle in degrees, leg) of the legs one may take after leg i (no U-turns, turns <= 120 deg)."""
        a = self.legs[i]
        out = []
        for j in self.by_entry.get(a.leave, []):
            b = self.legs[j]
            if b.k == a.k:
                continue
            t = self.turn_deg(a, b)
            if abs(t) <= 120.0:
                out.append((t, j))
        return out


def _build_route(net: _Network, first: int, lane0: int, length_m: float, ts, rng: np.random.Generator, *,
                 lateral_m: float = 0.0, kerb_lane: bool = False) -> _Route:
    """A route from the start of leg ``first`` in lane ``lane0``, at least ``length_m`` long, as a lane polyline
    (offsets right of the centre line, corners rounded by a quadratic Bezier through the lanes' crossing)."""
    chosen = [first]
    total = net.legs[first].length
    while total < length_m:
        opts = net.next_legs(chosen[-1])
        if not opts:
            break
        opts.sort(key=lambda o: abs(o[0]))
        turns = [o for o in opts if abs(o[0]) > 30.0]
        if turns and rng.uniform() < ts.turning_fraction:
            pick = turns[int(rng.integers(0, len(turns)))]
        else:
            pick = opts[0]
        chosen.append(pick[1])
        total += net.legs[pick[1]].length
    legs = [net.legs[i] for i in chosen]
    turns = [net.turn_deg(a, b) for a, b in zip(legs[:-1], legs[1:])] + [0.0]
    # lanes: a left turn leaves from lane 0 (next to the centre line) into lane 0, a right turn from the
    # kerb lane into the kerb lane; straight on keeps its lane (clipped to the next road's lanes)
    lanes_in, lanes_out = [], []
    lane = min(lane0, legs[0].n_lanes - 1)
    for i, leg in enumerate(legs):
        last = leg.n_lanes - 1
        lane_in = last if kerb_lane else min(lane, last)
        if kerb_lane:
            lane_out = last
        elif turns[i] > 30.0:
            lane_out = 0
        elif turns[i] < -30.0:
            lane_out = last
        elif leg.n_lanes > 1 and rng.uniform() < ts.lane_change_fraction:
            lane_out = int(rng.integers(0, leg.n_lanes - 1))
            lane_out += lane_out >= lane_in
        else:
            lane_out = lane_in
        lanes_in.append(lane_in)
        lanes_out.append(lane_out)
        nxt = legs[i + 1] if i + 1 < len(legs) else None
        if nxt is not None:
            lane = 0 if turns[i] > 30.0 else (nxt.n_lanes - 1 if turns[i] < -30.0 else lane_out)
    cuts = [0.0] * (len(legs) + 1)
    for i in range(1, len(legs)):
        cuts[i] = min(JUNCTION_CLEAR_M * min(legs[i - 1].width, legs[i].width), 0.4 * legs[i - 1].length,
                      0.4 * legs[i].length)
    pts: list[np.ndarray] = []
    out_legs: list[_RouteLeg] = []
    s_acc = 0.0
    for i, leg in enumerate(legs):
        part = _trim(leg.centre, start_m=cuts[i], end_m=cuts[i + 1])
        sp = polyline_arc_lengths(part)
        n = max(2, int(math.ceil(sp[-1] / 1.0)) + 1)  # 1 m vertices: the lane change is smooth
        at = np.linspace(0.0, sp[-1], n)
        part = np.stack([np.interp(at, sp, part[:, 0]), np.interp(at, sp, part[:, 1])], axis=1)
        c = cuts[i] + at  # leg coordinate of each vertex
        o_in, o_out = leg.offset(lanes_in[i]), leg.offset(lanes_out[i])
        change = (0.0, 0.0)
        if lanes_in[i] != lanes_out[i]:
            span = min(LANE_CHANGE_M, 0.5 * sp[-1])
            mid = cuts[i] + float(rng.uniform(0.3, 0.55)) * sp[-1]
            change = (mid - span / 2, mid + span / 2)
            w = _smoothstep((c - change[0]) / max(1e-9, change[1] - change[0]))
        else:
            w = np.zeros_like(c)
        lane_line = _offset_right(part, o_in + (o_out - o_in) * w + lateral_m)
        s_corner = -math.inf
        if pts:
            pa, pb = pts[-1][-1], lane_line[0]
            da = pts[-1][-1] - pts[-1][-2]
            db = lane_line[1] - lane_line[0]
            da, db = da / np.linalg.norm(da), db / np.linalg.norm(db)
            cross = da[0] * db[1] - da[1] * db[0]
            if abs(cross) > math.sin(math.radians(10.0)):
                u = ((pb - pa)[0] * db[1] - (pb - pa)[1] * db[0]) / cross
                ctrl = pa + u * da
            else:
                ctrl = 0.5 * (pa + pb)
            corner = _bezier(pa, ctrl, pb, 0.5)[1:-1]
            s_corner = s_acc
            if len(corner):
                s_acc += float(polyline_arc_lengths(np.vstack([pa, corner, pb]))[-1])
            else:
                s_acc += float(np.hypot(*(pb - pa)))
            pts.append(corner)
        s_part = s_acc
        out_legs.append(_RouteLeg(leg=leg, lane_in=lanes_in[i], lane_out=lanes_out[i], change_c=change,
                                  cut_in=cuts[i], s_corner=s_corner, s_part=s_part, turn_deg=turns[i]))
        pts.append(lane_line)
        s_acc += float(polyline_arc_lengths(lane_line)[-1])
    poly = np.vstack([p for p in pts if len(p)])
    keep = np.concatenate([[True], np.hypot(*np.diff(poly, axis=0).T) > 1e-6])
    poly = poly[keep]
    return _Route(legs=out_legs, polyline=poly, s_end=float(polyline_arc_lengths(poly)[-1]))


# -- the simulation ---------------------------------------------------------------------------------

@dataclass
class _Agent:
    cls: str
    size: tuple[float, float, float]
    colours: tuple[tuple, tuple]
    route: _Route
    v0: float
    s: float
    v: float
    t_knots: list = field(default_factory=list)
    s_knots: list = field(default_factory=list)
    v_knots: list = field(default_factory=list)
    a_knots: list = field(default_factory=list)
    active: bool = True
    passed_line: int = -1  # the route leg whose stop line this vehicle has committed to cross

    @property
    def length(self) -> float:
        return self.size[0]


def _idm(v: float, v0: float, gap: float, v_lead: float, ts) -> float:
    """Intelligent Driver Model acceleration (m/s^2) at speed v, desired v0, ``gap`` to a leader at v_lead."""
    a, b = ts.acceleration_mps2, ts.deceleration_mps2
    free = 1.0 - (v / max(v0, 0.1)) ** 4
    if not math.isfinite(gap):
        return a * free
    s_star = ts.min_gap_m + max(0.0, v * ts.time_headway_s + v * (v - v_lead) / (2 * math.sqrt(a * b)))
    return a * (free - (s_star / max(gap, 0.05)) ** 2)


def _state(ag: _Agent) -> tuple[int, float, tuple[int, ...]]:
    """(route leg index, leg coordinate of the centre, lanes occupied) of an agent now."""
    r = ag.route
    i = r.leg_at(ag.s)
    c = r.coord(i, ag.s)
    rl = r.legs[i]
    if rl.lane_in == rl.lane_out:
        lanes = (rl.lane_in,)
    elif c < rl.change_c[0] - ag.length / 2:
        lanes = (rl.lane_in,)
    elif c > rl.change_c[1] + ag.length / 2:
        lanes = (rl.lane_out,)
    else:
        lanes = (rl.lane_in, rl.lane_out)
    return i, c, lanes


LEFT_YIELD_M = 25.0


def _oncoming(net: _Network, occ: dict, agents: list, leg: _Leg) -> bool:
    """Whether traffic comes the other way: a vehicle moving within LEFT_YIELD_M of its stop line, or past it."""
    for j in leg.oncoming:
        other = net.legs[j]
        for lane in range(other.n_lanes):
            for c, idx in reversed(occ.get((j, lane), [])):
                if c < other.stop_c - LEFT_YIELD_M:
                    break
                if c + agents[idx].length / 2 >= other.stop_c or agents[idx].v > 2.0:
                    return True
    return False


def _simulate(net: _Network, agents: list[_Agent], t0_s: float, t1_s: float, ts, spawn, rng) -> None:
    """Step every agent from t0 to t1 (SIM_DT_S), recording its knots; ``spawn(t, occupancy)`` adds agents."""
    n_steps = int(math.ceil((t1_s - t0_s) / SIM_DT_S))
    dt = SIM_DT_S
    for step in range(n_steps + 1):
        t = t0_s + step * dt
        occ: dict[tuple[int, int], list[tuple[float, int]]] = {}
        states = {}
        for idx, ag in enumerate(agents):
            if not ag.active:
                continue
            i, c, lanes = _state(ag)
            states[idx] = (i, c, lanes)
            rl = ag.route.legs[i]
            for ln in lanes:
                occ.setdefault((rl.leg.index, ln), []).append((c, idx))
            if i > 0 and ag.s - ag.length / 2 < rl.s_part:
                # still in the junction: those behind it on the road it came from see it too, whichever
                # way they go on (it counts there as driving on past the end of that road's lane)
                prev = ag.route.legs[i - 1]
                c_prev = prev.leg.length - rl.cut_in + (ag.s - rl.s_corner)
                occ.setdefault((prev.leg.index, prev.lane_out), []).append((c_prev, idx))
        for lst in occ.values():
            lst.sort()
        if step == n_steps:
            break
        moves = []
        for idx, ag in enumerate(agents):
            if not ag.active:
                continue
            i, c, lanes = states[idx]
            rl = ag.route.legs[i]
            leg = rl.leg
            best_gap, v_lead = math.inf, 0.0
            for ln in lanes:
                lst = occ[(leg.index, ln)]
                k = lst.index((c, idx))
                if k + 1 < len(lst):
                    c2, j = lst[k + 1]
                    gap = c2 - c - (agents[j].length + ag.length) / 2
                    if gap < best_gap:
                        best_gap, v_lead = gap, agents[j].v
            if i + 1 < len(ag.route.legs):
                nxt = ag.route.legs[i + 1]
                lst = occ.get((nxt.leg.index, nxt.lane_in))
                if lst:
                    c2, j = lst[0]
                    gap = (leg.length - c) + c2 - (agents[j].length + ag.length) / 2
                    if gap < best_gap:
                        best_gap, v_lead = gap, agents[j].v
                # the stop line, a standing leader while the light is not green
                front = c + ag.length / 2
                if ag.passed_line != i and front < leg.stop_c:
                    if net.green(leg, t):
                        if rl.turn_deg > 30.0 and _oncoming(net, occ, agents, leg):
                            d = leg.stop_c - front  # a left turn waits for a gap in the oncoming traffic
                            if d < best_gap and (ag.v * ag.v / (2 * max(d, 1e-3)) <= HARD_BRAKE_MPS2 or ag.v < 0.5):
                                best_gap, v_lead = d, 0.0
                    else:
                        d = leg.stop_c - front
                        if ag.v * ag.v / (2 * max(d, 1e-3)) <= HARD_BRAKE_MPS2 or ag.v < 0.5:
                            if d < best_gap:
                                best_gap, v_lead = d, 0.0
                        else:
                            ag.passed_line = i
                elif front >= leg.stop_c:
                    ag.passed_line = i
            # slow down for a turn: in the corner and the 25 m before it
            v0 = ag.v0
            turning = (i + 1 < len(ag.route.legs) and abs(rl.turn_deg) > 30.0
                       and ag.route.legs[i + 1].s_corner - ag.s < 25.0)
            if turning or (i > 0 and abs(ag.route.legs[i - 1].turn_deg) > 30.0 and ag.s < rl.s_part):
                v0 = min(v0, ts.turn_speed_mps)
            a = _idm(ag.v, v0, best_gap, v_lead, ts)
            a = min(a, ts.acceleration_mps2)
            a = max(a, -HARD_BRAKE_MPS2 * 1.5)
            # the hard limit: never past the leader's old position minus HARD_GAP_M
            allow = best_gap - HARD_GAP_M if math.isfinite(best_gap) else math.inf
            moves.append((idx, a, allow))
        for idx, a, allow in moves:
            ag = agents[idx]
            v = ag.v
            if v + a * dt < 0:  # stops inside the step
                a = -v / dt if v > 0 else 0.0
            d = v * dt + 0.5 * a * dt * dt
            if d > max(allow, 0.0) + 1e-9:
                room = max(allow, 0.0)
                if v <= 1e-9:
                    a, d = 0.0, 0.0
                elif room <= 1e-6:
                    # already at the hard gap: stop within 1 ms (a brake no car has; it never happens in
                    # practice with IDM, but the gap is the promise)
                    tau = 1e-3
                    ag.t_knots.append(t)
                    ag.s_knots.append(ag.s)
                    ag.v_knots.append(v)
                    ag.a_knots.append(-v / tau)
                    ag.t_knots.append(t + tau)
                    ag.s_knots.append(ag.s + 0.5 * v * tau)
                    ag.v_knots.append(0.0)
                    ag.a_knots.append(0.0)
                    ag.s += 0.5 * v * tau
                    ag.v = 0.0
                    continue
                else:
                    # brake to stand exactly ``room`` ahead
                    a_stop = -v * v / (2 * room)
                    if v + a_stop * dt >= 0:  # still moving at the end of the step: travel less, keep going
                        a = 2 * (room - v * dt) / (dt * dt)
                        d = room
                    else:
                        a = a_stop
                        d = room
            if v + a * dt < -1e-9:  # stops inside the step: a knot where it stops
                tau = -v / a
                ag.t_knots.append(t)
                ag.s_knots.append(ag.s)
                ag.v_knots.append(v)
                ag.a_knots.append(a)
                ag.t_knots.append(t + tau)
                ag.s_knots.append(ag.s + v * tau + 0.5 * a * tau * tau)
                ag.v_knots.append(0.0)
                ag.a_knots.append(0.0)
                ag.s = ag.s_knots[-1]
                ag.v = 0.0
                continue
            ag.t_knots.append(t)
            ag.s_knots.append(ag.s)
            ag.v_knots.append(v)
            ag.a_knots.append(a)
            ag.s += v * dt + 0.5 * a * dt * dt
            ag.v = max(0.0, v + a * dt)
            if ag.s > ag.route.s_end - 1.0:  # off its route: on at constant speed, out of the simulation
                ag.active = False
                ag.t_knots.append(t + dt)
                ag.s_knots.append(ag.s)
                ag.v_knots.append(ag.v)
                ag.a_knots.append(0.0)
        spawn(t + dt, occ, agents)
    for ag in agents:  # the last knot: constant speed from here on
        if ag.active:
            ag.t_knots.append(t0_s + n_steps * dt)
            ag.s_knots.append(ag.s)
            ag.v_knots.append(ag.v)
            ag.a_knots.append(0.0)


def _draw_class(ts, rng: np.random.Generator) -> str:
    w = np.array([getattr(ts.classes, c) for c in VEHICLE_CLASSES], float)
    return VEHICLE_CLASSES[int(rng.choice(len(w), p=w / w.sum()))]


def place_traffic(spec, world: World, path: CameraPath, rng: np.random.Generator, *,
                  first_id: int = 1) -> list[VehiclePath]:
    """The road users of ``spec.traffic`` the camera sees: simulated traffic, parked cars, pedestrians.

    Returns VehiclePaths numbered from ``first_id`` (moving traffic, then parked, then pedestrians),
    only those whose footprint comes within view at some frame.
    """
    ts = spec.traffic
    img = spec.image
    duration_s = (img.n_frames - 1) / img.fps
    fx0, fy0, fx1, fy1 = ground_footprint(path, img.width_px, img.height_px)
    view = (fx0 - 15.0, fy0 - 15.0, fx1 + 15.0, fy1 + 15.0)
    out: list[VehiclePath] = []
    need_net = ts.density_per_lane_km > 0 or ts.cyclists_per_lane_km > 0 or ts.kerb_parking_per_km > 0 \
        or ts.pedestrians_per_km > 0
    if not need_net:
        return _number(out + _apart(_lot_parking(spec, world, view, rng)), first_id)
    margin = 60.0
    area = (fx0 - margin, fy0 - margin, fx1 + margin, fy1 + margin)
    net = _Network(world, ts, area, rng)
    if ts.density_per_lane_km > 0 or ts.cyclists_per_lane_km > 0:
        out += _moving(spec, net, area, view, duration_s, rng)
    out += _apart(_kerb_parking(spec, net, view, rng) + _lot_parking(spec, world, view, rng))
    out += _pedestrians(spec, net, view, duration_s, path, rng)
    return _number(out, first_id)


def _apart(parked: list[VehiclePath], gap_m: float = 0.2) -> list[VehiclePath]:
    """The parked vehicles less any that would touch one kept before it (a kerb where a lot's edge comes close,
    two kerbs at a bend)."""
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    out = []
    for vp in parked:
        x, y, th = vp.pose(0.0)
        corners = _rect_corners(x, y, vp.size_m[0], vp.size_m[1], th)
        if any(math.hypot(x - c[0], y - c[1]) < 14.0 and rects_overlap(corners, k, gap_m) for c, k in kept):
            continue
        kept.append((np.array([x, y]), corners))
        out.append(vp)
    return out


def _number(vps: list[VehiclePath], first_id: int) -> list[VehiclePath]:
    for k, vp in enumerate(vps):
        vp.vehicle_id = first_id + k
    return vps


def _in_box(p: np.ndarray, box, pad: float = 0.0) -> np.ndarray:
    return (p[..., 0] > box[0] - pad) & (p[..., 0] < box[2] + pad) & (p[..., 1] > box[1] - pad) & (
        p[..., 1] < box[3] + pad)


def _leg_in_area(leg: _Leg, area) -> bool:
    return bool(_in_box(leg.centre, area).any())


def _moving(spec, net: _Network, area, view, duration_s: float, rng: np.random.Generator) -> list[VehiclePath]:
    ts = spec.traffic
    lo, hi = ts.speed_range_mps
    t0 = -ts.warmup_s
    route_len = hi * (ts.warmup_s + duration_s) + 150.0
    agents: list[_Agent] = []

    def new_agent(leg_i: int, lane: int, c: float, cyclist: bool, drawn=None) -> _Agent:
        cls, size = drawn or draw(cyclist)
        v0 = float(rng.uniform(3.5, 6.0)) if cyclist else float(rng.uniform(lo, hi))
        if cls in ("bus", "truck"):
            v0 = min(v0, float(rng.uniform(lo, 0.5 * (lo + hi))))
        leg = net.legs[leg_i]
        lateral = (leg.lane_w / 2 - size[1] / 2 - 0.15) if cyclist else 0.0
        route = _build_route(net, leg_i, lane, route_len, ts, rng, lateral_m=lateral, kerb_lane=cyclist)
        return _Agent(cls=cls, size=size, colours=_draw_colours(cls, rng), route=route, v0=v0, s=c, v=0.0)

    def draw(cyclist: bool) -> tuple[str, tuple]:
        cls = "cyclist" if cyclist else _draw_class(ts, rng)
        return cls, _draw_size(cls, rng)

    # the lanes in the area, filled at the density with random gaps; entries from outside the area
    # fed at the flow density x speed
    streams = []  # (leg index, lane, per-metre density)
    for li, leg in enumerate(net.legs):
        if not _leg_in_area(leg, area):
            continue
        for lane in range(leg.n_lanes):
            rho = ts.density_per_lane_km / 1000.0
            if lane == leg.n_lanes - 1:
                rho_cyc = ts.cyclists_per_lane_km / 1000.0
            else:
                rho_cyc = 0.0
            streams.append((li, lane, rho, rho_cyc))
            for rate, cyc in ((rho, False), (rho_cyc, True)):
                if rate <= 0:
                    continue
                c = float(rng.exponential(1.0 / rate))
                while c < leg.stop_c - 4.0:
                    ag = new_agent(li, lane, c, cyc)
                    ag.v = min(ag.v0, 0.6 * ag.v0)
                    agents.append(ag)
                    c += max(ag.length + ts.min_gap_m + 4.0, float(rng.exponential(1.0 / rate)))
    # settle the initial fill: drop agents that overlap the one ahead in their lane
    agents.sort(key=lambda a: (a.route.legs[0].leg.index, a.route.legs[0].lane_in, a.s))
    kept: list[_Agent] = []
    for ag in agents:
        if kept and kept[-1].route.legs[0].leg is ag.route.legs[0].leg and \
                kept[-1].route.legs[0].lane_in == ag.route.legs[0].lane_in and \
                ag.s - ag.length / 2 - ts.min_gap_m < kept[-1].s + kept[-1].length / 2:
            continue
        kept.append(ag)
    agents[:] = kept
    entries = [(li, lane, rho, rc) for li, lane, rho, rc in streams if not net.inside[net.legs[li].entry]]
    mean_v = 0.5 * (lo + hi)
    next_t = {}
    for li, lane, rho, rc in entries:
        for cyc, rate in ((False, rho * mean_v), (True, rc * 4.5)):
            if rate > 0:
                next_t[(li, lane, cyc)] = t0 + float(rng.exponential(1.0 / rate))

    pending: dict = {}  # an arrival waiting for room keeps its class and size

    def spawn(t: float, occ, agents_: list[_Agent]) -> None:
        for li, lane, rho, rc in entries:
            for cyc, rate in ((False, rho * mean_v), (True, rc * 4.5)):
                key = (li, lane, cyc)
                if key not in next_t or t < next_t[key]:
                    continue
                lst = occ.get((li, lane), [])
                drawn = pending.pop(key, None) or draw(cyc)
                rear = lst[0][0] - agents_[lst[0][1]].length / 2 if lst else math.inf
                room = rear - drawn[1][0] / 2 - ts.min_gap_m
                if room < 3.0:  # no room at the entry: it arrives a little later
                    pending[key] = drawn
                    next_t[key] = t + 1.0
                    continue
                ag = new_agent(li, lane, 0.0, cyc, drawn)
                ag.v = min(ag.v0, math.sqrt(max(0.0, room - 3.0) * ts.deceleration_mps2))
                agents_.append(ag)
                next_t[key] = t + float(rng.exponential(1.0 / rate))

    _simulate(net, agents, t0, duration_s, ts, spawn, rng)
    out = []
    times = np.linspace(0.0, duration_s, max(2, int(math.ceil(duration_s / 0.5)) + 1))
    for ag in agents:
        if not ag.t_knots or len(ag.s_knots) == 0:
            continue
        t_k, s_k = np.asarray(ag.t_knots, float), np.asarray(ag.s_knots, float)
        vp = VehiclePath(vehicle_id=0, kind="profile", route_m=ag.route.polyline, s0_m=0.0, v0_mps=ag.v0,
                         size_m=ag.size, body_rgb=ag.colours[0], cabin_rgb=ag.colours[1], vclass=ag.cls,
                         profile_t_s=t_k, profile_s_m=s_k, profile_v_mps=np.asarray(ag.v_knots, float),
                         profile_a_mps2=np.asarray(ag.a_knots, float))
        vp.s0_m = vp._profile_s0
        pts = np.array([vp.pose(float(t))[:2] for t in times if t >= t_k[0] - 1e-9] or [[np.inf, np.inf]])
        if _in_box(pts, view, pad=ag.length).any():
            out.append(vp)
    return out


def _kerb_parking(spec, net: _Network, view, rng: np.random.Generator) -> list[VehiclePath]:
    """Cars (a few vans) along the kerbs of roads with a parking lane, away from the junctions."""
    ts = spec.traffic
    if ts.kerb_parking_per_km <= 0:
        return []
    out = []
    slot = 1000.0 / ts.kerb_parking_per_km
    for leg in net.legs:
        if leg.park_w <= 0 or not _in_box(leg.centre, view, pad=10.0).any():
            continue
        s = polyline_arc_lengths(leg.centre)
        clear = JUNCTION_CLEAR_M * leg.width + 2.0  # from where the corners start, plus a little (was 8 m)
        c = clear + float(rng.uniform(0, slot))
        while c < leg.length - clear:
            cls = "van" if rng.uniform() < 0.12 else "car"
            size = _draw_size(cls, rng)
            a, b = c - size[0] / 2, c + size[0] / 2
            if b < leg.length - clear:
                line = np.stack([np.interp([a, c, b], s, leg.centre[:, 0]), np.interp([a, c, b], s, leg.centre[:, 1])],
                                axis=1)
                off = leg.width / 2 - leg.park_w / 2 + float(rng.uniform(-0.15, 0.15))
                seg = _offset_right(line, off)
                if _in_box(seg[1], view):
                    body, glass = _draw_colours(cls, rng)
                    out.append(VehiclePath(vehicle_id=0, kind="parked", route_m=seg[[0, 2]],
                                           s0_m=float(np.hypot(*(seg[1] - seg[0]))), v0_mps=0.0, size_m=size,
                                           body_rgb=body, cabin_rgb=glass, vclass=cls))
            c += max(size[0] + 0.8, float(rng.normal(slot, 0.25 * slot)))
    return out


def _lot_parking(spec, world: World, view, rng: np.random.Generator) -> list[VehiclePath]:
    """Fill ``lot_fill_fraction`` of the stalls in view, each car a little off the stall's centre and axis."""
    ts = spec.traffic
    if ts.lot_fill_fraction <= 0 or not world.stalls:
        return []
    out = []
    for sx, sy, th in world.stalls:
        if not _in_box(np.array([sx, sy]), view) or rng.uniform() >= ts.lot_fill_fraction:
            continue
        size = _draw_size("car", rng)
        th = th + (0.0 if rng.uniform() < 0.7 else math.pi) + float(rng.normal(0, 0.03))
        d = np.array([math.cos(th), math.sin(th)])
        p = np.array([sx, sy]) + rng.uniform(-0.15, 0.15, 2) + d * float(rng.uniform(-0.1, 0.1))
        body, glass = _draw_colours("car", rng)
        out.append(VehiclePath(vehicle_id=0, kind="parked", route_m=np.array([p - d, p + d]), s0_m=1.0, v0_mps=0.0,
                               size_m=size, body_rgb=body, cabin_rgb=glass, vclass="car"))
    return out


def _pedestrians(spec, net: _Network, view, duration_s: float, path: CameraPath,
                 rng: np.random.Generator) -> list[VehiclePath]:
    """Walkers on the footpaths (FOOTPATH_M beyond the kerb, each keeping to its right), between junctions;
    one in six stands. Walkers keep 0.7 m apart at every frame time."""
    ts = spec.traffic
    if ts.pedestrians_per_km <= 0:
        return []
    times = np.arange(spec.image.n_frames) / spec.image.fps
    placed: list[np.ndarray] = []
    out = []
    for leg in net.legs:  # each directed leg: the footpath on its right-hand side, walked both ways
        if not _in_box(leg.centre, view, pad=5.0).any():
            continue
        clear = JUNCTION_CLEAR_M * leg.width + 2.5
        usable = leg.length - 2 * clear
        if usable < 6.0:
            continue
        n = int(rng.poisson(ts.pedestrians_per_km / 1000.0 * usable))
        side = leg.width / 2 + FOOTPATH_M
        for _ in range(n):
            forward = bool(rng.integers(0, 2))
            speed = 0.0 if rng.uniform() < 1 / 6 else float(rng.uniform(1.0, 1.7))
            travel = speed * duration_s
            if travel > usable - 1.0:
                continue
            c0 = clear + float(rng.uniform(0.5, usable - travel - 0.5))  # where the walk starts, leg coordinate
            part = _trim(leg.centre, start_m=clear, end_m=clear)
            # forward: the walker's right is away from the road; backward: toward it
            line = _offset_right(part, side + (WALK_SIDE_M if forward else -WALK_SIDE_M))
            sr = polyline_arc_lengths(line)
            frac = (c0 - clear) / max(1e-9, usable)
            if forward:
                route, s0 = line, frac * sr[-1]
            else:
                route, s0 = line[::-1], (1.0 - frac) * sr[-1]
            size = _draw_size("pedestrian", rng)
            body, hair = _draw_colours("pedestrian", rng)
            vp = VehiclePath(vehicle_id=0, kind="constant", route_m=route, s0_m=float(s0), v0_mps=speed,
                             size_m=size, body_rgb=body, cabin_rgb=hair, vclass="pedestrian")
            pts = np.array([vp.pose(float(t))[:2] for t in times])
            if not _in_box(pts, view).any():
                continue
            if any(np.min(np.hypot(*(pts - q).T)) < 0.7 for q in placed):
                continue
            placed.append(pts)
            out.append(vp)
    return out


# -- street furniture: trees over the road, footbridges -------------------------------------------

def street_furniture(spec, roads, buildings: list[Building], trees: list[Tree], seen,
                     rng: np.random.Generator) -> tuple[list[Tree], list[Building]]:
    """Street trees whose crowns overhang the road, and footbridges across roads in view.

    Returns the trees (the old ones, less those a bridge would cut through, plus the street
    trees) and the bridges (decks with parapets on two piers, as :class:`Building` s). Street
    crowns start CROWN_CLEAR_M above the road, above every road user.
    """
    ts = spec.traffic
    fx0, fy0, fx1, fy1 = seen
    view = (fx0 - 10.0, fy0 - 10.0, fx1 + 10.0, fy1 + 10.0)
    trees = list(trees)
    bridges: list[Building] = []
    near = [r for r in roads if _in_box(r.centre_m, view, pad=20.0).any()]
    for _ in range(ts.bridges):
        for _attempt in range(200):
            r = near[int(rng.integers(0, len(near)))] if near else None
            if r is None:
                break
            s = polyline_arc_lengths(r.centre_m)
            if s[-1] < 25.0:
                continue
            at = float(rng.uniform(0.25, 0.75)) * s[-1]
            p = np.array([np.interp(at, s, r.centre_m[:, 0]), np.interp(at, s, r.centre_m[:, 1])])
            if not _in_box(p, (fx0 + 3, fy0 + 3, fx1 - 3, fy1 - 3)):
                continue
            q = np.array([np.interp(at + 1.0, s, r.centre_m[:, 0]), np.interp(at + 1.0, s, r.centre_m[:, 1])])
            along = math.atan2(*(q - p)[::-1])
            yaw = along + 0.5 * math.pi  # the deck spans the road
            span = r.width_m + 2 * (FOOTPATH_M + 3.2)
            deck_w = float(rng.uniform(3.5, 6.0))
            clearance = float(rng.uniform(5.5, 6.5))
            corners = _rect_corners(p[0], p[1], span, deck_w, yaw)
            piers = [p + e * (span / 2 - 0.7) * np.array([math.cos(yaw), math.sin(yaw)]) for e in (-1, 1)]
            ok = not any(rects_overlap(corners, b.corners_xy(), 1.0) for b in buildings + bridges)
            for other in roads:
                if other is r or not ok:
                    continue
                if distance_to_polyline(np.array(piers), other.centre_m).min() < other.width_m / 2 + 1.5:
                    ok = False
                if distance_to_polyline(corners, other.centre_m).min() < other.width_m / 2 + 0.5:
                    ok = False  # not over a junction either
            if not ok:
                continue
            deck_t = 0.9
            parts = (Box((0.0, 0.0, clearance + deck_t / 2), (span, deck_w, deck_t)),
                     Box((0.0, -(deck_w / 2 - 0.12), clearance + deck_t + 0.5), (span, 0.24, 1.0)),
                     Box((0.0, deck_w / 2 - 0.12, clearance + deck_t + 0.5), (span, 0.24, 1.0)),
                     Box((-(span / 2 - 0.7), 0.0, clearance / 2), (1.0, 0.7 * deck_w, clearance)),
                     Box((span / 2 - 0.7, 0.0, clearance / 2), (1.0, 0.7 * deck_w, clearance)))
            top = clearance + deck_t + 1.0
            bridges.append(Building(centre=(float(p[0]), float(p[1]), top / 2), size=(span, deck_w, top),
                                    yaw_rad=float(yaw), parts=parts, roof_variant=1))
            trees = [t for t in trees if point_rect_distance(np.array([[t.x_m, t.y_m]]), corners)[0] > t.reach_m + 0.5]
            break
    if ts.street_trees_per_km > 0:
        gap = 1000.0 / ts.street_trees_per_km
        trunks = np.array([[t.x_m, t.y_m] for t in trees]).reshape(-1, 2)
        new: list[Tree] = []
        for r in near:
            s = polyline_arc_lengths(r.centre_m)
            for side in (1.0, -1.0):
                c = float(rng.uniform(0, gap))
                while c < s[-1]:
                    here = c
                    c += max(4.0, float(rng.normal(gap, 0.2 * gap)))
                    if here < JUNCTION_CLEAR_M * r.width_m + 6.0 or here > s[-1] - JUNCTION_CLEAR_M * r.width_m - 6.0:
                        continue
                    p2 = np.stack([np.interp([here, here + 0.5], s, r.centre_m[:, 0]),
                                   np.interp([here, here + 0.5], s, r.centre_m[:, 1])], axis=1)
                    p = _offset_right(p2, side * (r.width_m / 2 + STREET_TREE_M))[0]
                    if not _in_box(p, view):
                        continue
                    radius = float(rng.uniform(2.8, 4.6))
                    half = float(rng.uniform(1.6, 2.6))
                    height = CROWN_CLEAR_M + float(rng.uniform(0.0, 2.0)) + 2 * half
                    # the trunk clear of every road but its own kerb, of buildings, bridges and trunks
                    if any(distance_to_polyline(p[None], o.centre_m)[0] < o.width_m / 2 + STREET_TREE_M - 0.05
                           for o in near if o is not r):
                        continue
                    if any(point_rect_distance(p[None], b.corners_xy())[0] < radius + 0.5 for b in buildings + bridges):
                        continue
                    others = np.vstack([trunks, np.array([[t.x_m, t.y_m] for t in new]).reshape(-1, 2)])
                    if len(others) and np.hypot(*(others - p).T).min() < 3.0:
                        continue
                    # a broad-leaved crown of lobes (scenes.vegetation), none lower than the crown's bottom
                    new.append(Tree(x_m=float(p[0]), y_m=float(p[1]), height_m=height, crown_radius_m=radius,
                                    crown_half_height_m=half,
                                    variant=int(rng.integers(0, len(CROWN_BASES) - len(CONIFER_VARIANTS))),
                                    lobes=crown_lobes(rng, height_m=height, radius_m=radius, half_height_m=half),
                                    overhangs_road=True))
        trees += new
    return trees, bridges


def overpass_shadow_polygons(bridges: list[Building], light) -> list[np.ndarray]:
    """Ground polygons (P, 2) in the shadow of each bridge's deck (flat light paints them)."""
    to_sun = sun_direction(light.sun_elevation_deg, light.sun_azimuth_deg)
    away = -to_sun[:2] / max(1e-9, to_sun[2])
    polys = []
    for b in bridges:
        deck = b.parts[0]
        lo, hi = deck.centre[2] - deck.size[2] / 2, deck.centre[2] + deck.size[2] / 2
        c = _rect_corners(b.centre[0], b.centre[1], deck.size[0], deck.size[1], b.yaw_rad)
        hull = cv2.convexHull(np.vstack([c + away * lo, c + away * hi]).astype(np.float32))[:, 0]
        polys.append(hull.astype(np.float64))
    return polys
