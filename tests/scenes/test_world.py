"""The ground texture is built strip by strip, and a strip build equals the whole-texture build."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import scenes.world as world_mod
from scenes import load_scene_spec
from scenes.motion import camera_path


def _world(spec, *, strip_rows: int, draw_rows: int, monkeypatch):
    """build_world of ``spec`` with the given strip heights; (world, the world rng's next draw)."""
    monkeypatch.setattr(world_mod, "STRIP_ROWS", strip_rows)
    monkeypatch.setattr(world_mod, "_DRAW_ROWS", draw_rows)
    ss = np.random.SeedSequence(spec.seed)
    rng_jitter, rng_world = (np.random.Generator(np.random.PCG64(s)) for s in ss.spawn(2))
    path = camera_path(spec, rng_jitter)
    w = world_mod.build_world(spec, path, rng_world)
    return w, rng_world.uniform()


@pytest.mark.parametrize("preset", ["tiny", "urban-parallax"])
def test_strip_build_equals_whole_build(preset, monkeypatch):
    # one strip as tall as the texture is the whole-texture build (blur sees the true image
    # borders); strips of 7 rows (fewer than the blur halo, not dividing the height) must
    # give the same bytes, the same layout, and leave the random stream at the same place
    spec = load_scene_spec(preset, overrides={"image.width_px": 160, "image.height_px": 120})
    whole, next_whole = _world(spec, strip_rows=10**6, draw_rows=10**6, monkeypatch=monkeypatch)
    strips, next_strips = _world(spec, strip_rows=7, draw_rows=5, monkeypatch=monkeypatch)
    assert whole.ground_texture.shape[0] % 7 != 0
    assert whole.ground_texture.dtype == np.uint8
    np.testing.assert_array_equal(strips.ground_texture, whole.ground_texture)
    assert strips.stalls == whole.stalls and strips.buildings == whole.buildings and strips.trees == whole.trees
    for a, b in zip(strips.wall_textures + strips.roof_textures + strips.crown_textures,
                    whole.wall_textures + whole.roof_textures + whole.crown_textures, strict=True):
        np.testing.assert_array_equal(a, b)
    assert next_strips == next_whole
    # the texture is painted: roads, marks and shaded blocks, not a constant
    assert np.unique(whole.ground_texture.reshape(-1, 3), axis=0).shape[0] > 100


def test_multiscale_noise_equals_one_resize_per_octave(monkeypatch):
    # the reference: each octave one uniform draw of the whole lattice, one cubic resize,
    # clipped and weighted, summed in order (how the texture was shaded before strips)
    monkeypatch.setattr(world_mod, "STRIP_ROWS", 5)
    monkeypatch.setattr(world_mod, "_DRAW_ROWS", 3)
    shape, texel_m = (61, 47), 0.5
    ref_rng, rng = np.random.default_rng(7), np.random.default_rng(7)
    expected = np.zeros(shape, np.float32)
    octaves = [(cell_m / texel_m, amp) for cell_m, amp in world_mod.NOISE_OCTAVES_M
               if cell_m / texel_m >= 2] + [(world_mod.TEXELS_PER_PIXEL, world_mod.GRAIN_AMP)]
    assert len(octaves) == 5
    for cell_px, amp in octaves:
        gh, gw = int(np.ceil(shape[0] / cell_px)) + 2, int(np.ceil(shape[1] / cell_px)) + 2
        g = ref_rng.uniform(-1.0, 1.0, (gh, gw)).astype(np.float32)
        big = cv2.resize(g, (int(round(gw * cell_px)), int(round(gh * cell_px))), interpolation=cv2.INTER_CUBIC)
        expected += amp * np.clip(big[:shape[0], :shape[1]], -1.0, 1.0)
    got = world_mod._multiscale_noise(rng, shape, texel_m)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, expected)
    assert rng.uniform() == ref_rng.uniform()


def test_overlapping_shadows_darken_the_ground_once_to_the_ambient_level():
    # two buildings whose shadows overlap, and a tree whose shadow falls into theirs: the ground in
    # every shadow, overlaps included, keeps the ambient fraction of its light (a single fillPoly of
    # several contours would leave an overlap lit; separate shapes would darken it to ambient^2)
    from types import SimpleNamespace

    from scenes.world import Building, Tree, _paint_shadows
    from scenes.vegetation import crown_lobes

    light = SimpleNamespace(sun_elevation_deg=45.0, sun_azimuth_deg=90.0, ambient=0.45)  # sun in the east
    blocks = [Building(centre=(x, 0.0, 4.0), size=(6.0, 6.0, 8.0), yaw_rad=0.0, parts=(), roof_variant=0)
              for x in (10.0, 6.0)]
    rng = np.random.default_rng(0)
    tree = Tree(x_m=9.0, y_m=-6.0, height_m=8.0, crown_radius_m=3.0, crown_half_height_m=2.5, variant=0,
                lobes=crown_lobes(rng, height_m=8.0, radius_m=3.0, half_height_m=2.5))
    texel = 0.1
    canvas = world_mod._Canvas(-20.0, -15.0, texel, 400, 300)
    _paint_shadows(canvas, blocks, [tree], [], light)
    xs = -20.0 + (np.arange(400, dtype=np.float32) + 0.5) * texel
    ys = -15.0 + (np.arange(300, dtype=np.float32) + 0.5) * texel
    lit = np.full((300, 400), 1.0, np.float32)
    tex = world_mod._paint_ground([world_mod._Paint(slice(0, 300), slice(0, 400), (200.0, 200.0, 200.0))] + canvas.ops,
                                  lit, xs, ys)[..., 0].astype(float) / 200.0
    # the two shadows overlap west of the western building (x 0..3 m at y = 0): one level, ambient
    r = int((0.0 + 15.0) / texel)
    for x in (-2.0, 0.5, 2.0):
        assert abs(tex[r, int((x + 20.0) / texel)] - 0.45) < 0.02, x
    assert abs(np.median(tex[tex < 0.9]) - 0.45) < 0.02
    assert tex.min() > 0.43  # nowhere ambient^2


def test_roof_seams_hold_no_detail_at_the_texel():
    # a seam is band-limited to about two texels: a one-texel line aliases at the pixel and reads as sensor
    # noise in a frame's flat half (benchmarks/realism.py's noise_sigma); the seams still show (every 1.6 m)
    _, roofs = world_mod._building_textures(np.random.default_rng(1), 0.1)
    g = roofs[0].astype(np.float64).mean(axis=2)
    across = g[:, 2:] - 2 * g[:, 1:-1] + g[:, :-2]  # second difference across the seams
    assert across.std() < 2.0 * g.std(), (across.std(), g.std())  # one-texel seams: 2.8x
    profile = g.mean(axis=0)
    seams = profile[::16].mean()
    assert seams < np.median(profile) - 5.0  # darker lines every 16 texels


def test_roof_detail_adds_panels_metres_wide_and_keeps_the_seams_smooth():
    # world.detail: lighter and darker panels 1-3 m wide on the roof; no new detail at the texel
    _, plain = world_mod._building_textures(np.random.default_rng(1), 0.1)
    _, busy = world_mod._building_textures(np.random.default_rng(1), 0.1, detail=1.0)
    g0, g1 = (r[0].astype(np.float64).mean(axis=2) for r in (plain, busy))
    smooth0, smooth1 = (cv2.blur(g, (15, 15)) for g in (g0, g1))  # 1.5 m boxes: panels stay, seams go
    assert smooth1.std() > 1.5 * smooth0.std(), (smooth1.std(), smooth0.std())
    across = g1[:, 2:] - 2 * g1[:, 1:-1] + g1[:, :-2]
    assert across.std() < 2.0 * g1.std()
