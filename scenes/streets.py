"""Streets painted on the ground: verges and sidewalks, asphalt, kerbs, lane markings, junctions with
zebra crossings and stop lines.

Along every road side a block gets a strip: a sidewalk of paving with a kerb at the
road's edge where the block is built up or a parking lot, a verge of rough grass
(soft-edged toward the field) elsewhere. Junctions (three roads or more) are plain
asphalt over the ends of the lane markings; ``crosswalk_fraction`` of them have a zebra
crossing on every road into them, and the lanes that enter a junction end at a stop
line (right-hand traffic: the right half of the road, seen driving toward the junction).

Painting only: shapes in metres go to the ground canvas of :func:`scenes.world.build_world`.
"""

from __future__ import annotations

import numpy as np

from scenes.motion import polyline_arc_lengths
from scenes.world import KERB_RGB, MARK_RGB, _offset_right, _trim

__all__ = ["paint_streets", "junction_marks", "JUNCTION_RADIUS_FACTOR", "ZEBRA_STRIPE_M", "ZEBRA_LENGTH_M"]

JUNCTION_RADIUS_FACTOR = 0.55  # a junction's plain asphalt: this times its widest road's width, round its node
ZEBRA_STRIPE_M = 0.5  # stripes this wide, as far apart, across the road
ZEBRA_LENGTH_M = 3.0  # along the road
STOP_LINE_M = 0.4
MARK_OPACITY = (0.8, 0.95)  # lane lines, crossings and stop lines: KIT AIS's markings stand out crisp and white


def _strip(line: np.ndarray, inner_m: float, outer_m: float) -> np.ndarray:
    """The band between offsets ``inner_m`` and ``outer_m`` (right of the line's direction) as a polygon."""
    return np.vstack([_offset_right(line, inner_m), _offset_right(line, outer_m)[::-1]])


def _at(line: np.ndarray, s_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Point and unit tangent of a polyline at arc length ``s_m``."""
    s = polyline_arc_lengths(line)
    p = np.array([np.interp(s_m, s, line[:, 0]), np.interp(s_m, s, line[:, 1])])
    k = int(np.clip(np.searchsorted(s, s_m), 1, len(line) - 1))
    t = line[k] - line[k - 1]
    return p, t / max(1e-12, float(np.hypot(*t)))


def junction_marks(roads, node: int, node_m: np.ndarray, radius_m: float, *, zebra: bool):
    """Zebra stripes and stop lines of one junction: (stripes, stop lines), each a list of quads (4, 2) in metres.

    For each road into the junction: the crossing starts ``radius_m + 0.8`` m from the node, its stripes
    running along the road; the stop line lies 0.8 m beyond it (or where the crossing would start), over
    the half of the road whose traffic drives toward the node.
    """
    stripes, stops = [], []
    for r in roads:
        if node not in r.nodes:
            continue
        line = r.centre_m if r.nodes[0] == node else r.centre_m[::-1]  # leaving the node
        length = polyline_arc_lengths(line)[-1]
        d0 = radius_m + 0.8
        d_stop = d0 + (ZEBRA_LENGTH_M + 0.8 if zebra else 0.0)
        if d_stop + 2.0 > 0.5 * length:
            continue
        half = r.width_m / 2
        if zebra:
            p, t = _at(line, d0 + ZEBRA_LENGTH_M / 2)
            n = np.array([t[1], -t[0]])  # right of the direction leaving the node
            for u in np.arange(-half + 0.5 + ZEBRA_STRIPE_M / 2, half - 0.5, 2 * ZEBRA_STRIPE_M):
                c = p + u * n
                a, b = t * ZEBRA_LENGTH_M / 2, n * ZEBRA_STRIPE_M / 2
                stripes.append(np.array([c - a - b, c + a - b, c + a + b, c - a + b]))
        p, t = _at(line, d_stop + STOP_LINE_M / 2)
        n = np.array([t[1], -t[0]])
        # traffic toward the node drives on its right: to the left of the leaving direction
        a, b = t * STOP_LINE_M / 2, -n
        stops.append(np.array([p - a + 0.1 * b, p + a + 0.1 * b, p + a + (half - 0.3) * b, p - a + (half - 0.3) * b]))
    return stripes, stops


def paint_streets(canvas, *, roads, nodes_m: np.ndarray, cells, kinds, edges, widths_m: tuple[float, float],
                  material, crosswalk_fraction: float, rng: np.random.Generator, kerb_parking: bool = False) -> None:
    """Paint verges, sidewalks, roads, kerbs, markings and junctions onto ``canvas`` (a ``scenes.world._Canvas``).

    ``material(name, gain)`` gives a ground material's paint value (:mod:`scenes.textures`);
    ``cells`` and ``kinds`` the blocks and their land use; ``edges`` the road graph's edges
    ``(a, b, centre line, is road, major)``; ``kerb_parking``: traffic parks along the kerbs (a parking
    lane, marked, on roads wide enough for one).
    """
    w_major, w_minor = widths_m
    deg = np.bincount(np.array([r.nodes for r in roads]).ravel(), minlength=len(nodes_m)) if roads else np.zeros(0)
    junctions = [k for k in range(len(nodes_m)) if deg[k] >= 3]
    widest = {n: max(r.width_m for r in roads if n in r.nodes) for n in junctions}
    end_m = JUNCTION_RADIUS_FACTOR * w_major + 1.0  # kerbs stop short of the junction

    # -- verges and sidewalks, block side by block side ---------------------------------------
    kerbs = []
    for key, kind in kinds.items():
        _, ks = cells[key]
        built = kind in ("yard", "parking")
        for side in range(4):
            a, b, line, is_road, major = edges[ks[side]]
            if not is_road:
                continue
            w = w_major if major else w_minor
            inward = -1.0 if side in (0, 1) else 1.0  # offset sign toward the block (its polygon runs anticlockwise)
            if built:
                sw = float(rng.uniform(1.8, 3.0))
                canvas.polygon([_strip(line, inward * (w / 2 - 0.2), inward * (w / 2 + sw))],
                               material("paving", rng.uniform(0.92, 1.06) * np.ones(3)))
                if polyline_arc_lengths(line)[-1] > 2 * end_m + 2:
                    kerbs.append(_offset_right(_trim(line, start_m=end_m, end_m=end_m), inward * (w / 2 + 0.12)))
            else:
                vw = float(rng.uniform(1.2, 3.5))
                canvas.polygon([_strip(line, inward * (w / 2 - 0.2), inward * (w / 2 + vw))],
                               material("verge", rng.uniform(0.92, 1.06) * np.ones(3)), feather_m=0.5)

    # -- asphalt, patches -----------------------------------------------------------------------
    for r in roads:
        canvas.lines([r.centre_m], r.width_m, material("asphalt", rng.uniform(0.94, 1.06) * np.ones(3)))
    for r in roads:
        n = int(rng.poisson(polyline_arc_lengths(r.centre_m)[-1] / 40.0))
        if n:
            at = r.centre_m[rng.integers(0, len(r.centre_m), n)] + rng.uniform(-1, 1, (n, 2)) * r.width_m / 4
            canvas.ellipses(at, rng.uniform(0.6, 2.2, (n, 2)), rng.uniform(0, 180, n),
                            material("asphalt", rng.uniform(0.8, 1.15) * np.ones(3)), opacity=0.8)
    if kerbs:
        canvas.lines(kerbs, 0.3, KERB_RGB, opacity=0.95)

    # -- lane markings on main roads: edge lines, the centre line, and where traffic has them
    # (:func:`scenes.traffic.lane_layout`) dashed lines between the lanes of one direction and a solid
    # line along the parking lane; crisp and bright, as fresh thermoplastic paint is from above --
    from scenes.traffic import lane_layout  # here: scenes.traffic builds on scenes.world

    for r in roads:
        if not r.major:
            continue
        n_lanes, lane_w, park_w = lane_layout(r.width_m, kerb_parking=kerb_parking)
        edge = r.width_m / 2 - 0.35
        solid = [_offset_right(r.centre_m, edge), _offset_right(r.centre_m, -edge)]
        if park_w > 0:
            solid += [_offset_right(r.centre_m, e * (r.width_m / 2 - park_w)) for e in (1, -1)]
        canvas.lines(solid, 0.2, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
        s = polyline_arc_lengths(r.centre_m)
        dashes = []
        offsets = [0.0] + [e * k * lane_w for k in range(1, n_lanes) for e in (1, -1)]
        for off in offsets:
            line = _offset_right(r.centre_m, off) if off else r.centre_m
            for a in np.arange(rng.uniform(0, 9), s[-1] - 3.0, 9.0):  # 3 m dash, 6 m gap
                t = np.linspace(a, a + 3.0, 4)
                dashes.append(np.stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])], axis=1))
        canvas.lines(dashes, 0.15, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))

    # -- junctions: plain asphalt over the markings' ends, then crossings and stop lines -----------
    if not junctions:
        return
    radius = np.array([JUNCTION_RADIUS_FACTOR * widest[n] for n in junctions])
    canvas.ellipses(nodes_m[junctions], np.repeat(radius[:, None], 2, axis=1), np.zeros(len(junctions)),
                    material("asphalt"))
    stripes, stops = [], []
    for n, rad in zip(junctions, radius):
        zs, st = junction_marks(roads, n, nodes_m[n], float(rad), zebra=bool(rng.uniform() < crosswalk_fraction))
        stripes += zs
        stops += st
    if stripes:
        canvas.polygon(stripes, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
    if stops:
        canvas.polygon(stops, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
