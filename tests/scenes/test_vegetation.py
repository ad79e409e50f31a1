"""Trees, hedges and woods: varied crowns, shadows that start at the trunk, canopies over woods."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from scenes.vegetation import CANOPY_GRID_M, canopy_mesh, crown_lobes, sun_shading, tree_shadow_shapes, trunk_size
from scenes.world import Tree, sun_direction
from tests.scenes.test_world_layout import _world

BUILT = {"seed": 2, "camera.altitude_m": 40.0, "world.built_fraction": 0.6, "world.parking_fraction": 0.0,
         "world.wood_fraction": 0.2, "world.buildings.count": 8, "world.buildings.height_range_m": [4.0, 10.0],
         "world.buildings.footprint_range_m": [6.0, 12.0], "world.trees.density_per_ha": 40.0}
# single broad-leaved trees, few enough to stand alone
SPARSE = {"seed": 4, "camera.altitude_m": 40.0, "image.width_px": 320, "image.height_px": 240,
          "world.built_fraction": 0.5, "world.wood_fraction": 0.0, "world.parking_fraction": 0.0,
          "world.buildings.count": 0, "world.trees.density_per_ha": 12.0, "world.trees.hedge_fraction": 0.0,
          "world.trees.conifer_fraction": 0.0}


def _texel(world, p) -> tuple[int, int]:
    x0, y0 = world.extent_m[:2]
    return (int(math.floor((p[1] - y0) / world.texel_m)), int(math.floor((p[0] - x0) / world.texel_m)))


def test_crowns_are_varied_and_keep_inside_their_bounds():
    rng = np.random.default_rng(3)
    outlines = set()
    for _ in range(40):
        h, r, half = rng.uniform(6, 14), rng.uniform(1.5, 4), rng.uniform(1.5, 3)
        lobes = np.array(crown_lobes(rng, height_m=h, radius_m=r, half_height_m=half))
        assert 4 <= len(lobes) <= 7
        reach = np.hypot(lobes[:, 0], lobes[:, 1]) + np.maximum(lobes[:, 3], lobes[:, 4])
        assert reach.max() <= r + 1e-9  # within the reach the placement keeps clear of roads
        assert (lobes[:, 2] + lobes[:, 5]).max() <= h + 1e-9  # under the top
        assert (lobes[:, 2] - lobes[:, 5]).min() >= h - 2 * half - 1e-9  # above the crown's bottom
        outlines.add((len(lobes), round(float(lobes[1:, 3].sum()), 3)))
    assert len(outlines) > 30  # not one shape repeated


def test_a_world_has_conifers_lobed_crowns_and_several_colours():
    _, _, world, _ = _world("nominal", **{"world.trees.density_per_ha": 40.0})
    single = [t for t in world.trees if not t.bush]
    assert sum(t.conifer for t in single) >= 2 and sum(not t.conifer for t in single) >= 10
    assert len({len(t.lobes) for t in single if not t.conifer}) >= 3
    assert len({t.variant for t in single}) >= 4
    assert np.ptp([t.height_m for t in single]) > 4.0 and np.ptp([t.crown_radius_m for t in single]) > 1.5


@pytest.mark.parametrize(("elevation", "azimuth"), [(50.0, 135.0), (25.0, 300.0), (70.0, 20.0)])
def test_the_painted_tree_shadow_starts_at_the_trunk_base_and_falls_away_from_the_sun(elevation, azimuth):
    # one tree alone on the ground: its shadow must touch its trunk's base, run unbroken to the
    # crown's shadow, and not reach toward the sun
    light = {"light.sun_elevation_deg": elevation, "light.sun_azimuth_deg": azimuth}
    _, _, lit, _ = _world("tiny", **SPARSE, **light)
    _, _, unlit, _ = _world("tiny", **SPARSE, **light, **{"light.shadows": False})
    ratio = lit.ground_texture.astype(float).sum(axis=2) / np.maximum(1.0, unlit.ground_texture.astype(float).sum(axis=2))
    to_sun = sun_direction(elevation, azimuth)
    a = -to_sun[:2] / to_sun[2]
    u = a / np.hypot(*a)
    others = [(b.centre[:2], 0.5 * math.hypot(*b.size[:2]) + b.size[2] * np.hypot(*a)) for b in lit.buildings]
    checked = 0
    for t in lit.trees:
        if t.bush or t.conifer:
            continue
        base = np.array([t.x_m, t.y_m])
        reach = t.crown_radius_m + 1.0
        # another tree's crown or shadow could cover the points looked at
        crowded = [o for o in lit.trees if o is not t and np.hypot(o.x_m - t.x_m, o.y_m - t.y_m)
                   < reach + o.reach_m + o.height_m * np.hypot(*a)]
        crowded += [c for c, r in others if np.hypot(*(c - base)) < reach + r]
        crowded += [c for c in lit.canopies if np.hypot(*(c["outline"] - base).T).min() < reach + 30.0]
        x0, y0, x1, y1 = lit.extent_m
        if crowded or not (x0 + reach < t.x_m < x1 - reach and y0 + reach < t.y_m < y1 - reach):
            continue
        _, h_trunk = trunk_size(t)
        # from 0.15 m off the base (the trunk is 0.25 m wide) to the crown's shadow: shadowed, at the ambient level
        for s in np.arange(0.15, h_trunk * np.hypot(*a), 0.1):
            r, c = _texel(lit, base + s * u)
            assert ratio[r, c] < 0.8, (s, ratio[r, c])
        # toward the sun, beyond the crown's own reach, the ground is lit
        r, c = _texel(lit, base - (t.crown_radius_m + 1.0) * u)
        assert ratio[r, c] > 0.95
        checked += 1
    assert checked >= 2


def test_shadow_shapes_are_the_exact_projection_of_a_lobe():
    # an ellipsoid's shadow: every surface point projected along the sun lies in the ellipse, and the
    # ellipse's extreme points are projections of surface points
    to_sun = sun_direction(35.0, 200.0)
    t = Tree(x_m=3.0, y_m=-2.0, height_m=10.0, crown_radius_m=3.0, crown_half_height_m=3.0, variant=0,
             lobes=((0.5, -0.4, 7.0, 2.5, 2.0, 2.8),))
    (centres, axes, angles), polys = tree_shadow_shapes([t], to_sun)
    assert len(centres) == 1 and len(polys) == 1  # the lobe, and the trunk
    a = -to_sun[:2] / to_sun[2]
    th, ph = np.meshgrid(np.linspace(0, np.pi, 60), np.linspace(0, 2 * np.pi, 120))
    pts = np.stack([2.5 * np.sin(th) * np.cos(ph) + 3.5, 2.0 * np.sin(th) * np.sin(ph) - 2.4,
                    2.8 * np.cos(th) + 7.0], axis=-1).reshape(-1, 3)
    ground = pts[:, :2] + pts[:, 2:3] * a
    ang = math.radians(angles[0])
    R = np.array([[math.cos(ang), math.sin(ang)], [-math.sin(ang), math.cos(ang)]])
    local = (ground - centres[0]) @ R.T / axes[0]
    q = (local ** 2).sum(axis=1)
    assert q.max() <= 1.0 + 1e-6 and q.max() > 0.995
    # the trunk's strip starts at the base
    assert np.hypot(*(polys[0][:2].mean(axis=0) - (3.0, -2.0))) < 1e-9


def test_shadowed_ground_is_the_ambient_fraction_of_the_sunlit_ground_not_black():
    _, _, lit, _ = _world("tiny", **BUILT)
    _, _, unlit, _ = _world("tiny", **BUILT, **{"light.shadows": False})
    a, b = lit.ground_texture.astype(float), unlit.ground_texture.astype(float)
    shadow = (b - a).sum(axis=2) > 60
    ratio = a.sum(axis=2)[shadow] / b.sum(axis=2)[shadow]
    # deep inside a shadow (the edges are soft) the ground keeps 0.45 of its light: ambient, not black
    assert abs(np.median(ratio) - 0.45) < 0.03
    assert np.percentile(ratio, 2) > 0.4
    assert a[shadow].min() > 0


def test_a_wood_is_one_canopy_of_crowns_over_its_block():
    rng = np.random.default_rng(1)
    square = np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 40.0], [0.0, 40.0]])
    c = canopy_mesh(square, rng, inset_m=3.0, density_per_ha=250.0, crown_diameter_range_m=(3.5, 8.0),
                    height_range_m=(5.0, 14.0))
    pos = c["positions"]
    assert pos[:, 2].min() > 0.5  # above the ground: the truth sees a surface, not ground
    inner = (pos[:, 0] > 10) & (pos[:, 0] < 40) & (pos[:, 1] > 10) & (pos[:, 1] < 30)
    assert np.ptp(pos[inner, 2]) > 4.0 and pos[inner, 2].std() > 1.0  # crowns, not a flat lid
    assert (pos[:, :2] >= 3.0 - 1.0).all() and (pos[:, :2] <= np.array([47.0, 37.0]) + 1.0).all()
    # it covers the shrunk block: the triangles' area is that of 44 x 34 m, within a grid step all round
    p = pos[c["indices"].astype(int)]
    e1, e2 = p[:, 1, :2] - p[:, 0, :2], p[:, 2, :2] - p[:, 0, :2]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    g = CANOPY_GRID_M
    assert (44 - g) * (34 - g) < area < (44 + g) * (34 + g)
    assert len(np.unique(np.round(c["tint"], 3), axis=0)) > 20  # each crown its own tint
    assert (c["normals"][:, 2] > 0).all()


def test_baked_sun_shading_is_ambient_away_from_the_sun_and_one_on_flat_ground():
    s = sun_direction(50.0, 135.0)
    k = sun_shading(np.array([[0, 0, 1.0], -s, s]), s, 0.45)
    np.testing.assert_allclose(k, [1.0, 0.45, 1.15], atol=1e-6)


def test_crown_detail_makes_leaf_clumps_larger_and_deeper_with_the_same_draws():
    from scenes.vegetation import crown_texture

    plain = crown_texture(np.random.default_rng(3), (255, 255, 255)).astype(np.float64).mean(axis=2)
    busy = crown_texture(np.random.default_rng(3), (255, 255, 255), detail=1.0).astype(np.float64).mean(axis=2)
    # clumps a fifth of a lobe wide: seen through a box of 12 texels (a tenth), the busy crown varies more
    b0, b1 = (cv2.blur(g, (12, 12)) for g in (plain, busy))
    assert b1.std() > 2.0 * b0.std(), (b1.std(), b0.std())
