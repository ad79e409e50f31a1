"""Streets painted on the ground: verges and sidewalks, asphalt, kerbs, lane markings, junctions with
zebra crossings and stop lines.

Along every road side a block gets a strip: a sidewalk of paving with a kerb at the
road's edge where the block is built up or a parking lot, a verge of rough grass
(soft-edged toward the field) elsewhere. Junctions (three roads or more) are plain
asphalt over the ends of the lane markings; ``crosswalk_fraction`` of them have a zebra
crossing on every road into them, and the lanes that enter a junction end at a stop
line (right-hand traffic: the right half of the road, seen driving toward the junction).

Lane markings on main roads and on any road of two lanes a direction, from a junction's mouth to
the next (corners where two marked roads meet at an angle are paved plain, as junctions are).

Small things (:func:`paint_clutter`, ``world.clutter``): manholes, gullies, patched cuts, sealed
cracks, oil strips down the lanes, direction arrows before junctions, lamp posts and their
shadows, tramlines in fields, and in built blocks bins, sheds, planters and garden walls with
theirs (the dormer rows on roofs that come with them: :func:`scenes.world._roof_rows`).

Painting only: shapes in metres go to the ground canvas of :func:`scenes.world.build_world`.
"""

from __future__ import annotations

import cv2
import numpy as np

from scenes.motion import polyline_arc_lengths
from scenes.world import KERB_RGB, MARK_RGB, _offset_right, _trim

__all__ = ["paint_streets", "paint_clutter", "junction_marks", "JUNCTION_RADIUS_FACTOR", "ZEBRA_STRIPE_M",
           "ZEBRA_LENGTH_M"]

JUNCTION_RADIUS_FACTOR = 0.55  # a junction's plain asphalt: this times its widest road's width, round its node
ZEBRA_STRIPE_M = 0.5  # stripes this wide, as far apart, across the road
ZEBRA_LENGTH_M = 3.0  # along the road
STOP_LINE_M = 0.4
MARK_OPACITY = (0.8, 0.95)  # lane lines, crossings and stop lines: KIT AIS's markings stand out crisp and white
# ``world.edges`` 1: light granite kerbs with a gutter of dark setts on the road's side, and minor roads marked
# (:func:`_paint_minor_marks`): thin lines of high contrast, as KIT AIS's streets are full of. (Lighter sidewalk
# paving, 2-3 m bands, was tried: it added as many strong gradients but steepened the spectrum, as large areas
# of contrast do; thin lines flatten it, docs/realism.md)
GUTTER_RGB = (64, 64, 66)
KERB_EDGES_RGB = (218, 216, 208)  # granite kerb stones, the lightest line of a street from above
GUTTER_M = 0.3
MINOR_LINE_M = 0.12  # a minor road's dashed centre line and parking-lane lines: narrower than a main road's


def _marked(road, lanes_per_direction: int) -> bool:
    """Whether a road has lane markings: main roads, and any road of two lanes a direction or more (a wide
    minor road is marked as a main one is: its traffic keeps to lanes, :func:`scenes.traffic.lane_layout`)."""
    return bool(road.major or lanes_per_direction >= 2)


def _marked_corners(roads, deg: np.ndarray, kerb_parking: bool) -> dict[int, float]:
    """Nodes where exactly two roads meet, turning by more than 30 deg, one of them marked: {node: wider width}."""
    from scenes.traffic import lane_layout  # here: scenes.traffic builds on scenes.world

    leaving: dict[int, list[tuple[np.ndarray, float, bool]]] = {}
    for r in roads:
        marked = _marked(r, lane_layout(r.width_m, kerb_parking=kerb_parking)[0])
        for node, line in ((r.nodes[0], r.centre_m), (r.nodes[1], r.centre_m[::-1])):
            if deg[node] == 2:
                t = line[min(2, len(line) - 1)] - line[0]
                leaving.setdefault(node, []).append((t / max(1e-12, float(np.hypot(*t))), r.width_m, marked))
    return {n: max(w for _, w, _ in v) for n, v in leaving.items()
            if len(v) == 2 and (v[0][2] or v[1][2]) and float(v[0][0] @ v[1][0]) > -np.cos(np.radians(30.0))}


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
                  material, crosswalk_fraction: float, rng: np.random.Generator, kerb_parking: bool = False,
                  contrast: float = 0.0, rng_contrast: np.random.Generator | None = None) -> None:
    """Paint verges, sidewalks, roads, kerbs, markings and junctions onto ``canvas`` (a ``scenes.world._Canvas``).

    ``material(name, gain)`` gives a ground material's paint value (:mod:`scenes.textures`);
    ``cells`` and ``kinds`` the blocks and their land use; ``edges`` the road graph's edges
    ``(a, b, centre line, is road, major)``; ``kerb_parking``: traffic parks along the kerbs (a parking
    lane, marked, on roads wide enough for one). ``contrast`` (``world.edges``, 0-1): kerbs lighter (toward
    KERB_EDGES_RGB), a dark gutter beside them (``contrast`` opaque), and that share of the unmarked roads
    with a dashed centre line and, where traffic parks, the parking lanes' lines (chosen by ``rng_contrast``,
    so ``rng`` draws the same as without).
    """
    w_major, w_minor = widths_m
    deg = np.bincount(np.array([r.nodes for r in roads]).ravel(), minlength=len(nodes_m)) if roads else np.zeros(0)
    junctions = [k for k in range(len(nodes_m)) if deg[k] >= 3]
    widest = {n: max(r.width_m for r in roads if n in r.nodes) for n in junctions}
    end_m = JUNCTION_RADIUS_FACTOR * w_major + 1.0  # kerbs stop short of the junction

    # -- verges and sidewalks, block side by block side ---------------------------------------
    kerbs, kerb_sides = [], []
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
                    kerb_sides.append((kerbs[-1], inward))
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
        kerb_rgb = tuple((1.0 - contrast) * a + contrast * b for a, b in zip(KERB_RGB, KERB_EDGES_RGB))
        canvas.lines(kerbs, 0.3, kerb_rgb, opacity=0.95)
        if contrast > 0:  # the gutter: a row of dark setts on the road's side of the kerb
            canvas.lines([_offset_right(k, -np.sign(o) * (0.15 + GUTTER_M / 2)) for k, o in kerb_sides],
                         GUTTER_M, GUTTER_RGB, opacity=float(contrast))

    # -- lane markings on main roads and on minor roads of two lanes a direction (:func:`_marked`): edge
    # lines, the centre line, and where traffic has them (:func:`scenes.traffic.lane_layout`) dashed lines
    # between the lanes of one direction and a solid line along the parking lane; crisp and bright, as
    # fresh thermoplastic paint is from above --
    from scenes.traffic import lane_layout  # here: scenes.traffic builds on scenes.world

    corners = _marked_corners(roads, deg, kerb_parking)
    plain_width = {**corners, **widest}  # nodes paved plain, and the widest road into each
    for r in roads:
        n_lanes, lane_w, park_w = lane_layout(r.width_m, kerb_parking=kerb_parking)
        marked = _marked(r, n_lanes)
        minor = not marked and contrast > 0 and rng_contrast is not None and rng_contrast.uniform() < contrast
        if not (marked or minor):
            continue
        # the lines start at the junction's mouth (its plain asphalt and the stop line), not inside the
        # crossing road's carriageway
        ends = [JUNCTION_RADIUS_FACTOR * plain_width[n] + 0.8 if n in plain_width else 0.0 for n in r.nodes]
        if polyline_arc_lengths(r.centre_m)[-1] - sum(ends) < 3.0:
            continue
        centre = _trim(r.centre_m, start_m=ends[0], end_m=ends[1])
        if minor:
            _paint_minor_marks(canvas, centre, r.width_m, park_w, rng_contrast)
            continue
        edge = r.width_m / 2 - 0.35
        solid = [_offset_right(centre, edge), _offset_right(centre, -edge)]
        if park_w > 0:
            solid += [_offset_right(centre, e * (r.width_m / 2 - park_w)) for e in (1, -1)]
        canvas.lines(solid, 0.2, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
        s = polyline_arc_lengths(centre)
        dashes = []
        offsets = [0.0] + [e * k * lane_w for k in range(1, n_lanes) for e in (1, -1)]
        for off in offsets:
            line = _offset_right(centre, off) if off else centre
            for a in np.arange(rng.uniform(0, 9), s[-1] - 3.0, 9.0):  # 3 m dash, 6 m gap
                t = np.linspace(a, a + 3.0, 4)
                dashes.append(np.stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])], axis=1))
        canvas.lines(dashes, 0.15, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))

    # -- junctions and marked corners: plain asphalt over the markings' ends (where two roads meet at
    # an angle their lines would cross), then crossings and stop lines at junctions ------------------
    plain = junctions + sorted(corners)
    if not plain:
        return
    radius = np.array([JUNCTION_RADIUS_FACTOR * (widest[n] if n in widest else corners[n]) for n in plain])
    canvas.ellipses(nodes_m[plain], np.repeat(radius[:, None], 2, axis=1), np.zeros(len(plain)), material("asphalt"))
    radius = radius[:len(junctions)]
    if not junctions:
        return
    stripes, stops = [], []
    for n, rad in zip(junctions, radius):
        zs, st = junction_marks(roads, n, nodes_m[n], float(rad), zebra=bool(rng.uniform() < crosswalk_fraction))
        stripes += zs
        stops += st
    if stripes:
        canvas.polygon(stripes, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
    if stops:
        canvas.polygon(stops, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))


# -- small things on the ground: what fills a real street and yard at the 1-4 m scale -------------------
# (per unit of ``world.clutter``; 1 = a central European city: KIT AIS's Munich frames show a manhole or
# gully every 10-20 m of road, patched utility cuts, sealed cracks, a darker oil strip down each lane, lamp
# posts 25-35 m apart with their long thin shadows, and courtyards full of bins, sheds, planters, walls)
CLUTTER_PALETTE = ((52, 56, 58), (70, 74, 70), (196, 194, 186), (214, 212, 206), (150, 96, 74),
                   (150, 124, 96), (74, 96, 62), (96, 112, 130), (120, 118, 112))
MANHOLE_RGB = (74, 74, 76)  # cast iron, dark and a little rough
GULLY_RGB = (44, 44, 46)
CRACK_RGB = (54, 54, 56)  # bitumen sealant


def _paint_minor_marks(canvas, centre: np.ndarray, width_m: float, park_w: float, rng: np.random.Generator) -> None:
    """A minor road's markings (``world.edges``): a dashed centre line (3 m dashes, 6 m gaps, as a town's
    guide line) and, where traffic parks along the kerbs, a solid line between the parking lane and the
    lane, MINOR_LINE_M wide. ``centre`` is the road's centre line trimmed to the junctions' mouths."""
    s = polyline_arc_lengths(centre)
    dashes = []
    for a in np.arange(rng.uniform(0, 9), s[-1] - 3.0, 9.0):
        t = np.linspace(a, a + 3.0, 4)
        dashes.append(np.stack([np.interp(t, s, centre[:, 0]), np.interp(t, s, centre[:, 1])], axis=1))
    solid = [_offset_right(centre, e * (width_m / 2 - park_w)) for e in (1, -1)] if park_w > 0 else []
    if dashes:
        canvas.lines(dashes, MINOR_LINE_M, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
    if solid:
        canvas.lines(solid, MINOR_LINE_M, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))


def _points_along(line: np.ndarray, s_m: np.ndarray, offset_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) at arc lengths ``s_m`` and offsets ``offset_m`` right of a polyline, and the tangents (N, 2)."""
    s = polyline_arc_lengths(line)
    t = np.gradient(line, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    tx, ty = np.interp(s_m, s, t[:, 0]), np.interp(s_m, s, t[:, 1])
    n = np.hypot(tx, ty)
    tx, ty = tx / np.maximum(n, 1e-12), ty / np.maximum(n, 1e-12)
    p = np.column_stack([np.interp(s_m, s, line[:, 0]), np.interp(s_m, s, line[:, 1])])
    return p + offset_m[:, None] * np.column_stack([ty, -tx]), np.column_stack([tx, ty])


def _quads(centres: np.ndarray, along: np.ndarray, length_m: np.ndarray, width_m: np.ndarray) -> list[np.ndarray]:
    """Rectangles (4, 2) centred at ``centres`` (N, 2), ``length_m`` along the unit vectors ``along`` (N, 2)."""
    a = along * (length_m / 2)[:, None]
    b = np.column_stack([-along[:, 1], along[:, 0]]) * (width_m / 2)[:, None]
    return [np.array([c - x - y, c + x - y, c + x + y, c - x + y]) for c, x, y in zip(centres, a, b)]


ARROW_LENGTH_M = 5.0  # a lane arrow from the shaft's end to the tip


def _arrow(tip: np.ndarray, forward: np.ndarray, turn: float) -> list[np.ndarray]:
    """A lane arrow as polygons (metres): a shaft 0.15 m wide and a head 0.9 m wide, 1.4 m long, its tip at
    ``tip`` pointing along the unit vector ``forward``; ``turn`` -1 / 1 bends the head 50 deg left / right
    (of the direction of travel), 0 straight on."""
    f = np.asarray(forward, np.float64)
    side = np.array([f[1], -f[0]])  # right of the direction of travel
    base = tip - f * ARROW_LENGTH_M
    if turn:
        a = -turn * np.radians(50.0)  # right: clockwise
        c, s = np.cos(a), np.sin(a)
        h = np.array([c * f[0] - s * f[1], s * f[0] + c * f[1]])
        bend = tip - f * 1.6
        head_tip = bend + h * 1.6
    else:
        h, bend, head_tip = f, tip - f * 1.4, tip
    hs = np.array([h[1], -h[0]])
    shaft = np.array([base - side * 0.075, bend - side * 0.075, bend + side * 0.075, base + side * 0.075])
    neck = head_tip - h * 1.4
    head = np.array([neck - hs * 0.45, head_tip, neck + hs * 0.45])
    polys = [shaft, head]
    if turn:
        polys.append(np.array([bend - hs * 0.075, neck - hs * 0.075, neck + hs * 0.075, bend + hs * 0.075]))
    return polys


def _shadow(poly: np.ndarray, away: np.ndarray, height_m: float) -> np.ndarray:
    """The ground shadow (convex hull) of a prism over ``poly`` (P, 2), ``height_m`` tall; ``away`` the shadow's
    ground offset per metre of height."""
    pts = np.vstack([poly, poly + away * height_m]).astype(np.float32)
    return cv2.convexHull(pts)[:, 0].astype(np.float64)


def paint_clutter(canvas, *, roads, cells, kinds, buildings=(), row_angles=None, widths_m: tuple[float, float],
                  material, clearance, density: float, away: np.ndarray | None, rng: np.random.Generator,
                  kerb_parking: bool = False) -> list[np.ndarray]:
    """Paint the small things of streets and yards onto ``canvas``; returns their shadows' polygons (metres).

    Roads: manholes, gullies along the kerb, patched utility cuts (sharp-edged, darker or lighter
    asphalt), sealed cracks, and on main roads a darker oil strip down each lane and direction arrows
    in every lane before each end. Road sides: lamp posts. Built blocks (``kinds`` ``yard``) away from
    the streets (``clearance(points) -> (P,)`` metres from the nearest road's edge): bins, sheds,
    planters, benches (0.5-2.5 m, of varied albedo), half of them against the walls of ``buildings``
    (:class:`scenes.world.Building`), and garden walls. ``away`` (2,) is a shadow's ground offset per
    metre of height (None: no shadows, as under ``light.mode: sun``, which casts them itself); the
    caller paints the shadows with the buildings', as one union. Fields under a crop (``row_angles``:
    {block key: the rows' direction, radians}) get tramlines, the tractor's wheel tracks along the
    rows every 18-24 m (a sprayer's width), 1.8 m apart, bare and darker. ``density`` scales every
    count (``world.clutter``).
    """
    from scenes.traffic import lane_layout  # here: scenes.traffic builds on scenes.world

    shadows: list[np.ndarray] = []
    if density <= 0:
        return shadows
    manholes, gullies, patches_dark, patches_light, cracks, oil, lamps, arrows = [], [], [], [], [], [], [], []
    for r in roads:
        line = r.centre_m
        L = float(polyline_arc_lengths(line)[-1])
        if L < 4.0:
            continue
        half = r.width_m / 2
        n = int(rng.poisson(density * L / 20.0))
        p, _ = _points_along(line, rng.uniform(0, L, n), rng.uniform(-1, 1, n) * max(0.0, half - 1.2))
        manholes.append(p)
        n = int(rng.poisson(density * L / 12.0))
        p, t = _points_along(line, rng.uniform(0, L, n), rng.choice([-1.0, 1.0], n) * (half - 0.4))
        gullies += _quads(p, t, np.full(n, 0.7), np.full(n, 0.4))
        n = int(rng.poisson(density * L / 15.0))
        p, t = _points_along(line, rng.uniform(0, L, n), rng.uniform(-1, 1, n) * max(0.0, half - 1.5))
        for q, dark in zip(_quads(p, t, rng.uniform(1.0, 5.0, n), rng.uniform(0.8, 2.5, n)), rng.uniform(size=n) < 0.6):
            (patches_dark if dark else patches_light).append(q)
        n = int(rng.poisson(density * L / 6.0))
        for s0, off, ang, ln in zip(rng.uniform(0, L, n), rng.uniform(-1, 1, n) * half * 0.9,
                                    rng.choice([0.0, 0.5 * np.pi], n) + rng.uniform(-0.3, 0.3, n),
                                    rng.uniform(1.5, 6.0, n)):
            p0, t0 = _points_along(line, np.array([s0]), np.array([off]))
            k = 6
            a = ang + np.cumsum(rng.normal(0, 0.25, k))  # a crack wanders
            d = np.column_stack([np.cos(a), np.sin(a)]) * (ln / k)
            rot = np.array([[t0[0, 0], -t0[0, 1]], [t0[0, 1], t0[0, 0]]])
            cracks.append(p0[0] + np.vstack([[0.0, 0.0], np.cumsum(d @ rot.T, axis=0)]))
        n_lanes, lane_w, park_w = lane_layout(r.width_m, kerb_parking=kerb_parking)
        if _marked(r, n_lanes):
            clear_m = JUNCTION_RADIUS_FACTOR * r.width_m + 1.0  # not over a junction's plain asphalt
            if L > 2 * clear_m + 4.0:
                inner = _trim(line, start_m=clear_m, end_m=clear_m)
                for k in range(n_lanes):
                    for e in (1.0, -1.0):
                        oil.append(_offset_right(inner, e * (k + 0.5) * lane_w))
            # direction arrows in every lane before each end (a junction), beyond the stop line
            tip_m = JUNCTION_RADIUS_FACTOR * r.width_m + 0.8 + ZEBRA_LENGTH_M + 0.8 + STOP_LINE_M + 4.0
            if L > 2 * (tip_m + ARROW_LENGTH_M + 4.0):
                for end, toward in ((L, 1.0), (0.0, -1.0)):
                    # right-hand traffic: lanes toward the end lie right of the direction of travel
                    s_tip = end - toward * tip_m
                    for k in range(n_lanes):
                        p, t = _points_along(line, np.array([s_tip]), np.array([toward * (k + 0.5) * lane_w]))
                        turn = float(rng.choice([0.0, 0.0, 1.0, -1.0]))
                        arrows += _arrow(p[0], toward * t[0], turn)
        # lamp posts on both sides, 25-35 m apart, a little back from the road's edge
        for e in (1.0, -1.0):
            s_at = np.arange(rng.uniform(0, 30), L, 30.0 / density) + rng.uniform(-5, 5)
            s_at = s_at[(s_at > 0) & (s_at < L)]
            if len(s_at):
                p, _ = _points_along(line, s_at, np.full(len(s_at), e * (half + 0.6)))
                lamps += [(q, float(rng.uniform(6.0, 9.0))) for q in p]
    if oil:
        canvas.lines(oil, 0.9, 0.93, mode="mul")
    if patches_dark:
        canvas.polygon(patches_dark, material("asphalt", rng.uniform(0.76, 0.88) * np.ones(3)))
    if patches_light:
        canvas.polygon(patches_light, material("asphalt", rng.uniform(1.1, 1.2) * np.ones(3)))
    if cracks:
        canvas.lines(cracks, 0.08, CRACK_RGB, opacity=0.75)
    if arrows:
        canvas.polygon(arrows, MARK_RGB, opacity=float(rng.uniform(*MARK_OPACITY)))
    if manholes:
        c = np.vstack(manholes)
        canvas.ellipses(c, np.full((len(c), 2), 0.33), np.zeros(len(c)), MANHOLE_RGB, opacity=0.9)
    if gullies:
        canvas.polygon(gullies, GULLY_RGB, opacity=0.9)
    for q, h in lamps:
        canvas.ellipses(q[None], np.array([[0.25, 0.25]]), np.zeros(1), (150, 150, 146))  # the pole's foot
        if away is not None:
            shaft = _quads(q[None] + away * h / 2, (away / max(1e-9, float(np.hypot(*away))))[None],
                           np.array([float(np.hypot(*away)) * h]), np.array([0.18]))[0]
            shadows.append(shaft)

    # -- tramlines in fields under a crop: pairs of wheel tracks along the rows, a headland clear ----
    tracks = []
    for key, ang in (row_angles or {}).items():
        poly = cells[key][0]
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        u, v = np.array([np.cos(ang), np.sin(ang)]), np.array([-np.sin(ang), np.cos(ang)])
        c = poly.mean(axis=0)
        reach = float(np.hypot(*(poly.max(axis=0) - poly.min(axis=0))))
        along = np.arange(-reach / 2, reach / 2, 1.0)
        for off in np.arange(-reach / 2 + rng.uniform(0, 24), reach / 2, rng.uniform(18.0, 24.0)):
            for wheel in (-0.9, 0.9):
                pts = c + v * (off + wheel) + along[:, None] * u
                inside = np.array([cv2.pointPolygonTest(contour, (float(x), float(y)), True) > 6.0 for x, y in pts])
                # runs of points inside the headland: one polyline each
                edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
                tracks += [pts[a:b] for a, b in zip(edges[::2], edges[1::2]) if b - a >= 3]
    if tracks:
        canvas.lines(tracks, 0.4, 0.86, mode="mul")

    # -- yards: small objects and garden walls, away from the streets -------------------------------
    palette = np.asarray(CLUTTER_PALETTE, np.float64)
    for key, kind in kinds.items():
        if kind != "yard":
            continue
        poly = cells[key][0]
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        area = float(np.prod(hi - lo))
        n = int(rng.poisson(density * area / 80.0))
        if n == 0:
            continue
        pts = rng.uniform(lo, hi, (n, 2))
        e = poly[1] - poly[0]
        yaw = float(np.arctan2(e[1], e[0]))
        ang = yaw + rng.choice([0.0, 0.5 * np.pi], n) + rng.normal(0, 0.05, n)
        sizes = np.column_stack([rng.uniform(0.5, 2.5, n), rng.uniform(0.5, 2.0, n)])
        # half stand against a building's wall (bins, bike sheds, plant), set out by half their depth
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        walls = [b.corners_xy() for b in buildings
                 if cv2.pointPolygonTest(contour, (float(b.centre[0]), float(b.centre[1])), False) > 0]
        for i in np.nonzero(rng.uniform(size=n) < (0.5 if walls else 0.0))[0]:
            c = walls[int(rng.integers(0, len(walls)))]
            k = int(rng.integers(0, 4))
            a, b = c[k], c[(k + 1) % 4]
            t = (b - a) / max(1e-9, float(np.hypot(*(b - a))))
            out = np.array([t[1], -t[0]])
            if np.dot(out, a - c.mean(axis=0)) < 0:
                out = -out
            pts[i] = a + rng.uniform(0.05, 0.95) * (b - a) + out * (0.2 + sizes[i, 1] / 2)
            ang[i] = float(np.arctan2(t[1], t[0]))
        margin = 4.0  # clear of the sidewalk and kerb
        keep = (clearance(pts) > margin) & np.array(
            [cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0 for x, y in pts], bool)
        if not keep.any():
            continue
        pts, ang, sizes = pts[keep], ang[keep], sizes[keep]
        m = len(pts)
        along = np.column_stack([np.cos(ang), np.sin(ang)])
        quads = _quads(pts, along, sizes[:, 0], sizes[:, 1])
        heights = rng.uniform(0.4, 2.5, m)
        colours = palette[rng.integers(0, len(palette), m)] * rng.uniform(0.9, 1.1, (m, 1))
        for q, h, c in zip(quads, heights, colours):
            if away is not None:
                shadows.append(_shadow(q, away, float(h)))
            canvas.polygon([q], tuple(float(v) for v in c))
        # garden walls and fences between plots: straight runs along the block's axes
        k = int(rng.poisson(density * area / 1500.0))
        for _ in range(k):
            p0 = rng.uniform(lo, hi)
            a = yaw + float(rng.choice([0.0, 0.5 * np.pi]))
            ln = float(rng.uniform(6.0, 25.0))
            seg = np.array([p0, p0 + ln * np.array([np.cos(a), np.sin(a)])])
            if (clearance(seg) <= margin).any():
                continue
            h = float(rng.uniform(1.0, 2.2))
            canvas.lines([seg], 0.3, (176, 172, 164))
            if away is not None:
                shadows.append(_shadow(_quads(seg.mean(axis=0)[None], (seg[1] - seg[0])[None] / ln,
                                              np.array([ln]), np.array([0.3]))[0], away, h))
    return shadows
