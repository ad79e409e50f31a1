"""Streets: kerbs and sidewalks by built-up blocks, zebra crossings and stop lines at junctions."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from scenes.streets import ZEBRA_LENGTH_M, junction_marks
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
