"""City traffic (scenes/traffic.py): queues at lights keep their gaps, classes at their sizes, the
truth stays exact for every new mover, parked vehicles stand with the ground, occluders hide."""

from __future__ import annotations

import math

import numpy as np
import pytest

from algorithms.flow import as_gray, warp_backward
from scenes import SceneSpecError, load_scene_spec
from scenes.generate import SceneGenerator
from scenes.motion import VehiclePath, camera_path
from scenes.traffic import (CLASS_SIZES_M, CLASSES, HARD_GAP_M, LANE_CHANGE_M, _Agent, _build_route, _draw_size, _Network, _simulate,
                            lane_layout, place_traffic, vehicle_parts, vehicle_shape)
from scenes.world import Road, World, _rect_corners, build_world, distance_to_polyline, rects_overlap

CITY_TINY = {"vehicles.count": 0, "camera.altitude_m": 45.0, "camera.ground_speed_mps": 2.0,
             "world.road_spacing_m": 45.0, "world.road_width_m": 16.0, "world.road_drop_fraction": 0.0,
             "world.parking_fraction": 0.25, "world.built_fraction": 0.3, "world.wood_fraction": 0.0,
             "traffic.density_per_lane_km": 40.0, "traffic.kerb_parking_per_km": 120.0,
             "traffic.lot_fill_fraction": 0.8, "traffic.pedestrians_per_km": 80.0,
             "traffic.cyclists_per_lane_km": 6.0, "traffic.warmup_s": 15.0,
             "traffic.classes": {"car": 0.5, "van": 0.2, "truck": 0.1, "bus": 0.1, "motorbike": 0.1}}


def _cross_world(width_m: float = 8.0, arm_m: float = 200.0) -> World:
    """A straight four-way junction at the origin: arms to +-arm_m along x and y, one lane each way."""
    nodes = np.array([[0.0, 0.0], [-arm_m, 0.0], [arm_m, 0.0], [0.0, -arm_m], [0.0, arm_m]])
    roads = []
    for k in range(1, 5):
        t = np.linspace(0.0, 1.0, int(arm_m / 2) + 1)[:, None]
        roads.append(Road(centre_m=nodes[k] * (1 - t) + nodes[0] * t, width_m=width_m, major=True, nodes=(k, 0)))
    return World(extent_m=(-arm_m, -arm_m, arm_m, arm_m), texel_m=1.0, ground_texture=np.zeros((4, 4, 3), np.uint8),
                 roads=roads, nodes_m=nodes, road_width_m=width_m)


def _paths(agents) -> list[VehiclePath]:
    return [VehiclePath(vehicle_id=k + 1, kind="profile", route_m=a.route.polyline, s0_m=0.0, v0_mps=a.v0,
                        size_m=a.size, profile_t_s=np.asarray(a.t_knots), profile_s_m=np.asarray(a.s_knots),
                        profile_v_mps=np.asarray(a.v_knots), profile_a_mps2=np.asarray(a.a_knots))
            for k, a in enumerate(agents)]


def test_a_queue_stops_behind_the_red_light_keeps_its_gaps_and_drives_off_on_green():
    ts = load_scene_spec("tiny", overrides={"traffic.turning_fraction": 0.0}).traffic
    world = _cross_world()
    net = _Network(world, ts, (-150.0, -150.0, 150.0, 150.0), np.random.default_rng(0))
    red_until_s = 30.0
    net.green = lambda leg, t: t >= red_until_s  # every approach red, then green
    west = next(i for i, leg in enumerate(net.legs) if leg.entry == 1)  # from (-200, 0) east to the junction
    leg = net.legs[west]
    assert leg.stop_c < leg.length - 5.0
    rng = np.random.default_rng(1)
    agents = []
    for k, cls in enumerate(["car", "bus", "car", "van", "car", "motorbike", "truck", "car"]):
        route = _build_route(net, west, 0, 400.0, ts, rng)
        agents.append(_Agent(cls=cls, size=_draw_size(cls, rng), colours=((0, 0, 0), (0, 0, 0)), route=route,
                             v0=12.0, s=120.0 - 14.0 * k, v=10.0))
    _simulate(net, agents, 0.0, 70.0, ts, lambda *a: None, rng)
    paths = _paths(agents)

    t = np.arange(0.0, 70.0, 0.01)
    s = np.array([[p._profile_at(float(x))[0] for x in t] for p in paths])  # arc length on the same straight route
    front = s + np.array([a.size[0] / 2 for a in agents])[:, None]
    rear = s - np.array([a.size[0] / 2 for a in agents])[:, None]
    red = t < red_until_s
    # nobody's front passes the stop line while it is red, and the queue stands still before green
    assert front[:, red].max() <= leg.stop_c + 1e-6
    standing = (t > red_until_s - 2.0) & red
    assert max(p.speed(float(x)) for p in paths for x in t[standing]) < 0.3
    assert front[0, standing].min() > leg.stop_c - ts.min_gap_m - 0.5  # the first waits at the line
    # bumper to bumper, never below the hard gap, at any instant (not only at the steps)
    gaps = rear[:-1] - front[1:]
    assert gaps.min() >= HARD_GAP_M - 1e-6, gaps.min()
    # a real queue: standing gaps near the jam distance s0
    assert np.all(gaps[:, standing] < ts.min_gap_m + 1.5)
    # green: all drive off across the line, accelerating no harder than a_max; speeds are the slope of s
    assert (front[:, -1] > leg.stop_c + 10.0).all()
    for p in paths:
        assert p.profile_a_mps2.max() <= ts.acceleration_mps2 + 1e-9
        h = 1e-5
        v_num = np.array([(p.distance(float(x) + h) - p.distance(float(x) - h)) / (2 * h) for x in t[::50]])
        v_closed = np.array([p.speed(float(x)) for x in t[::50]])
        assert np.abs(v_num - v_closed).max() < 0.01


def test_lights_give_one_axis_green_at_a_time_with_all_red_between():
    ts = load_scene_spec("tiny", overrides={"traffic.green_s": 12.0, "traffic.clearance_s": 3.0}).traffic
    net = _Network(_cross_world(), ts, (-150.0, -150.0, 150.0, 150.0), np.random.default_rng(0))
    into = [leg for leg in net.legs if leg.leave == 0]
    assert len(into) == 4 and sorted(leg.approach for leg in into) == [0, 0, 1, 1]
    for leg in into:  # the oncoming approach is the one from the other side, green with it
        assert [net.legs[j].entry for j in leg.oncoming] == [{1: 2, 2: 1, 3: 4, 4: 3}[leg.entry]]
    t = np.arange(0.0, 60.0, 0.05)
    green = np.array([[net.green(leg, float(x)) for x in t] for leg in into])
    phase = {leg.approach: green[k] for k, leg in enumerate(into)}
    assert not (phase[0] & phase[1]).any()  # never both axes
    for k, leg in enumerate(into):
        assert (green[k] == phase[leg.approach]).all()  # opposite approaches together
        share = green[k].mean()
        assert share == pytest.approx(12.0 / 30.0, abs=0.01)  # green 12 s of each 30 s cycle
    all_red = ~(phase[0] | phase[1])
    assert all_red.mean() == pytest.approx(6.0 / 30.0, abs=0.01)
    assert net.green(net.legs[next(i for i, g in enumerate(net.legs) if g.leave != 0)], 3.0)  # no light there


def test_profile_positions_are_continuous_between_knots():
    vp = VehiclePath(vehicle_id=1, kind="profile", route_m=np.array([[0.0, 0.0], [500.0, 0.0]]), s0_m=0.0, v0_mps=10,
                     profile_t_s=np.array([-1.0, 0.0, 0.1, 0.25]), profile_s_m=np.array([0.0, 10.0, 11.0, 12.2]),
                     profile_v_mps=np.array([10.0, 10.0, 10.0, 6.0]), profile_a_mps2=np.array([0.0, 0.0, -26.666666, 0.0]))
    # S(0) is arc length 10 (s0_m follows the profile), the route runs along +x from 0
    vp.s0_m = vp._profile_s0
    assert vp.pose(0.0)[0] == pytest.approx(10.0)
    assert vp.pose(0.05)[0] == pytest.approx(10.5)
    assert vp.pose(-2.0)[0] == pytest.approx(-10.0)  # before the first knot: on at v_0
    assert vp.speed(0.175) == pytest.approx(10.0 - 26.666666 * 0.075)
    with pytest.raises(ValueError, match="profile_t_s"):
        VehiclePath(vehicle_id=1, kind="profile", route_m=np.array([[0.0, 0.0], [1.0, 0.0]]), s0_m=0.0, v0_mps=1,
                    profile_t_s=np.array([0.0, 0.0]), profile_s_m=np.zeros(2), profile_v_mps=np.zeros(2),
                    profile_a_mps2=np.zeros(2))


def test_routes_turn_at_junctions_and_change_lanes_on_wide_roads():
    world = _cross_world(width_m=16.0)
    assert lane_layout(16.0, kerb_parking=False) == (2, 4.0, 0.0)
    assert lane_layout(16.0, kerb_parking=True) == (2, (8.0 - 2.4) / 2, 2.4)
    assert lane_layout(8.0, kerb_parking=True) == (1, 4.0, 0.0)  # too narrow for a parking lane
    turn = load_scene_spec("tiny", overrides={"traffic.turning_fraction": 1.0}).traffic
    net = _Network(world, turn, (-150.0, -150.0, 150.0, 150.0), np.random.default_rng(0))
    west = next(i for i, leg in enumerate(net.legs) if leg.entry == 1)
    route = _build_route(net, west, 0, 300.0, turn, np.random.default_rng(3))
    d = np.diff(route.polyline, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    assert abs(math.degrees(heading[-1] - heading[0])) == pytest.approx(90.0, abs=1.0)  # it turned
    assert np.abs(np.diff(heading)).max() < math.radians(20.0)  # through a rounded corner
    change = load_scene_spec("tiny", overrides={"traffic.turning_fraction": 0.0,
                                                "traffic.lane_change_fraction": 1.0}).traffic
    route = _build_route(net, west, 0, 300.0, change, np.random.default_rng(3))
    # on the first leg (driving +x, its right side is -y) the lane moves from lane 0 (2 m) to lane 1 (6 m)
    first = route.polyline[route.polyline[:, 0] < -20.0]
    lateral = -first[:, 1]
    assert lateral[0] == pytest.approx(2.0) and lateral[-1] == pytest.approx(6.0)
    # smoothly: an S-curve over LANE_CHANGE_M, whose steepest slope is 1.5 x 4 m / 30 m (11 deg)
    slope = np.abs(np.diff(lateral)) / np.hypot(*np.diff(first, axis=0).T)
    assert slope.max() < 1.5 * 4.0 / LANE_CHANGE_M + 1e-3 and (slope > 0).sum() > 20


@pytest.fixture(scope="module")
def city_world():
    spec = load_scene_spec("tiny", overrides={**CITY_TINY, "image.width_px": 640, "image.height_px": 480,
                                              "camera.altitude_m": 120.0})
    ss = np.random.SeedSequence(spec.seed)
    rngs = [np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(5)]
    path = camera_path(spec, rngs[0])
    world = build_world(spec, path, rngs[1])
    return spec, path, world, place_traffic(spec, world, path, rngs[4])


def test_every_class_drives_at_its_real_size_and_the_shape_fills_it(city_world):
    _, _, _, users = city_world
    seen = {u.vclass for u in users}
    assert set(CLASSES) <= seen, seen
    for u in users:
        (l0, l1), (w0, w1), (h0, h1) = CLASS_SIZES_M[u.vclass]
        L, W, H = u.size_m
        assert l0 <= L <= l1 and w0 <= W <= w1 and h0 <= H <= h1, (u.vclass, u.size_m)
        boxes = vehicle_shape(u)
        lo = np.min([np.subtract(b.centre, np.divide(b.size, 2)) for b in boxes], axis=0)
        hi = np.max([np.add(b.centre, np.divide(b.size, 2)) for b in boxes], axis=0)
        # within its size, standing on the ground, as long and tall as its class says
        assert (lo >= (-L / 2 - 1e-9, -W / 2 - 1e-9, -1e-9)).all() and (hi <= (L / 2 + 1e-9, W / 2 + 1e-9, H + 1e-9)).all()
        assert hi[0] - lo[0] > 0.9 * L and hi[2] > 0.9 * H
        assert len(vehicle_parts(u)) == len(boxes)
    # a bus is 2.5-3x a car's length, a pedestrian a tenth of it
    by = {c: np.mean([u.size_m[0] for u in users if u.vclass == c]) for c in seen}
    assert 2.0 < by["bus"] / by["car"] < 3.5 and by["pedestrian"] / by["car"] < 0.12


def test_traffic_fills_the_view_parked_and_moving(city_world):
    _, path, _, users = city_world
    parked = [u for u in users if u.parked]
    moving = [u for u in users if u.kind == "profile" and u.speed(0.0) > 0.5]
    queued = [u for u in users if u.kind == "profile" and u.speed(0.0) <= 0.5]
    assert len(parked) >= 10 and len(moving) >= 5 and len(queued) >= 1, (len(parked), len(moving), len(queued))
    for u in parked:  # parked means still: the same pose at every time
        assert u.pose(0.0) == u.pose(0.37) == u.pose(5.0)


def test_no_two_road_users_ever_overlap(city_world):
    # moving ones by the gap they keep, parked ones by their places, walkers on their footpaths
    _, path, _, users = city_world
    assert len(users) > 50
    for t in np.linspace(0.0, path.t_s[-1], 11):
        poses = [u.pose(float(t)) for u in users]
        rects = [_rect_corners(x, y, u.size_m[0], u.size_m[1], th) for (x, y, th), u in zip(poses, users)]
        xy = np.array([p[:2] for p in poses])
        for i in range(len(users)):
            near = np.flatnonzero(np.hypot(*(xy[i + 1:] - xy[i]).T) < 14.0) + i + 1
            for j in near:
                assert not rects_overlap(rects[i], rects[j], 0.0), (t, users[i].vclass, users[j].vclass)


def test_street_trees_overhang_roads_above_every_road_user_and_bridges_stand_clear():
    spec = load_scene_spec("city")
    ss = np.random.SeedSequence(spec.seed)
    rngs = [np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(5)]
    path = camera_path(spec, rngs[0])
    world = build_world(spec, path, rngs[1])
    street = [t for t in world.trees if t.overhangs_road]
    assert len(street) >= 5 and len(world.overpasses) == 1
    tallest = max(h[1] for _, _, h in CLASS_SIZES_M.values())
    over = 0
    for t in street:
        assert t.height_m - 2 * t.crown_half_height_m >= tallest + 0.5  # a bus passes under the crown
        d = min(distance_to_polyline(np.array([[t.x_m, t.y_m]]), r.centre_m)[0] - r.width_m / 2 for r in world.roads)
        assert d > 1.5  # the trunk stands beyond the kerb (the footpath passes between)
        over += t.crown_radius_m > d + 1.0  # and the crown reaches a metre or more over the road
    assert over >= 0.8 * len(street)
    b = world.overpasses[0]
    deck = b.parts[0]
    assert deck.centre[2] - deck.size[2] / 2 >= tallest + 1.5
    for other in world.buildings:
        assert not rects_overlap(b.corners_xy(), other.corners_xy(), 0.5)
    # its piers stand off every road (the first two boxes after the parapets)
    for pier in b.parts[3:5]:
        c, s_ = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
        p = np.array([[b.centre[0] + c * pier.centre[0] - s_ * pier.centre[1],
                       b.centre[1] + s_ * pier.centre[0] + c * pier.centre[1]]])
        assert min(distance_to_polyline(p, r.centre_m)[0] - r.width_m / 2 for r in world.roads) > pier.size[0] / 2
    assert world.top_m >= b.top_m


def test_spec_errors_name_the_traffic_field():
    with pytest.raises(SceneSpecError, match=r"traffic\.density_per_lane_km"):
        load_scene_spec("tiny", overrides={"traffic.density_per_lane_km": -1.0})
    with pytest.raises(SceneSpecError, match=r"traffic\.parked: unknown key"):
        load_scene_spec("tiny", overrides={"traffic.parked": 3})
    with pytest.raises(SceneSpecError, match=r"traffic: speed_range_mps: expected 0 < low <= high"):
        load_scene_spec("tiny", overrides={"traffic.speed_range_mps": [9.0, 4.0]})
    with pytest.raises(SceneSpecError, match=r"traffic\.classes.*car \+ van"):
        load_scene_spec("tiny", overrides={"traffic.classes": {"car": 0, "van": 0, "truck": 0, "bus": 0,
                                                               "motorbike": 0}})
    with pytest.raises(SceneSpecError, match=r"traffic\.speed_range_mps: a vehicle at 200"):
        load_scene_spec("tiny", overrides={"traffic.density_per_lane_km": 10.0, "traffic.speed_range_mps": [5, 200]})
    with pytest.raises(SceneSpecError, match=r"traffic\.junctions"):
        load_scene_spec("tiny", overrides={"traffic.junctions": "roundabout"})
    spec = load_scene_spec("city")
    assert spec.traffic.density_per_lane_km > 0 and spec.vehicles.count == 0


# -- rendered: truth, parked flow, occlusion -----------------------------------------------------

@pytest.fixture(scope="module")
def city_frames():
    spec = load_scene_spec("tiny", overrides={**CITY_TINY, "image.width_px": 320, "image.height_px": 240,
                                              "image.n_frames": 3, "light.shadows": False,
                                              "traffic.street_trees_per_km": 60.0, "traffic.bridges": 1})
    gen = SceneGenerator(spec)
    frames = list(gen.frames())
    return gen, frames


@pytest.mark.gl
def test_warping_by_true_flow_reproduces_every_new_mover():
    import cv2

    # low (30 m: a pedestrian is 5 px wide), flat light without vehicle shadows (a shadow moving over
    # static ground breaks brightness constancy by design); seeds one after another until every class
    # has moved in view (seeds 1, 5 and 7 do between them: tried first, each world costs seconds to build)
    pooled: dict[str, np.ndarray] = {}
    for seed in (1, 5, 7, 2, 3, 4, 6, 8):
        if set(CLASSES) <= set(pooled):
            break
        spec = load_scene_spec("tiny", overrides={
            **CITY_TINY, "seed": seed, "image.width_px": 480, "image.height_px": 360, "image.n_frames": 2,
            "camera.altitude_m": 30.0, "light.shadows": False, "traffic.junctions": "none",
            "traffic.street_trees_per_km": 60.0, "traffic.cyclists_per_lane_km": 30.0,
            "traffic.pedestrians_per_km": 200.0,
            "traffic.classes": {"car": 0.2, "van": 0.2, "truck": 0.2, "bus": 0.2, "motorbike": 0.2}})
        gen = SceneGenerator(spec)
        f0_out, f1_out = gen.frames()
        truth = f1_out.pair
        f0, f1 = as_gray(f0_out.rgb), as_gray(f1_out.rgb)
        warped, _ = warp_backward(f1, truth.flow)
        for v in gen.vehicles:
            mask = truth.valid & (truth.instances == v.vehicle_id)
            # its own pixels away from its outline (bilinear warping mixes the ground in there)
            inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            local = np.hypot(*(truth.flow - truth.flow_camera)[inner].T)
            if inner.sum() < 2 or np.median(local) < 0.2:
                continue
            pooled.setdefault(v.vclass, np.zeros(3))
            pooled[v.vclass] += (np.abs(warped - f0)[inner].sum(), np.abs(f1 - f0)[inner].sum(), inner.sum())
    assert set(CLASSES) <= set(pooled), sorted(pooled)
    for cls, (err, zero, n) in pooled.items():
        # tiny movers of high contrast keep some interpolation error (pedestrians: 3 of 42 gray levels)
        assert zero / n > 3.0 and err / n < 0.3 * zero / n + 1.0, (cls, err / n, zero / n, n)


@pytest.mark.gl
def test_parked_vehicles_have_zero_flow_relative_to_the_ground(city_frames):
    gen, frames = city_frames
    parked = [v.vehicle_id for v in gen.vehicles if v.parked]
    moving = [v.vehicle_id for v in gen.vehicles if not v.parked and v.speed(0.0) > 1.0]
    truth = frames[1].pair
    on_parked = truth.valid & np.isin(truth.instances, parked)
    assert on_parked.sum() > 200
    local = truth.flow - truth.flow_camera
    assert np.abs(local[on_parked]).max() < 1e-3
    on_moving = truth.valid & np.isin(truth.instances, moving)
    assert np.hypot(*local[on_moving].T).mean() > 0.1  # and the movers really move relative to the ground


@pytest.mark.gl
def test_visible_fraction_drops_under_street_trees_and_bridges(city_frames):
    import pandas as pd

    # the same traffic without street trees and bridge: the traffic's stream and the roads it drives
    # do not depend on them, so every vehicle stands where it stood
    gen, _ = city_frames
    assert [t for t in gen.world.trees if t.overhangs_road] and gen.world.overpasses
    bare = SceneGenerator(load_scene_spec(gen.spec, overrides={"traffic.street_trees_per_km": 0.0,
                                                               "traffic.bridges": 0}))
    assert [v.pose(0.0) for v in bare.vehicles] == [v.pose(0.0) for v in gen.vehicles]
    _, surf = bare.render_frame(0)
    bare._tracks(0, surf)
    pixels_bare = np.bincount(surf.instances.ravel(), minlength=len(gen.vehicles) + 1)
    _, surf = gen.render_frame(0)
    pixels = np.bincount(surf.instances.ravel(), minlength=len(gen.vehicles) + 1)
    with_ = pd.DataFrame(gen.track_table()).query("frame == 0").set_index("vehicle_id")
    without = pd.DataFrame(bare.track_table()).query("frame == 0").set_index("vehicle_id")
    w, h = gen.spec.image.width_px, gen.spec.image.height_px
    inside = ((without.bbox_x0_px > 1) & (without.bbox_y0_px > 1) & (without.bbox_x1_px < w - 2)
              & (without.bbox_y1_px < h - 2) & (without.visible == 1))
    # in the open, a vehicle inside the image shows (nearly) all of itself
    assert inside.sum() >= 10 and without.visible_fraction[inside].median() == 1.0
    assert without.visible_fraction[inside].quantile(0.1) > 0.85
    # under a crown or the deck the share drops, by as much as its pixels do
    drop = without.visible_fraction - with_.visible_fraction
    hidden = inside & (drop > 0.1)
    assert hidden.sum() >= 2 and drop[inside].max() > 0.5, drop[inside]
    ids = hidden[hidden].index.to_numpy()
    ratio = pixels[ids] / np.maximum(pixels_bare[ids], 1)
    np.testing.assert_allclose(with_.visible_fraction[ids] / without.visible_fraction[ids], ratio, atol=0.2)
    assert (with_.visible_fraction <= without.visible_fraction + 1e-9).all()
    # 0 exactly when the vehicle is not seen at all; classes by name
    assert ((with_.visible == 0) == (with_.visible_fraction == 0)).all()
    assert set(with_["class"]) <= set(CLASSES)


@pytest.mark.gl
def test_simulated_motion_stays_exact_between_frames_under_rolling_shutter_and_lens():
    import cv2

    # every band of rows is rendered at its own instant, and the truth places each vehicle there by
    # the same closed form of its speed profile: warping still explains the moving vehicles
    spec = load_scene_spec("realistic", overrides={
        "image.n_frames": 3, "camera.altitude_m": 45.0, "light.mode": "flat", "light.shadows": False,
        "light.illumination_drift_per_s": 0.0, "sensor.motion_blur.exposure_s": 0.0,
        "sensor.noise.gaussian_std": 0.0, "sensor.noise.full_well_e": 0.0, "sensor.compression.codec": "none",
        "sensor.haze.extinction_per_km": 0.0, "traffic.density_per_lane_km": 40.0, "traffic.junctions": "none"})
    assert spec.sensor.rolling_shutter.line_delay_s > 0 and spec.sensor.lens.k1 != 0
    gen = SceneGenerator(spec)
    assert any(v.kind == "profile" for v in gen.vehicles)
    frames = list(gen.frames())
    err = zero = n = 0.0
    for a, b in zip(frames, frames[1:]):
        truth = b.pair
        f0, f1 = as_gray(a.rgb), as_gray(b.rgb)
        warped, _ = warp_backward(f1, truth.flow)
        for v in gen.vehicles:
            mask = truth.valid & (truth.instances == v.vehicle_id)
            inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
            if v.kind != "profile" or inner.sum() < 2 or np.median(
                    np.hypot(*(truth.flow - truth.flow_camera)[inner].T)) < 0.2:
                continue
            err += np.abs(warped - f0)[inner].sum()
            zero += np.abs(f1 - f0)[inner].sum()
            n += inner.sum()
    assert n > 500 and zero / n > 5.0
    assert err / n < 0.1 * zero / n + 0.5, (err / n, zero / n, n)
