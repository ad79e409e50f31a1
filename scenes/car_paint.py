"""How vehicles look from above: body colours as they occur on the road, glass, and a sky highlight.

Body colours are drawn from the shares of car colours on European roads (white, black,
grey and silver make up three cars in four; then blue, red, and a few browns, greens,
yellows and oranges), each car a little lighter or darker than the next. Seen from
above a car shows its bonnet, windscreen, roof, rear window and boot: the glass cabin
of :func:`scenes.world.vehicle_boxes` under a roof shorter than it. A glossy top
reflects the bright sky along its crown: under flat light that highlight is painted,
a lighter band along the middle of the roof, bonnet and boot (the top face split in
three strips, the box itself unchanged, so the ground truth's boxes stay exact); under
sun light the material's specular term makes it.

No OpenGL: meshes are plain arrays that :mod:`scenes.render` uploads.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CAR_COLOURS", "GLASS_RGB", "car_colour", "colour_by_share", "vehicle_parts", "HIGHLIGHT", "GLOSS_ROUGHNESS"]

# (share, RGB), muted as a camera sees them through some air: nothing fully saturated
CAR_COLOURS = ((0.26, (226, 226, 222)), (0.19, (30, 30, 34)), (0.17, (112, 114, 118)), (0.13, (170, 172, 176)),
               (0.09, (42, 62, 118)), (0.07, (150, 36, 34)), (0.03, (110, 86, 62)), (0.02, (48, 78, 56)),
               (0.02, (196, 168, 58)), (0.02, (198, 106, 40)))
GLASS_RGB = (34, 40, 48)
HIGHLIGHT = 0.2  # the band is this far from the body colour toward white
HIGHLIGHT_BAND = (0.25, 0.75)  # across the top, as fractions of its width
GLOSS_ROUGHNESS = 0.35  # sun light: a glossy paint's roughness (1 = matt)


def car_colour(rng: np.random.Generator) -> tuple[int, int, int]:
    """A body colour drawn by the shares of :data:`CAR_COLOURS`, lighter or darker by up to 8 %."""
    shares = np.array([s for s, _ in CAR_COLOURS])
    k = int(rng.choice(len(CAR_COLOURS), p=shares / shares.sum()))
    rgb = np.asarray(CAR_COLOURS[k][1], np.float64) * rng.uniform(0.92, 1.08)
    return tuple(int(v) for v in np.clip(np.rint(rgb), 0, 255))


def colour_by_share(q: float) -> tuple[int, int, int]:
    """The body colour of :data:`CAR_COLOURS` at quantile ``q`` in [0, 1) of their cumulative shares
    (for a caller that draws ``q`` from its own stream and varies the colour itself)."""
    if not 0.0 <= q < 1.0:
        raise ValueError(f"q: expected a quantile in [0, 1), got {q}")
    shares = np.cumsum([s for s, _ in CAR_COLOURS])
    k = min(int(np.searchsorted(shares / shares[-1], q, side="right")), len(CAR_COLOURS) - 1)
    return CAR_COLOURS[k][1]


def _rgba(rgb, k: float = 1.0) -> np.ndarray:
    return np.array([min(1.0, rgb[0] / 255 * k), min(1.0, rgb[1] / 255 * k), min(1.0, rgb[2] / 255 * k), 1.0],
                    np.float32)


def _box_with_banded_top(box, rgb, *, band_rgb, side_shade: float) -> dict[str, np.ndarray]:
    """A box's walls and top (its floor is never seen), the top split across its width into three strips,
    the middle one ``band_rgb``: (positions, normals, indices, colours RGBA float32)."""
    c = np.asarray(box.centre, np.float64)
    h = np.asarray(box.size, np.float64) / 2
    pos, nrm, col, idx = [], [], [], []

    def quad(corners, normal, rgba):
        base = len(pos)
        pos.extend(corners)
        nrm.extend([normal] * 4)
        col.extend([rgba] * 4)
        idx.extend([(base, base + 1, base + 2), (base, base + 2, base + 3)])

    x0, x1, y0, y1, z0, z1 = c[0] - h[0], c[0] + h[0], c[1] - h[1], c[1] + h[1], c[2] - h[2], c[2] + h[2]
    side = _rgba(rgb, side_shade)
    # walls, anticlockwise seen from outside
    quad([(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)], (-1, 0, 0), side)
    quad([(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)], (1, 0, 0), side)
    quad([(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)], (0, -1, 0), side)
    quad([(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)], (0, 1, 0), side)
    ys = [y0, y0 + HIGHLIGHT_BAND[0] * (y1 - y0), y0 + HIGHLIGHT_BAND[1] * (y1 - y0), y1]
    for k in range(3):
        rgba = _rgba(band_rgb if k == 1 else rgb)
        quad([(x0, ys[k], z1), (x1, ys[k], z1), (x1, ys[k + 1], z1), (x0, ys[k + 1], z1)], (0, 0, 1), rgba)
    return {"positions": np.asarray(pos, np.float32), "normals": np.asarray(nrm, np.float32),
            "indices": np.asarray(idx, np.uint32), "colours": np.asarray(col, np.float32)}


def vehicle_parts(boxes, colours, *, glossy, side_shade: float, paint_highlight: bool) -> list[dict]:
    """Mesh parts of one vehicle: each box of ``boxes`` in its colour of ``colours`` (RGB 0-255).

    ``glossy[i]``: box i's top carries the sky highlight band (painted when ``paint_highlight``, i.e.
    under flat light; else left to the material). ``side_shade``: the walls' brightness relative to
    the top (flat light's fixed shading; 1 under sun light, which shades them itself).
    """
    parts = []
    for box, rgb, gloss in zip(boxes, colours, glossy):
        rgb = np.asarray(rgb, np.float64)
        band = rgb + HIGHLIGHT * (255.0 - rgb) if gloss and paint_highlight else rgb
        parts.append(_box_with_banded_top(box, rgb, band_rgb=band, side_shade=side_shade))
    return parts
