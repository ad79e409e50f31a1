"""Trees, hedges and woods as a camera 100 m up sees them: irregular crowns, conifers, canopies.

A deciduous crown is a main lobe and 3-6 smaller ones around it (ellipsoids of varied
radii and heights), so no two trees have the same outline; a conifer is a narrow cone;
a hedge is a row of small lobes. A wood is not a pile of separate trees but one canopy:
a height field of overlapping crowns (each a paraboloid cap of its own height, radius
and tint) over the whole block, tapering at its edge.

Shadows painted under flat light (:func:`tree_shadow_shapes`) are each lobe's exact
parallel projection along the sun (an ellipsoid projects to an ellipse), a cone's is
the hull of its base and apex, and the trunk's runs from its base on the ground to the
crown's: so a tree's shadow starts at its trunk, as it does in the sun.

No OpenGL: meshes are plain arrays that :mod:`scenes.render` uploads.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["CROWN_BASES", "CONIFER_VARIANTS", "crown_lobes", "hedge_lobes", "conifer_lobe", "tree_shadow_shapes",
           "trunk_size", "crown_texture", "canopy_texture", "canopy_mesh", "unit_cone", "sun_shading",
           "CANOPY_GRID_M"]

# crown colours (one instanced draw each): four deciduous greens (dark, fresh, yellowish, bluish),
# then two conifer greens (dark, bluish); muted and a little blue, as seen through some air (KIT AIS
# crowns average about RGB (50, 64, 58))
CROWN_BASES = ((50, 68, 50), (64, 82, 56), (76, 90, 58), (58, 72, 60), (38, 52, 46), (44, 56, 58))
CONIFER_VARIANTS = (4, 5)
CANOPY_GRID_M = 1.3  # vertex spacing of a wood's canopy height field


def crown_lobes(rng: np.random.Generator, *, height_m: float, radius_m: float,
                half_height_m: float) -> tuple[tuple[float, ...], ...]:
    """The lobes of a deciduous crown whose top is at ``height_m``, horizontal reach ``radius_m`` and
    vertical half extent ``half_height_m``: ``(dx, dy, zc, rx, ry, rz)`` each, metres, in the tree's frame.

    Every lobe stays inside the reach and under the top, and no lobe's bottom is lower than the
    crown's (``height_m - 2 half_height_m``).
    """
    lobes = []
    zc = height_m - half_height_m
    r0 = radius_m * rng.uniform(0.62, 0.78)
    lobes.append((0.0, 0.0, zc, r0 * rng.uniform(0.9, 1.0), r0 * rng.uniform(0.9, 1.0), half_height_m * 0.92))
    n = int(rng.integers(3, 7))
    ang0 = rng.uniform(0, 2 * math.pi)
    for k in range(n):
        a = ang0 + 2 * math.pi * k / n + rng.uniform(-0.4, 0.4)
        r = radius_m * rng.uniform(0.36, 0.55)
        d = rng.uniform(0.25, 1.0) * (radius_m - r)
        rz = min(r * rng.uniform(0.7, 1.0), half_height_m)
        # the lobe's top at most the crown's top, its bottom at least the crown's bottom
        z = float(np.clip(zc + rng.uniform(-0.4, 0.25) * half_height_m, height_m - 2 * half_height_m + rz,
                          height_m - rz))
        lobes.append((d * math.cos(a), d * math.sin(a), z, r, r * rng.uniform(0.85, 1.0), rz))
    return tuple(tuple(float(v) for v in lobe) for lobe in lobes)


def hedge_lobes(rng: np.random.Generator, *, height_m: float, radius_m: float, length_m: float,
                yaw_rad: float) -> tuple[tuple[float, ...], ...]:
    """A hedge bush: two round lobes along ``yaw_rad`` over ``length_m``, ``radius_m`` across, top at ``height_m``
    (bushes stand closer than their length: a row of them is a closed hedge; every lobe is an instance that
    the rasteriser pays for)."""
    n = 2
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    half = 0.45 * height_m
    out = []
    for t in np.linspace(-0.5, 0.5, n) * max(0.0, length_m - 2 * radius_m):
        r = radius_m * rng.uniform(0.8, 1.0)
        rz = half * rng.uniform(0.8, 1.0)
        out.append((float(t * c), float(t * s), float(height_m - rz), float(r), float(r), float(rz)))
    return tuple(out)


def conifer_lobe(*, height_m: float, radius_m: float, crown_base_m: float) -> tuple[tuple[float, ...], ...]:
    """A conifer's crown: one cone ``(0, 0, base z, r, r, length)`` from ``crown_base_m`` up to ``height_m``."""
    return ((0.0, 0.0, float(crown_base_m), float(radius_m), float(radius_m), float(height_m - crown_base_m)),)


def trunk_size(tree) -> tuple[float, float]:
    """A tree's trunk: (width, height) in metres; it reaches 30 % into the crown's lower half."""
    h = tree.height_m - 2 * tree.crown_half_height_m + 0.3 * tree.crown_half_height_m
    return max(0.25, 0.08 * tree.crown_radius_m), h


def tree_shadow_shapes(trees, to_sun: np.ndarray):
    """The ground shadows of ``trees`` for a sun in direction ``to_sun`` (3,): each lobe's exact projection.

    A point at height z falls on the ground at ``(x, y) + z a`` with ``a = -to_sun[:2] / to_sun[2]``; an
    ellipsoid with horizontal semi-axes rx, ry and vertical rz projects to the ellipse ``A A^T`` with
    ``A = [[rx, 0, rz ax], [0, ry, rz ay]]``. A cone projects to the hull of its base ellipse and apex.
    The trunk projects to a strip from its base (the tree's position) to its top's shadow, which lies
    inside the crown's: the shadow is one piece from the trunk on.

    Returns
    -------
    ellipses : (centres (E, 2), axes (E, 2) semi-axes, angles (E,) degrees), metres
    polygons : list of (P, 2) arrays, metres (trunks and cones)
    """
    a = -np.asarray(to_sun[:2], np.float64) / max(1e-9, float(to_sun[2]))
    centres, axes, angles, polys = [], [], [], []
    for t in trees:
        base = np.array([t.x_m, t.y_m])
        if t.conifer:
            _, _, zb, r, _, length = t.lobes[0]
            ring = base + r * np.column_stack([np.cos(np.linspace(0, 2 * math.pi, 16, endpoint=False)),
                                               np.sin(np.linspace(0, 2 * math.pi, 16, endpoint=False))])
            pts = np.vstack([ring + zb * a, base + (zb + length) * a])
            polys.append(cv2.convexHull(pts.astype(np.float32))[:, 0].astype(np.float64))
        else:
            for dx, dy, zc, rx, ry, rz in t.lobes:
                M = np.array([[rx, 0.0, rz * a[0]], [0.0, ry, rz * a[1]]])
                w, v = np.linalg.eigh(M @ M.T)  # ascending
                centres.append(base + (dx, dy) + zc * a)
                axes.append((math.sqrt(max(w[1], 1e-12)), math.sqrt(max(w[0], 1e-12))))
                angles.append(math.degrees(math.atan2(v[1, 1], v[0, 1])))
        if not t.bush:
            w_m, h_m = trunk_size(t)
            n = np.array([-a[1], a[0]]) / max(1e-9, math.hypot(*a)) * w_m / 2 if math.hypot(*a) > 1e-9 else \
                np.array([w_m / 2, 0.0])
            top = base + h_m * a
            polys.append(np.array([base - n, base + n, top + n, top - n]))
    return ((np.asarray(centres, np.float64).reshape(-1, 2), np.asarray(axes, np.float64).reshape(-1, 2),
             np.asarray(angles, np.float64)), polys)


def sun_shading(normals: np.ndarray, to_sun: np.ndarray, ambient: float) -> np.ndarray:
    """Brightness (n,) float32 of surfaces with ``normals`` (n, 3) under a sun and sky, relative to flat
    sunlit ground: ``ambient + (1 - ambient) n.s / s_z``, capped at 1.15 (faces turned to the sun are a
    little brighter than the ground), ``ambient`` where the sun does not reach."""
    s = np.asarray(to_sun, np.float64)
    lit = np.clip(normals @ s, 0.0, None) / max(0.2, s[2])
    return np.minimum(1.15, ambient + (1.0 - ambient) * lit).astype(np.float32)


def _leafy(rng: np.random.Generator, n: int, base, *, clump_px: float, gaps: float,
           clump_depth: float = 0.2) -> np.ndarray:
    """Leaves: clusters ``clump_px`` wide lit on top and shaded between (``clump_depth``, relative; smooth,
    no hard specks), with finer twigs and leaves in them; uint8 (n, n, 3), periodic."""
    f = np.fft.rfft2(rng.standard_normal((n, n)))
    fy, fx = np.fft.fftfreq(n)[:, None], np.fft.rfftfreq(n)[None, :]
    fr = np.hypot(fx, fy)
    fr[0, 0] = 1.0
    band = np.exp(-0.5 * (np.log(fr * clump_px) / 0.5) ** 2)  # clusters about clump_px wide
    clumps = np.fft.irfft2(f * band, s=(n, n))
    fine = np.fft.irfft2(f * np.exp(-0.5 * (np.log(fr * 3.0) / 0.6) ** 2), s=(n, n))
    clumps /= clumps.std()
    fine /= fine.std()
    k = 1.0 + clump_depth * clumps + 0.08 * fine - gaps * 0.5 * (np.tanh(-clumps - 0.8) + 1.0)  # shaded hollows
    # a little hue: sunlit leaves yellower, hollows bluer
    tex = np.asarray(base, np.float64) * np.clip(k, 0.35, 1.6)[..., None]
    tex[..., 0] *= 1.0 + 0.04 * clumps
    tex[..., 2] *= 1.0 - 0.04 * clumps
    return np.clip(np.rint(tex), 0, 255).astype(np.uint8)


def crown_texture(rng: np.random.Generator, base, *, detail: float = 0.0) -> np.ndarray:
    """A crown's leaves, (128, 128, 3) uint8, mapped top-down across a lobe.

    ``detail`` (``world.detail``): clumps of leaves lit on top and shaded between, a fifth of a lobe
    wide at 1 (a metre on a lobe 5 m across, where the crowns of KIT AIS's Munich streets are
    patchy), instead of a tenth; the same random draws at every ``detail``.
    """
    return _leafy(rng, 128, base, clump_px=10.0 * (1.0 + 1.5 * detail), gaps=0.35 + 0.15 * detail,
                  clump_depth=0.2 + 0.2 * detail)


def canopy_texture(rng: np.random.Generator) -> np.ndarray:
    """A wood's canopy leaves, (256, 256, 3) uint8, repeated every 12 m; the crowns' tints come on top."""
    return _leafy(rng, 256, (255, 255, 255), clump_px=14.0, gaps=0.3)


def unit_cone(segments: int = 10) -> dict[str, np.ndarray]:
    """A cone of radius 1 from z = 0 to its apex at z = 1 (the base left open: never seen from above), with
    top-down UVs."""
    a = 2 * np.pi * np.arange(segments) / segments
    ring = np.column_stack([np.cos(a), np.sin(a), np.zeros(segments)])
    v = np.vstack([[0.0, 0.0, 1.0], ring]).astype(np.float32)
    nrm = np.vstack([[0.0, 0.0, 1.0], ring * (1 / math.sqrt(2)) + [0.0, 0.0, 1 / math.sqrt(2)]]).astype(np.float32)
    faces = [(0, 1 + k, 1 + (k + 1) % segments) for k in range(segments)]
    return {"positions": v, "normals": nrm, "indices": np.asarray(faces, np.uint32),
            "texcoords": (0.5 + 0.5 * v[:, :2]).astype(np.float32)}


def canopy_mesh(poly_m: np.ndarray, rng: np.random.Generator, *, inset_m: float, density_per_ha: float,
                crown_diameter_range_m: tuple[float, float], height_range_m: tuple[float, float]):
    """A wood's canopy over the polygon ``poly_m`` (P, 2) shrunk by ``inset_m``: one height field of crowns.

    Crowns are discs of ``density_per_ha`` per hectare (at least two per crown area: a closed canopy),
    diameters 1.3x ``crown_diameter_range_m``, tops in ``height_range_m``; the surface is the highest
    paraboloid cap over each point, lowered toward the edge (round crowns at the rim, not a cliff).
    Vertices lie on a ``CANOPY_GRID_M`` grid; each vertex takes the tint of its crown.

    Returns
    -------
    dict with ``positions`` (V, 3), ``normals`` (V, 3), ``texcoords`` (V, 2) (metres / 12), ``tint`` (V, 3) in
    0..1, ``indices`` (T, 3) uint32; ``outline`` (Q, 2) the canopy's footprint and ``edge_height_m``, the
    height of its rim (for painted shadows), or None if nothing is left.
    """
    g = CANOPY_GRID_M
    lo, hi = poly_m.min(axis=0) - g, poly_m.max(axis=0) + g
    nx, ny = int(math.ceil((hi[0] - lo[0]) / g)) + 1, int(math.ceil((hi[1] - lo[1]) / g)) + 1
    if nx < 4 or ny < 4:
        return None
    mask = np.zeros((ny, nx), np.uint8)
    cv2.fillPoly(mask, [np.rint((poly_m - lo) / g * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    # metres inside the shrunk outline (the transform measures to the nearest outside grid point, about
    # half a grid step beyond the outline)
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, 5) * g - 0.5 * g - inset_m
    inside = dist > 0
    if inside.sum() < 16:
        return None
    X, Y = lo[0] + np.arange(nx) * g, lo[1] + np.arange(ny) * g
    XX, YY = np.meshgrid(X, Y)
    area_m2 = float(inside.sum()) * g * g
    d_lo, d_hi = (1.3 * v for v in crown_diameter_range_m)
    mean_area = math.pi * (0.25 * (d_lo + d_hi)) ** 2
    n = max(int(rng.poisson(density_per_ha * area_m2 / 1e4)), int(2 * area_m2 / mean_area))
    pts = np.column_stack([XX[inside], YY[inside]])
    at = pts[rng.integers(0, len(pts), n)] + rng.uniform(-0.5, 0.5, (n, 2)) * g
    rad = 0.5 * rng.uniform(d_lo, d_hi, n)
    top = rng.uniform(*height_range_m, n)
    depth = rad * rng.uniform(0.5, 0.9, n)  # a cap this deep at its rim
    tint = np.clip(rng.normal(1.0, 0.09, (n, 1)) * (1.0 + rng.normal(0.0, 0.05, (n, 3))), 0.6, 1.4)
    base_col = np.asarray(CROWN_BASES[:4], np.float64)[rng.integers(0, 4, n)] / 255.0
    z = np.full((ny, nx), -np.inf)
    owner = np.zeros((ny, nx), np.int64)
    for k in range(n):
        r = rad[k]
        c0, c1 = max(0, int((at[k, 0] - r - lo[0]) / g)), min(nx, int((at[k, 0] + r - lo[0]) / g) + 2)
        r0, r1 = max(0, int((at[k, 1] - r - lo[1]) / g)), min(ny, int((at[k, 1] + r - lo[1]) / g) + 2)
        if c1 <= c0 or r1 <= r0:
            continue
        d2 = ((XX[r0:r1, c0:c1] - at[k, 0]) ** 2 + (YY[r0:r1, c0:c1] - at[k, 1]) ** 2) / (r * r)
        cap = np.where(d2 < 1.0, top[k] - depth[k] * d2, -np.inf)
        better = cap > z[r0:r1, c0:c1]
        z[r0:r1, c0:c1][better] = cap[better]
        owner[r0:r1, c0:c1][better] = k
    floor = float(0.55 * np.mean(height_range_m))
    z = np.where(np.isfinite(z), np.maximum(z, floor), floor)
    z *= np.clip(0.3 + 0.7 * dist / 4.0, 0.3, 1.0)  # crowns round off toward the rim
    # vertices: every grid point inside; triangles: grid squares with all four corners inside
    vid = -np.ones((ny, nx), np.int64)
    vid[inside] = np.arange(int(inside.sum()))
    q = inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]
    a, b, c, d = vid[:-1, :-1][q], vid[:-1, 1:][q], vid[1:, 1:][q], vid[1:, :-1][q]
    if not len(a):
        return None
    indices = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.uint32)
    gz_y, gz_x = np.gradient(z, g)
    nrm = np.stack([-gz_x, -gz_y, np.ones_like(z)], axis=-1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    pos = np.column_stack([XX[inside], YY[inside], z[inside]])
    col = base_col[owner[inside]] * tint[owner[inside]]
    contours, _ = cv2.findContours(inside.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    rim = cv2.approxPolyDP(max(contours, key=cv2.contourArea), 0.7, True)  # no stair steps of the grid
    outline = rim[:, 0].astype(np.float64) * g + lo
    return {"positions": pos.astype(np.float32), "normals": nrm[inside].astype(np.float32),
            "texcoords": (pos[:, :2] / 12.0).astype(np.float32), "tint": np.clip(col, 0, 1).astype(np.float32),
            "indices": indices, "outline": outline, "edge_height_m": float(0.6 * np.median(top)),
            "top_m": float(z[inside].max())}
