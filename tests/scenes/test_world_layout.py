"""The world's layout: roads irregular yet drivable, nothing intersects, vehicles on roads, no stripes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes import load_scene_spec
from scenes.motion import camera_path, polyline_arc_lengths
from scenes.world import (build_world, distance_to_polyline, field_rows, place_vehicles, point_rect_distance,
                          rects_overlap)


def _world(preset: str, **overrides):
    spec = load_scene_spec(preset, overrides=overrides or None)
    ss = np.random.SeedSequence(spec.seed)
    rng_jitter, rng_world, rng_vehicles = (np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(3))
    path = camera_path(spec, rng_jitter)
    world = build_world(spec, path, rng_world)
    return spec, path, world, rng_vehicles


def _resampled(line: np.ndarray, step_m: float = 0.25) -> np.ndarray:
    s = polyline_arc_lengths(line)
    t = np.linspace(0.0, s[-1], max(2, int(math.ceil(s[-1] / step_m)) + 1))
    return np.stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])], axis=1)


def _near(world, pts: np.ndarray, pad_m: float):
    lo, hi = pts.min(axis=0) - pad_m, pts.max(axis=0) + pad_m
    return [r for r in world.roads if (r.centre_m.max(axis=0) > lo).all() and (r.centre_m.min(axis=0) < hi).all()]


@pytest.fixture(scope="module")
def urban():
    return _world("urban-parallax")


def test_buildings_never_intersect_each_other_roads_or_trees(urban):
    _, _, world, _ = urban
    assert len(world.buildings) >= 15
    corners = [b.corners_xy() for b in world.buildings]
    for i, a in enumerate(corners):
        for b in corners[i + 1:]:
            assert not rects_overlap(a, b, 0.0)
    for b, c in zip(world.buildings, corners):
        for r in _near(world, c, 60.0):
            # the road's asphalt (centre line +- half width) stays off the footprint
            assert point_rect_distance(_resampled(r.centre_m), c).min() > r.width_m / 2
        for t in world.trees:
            assert point_rect_distance(np.array([[t.x_m, t.y_m]]), c)[0] > t.reach_m
        # parapets and roof units stand on the roof, inside the footprint
        lo = min(p.centre[2] - p.size[2] / 2 for p in b.parts)
        assert lo == 0.0
        for p in b.parts[1:]:
            assert p.centre[2] - p.size[2] / 2 >= b.size[2] - 1e-9
            assert abs(p.centre[0]) + p.size[0] / 2 <= b.size[0] / 2 + 1e-9
            assert abs(p.centre[1]) + p.size[1] / 2 <= b.size[1] / 2 + 1e-9


@pytest.mark.parametrize("preset", ["nominal", "urban-parallax"])
def test_trees_stand_above_the_ground_and_off_the_roads(preset, urban):
    _, _, world, _ = urban if preset == "urban-parallax" else _world(preset)
    assert len(world.trees) > 10
    for t in world.trees:
        # the crown's lowest point is above z = 0: the depth-based ground truth sees a tree, not ground
        assert t.height_m - 2 * t.crown_half_height_m > 0.05
        p = np.array([[t.x_m, t.y_m]])
        for r in _near(world, p, 60.0):
            assert distance_to_polyline(p, r.centre_m)[0] > r.width_m / 2 + t.reach_m


def test_road_network_is_irregular_by_default_and_a_grid_at_zero_irregularity():
    def shape(world):
        bend = max(distance_to_polyline(r.centre_m, r.centre_m[[0, -1]]).max() for r in world.roads)
        degree = np.bincount(np.array([r.nodes for r in world.roads]).ravel())
        angles = np.array([math.atan2(*(r.centre_m[-1] - r.centre_m[0])[::-1]) for r in world.roads])
        return bend, degree[degree > 0], np.mod(angles, 0.5 * math.pi)

    bend, degree, angles = shape(_world("nominal")[2])
    assert bend > 2.0  # curved roads
    assert (degree == 3).sum() >= 3  # T junctions
    assert np.ptp(angles) > 0.2  # not all at right angles
    bend, degree, angles = shape(_world("nominal", **{"world.road_irregularity": 0.0,
                                                      "world.road_drop_fraction": 0.0})[2])
    assert bend < 1e-9
    assert np.ptp(angles) < 1e-9 or np.ptp(np.mod(angles + 0.25 * math.pi, 0.5 * math.pi)) < 1e-9
    assert (degree == 3).sum() == 0 or degree.max() == 4  # only the grid's border has fewer roads


@pytest.mark.parametrize(("preset", "seed"), [("tiny", 1), ("tiny", 2), ("nominal", 1), ("thesis", 3),
                                              ("fast-vehicles", 4)])
def test_vehicles_drive_on_roads_and_park_on_roads_or_stalls(preset, seed):
    spec, path, world, rng = _world(preset, seed=seed)
    vehicles = place_vehicles(spec, world, path, rng)
    assert len(vehicles) == spec.vehicles.count
    stalls = np.array([s[:2] for s in world.stalls]).reshape(-1, 2)
    for v in vehicles:
        pts = np.array([v.pose(float(t))[:2] for t in path.t_s])
        on_road = np.full(len(pts), np.inf)
        for r in _near(world, pts, 60.0):
            on_road = np.minimum(on_road, distance_to_polyline(pts, r.centre_m) - r.width_m / 2)
        if v.parked:
            in_stall = len(stalls) and np.hypot(*(stalls - pts[0]).T).min() < 1e-6
            assert in_stall or on_road.max() < 0, (v.vehicle_id, on_road.max())
        else:
            # the centre is on the asphalt at every frame, curves and junction corners included
            assert on_road.max() < 0, (v.vehicle_id, on_road.max())
            # and it really drives: each frame's step matches its speed
            step = np.hypot(*np.diff(pts, axis=0).T)
            assert step.max() > 0


def test_same_seed_same_world_other_seed_other_world():
    _, _, a, _ = _world("tiny")
    _, _, b, _ = _world("tiny")
    _, _, c, _ = _world("tiny", seed=99)
    np.testing.assert_array_equal(a.ground_texture, b.ground_texture)
    assert a.trees == b.trees and a.buildings == b.buildings and len(a.roads) == len(b.roads)
    assert all(np.array_equal(r.centre_m, q.centre_m) for r, q in zip(a.roads, b.roads))
    assert len(a.canopies) == len(b.canopies)
    for p, q in zip(a.canopies, b.canopies):
        for key in ("positions", "tint", "indices", "outline"):
            np.testing.assert_array_equal(p[key], q[key])
    for p, q in zip(a.crown_textures + [a.canopy_texture] * bool(a.canopies),
                    b.crown_textures + [b.canopy_texture] * bool(b.canopies)):
        np.testing.assert_array_equal(p, q)
    assert a.ground_texture.shape != c.ground_texture.shape or not np.array_equal(a.ground_texture, c.ground_texture)


def test_field_rows_have_no_dominant_frequency():
    # A stripe pattern puts its energy in one spatial frequency (a pure sinusoid: half in each of
    # its two FFT peaks), which lets a flow method lock onto the wrong row (aperture, aliasing).
    # Bent, fading rows spread it: no frequency may hold more than 10 % of the pattern's energy.
    rng = np.random.default_rng(5)
    x = np.arange(0.0, 80.0, 0.2)
    X, Y = np.meshgrid(x, x)
    checked = 0
    for _ in range(12):
        rows = field_rows(rng, np.zeros(3), rng.uniform(0, math.pi))
        if rows.amp == 0:
            continue
        v = rows(X, Y)[..., 0]
        assert np.abs(v).max() <= rows.amp + 1e-9 <= 5.0 + 1e-9  # faint: a few gray levels about the base
        v = v - v.mean()
        P = np.abs(np.fft.fft2(v)) ** 2
        assert P.max() / P.sum() < 0.1
        checked += 1
    assert checked >= 5
