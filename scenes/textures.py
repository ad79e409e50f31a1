"""Ground materials: grass, meadow, soil, gravel, yards, wood floor, asphalt, each its own texture.

A material is a periodic RGB tile (``TILE_PX`` texels a side) made once per world by
spectral synthesis: white noise shaped in the Fourier domain to a power law
``P(f) ~ f^-beta`` between two wavelengths, one layer per physical feature (blades and
tufts of grass, clods of soil, stones of gravel, moisture patches, stains), each with
its own band, slope, depth and tint. So materials differ in their spectra and colours,
not only in a base colour over one shared cloud noise. A block samples its material's
tile at world coordinates with its own random offset (two blocks of grass never line
up), and the tile repeats only every ``TILE_PX`` texels (74 m at 120 m altitude), more
than a block is wide. Shapes are painted with soft edges (:meth:`scenes.world._Canvas.polygon`
``feather_m``), so patches blend into one another as real ground does.

No I/O, no OpenGL: arrays in, arrays out; every draw from an explicit Generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TILE_PX", "Layer", "MATERIALS", "DETAIL_LAYERS", "spectral_noise", "material_tile", "MaterialPattern"]

TILE_PX = 512  # texels a side of every material tile (periodic)


@dataclass(frozen=True)
class Layer:
    """One feature of a material: noise with ``P(f) ~ f^-beta`` between wavelengths ``shortest_m`` and
    ``longest_m``, unit standard deviation, scaled by ``depth``.

    ``tint`` None: a brightness change (relative, ``1 + depth n``). ``tint`` an RGB triple: a blend
    toward that colour where the noise exceeds ``threshold`` (standard deviations), over
    ``softness`` standard deviations (patches: dry grass, bare earth, stones, flowers), at most
    ``depth`` of the way.
    """

    beta: float
    shortest_m: float
    longest_m: float
    depth: float
    tint: tuple[float, float, float] | None = None
    threshold: float = 0.0
    softness: float = 1.0


# base RGB and layers; depths are relative brightness (a few gray levels to ~20 % at most): aerial
# photographs of ground are muted. The finest layers stay faint (a few %): content near the pixel
# scale is what bilinear resampling, and so the warp check of the flow truth, gets wrong
MATERIALS: dict[str, tuple[tuple[float, float, float], tuple[Layer, ...]]] = {
    # mown grass: fine even blades, faint clumps, dry yellowish patches metres wide
    "grass": ((84, 102, 66), (Layer(0.5, 0.15, 0.6, 0.042), Layer(2.0, 0.6, 4.0, 0.06),
                              Layer(2.5, 4.0, 30.0, 0.5, (128, 124, 84), 0.8, 1.2))),
    # meadow: tussocks half a metre to two (strong middle band), flower specks, brown patches
    "meadow": ((110, 118, 78), (Layer(0.5, 0.15, 0.5, 0.03), Layer(1.0, 0.5, 2.0, 0.14),
                                Layer(0.0, 0.15, 0.35, 0.8, (196, 190, 150), 2.3, 0.4),
                                Layer(2.5, 5.0, 25.0, 0.45, (126, 112, 80), 0.6, 1.5))),
    # bare soil: clods (steep slope from 1 m down), damp darker patches, pale stones
    "soil": ((128, 108, 86), (Layer(1.5, 0.15, 1.2, 0.12), Layer(2.5, 3.0, 25.0, 0.5, (96, 80, 64), 0.3, 1.5),
                              Layer(0.0, 0.15, 0.3, 0.7, (168, 158, 142), 2.4, 0.5))),
    # gravel: flat white grain at the texel (stones), little else
    "gravel": ((148, 144, 136), (Layer(0.0, 0.15, 0.45, 0.096), Layer(2.0, 2.0, 15.0, 0.04),
                                 Layer(0.0, 0.15, 0.3, 0.6, (96, 94, 90), 2.0, 0.6))),
    # yards: worn concrete and paving, patches and tyre marks half a metre to metres wide, oil and water
    # stains, fine grain (KIT AIS's courtyards and roads vary by 6-10 % over a few metres)
    "yard": ((136, 134, 128), (Layer(0.5, 0.15, 0.5, 0.016), Layer(1.5, 0.5, 12.0, 0.07),
                               Layer(2.5, 3.0, 20.0, 0.35, (112, 110, 106), 1.6, 1.0))),
    # the floor under a wood's canopy: dark, leaf litter and undergrowth
    "wood": ((56, 66, 44), (Layer(1.0, 0.15, 2.0, 0.14), Layer(2.0, 2.0, 15.0, 0.1))),
    # lawns in yards: finer and greener than a field of grass
    "lawn": ((84, 112, 62), (Layer(0.5, 0.15, 0.5, 0.036), Layer(2.0, 0.5, 6.0, 0.05))),
    # verges along roads: rough grass, some dry
    "verge": ((100, 112, 72), (Layer(0.5, 0.15, 0.8, 0.048), Layer(2.0, 1.0, 10.0, 0.4, (138, 130, 96), 0.8, 1.0))),
    # sidewalk paving: light, slightly blotchy
    "paving": ((150, 148, 142), (Layer(0.3, 0.15, 0.5, 0.02), Layer(1.5, 0.5, 10.0, 0.07))),
    # asphalt: aggregate grain and faint patching
    "asphalt": ((108, 108, 112), (Layer(0.0, 0.15, 0.4, 0.024), Layer(1.5, 0.6, 20.0, 0.07))),
    # crops under the field rows: a little grain only (the rows carry the rest)
    "crop": ((1.0, 1.0, 1.0), (Layer(0.5, 0.15, 0.8, 0.036), Layer(2.0, 0.8, 8.0, 0.04))),
}


# ``world.detail``: what a material has at 1-3 m besides its grain and its patches metres wide (at
# detail 1; the depths scale with it). KIT AIS's Munich blocks are busy at every metre, where the
# materials above are nearly flat: worn and relaid paving, stains and the things standing in yards,
# shrubs and bare spots in grass: dark and light blotches a metre or so across where a noise of
# wavelengths 2.4-4 m exceeds 1-1.3 standard deviations, blended in over 1.2 of one. Sparse and
# distinct, not an even grain: finer blotches (0.8 m) or harder edges added as much to the slope
# but two to three times as much to realism.py's noise estimate, which then counts them in a
# frame's flat half (docs/realism.md); bilinear warping reproduces them (the warp check of the truth)
DETAIL_LAYERS: dict[str, tuple[Layer, ...]] = {
    "grass": (Layer(0.5, 2.4, 3.0, 0.77, (46, 60, 38), 1.0, 1.2), Layer(0.5, 3.0, 3.6, 0.68, (150, 140, 104), 1.3, 1.2)),
    "meadow": (Layer(0.5, 2.4, 3.0, 0.77, (58, 68, 42), 1.0, 1.2),),
    "soil": (Layer(0.5, 2.4, 3.0, 0.77, (80, 66, 52), 1.0, 1.2),),
    "gravel": (Layer(0.5, 2.4, 3.0, 0.68, (100, 98, 94), 1.3, 1.2),),
    "yard": (Layer(0.5, 2.4, 3.0, 0.77, (62, 62, 64), 1.0, 1.2), Layer(0.5, 3.6, 4.0, 0.77, (200, 196, 186), 1.1, 1.2)),
    "wood": (),
    "lawn": (Layer(0.5, 2.4, 3.0, 0.77, (44, 62, 36), 1.0, 1.2),),
    "verge": (Layer(0.5, 2.4, 3.0, 0.77, (56, 68, 42), 1.0, 1.2),),
    "paving": (Layer(0.5, 2.4, 3.0, 0.77, (92, 90, 86), 1.2, 1.2),),
    "asphalt": (Layer(0.5, 2.7, 3.3, 0.68, (70, 70, 74), 1.3, 1.2),),
    "crop": (Layer(0.5, 2.4, 3.0, 0.68, (0.75, 0.75, 0.72), 1.3, 1.2),),
}


def spectral_noise(white_f: np.ndarray, texel_m: float, *, beta: float, shortest_m: float,
                   longest_m: float) -> np.ndarray:
    """Periodic noise (n, n) float32, zero mean, unit standard deviation, shaped from a white spectrum.

    Parameters
    ----------
    white_f : (n, n // 2 + 1) complex, ``numpy.fft.rfft2`` of white noise (shared by a material's layers,
        which are then correlated as real features are: tufts sit in clumps)
    texel_m : float, metres per texel
    beta : float, the power spectrum's slope, ``P(f) ~ f^-beta`` (0 white, 2 Brownian-like)
    shortest_m, longest_m : float, the band kept (wavelengths in metres; soft-edged at both ends);
        nothing finer than three texels (two image pixels: the texel is 1 / 1.5 of the ground sampling
        distance) is kept, so that resampling the texture at another sub-pixel phase changes it little
        (flow ground truth is checked by warping frames)
    """
    n = white_f.shape[0]
    fy = np.fft.fftfreq(n)[:, None]
    fx = np.fft.rfftfreq(n)[None, :]
    f = (np.hypot(fx, fy) / texel_m).astype(np.float32)  # cycles per metre
    f[0, 0] = 1.0
    hi, lo = 1.0 / max(shortest_m, 3 * texel_m), 1.0 / longest_m
    # amplitude ~ f^(-beta/2) in the band, Gaussian roll-off outside it (no ringing)
    logf = np.log(f)
    amp = np.exp(-0.5 * beta * logf
                 - 0.5 * (np.maximum(0.0, logf - math.log(hi)) / 0.35) ** 2
                 - 0.5 * (np.maximum(0.0, math.log(lo) - logf) / 0.35) ** 2)
    amp[0, 0] = 0.0
    out = np.fft.irfft2(white_f * amp, s=(n, n))
    sd = out.std()
    return (out / sd if sd > 0 else out).astype(np.float32)


def material_tile(name: str, rng: np.random.Generator, texel_m: float, *, n: int = TILE_PX,
                  detail: float = 0.0) -> np.ndarray:
    """The RGB tile (n, n, 3) float32 of material ``name`` (gray levels, not clipped), periodic in both axes.

    ``detail`` (``world.detail``, >= 0) adds the material's :data:`DETAIL_LAYERS` at that strength
    (their depths times ``detail``); the random draws are the same at every ``detail``.
    """
    if name not in MATERIALS:
        raise KeyError(f"unknown ground material {name!r}; expected one of {sorted(MATERIALS)}")
    if not detail >= 0.0:
        raise ValueError(f"detail must be >= 0, got {detail!r}")
    base, layers = MATERIALS[name]
    # the detail layers' noise is the shared one moved by a third and a fifth of the tile, and more for
    # each next layer: a field of its own (the same white noise draws), not dark where the material is
    # already light
    shifts = [(0, 0)] * len(layers)
    if detail > 0.0:
        extra = DETAIL_LAYERS[name]
        layers = layers + tuple(Layer(la.beta, la.shortest_m, la.longest_m, la.depth * detail, la.tint,
                                      la.threshold, la.softness) for la in extra)
        shifts += [(n * (k + 1) // 3, n * (k + 1) // 5) for k in range(len(extra))]
    white_f = np.fft.rfft2(rng.standard_normal((n, n), dtype=np.float32))
    tile = np.empty((n, n, 3), np.float32)
    tile[...] = np.asarray(base, np.float32)
    for layer, shift in zip(layers, shifts, strict=True):
        noise = spectral_noise(white_f, texel_m, beta=layer.beta, shortest_m=layer.shortest_m,
                               longest_m=layer.longest_m)
        if shift != (0, 0):
            noise = np.roll(noise, shift, axis=(0, 1))
        if layer.tint is None:
            tile *= (1.0 + layer.depth * noise)[..., None]
        else:
            w = np.minimum(1.0, np.clip((noise - layer.threshold) / layer.softness, 0.0, 1.0) * layer.depth)
            tile += w[..., None] * (np.asarray(layer.tint, np.float32) - tile)
    return tile


@dataclass(frozen=True)
class MaterialPattern:
    """A paint value for :class:`scenes.world._Paint`: the tile sampled at world coordinates.

    ``pattern(X, Y) -> (h, w, 3)``: texel ``((X - x0) / texel, (Y - y0) / texel)`` of the tile
    (nearest, wrapped), moved by ``offset_px`` and scaled by ``gain`` (a block's own brightness and
    hue). ``under`` (another pattern or None) is multiplied by the tile's brightness instead, for
    crops under field rows: then the tile is a modulation about 1.
    """

    tile: np.ndarray  # (n, n, 3) float32
    x0_m: float
    y0_m: float
    texel_m: float
    offset_px: tuple[int, int] = (0, 0)
    gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    under: object = None

    def __call__(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        n = self.tile.shape[0]

        def index(v, v0, off):
            # texel centres sit at (k + 0.5) texels: rounding (not flooring) is safe from float error
            return (np.rint((v - v0) / self.texel_m - 0.5).astype(np.int64) + off) % n

        if X.ndim == 2 and X.shape[0] > 1 and X.shape[1] > 1 and (X[0] == X[-1]).all() and (Y[:, 0] == Y[:, -1]).all():
            # a grid (rows of equal X, columns of equal Y): index once per row and column
            # two takes (row copies) are 4x faster than one 2-D fancy index
            v = self.tile.take(index(Y[:, 0], self.y0_m, self.offset_px[1]), axis=0).take(
                index(X[0], self.x0_m, self.offset_px[0]), axis=1)
        else:
            v = self.tile[index(Y, self.y0_m, self.offset_px[1]), index(X, self.x0_m, self.offset_px[0])]
        v = v * np.asarray(self.gain, np.float32)
        if self.under is not None:
            return self.under(X, Y) * v
        return v
