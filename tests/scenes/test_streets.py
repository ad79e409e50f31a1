"""Streets: kerbs and sidewalks by built-up blocks, zebra crossings and stop lines at junctions."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from scenes.streets import JUNCTION_RADIUS_FACTOR, ZEBRA_LENGTH_M, junction_marks
from scenes.world import _offset_right
from tests.scenes.test_world_layout import _world

BARE = {"world.buildings.count": 0, "world.trees.density_per_ha": 0.0, "world.trees.wood_density_per_ha": 0.0,
        "world.trees.hedge_fraction": 0.0, "world.parking_fraction": 0.0, "world.wood_fraction": 0.0,
        "vehicles.count": 0}


def _road(end, nodes, width=8.0):
    t = np.linspace(0.0, 1.0, 30)[:, None]
    return SimpleNamespace(centre_m=t * np.asarray(end, float), nodes=nodes, width_m=width)


def test_crossings_lie_across_each_road_and_stop_lines_on_the_incoming_half():
    roads = [_road((50.0, 0.0), (0, 1)), _road((0.0, 50.0), (0, 2)), _road((-40.0, 0.0), (0, 3), width=6.0)]
    stripes, stops = junction_marks(roads, 0, np.zeros(2), 4.4, zebra=True)
    assert len(stops) == 3 and len(stripes) >= 3 * 6
    for q in stripes:
        # each stripe on one road: within its width, 4.4 + 0.8 .. + 3 m from the node, along it
        along = [np.abs(q[:, k]).max() for k in (0, 1)]
        k = int(np.argmax(along))
        d = np.abs(q[:, k])
        assert np.all(d >= 5.2 - 1e-9) and np.all(d <= 5.2 + ZEBRA_LENGTH_M + 1e-9)
        half = 4.0 if (k == 1 or q[0, 0] > 0) else 3.0
        assert np.abs(q[:, 1 - k]).max() <= half - 0.5 + 0.25 + 1e-9
    # right-hand traffic: the stop line lies on the right of a car driving toward the node
    for q in stops:
        c = q.mean(axis=0)
        axis = np.eye(2)[int(np.argmax(np.abs(c)))] * np.sign(c[int(np.argmax(np.abs(c)))])  # the road leaving
        assert c @ axis > 5.2 + ZEBRA_LENGTH_M  # beyond the crossing
        toward = -axis
        right = np.array([toward[1], -toward[0]])
        assert q @ right @ np.ones(4) > 0 and (q @ right > 0).all(), (c, axis)
    stripes, stops = junction_marks(roads, 0, np.zeros(2), 4.4, zebra=False)
    assert not stripes and len(stops) == 3
    assert min(np.abs(q.mean(axis=0)).max() for q in stops) < 5.2 + 0.5  # where the crossing would start


def test_crossings_are_painted_at_junctions_when_asked():
    def bright_near_junctions(fraction):
        _, _, world, _ = _world("tiny", **BARE, **{"world.crosswalk_fraction": fraction, "seed": 5})
        g = world.ground_texture.astype(float).mean(axis=2)
        x0, y0 = world.extent_m[:2]
        deg = np.bincount(np.array([r.nodes for r in world.roads]).ravel())
        count = 0
        for n in np.nonzero(deg >= 3)[0]:
            cx, cy = (world.nodes_m[n] - (x0, y0)) / world.texel_m
            r = int(12.0 / world.texel_m)
            if not (r <= cx < g.shape[1] - r and r <= cy < g.shape[0] - r):
                continue
            count += int((g[int(cy) - r:int(cy) + r, int(cx) - r:int(cx) + r] > 170).sum())
        return count

    assert bright_near_junctions(1.0) > 3 * max(1, bright_near_junctions(0.0))


def test_built_up_blocks_have_a_light_kerb_at_the_road_edge():
    _, _, world, _ = _world("tiny", **{**BARE, "world.built_fraction": 1.0})
    g = world.ground_texture.astype(float).mean(axis=2)
    x0, y0, x1, y1 = world.extent_m
    kerb, asphalt = [], []
    for r in world.roads:
        for side in (-1.0, 1.0):
            for off, out in ((r.width_m / 2 + 0.12, kerb), (r.width_m / 2 - 1.0, asphalt)):
                pts = _offset_right(r.centre_m, side * off)[5:-5]  # away from the junctions
                for x, y in pts:
                    if x0 < x < x1 and y0 < y < y1:
                        out.append(g[int((y - y0) / world.texel_m), int((x - x0) / world.texel_m)])
    assert len(kerb) > 30
    assert np.median(kerb) > np.median(asphalt) + 25
    assert math.isfinite(float(np.median(kerb)))


CLUTTERED = {**BARE, "seed": 3, "world.built_fraction": 0.8, "world.buildings.count": 4,
             "world.buildings.footprint_range_m": [6.0, 10.0], "world.road_width_m": 12.0}


def _worlds_with(overrides: dict, key: str):
    """The ``tiny`` world of ``overrides`` without and with ``key`` at 1, checked to have the same roads and as many
    buildings (the truth is made of them)."""
    _, _, plain, _ = _world("tiny", **overrides)
    _, _, other, _ = _world("tiny", **overrides, **{key: 1.0})
    assert len(plain.roads) == len(other.roads) and len(plain.buildings) == len(other.buildings) > 0
    for a, b in zip(plain.roads, other.roads):
        assert np.array_equal(a.centre_m, b.centre_m)
    return plain, other


def test_clutter_paints_the_ground_only_and_leaves_the_rest_of_the_world_as_it_was():
    # its own random stream: roads, buildings and trees (what the truth is made of) stay the same
    plain, busy = _worlds_with(CLUTTERED, "world.clutter")
    # the same blocks (only dormer rows on some roofs): footprints, heights and the first parts as they were
    assert [(b.centre, b.size, b.parts[:5]) for b in plain.buildings] == [(b.centre, b.size, b.parts[:5])
                                                                          for b in busy.buildings]
    assert any(len(b.parts) > len(a.parts) for a, b in zip(plain.buildings, busy.buildings))
    assert [(t.x_m, t.y_m) for t in plain.trees] == [(t.x_m, t.y_m) for t in busy.trees]
    d = np.abs(plain.ground_texture.astype(int) - busy.ground_texture.astype(int)).max(axis=2)
    # small things: a few per cent of the ground changes, and where it does, by more than the grain
    assert 0.01 < (d > 8).mean() < 0.3, (d > 8).mean()


def test_clutter_makes_the_ground_busier_at_the_scale_of_a_few_pixels():
    # what the small things are for: local contrast in 15-texel windows, as benchmarks/realism.py measures it
    import cv2

    def contrast(world):
        g = world.ground_texture.astype(np.float32).mean(axis=2)
        m, s = cv2.blur(g, (15, 15)), cv2.blur(g * g, (15, 15))
        return float(np.median(np.sqrt(np.maximum(s - m * m, 0))))

    _, _, plain, _ = _world("tiny", **CLUTTERED)
    _, _, busy, _ = _world("tiny", **CLUTTERED, **{"world.clutter": 2.0})
    assert contrast(busy) > 1.1 * contrast(plain)


def test_clutter_shadows_fall_away_from_the_sun_and_only_under_flat_light():
    from scenes.streets import paint_clutter
    from scenes.world import _Canvas

    road = SimpleNamespace(centre_m=np.column_stack([np.linspace(0, 200, 101), np.zeros(101)]), width_m=10.0,
                           major=True, nodes=(0, 1))

    def run(away):
        canvas = _Canvas(-20.0, -30.0, 0.1, 2400, 600)
        shadows = paint_clutter(canvas, roads=[road], cells={}, kinds={}, widths_m=(10.0, 7.5),
                                material=lambda name, gain=(1, 1, 1): (100, 100, 100),
                                clearance=lambda p: np.full(len(p), 10.0), density=1.0, away=away,
                                rng=np.random.default_rng(4))
        return canvas, shadows

    away = np.array([0.3, -0.8])  # a sun in the south-west, 49 deg up
    canvas, shadows = run(away)
    assert canvas.ops and len(shadows) >= 10  # lamp posts every 30 m on both sides
    u = away / np.hypot(*away)
    for q in shadows:
        # a pole's shadow: a thin quad along the sun's direction, 6-9 m tall poles
        along = (q - q.mean(axis=0)) @ u
        across = (q - q.mean(axis=0)) @ np.array([-u[1], u[0]])
        length = along.max() - along.min()
        assert 6.0 * np.hypot(*away) - 1e-6 <= length <= 9.0 * np.hypot(*away) + 1e-6
        assert across.max() - across.min() < 0.2
    _, none = run(None)
    assert none == []


def test_wide_minor_roads_are_marked_and_corners_paved_plain_over_the_lines():
    from scenes.streets import _marked, _marked_corners

    def road(pts, nodes, width, major=False):
        t = np.linspace(0.0, 1.0, 20)[:, None]
        a, b = (np.asarray(p, float) for p in pts)
        return SimpleNamespace(centre_m=a + t * (b - a), nodes=nodes, width_m=width, major=major)

    # an 18 m minor road has two lanes a direction (with a parking lane): marked; a 9 m one is not
    assert _marked(road(((0, 0), (50, 0)), (0, 1), 18.0), 2) and not _marked(road(((0, 0), (50, 0)), (0, 1), 9.0), 1)
    turn = [road(((0, 0), (50, 0)), (0, 1), 18.0), road(((0, 0), (0, 50)), (0, 2), 18.0)]
    straight = [road(((0, 0), (50, 0)), (0, 1), 18.0), road(((0, 0), (-50, 0)), (0, 2), 18.0)]
    quiet = [road(((0, 0), (50, 0)), (0, 1), 9.0), road(((0, 0), (0, 50)), (0, 2), 9.0)]
    deg = np.array([2, 1, 1])
    assert _marked_corners(turn, deg, True) == {0: 18.0}  # lines of the two roads would cross there
    assert _marked_corners(straight, deg, True) == {}  # the lines run on
    assert _marked_corners(quiet, deg, True) == {}  # nothing painted to cover


def test_lane_lines_stop_at_the_junction_mouth():
    # a wide road world: no marking paint inside a junction's crossing carriageway, beyond its stop lines
    _, _, world, _ = _world("tiny", **BARE, **{"seed": 5, "world.road_width_m": 24.0, "world.crosswalk_fraction": 0.0})
    g = world.ground_texture.astype(float).mean(axis=2)
    x0, y0 = world.extent_m[:2]
    deg = np.bincount(np.array([r.nodes for r in world.roads]).ravel())
    checked = 0
    for n in np.nonzero(deg >= 3)[0]:
        cx, cy = (world.nodes_m[n] - (x0, y0)) / world.texel_m
        # the junction's plain asphalt reaches 0.55 x the widest road, the stop lines start 0.8 m beyond: the
        # edge lines of one road, half its width off its centre, would cross the other's carriageway there
        widest = max(rd.width_m for rd in world.roads if n in rd.nodes)
        r = int((JUNCTION_RADIUS_FACTOR * widest + 0.6) / world.texel_m)
        if not (r <= cx < g.shape[1] - r and r <= cy < g.shape[0] - r):
            continue
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        disc = g[int(cy) + yy, int(cx) + xx][np.hypot(yy, xx) <= r]
        assert (disc > 160).mean() < 4e-4, (n, (disc > 160).mean())  # a texel or two of a stop line's edge
        checked += 1
    assert checked >= 1


def test_tramlines_run_along_a_fields_rows_in_pairs_inside_a_headland():
    from scenes.streets import paint_clutter
    from scenes.world import _Canvas

    texel = 0.1
    field = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 80.0], [0.0, 80.0]])
    canvas = _Canvas(0.0, 0.0, texel, 1000, 800)
    paint_clutter(canvas, roads=[], cells={(0, 0): (field, None)}, kinds={(0, 0): "field"},
                  row_angles={(0, 0): 0.0}, widths_m=(10.0, 7.5), material=None,
                  clearance=lambda p: np.full(len(p), 50.0), density=1.0, away=None, rng=np.random.default_rng(2))
    buf = np.ones((800, 1000, 3), np.float32)
    xs, ys = (np.arange(1000) + 0.5) * texel, (np.arange(800) + 0.5) * texel
    for op in canvas.ops:
        op.apply(buf, 0, xs, ys)
    g = buf[..., 0]
    rows = g[:, 300:700].mean(axis=1)  # along x, the rows' direction: tracks are dark rows of texels
    dark = np.flatnonzero(rows < 0.95) * texel
    assert len(dark) and dark.min() > 6.0 - 0.3 and dark.max() < 80.0 - 6.0 + 0.3  # a 6 m headland
    # wheel tracks in pairs 1.8 m apart, the pairs 18-24 m apart
    centres = [float(np.mean(r)) for r in np.split(dark, np.flatnonzero(np.diff(dark) > 0.5) + 1)]
    gaps = np.diff(centres)
    assert np.allclose(gaps[::2], 1.8, atol=0.15), centres
    assert np.all((gaps[1::2] > 18.0 - 1.8 - 0.2) & (gaps[1::2] < 24.0 - 1.8 + 0.2)), centres
    # the tracks are darker than the crop, not painted over it
    assert 0.8 < g.min() < 0.9


EDGED = {**BARE, "seed": 5, "world.built_fraction": 0.8, "world.buildings.count": 4,
         "world.buildings.footprint_range_m": [6.0, 10.0], "world.road_width_m": 16.0,
         "traffic.kerb_parking_per_km": 100.0, "camera.altitude_m": 25.0}  # 0.12 m texels: a line is a texel wide


def _samples(world, roads, offset_m: float, trim_m: float = 14.0) -> np.ndarray:
    """Gray levels of the ground texture along the roads' centre lines moved ``offset_m`` to the right (both
    sides for a nonzero offset), away from the junctions and their crossings."""
    from scenes.world import _trim
    from tests.scenes.test_world_layout import _resampled

    g = world.ground_texture.astype(float).mean(axis=2)
    x0, y0, x1, y1 = world.extent_m
    out = []
    for r in roads:
        line = _resampled(_trim(r.centre_m, start_m=trim_m, end_m=trim_m), 0.5)
        for side in ((1.0, -1.0) if offset_m else (1.0,)):
            for x, y in _offset_right(line, side * offset_m):
                if x0 < x < x1 and y0 < y < y1:
                    out.append(g[int((y - y0) / world.texel_m), int((x - x0) / world.texel_m)])
    return np.asarray(out)


def test_edges_paint_the_ground_and_tint_roofs_only_and_leave_the_rest_of_the_world_as_it_was():
    # world.edges draws from its own stream: roads, buildings and trees (what the truth is made of) stay the same
    plain, edged = _worlds_with(EDGED, "world.edges")
    assert plain.buildings == edged.buildings
    assert [(t.x_m, t.y_m) for t in plain.trees] == [(t.x_m, t.y_m) for t in edged.trees]
    d = np.abs(plain.ground_texture.astype(int) - edged.ground_texture.astype(int)).max(axis=2)
    # kerbs, gutters and lines: a little of the ground changes, the blocks' insides and the fields do not
    assert 0.003 < (d > 8).mean() < 0.1, (d > 8).mean()


def test_edges_mark_minor_roads_and_lay_a_light_kerb_and_a_dark_gutter():
    from scenes.streets import _marked
    from scenes.traffic import lane_layout

    spec, _, plain, _ = _world("tiny", **EDGED)
    _, _, edged, _ = _world("tiny", **EDGED, **{"world.edges": 1.0})
    minor = [r for r in plain.roads if not _marked(r, lane_layout(r.width_m, kerb_parking=True)[0])]
    assert minor  # 12 m minor roads: one lane a direction and a parking lane, unmarked without edges
    # a dashed centre line: 3 m of paint in every 9 m
    line0, line1 = _samples(plain, minor, 0.0), _samples(edged, minor, 0.0)
    assert len(line1) > 30
    assert (line1 > 150).mean() > (line0 > 150).mean() + 0.2, ((line0 > 150).mean(), (line1 > 150).mean())
    # the parking lanes' solid lines, 2.4 m in from each kerb
    _, _, park_w = lane_layout(minor[0].width_m, kerb_parking=True)
    park0, park1 = (_samples(world, minor, minor[0].width_m / 2 - park_w) for world in (plain, edged))
    assert (park1 > 150).mean() > 0.7 and (park0 > 150).mean() < 0.3, ((park0 > 150).mean(), (park1 > 150).mean())
    # by the built blocks: the kerb lighter, the gutter on the road's side of it darker than the asphalt
    w = minor[0].width_m
    # (the kerb, 0.3 m, spans w / 2 - 0.03 .. w / 2 + 0.27; half the road sides are verges, with no kerb)
    kerb0 = np.percentile(_samples(plain, minor, w / 2 + 0.2), 75)
    for world, edges in ((plain, False), (edged, True)):
        kerb, gutter, asphalt = (_samples(world, minor, o) for o in (w / 2 + 0.2, w / 2 - 0.18, w / 2 - 1.2))
        assert (np.percentile(kerb, 75) > kerb0 + 12) == edges, (np.percentile(kerb, 75), kerb0)
        assert (np.median(gutter) < np.median(asphalt) - 20) == edges, (np.median(gutter), np.median(asphalt))


def test_edges_widen_the_roofs_from_white_gravel_to_dark_bitumen_and_keep_the_footbridges_concrete():
    from scenes import world as world_mod

    assert world_mod.roof_tints(0.0) == world_mod.ROOF_TINTS
    shades = {}
    for e in (0.0, 1.0):
        _, roofs = world_mod._building_textures(np.random.default_rng(1), 0.1, edges=e)
        mean = roofs[0].astype(np.float64).reshape(-1, 3).mean(axis=0)
        shades[e] = np.array([(mean * np.minimum(1.0, t)) @ (0.299, 0.587, 0.114) for t in world_mod.roof_tints(e)])
    # vertex colours cannot exceed 1: a lighter roof is a lighter texture, every tint at most 1
    assert max(max(t) for t in world_mod.roof_tints(1.0)) <= 1.0
    assert shades[1.0].max() > 195 and shades[1.0].min() < 95  # white gravel to bitumen (KIT AIS: 80-220)
    assert np.ptp(shades[1.0]) > 2 * np.ptp(shades[0.0])
    assert abs(shades[1.0][1] - shades[0.0][1]) < 0.02 * shades[0.0][1]  # variant 1: the footbridges' concrete


def test_edges_outline_every_roof_with_a_parapet_that_stands_out():
    from scenes import world as world_mod

    gray = np.array([0.299, 0.587, 0.114])
    for e in (0.5, 1.0):
        for roof, parapet in zip(world_mod.roof_tints(e), world_mod.parapet_tints(e), strict=True):
            # dark flashing round a light roof, light coping round a dark one: a third of the range apart at 1
            assert abs(np.asarray(roof) @ gray - np.asarray(parapet) @ gray) > 0.25 * e, (e, roof, parapet)
    # without edges: 0.85 of the roof's tint, as the renderer draws it when World.parapet_tints is None
    for roof, parapet in zip(world_mod.roof_tints(0.0), world_mod.parapet_tints(0.0)):
        assert np.allclose(parapet, 0.85 * np.asarray(roof))
