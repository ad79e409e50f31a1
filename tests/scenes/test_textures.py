"""Ground materials: each its own colour and spectrum, periodic tiles, soft transitions."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.textures import MATERIALS, MaterialPattern, material_tile, spectral_noise
from scenes.world import _Canvas, _paint_ground

TEXEL_M = 0.15


def _radial_power(img: np.ndarray, texel_m: float):
    """Radially averaged power spectrum of a periodic tile: (frequency in cycles / m, power)."""
    n = img.shape[0]
    P = np.abs(np.fft.fft2(img - img.mean())) ** 2
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n))) / texel_m
    bins = np.linspace(0, f.max(), 60)
    k = np.digitize(f.ravel(), bins)
    power = np.bincount(k, P.ravel(), len(bins) + 1)[1:-1] / np.maximum(1, np.bincount(k, None, len(bins) + 1)[1:-1])
    return 0.5 * (bins[1:] + bins[:-1]), power


@pytest.mark.parametrize("beta", [0.0, 1.0, 2.0])
def test_spectral_noise_has_the_power_law_asked_for_inside_its_band(beta):
    rng = np.random.default_rng(0)
    white = np.fft.rfft2(rng.standard_normal((256, 256)))
    n = spectral_noise(white, TEXEL_M, beta=beta, shortest_m=0.5, longest_m=20.0)
    assert n.dtype == np.float32 and abs(float(n.mean())) < 1e-4 and abs(float(n.std()) - 1.0) < 1e-3
    f, p = _radial_power(n, TEXEL_M)
    band = (f > 1 / 8.0) & (f < 1 / 1.2)  # well inside (the roll-off is soft at both ends)
    slope = np.polyfit(np.log(f[band]), np.log(p[band]), 1)[0]
    assert abs(slope + beta) < 0.35, slope


def test_materials_differ_in_colour_and_in_spectrum():
    rng = np.random.default_rng(1)
    names = ["grass", "meadow", "soil", "gravel", "yard"]
    tiles = {name: material_tile(name, rng, TEXEL_M, n=256) for name in names}
    means = {k: t.reshape(-1, 3).mean(axis=0) for k, t in tiles.items()}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert np.abs(means[a] - means[b]).sum() > 15, (a, b)  # told apart by colour
    # and by texture: the share of brightness variance at wavelengths under half a metre
    spectra = {k: _radial_power(t.mean(axis=2), TEXEL_M) for k, t in tiles.items()}
    share = {k: {"fine": p[f > 2.0].sum() / p.sum(), "mid": p[(f > 0.5) & (f < 2.0)].sum() / p.sum(),
                 "low": p[f < 0.2].sum() / p.sum()} for k, (f, p) in spectra.items()}
    # gravel's stones at the texel
    assert share["gravel"]["fine"] > 2 * share["soil"]["fine"] and share["gravel"]["fine"] > 2 * share["yard"]["fine"]
    # meadow's tussocks at 0.5-2 m, more than mown grass or soil
    assert share["meadow"]["mid"] > 2 * share["grass"]["mid"] and share["meadow"]["mid"] > 2 * share["soil"]["mid"]
    # grass and soil vary most over metres (dry and damp patches), meadow hardly
    assert min(share["grass"]["low"], share["soil"]["low"]) > 5 * share["meadow"]["low"]


def test_a_tile_repeats_seamlessly_and_a_pattern_samples_it_at_world_texels():
    rng = np.random.default_rng(2)
    tile = material_tile("soil", rng, TEXEL_M, n=64)
    # periodic: the jump across the seam is no larger than between any two neighbours
    inner = np.abs(np.diff(tile, axis=1)).mean()
    seam = np.abs(tile[:, 0] - tile[:, -1]).mean()
    assert seam < 2 * inner
    pat = MaterialPattern(tile, x0_m=10.0, y0_m=-5.0, texel_m=TEXEL_M, offset_px=(3, 60), gain=(1.0, 0.5, 2.0))
    X = 10.0 + (np.arange(130) + 0.5) * TEXEL_M
    Y = np.full(130, -5.0 + 7.5 * TEXEL_M)
    got = pat(X, Y)
    cols = (np.arange(130) + 3) % 64
    np.testing.assert_allclose(got, tile[(7 + 60) % 64, cols] * np.float32([1.0, 0.5, 2.0]), rtol=1e-6)


def test_unknown_material_is_refused_with_the_valid_names():
    with pytest.raises(KeyError, match="unknown ground material 'lava'.*grass"):
        material_tile("lava", np.random.default_rng(0), TEXEL_M)


@pytest.mark.parametrize(("feather_m", "lo_m", "hi_m"), [(0.0, 0.0, 0.5), (1.5, 3.0, 5.0)])
def test_a_feathered_patch_blends_in_over_metres(feather_m, lo_m, hi_m):
    # a patch of another material over a block: its edge goes from 10 % to 90 % over 2.56 sigma of the
    # feather (a Gaussian edge), where an unfeathered one is as sharp as the texture's blur
    texel = 0.1
    canvas = _Canvas(0.0, 0.0, texel, 400, 40)
    canvas.polygon([np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 4.0], [0.0, 4.0]])], (100.0, 100.0, 100.0))
    canvas.polygon([np.array([[20.0, -5.0], [60.0, -5.0], [60.0, 9.0], [20.0, 9.0]])], (200.0, 200.0, 200.0),
                   feather_m=feather_m)
    xs = (np.arange(400, dtype=np.float32) + 0.5) * texel
    ys = (np.arange(40, dtype=np.float32) + 0.5) * texel
    g = _paint_ground(canvas.ops, np.ones((40, 400), np.float32), xs, ys)[20, :, 0].astype(float)
    lo, hi = np.searchsorted(g, 110.0), np.searchsorted(g, 190.0)
    width_m = (hi - lo) * texel
    assert lo_m <= width_m <= hi_m, width_m
    assert abs(0.5 * (lo + hi) * texel - 20.0) < 0.3  # centred on the patch's outline


def test_materials_all_build():
    rng = np.random.default_rng(4)
    for name in MATERIALS:
        t = material_tile(name, rng, TEXEL_M, n=32)
        assert t.shape == (32, 32, 3) and np.isfinite(t).all()


def _band_power(tile: np.ndarray, lo_m: float, hi_m: float) -> float:
    f, p = _radial_power(tile.mean(axis=2), TEXEL_M)
    return float(p[(f > 1 / hi_m) & (f < 1 / lo_m)].sum())


@pytest.mark.parametrize("name", ["yard", "grass", "lawn", "asphalt", "soil", "meadow"])
def test_detail_adds_structure_at_1_to_3_m_and_little_at_the_texel(name):
    # world.detail: the same draws, power added at 1-3 m (KIT AIS's busy blocks), hardly any at the texel
    plain = material_tile(name, np.random.default_rng(4), TEXEL_M, n=256)
    same = material_tile(name, np.random.default_rng(4), TEXEL_M, n=256, detail=0.0)
    busy = material_tile(name, np.random.default_rng(4), TEXEL_M, n=256, detail=1.0)
    np.testing.assert_array_equal(plain, same)
    mid = _band_power(busy, 1.0, 3.0) - _band_power(plain, 1.0, 3.0)
    fine = _band_power(busy, 2 * TEXEL_M, 3 * TEXEL_M) - _band_power(plain, 2 * TEXEL_M, 3 * TEXEL_M)
    assert mid > 0.4 * _band_power(plain, 1.0, 3.0), (mid, _band_power(plain, 1.0, 3.0))
    assert mid > 4.0 * fine, (mid, fine)  # four times the power at 1-3 m as at 2-3 texels (0.3-0.45 m)


def test_negative_detail_is_refused():
    with pytest.raises(ValueError, match="detail must be >= 0, got -1"):
        material_tile("yard", np.random.default_rng(0), TEXEL_M, detail=-1.0)
