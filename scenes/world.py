"""The world: an irregular road network, fields, grass, woods, parking lots and yards painted on the
ground; buildings with roof detail; trees and hedges; vehicles on the roads.

Everything is generated deterministically from ``numpy.random.Generator``s
derived from the spec seed. The ground texture's texel is finer than the
camera's ground sampling distance (GSD), so every image pixel sees detail:
optical flow needs gradients, and a blurry ground would make the benchmark lie.
No paint is periodic over more than a few metres without irregularity: field
rows are soft, low in contrast and wander; markings are worn; asphalt is patched.

Roads are the edges of a jittered, rotated grid graph, each a curved polyline
(a quadratic Bezier), with some minor edges left out (T junctions, larger
blocks). Vehicles drive along routes through this graph (right-hand lane,
rounded corners at junctions). Buildings, trees and hedges are placed so that
they never intersect a road, a building, or each other's trunks; all stand on
the ground (z >= 0), so their ground truth comes from the rendered depth.

No OpenGL here: meshes are plain arrays that :mod:`scenes.render` uploads.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from scenes.car_paint import GLASS_RGB, car_colour
from scenes.motion import CameraPath, VehiclePath, polyline_arc_lengths
from scenes.textures import TILE_PX, MaterialPattern, material_tile
from scenes.vegetation import (CONIFER_VARIANTS, CROWN_BASES, canopy_mesh, canopy_texture, conifer_lobe, crown_lobes,
                               crown_texture, hedge_lobes, tree_shadow_shapes)

__all__ = [
    "Box",
    "Road",
    "Building",
    "Tree",
    "World",
    "build_world",
    "place_vehicles",
    "vehicle_boxes",
    "box_mesh",
    "ground_footprint",
    "distance_to_polyline",
    "rects_overlap",
    "point_rect_distance",
    "sun_direction",
    "field_rows",
]

# texel = GSD / TEXELS_PER_PIXEL: a little finer than a pixel, so the texture never looks blurred
TEXELS_PER_PIXEL = 1.5
MAX_TEXTURE_PX = 4096  # per ground tile uploaded to GL
MAX_GROUND_TEXELS = 60_000_000
ROAD_RGB = (108, 108, 112)  # aged asphalt, lighter than new (KIT AIS roads: about 125)
MARK_RGB = (226, 226, 220)  # road paint (the brightest 2 % of a KIT AIS frame, paint among it: 163-238 gray)
KERB_RGB = (184, 182, 174)
# every building shares one facade and one roof texture (one draw each); roofs differ by a tint
ROOF_TINTS = ((1.0, 1.0, 1.0), (0.74, 0.72, 0.7), (1.1, 1.05, 0.95), (0.85, 0.88, 0.92),
              (1.06, 0.8, 0.7))  # the last: clay tiles, as on Munich's older blocks
# ``world.edges`` 1: roofs from white gravel to dark bitumen and red clay (KIT AIS's Munich roofs span 80-220
# gray levels), as tints of a roof texture ROOF_EDGES_GAIN times lighter (a vertex colour cannot exceed 1, so
# a white roof needs the lighter texture); variant 1 (the footbridges' concrete) keeps its brightness
ROOF_EDGES_GAIN = 1.4
ROOF_TINTS_EDGES = ((0.71, 0.71, 0.71), (0.53, 0.51, 0.5), (1.0, 0.98, 0.94), (0.4, 0.4, 0.43),
                    (0.96, 0.58, 0.47))
# and the parapet round a roof: metal flashing or concrete coping, dark round a light roof and light round a
# dark one (a roof's outline is sharp from above); without ``world.edges`` 0.85 of the roof's tint
PARAPET_DARK, PARAPET_LIGHT = (0.36, 0.36, 0.38), (0.97, 0.96, 0.93)
N_CROWN_VARIANTS = len(CROWN_BASES)  # crown colours (the last ones conifers'), all in one draw
ROAD_SAMPLE_M = 2.0  # road polylines are sampled this finely (the test of clearances resamples them finer)
ROAD_CLEARANCE_M = 1.5  # buildings keep this far from a road's edge, trees a little less
BUILDING_GAP_M = 1.5  # between two buildings' footprints


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in its own frame: centre (3,) and size (3,) in metres."""

    centre: tuple[float, float, float]
    size: tuple[float, float, float]


@dataclass(frozen=True)
class Road:
    """A road segment between two junctions: centre line (M, 2) metres, width in metres."""

    centre_m: np.ndarray
    width_m: float
    major: bool
    nodes: tuple[int, int]


@dataclass(frozen=True)
class Building:
    """A flat-roofed building: footprint centre ``centre[:2]``, ``size`` (length, width, wall height),
    turned by ``yaw_rad``; ``parts`` are its boxes in the building frame (walls, parapet, roof units)."""

    centre: tuple[float, float, float]  # (x, y, height / 2), as a Box's
    size: tuple[float, float, float]
    yaw_rad: float
    parts: tuple[Box, ...]
    roof_variant: int

    @property
    def top_m(self) -> float:
        return max(b.centre[2] + b.size[2] / 2 for b in self.parts)

    def corners_xy(self) -> np.ndarray:
        """The footprint's corners (4, 2), anticlockwise."""
        return _rect_corners(self.centre[0], self.centre[1], self.size[0], self.size[1], self.yaw_rad)


@dataclass(frozen=True)
class Tree:
    """A tree or hedge bush: a crown reaching ``crown_radius_m`` across and ``crown_half_height_m`` down
    from its top at ``height_m``, made of ``lobes`` ``(dx, dy, zc, rx, ry, rz)`` (ellipsoids in the tree's
    frame; for a conifer one cone: base height, radii, length: :mod:`scenes.vegetation`); trunk under it.
    Always above the ground."""

    x_m: float
    y_m: float
    height_m: float
    crown_radius_m: float
    crown_half_height_m: float
    variant: int
    bush: bool = False
    yaw_rad: float = 0.0  # hedge bushes are stretched along their row
    stretch: float = 1.0  # radius along the row / crown_radius_m
    lobes: tuple = ()
    conifer: bool = False
    overhangs_road: bool = False  # a street tree (scenes.traffic): its crown reaches over the road, high up

    @property
    def reach_m(self) -> float:
        """The crown's largest horizontal radius."""
        return self.crown_radius_m * max(1.0, self.stretch)


@dataclass
class World:
    extent_m: tuple[float, float, float, float]  # x0, y0, x1, y1 of the ground texture
    texel_m: float
    ground_texture: np.ndarray  # (Ht, Wt, 3) uint8; row r <-> y = y0 + (r + 0.5) * texel
    roads: list[Road]
    nodes_m: np.ndarray  # (N, 2) junctions of the road graph
    road_width_m: float  # of the main roads
    buildings: list[Building] = field(default_factory=list)
    trees: list[Tree] = field(default_factory=list)
    stalls: list[tuple[float, float, float]] = field(default_factory=list)  # parking: x, y, theta
    wall_textures: list[np.ndarray] = field(default_factory=list)
    roof_textures: list[np.ndarray] = field(default_factory=list)
    crown_textures: list[np.ndarray] = field(default_factory=list)  # one: gray leaves, tinted per crown
    canopies: list[dict] = field(default_factory=list)  # woods: height-field meshes (scenes.vegetation)
    canopy_texture: np.ndarray | None = None
    overpasses: list[Building] = field(default_factory=list)  # footbridges over roads (scenes.traffic)
    roof_tints: tuple = ROOF_TINTS  # RGB gain of the roof texture per ``Building.roof_variant``
    parapet_tints: tuple | None = None  # RGB gain of the parapets per variant; None: 0.85 of ``roof_tints``

    @property
    def top_m(self) -> float:
        """Height of the highest static thing (0 for a bare ground)."""
        return max([b.top_m for b in self.buildings + self.overpasses] + [t.height_m for t in self.trees]
                   + [c["top_m"] for c in self.canopies], default=0.0)

    def adjacency(self) -> dict[int, list[tuple[int, int]]]:
        """node -> [(road index, other node)] over the road graph."""
        adj: dict[int, list[tuple[int, int]]] = {}
        for k, r in enumerate(self.roads):
            a, b = r.nodes
            adj.setdefault(a, []).append((k, b))
            adj.setdefault(b, []).append((k, a))
        return adj


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector (3,) from the ground toward the sun; azimuth clockwise from north (+y)."""
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def ground_footprint(path: CameraPath, width_px: int, height_px: int) -> tuple[float, float, float, float]:
    """Bounding box (x0, y0, x1, y1) of the ground seen by every frame of ``path``."""
    corners = np.array([[0, 0, 1], [width_px - 1, 0, 1], [0, height_px - 1, 1],
                        [width_px - 1, height_px - 1, 1], [(width_px - 1) / 2, (height_px - 1) / 2, 1]], float)
    rays_c = corners @ np.linalg.inv(path.K).T  # (5, 3), z = 1
    rays_w = np.einsum("nij,kj->nki", path.R, rays_c)  # (N, 5, 3)
    lam = -path.C[:, None, 2] / rays_w[..., 2]
    pts = path.C[:, None, :2] + lam[..., None] * rays_w[..., :2]
    return (float(pts[..., 0].min()), float(pts[..., 1].min()),
            float(pts[..., 0].max()), float(pts[..., 1].max()))


# -- geometry helpers ---------------------------------------------------------------------

def _rect_corners(cx: float, cy: float, sx: float, sy: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-sx / 2, -sy / 2], [sx / 2, -sy / 2], [sx / 2, sy / 2], [-sx / 2, sy / 2]])
    return local @ np.array([[c, s], [-s, c]]) + (cx, cy)


def distance_to_polyline(points_m: np.ndarray, line_m: np.ndarray) -> np.ndarray:
    """Distance (P,) from each point (P, 2) to the polyline (M, 2), metres."""
    p = np.asarray(points_m, np.float64).reshape(-1, 2)
    a, b = line_m[:-1], line_m[1:]
    ab = b - a
    L2 = np.maximum((ab ** 2).sum(axis=1), 1e-12)
    t = np.clip(((p[:, None, :] - a[None]) * ab[None]).sum(axis=2) / L2, 0.0, 1.0)
    q = a[None] + t[..., None] * ab[None]
    return np.sqrt(((p[:, None, :] - q) ** 2).sum(axis=2)).min(axis=1)


def rects_overlap(a: np.ndarray, b: np.ndarray, gap_m: float = 0.0) -> bool:
    """Whether two convex quads (4, 2) come closer than ``gap_m`` (separating axis test on their edges)."""
    for poly in (a, b):
        for k in range(4):
            e = poly[(k + 1) % 4] - poly[k]
            n = np.array([-e[1], e[0]]) / max(1e-12, math.hypot(*e))
            pa, pb = a @ n, b @ n
            if pa.max() + gap_m <= pb.min() or pb.max() + gap_m <= pa.min():
                return False
    return True


def point_rect_distance(points_m: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Distance (P,) from points (P, 2) to a rectangle given by its corners (4, 2); 0 inside."""
    c = corners.mean(axis=0)
    ex, ey = corners[1] - corners[0], corners[3] - corners[0]
    sx, sy = math.hypot(*ex), math.hypot(*ey)
    d = np.asarray(points_m, np.float64).reshape(-1, 2) - c
    lx, ly = np.abs(d @ (ex / sx)) - sx / 2, np.abs(d @ (ey / sy)) - sy / 2
    return np.hypot(np.maximum(lx, 0), np.maximum(ly, 0))


def _bezier(p0: np.ndarray, ctrl: np.ndarray, p1: np.ndarray, step_m: float) -> np.ndarray:
    n = max(2, int(math.ceil(np.hypot(*(p1 - p0)) / step_m)) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * ctrl + t ** 2 * p1


def _trim(line: np.ndarray, *, start_m: float = 0.0, end_m: float = 0.0) -> np.ndarray:
    """The part of a polyline from arc length ``start_m`` to ``length - end_m``."""
    s = polyline_arc_lengths(line)
    a, b = start_m, s[-1] - end_m
    keep = (s > a) & (s < b)
    pa = np.array([np.interp(a, s, line[:, 0]), np.interp(a, s, line[:, 1])])
    pb = np.array([np.interp(b, s, line[:, 0]), np.interp(b, s, line[:, 1])])
    return np.vstack([pa, line[keep], pb])


def _offset_right(line: np.ndarray, offset_m: np.ndarray | float) -> np.ndarray:
    """The polyline moved ``offset_m`` to the right of its direction (per vertex or one value)."""
    t = np.gradient(line, axis=0)
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    right = np.stack([t[:, 1], -t[:, 0]], axis=1)
    return line + np.asarray(offset_m, np.float64).reshape(-1, 1) * right


# value-noise octaves (cell size in metres, weight) that shade the ground: weak at 40 m (no cloudy
# blotches: photographs of fields are fairly even), strongest at 1 m and at the pixel (grain to track)
# (the materials of scenes/textures.py carry each surface's own detail; this shade adds light and soil
# moisture over everything, weaker than it was at 40 m, and the smooth grain that flow needs)
NOISE_OCTAVES_M = ((40.0, 0.05), (10.0, 0.04), (3.0, 0.04), (1.0, 0.1))
# ``world.detail`` 1: light and soil at 2-4 m on top (cells of value noise, weights), where KIT AIS's
# ground has two to three times the power of the octaves above (docs/realism.md)
DETAIL_OCTAVES_M = ((2.0, 0.05),)
GRAIN_AMP = 0.03  # KIT AIS's flattest half shows about 0.5 gray levels of pixel-scale variation
STRIP_ROWS = 256  # the ground texture is painted, shaded and blurred this many rows at a time
_BLUR_HALO_ROWS = 8  # > the blur kernel's radius (3 texels): a strip's blur sees its true neighbours
_DRAW_ROWS = 1024  # noise lattices are drawn this many rows at a time (no float64 copy of a big one)


def _noise_lattice(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Uniform [-1, 1) values, float32: the same draws as ``rng.uniform(-1, 1, shape)``, in row chunks."""
    g = np.empty(shape, np.float32)
    for r0 in range(0, shape[0], _DRAW_ROWS):
        g[r0:r0 + _DRAW_ROWS] = rng.uniform(-1.0, 1.0, (min(_DRAW_ROWS, shape[0] - r0), shape[1]))
    return g


def _noise_upsampled(rng: np.random.Generator, shape: tuple[int, int], cell_px: float) -> np.ndarray:
    """Smooth value noise, unclipped, features about ``cell_px`` texels wide, float32.

    At least ``shape``: the caller crops to ``[:h, :w]``. One resize of the whole
    lattice: strips of it would interpolate at other phases and change the values.
    """
    h, w = shape
    gh, gw = max(2, int(math.ceil(h / cell_px)) + 2), max(2, int(math.ceil(w / cell_px)) + 2)
    g = _noise_lattice(rng, (gh, gw))
    return cv2.resize(g, (int(round(gw * cell_px)), int(round(gh * cell_px))), interpolation=cv2.INTER_CUBIC)


def _multiscale_noise(rng: np.random.Generator, shape: tuple[int, int], texel_m: float, *,
                      octaves_m=NOISE_OCTAVES_M, grain: bool = True) -> np.ndarray:
    """Sum of octaves (``octaves_m``: cell metres, weight) from 40 m down to one texel (``grain``: and
    a last one at about a pixel); fine octaves keep detail at the GSD.

    Each octave, value noise clipped to [-1, 1] and weighted, is added strip by strip
    in place, so only the sum and one octave are ever whole in memory.
    """
    h, w = shape
    total = np.zeros(shape, np.float32)
    # grain at about one image pixel (TEXELS_PER_PIXEL texels): detail at the GSD, yet smooth
    # enough inside a pixel that resampling at another sub-pixel phase changes it little
    octaves = [(cell_m / texel_m, amp) for cell_m, amp in octaves_m
               if cell_m / texel_m >= 2] + ([(TEXELS_PER_PIXEL, GRAIN_AMP)] if grain else [])
    for cell_px, amp in octaves:
        big = _noise_upsampled(rng, shape, cell_px)
        for r0 in range(0, h, STRIP_ROWS):
            octave = big[r0:min(h, r0 + STRIP_ROWS), :w]
            np.clip(octave, -1.0, 1.0, out=octave)
            octave *= amp
            total[r0:r0 + STRIP_ROWS] += octave
        del big, octave  # the last strip's view would keep this octave alive through the next
    return total



# -- ground paint --------------------------------------------------------------------------

@dataclass(frozen=True)
class _Rows:
    """A field's rows: soft, low in contrast, wandering. ``base + amp(X, Y) sin(phase(X, Y))`` where the
    phase runs across the rows (``period`` metres apart at angle ``ang``) and is bent by a few long,
    weak waves, and the contrast ``amp`` fades in and out: nothing a flow method could lock on to
    over more than a few rows."""

    base: np.ndarray  # (3,) RGB
    period: float  # metres
    ang: float  # radians
    amp: float  # gray levels
    waves: np.ndarray  # (3, 4): kx, ky (rad/m), phase, amplitude (rad) of the bending waves

    def __call__(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        phase = 2 * math.pi * (X * math.cos(self.ang) + Y * math.sin(self.ang)) / self.period
        for kx, ky, ph, a in self.waves:
            phase += a * np.sin(kx * X + ky * Y + ph)
        kx, ky, ph, _ = self.waves[0]
        amp = self.amp * (0.5 + 0.5 * np.sin(0.7 * ky * X - 0.7 * kx * Y + 2 * ph))
        return self.base + (amp * np.sin(phase))[..., None]


@dataclass(frozen=True)
class _Paint:
    """Paint ``value`` on the texels ``[rows, cols]`` (slices), through ``alpha`` (uint8 coverage over
    those texels, or None for all of them). ``mode`` ``set`` blends toward ``value`` (an RGB triple,
    a grey level, or a pattern ``f(X, Y) -> (..., 3)`` of texel centres' coordinates in metres, any
    shape); ``mul`` multiplies by it (shadows)."""

    rows: slice
    cols: slice
    value: object
    alpha: np.ndarray | None = None
    mode: str = "set"

    def apply(self, buf: np.ndarray, r0: int, xs: np.ndarray, ys: np.ndarray) -> None:
        """Paint onto ``buf``, the texture's rows ``r0 .. r0 + len(buf)`` (float32, (n, Wt, 3))."""
        r1 = r0 + buf.shape[0]
        a, b = max(self.rows.start, r0), min(self.rows.stop, r1)
        if b <= a or self.cols.stop <= self.cols.start:
            return
        local = slice(a - r0, b - r0)
        value = self.value
        if callable(value) and self.alpha is not None and (
                4 * np.count_nonzero(alpha := self.alpha[a - self.rows.start:b - self.rows.start]) < alpha.size):
            # a sparse shape's pattern is evaluated on the covered texels only (a diagonal road's box is
            # mostly empty); a dense one's on its whole box, below
            rr, cc = np.nonzero(alpha)
            if not len(rr):
                return
            v = value(xs[self.cols][cc], ys[a:b][rr]).astype(np.float32)
            w = alpha[rr, cc].astype(np.float32)[:, None]
            w *= np.float32(1 / 255)
            region = buf[local, self.cols]
            if self.mode == "mul":
                region[rr, cc] *= 1 + w * (v - 1)
            else:
                px = region[rr, cc]
                px += w * (v - px)
                region[rr, cc] = px
            return
        if callable(value):
            X, Y = np.meshgrid(xs[self.cols], ys[a:b])
            value = value(X, Y).astype(np.float32)
        else:
            value = np.asarray(value, np.float32)
        region = buf[local, self.cols]
        if self.alpha is None:
            if self.mode == "mul":
                region *= value
            else:
                region[...] = value
            return
        w = self.alpha[a - self.rows.start:b - self.rows.start].astype(np.float32)[..., None]
        w *= np.float32(1 / 255)
        if self.mode == "mul":
            region *= 1 + w * (value - 1)
        else:
            region += w * (value - region)


class _Canvas:
    """Turns shapes in world metres into paint operations on the ground texture (coverage masks drawn
    with OpenCV, anti-aliased, cropped to each shape's bounding box)."""

    SHIFT = 4  # OpenCV fixed-point bits: sub-texel coordinates

    def __init__(self, x0: float, y0: float, texel: float, wt: int, ht: int):
        self.x0, self.y0, self.texel, self.wt, self.ht = x0, y0, texel, wt, ht
        self.ops: list[_Paint] = []

    def _crop(self, pts_m: np.ndarray, pad_m: float):
        px = (np.asarray(pts_m, np.float64).reshape(-1, 2) - (self.x0, self.y0)) / self.texel - 0.5
        pad = pad_m / self.texel + 2
        c0, c1 = max(0, int(math.floor(px[:, 0].min() - pad))), min(self.wt, int(math.ceil(px[:, 0].max() + pad)))
        r0, r1 = max(0, int(math.floor(px[:, 1].min() - pad))), min(self.ht, int(math.ceil(px[:, 1].max() + pad)))
        if c1 <= c0 or r1 <= r0:
            return None
        return r0, r1, c0, c1

    def _fixed(self, pts_m: np.ndarray, r0: int, c0: int) -> np.ndarray:
        px = (np.asarray(pts_m, np.float64) - (self.x0, self.y0)) / self.texel - 0.5 - (c0, r0)
        return np.rint(px * (1 << self.SHIFT)).astype(np.int32)

    def _add(self, crop, mask: np.ndarray, value, mode: str, opacity: float) -> None:
        r0, r1, c0, c1 = crop
        if opacity < 1.0:
            mask = np.rint(mask * opacity).astype(np.uint8)
        if mask.any():
            self.ops.append(_Paint(slice(r0, r1), slice(c0, c1), value, mask, mode))

    def polygon(self, polys_m: list[np.ndarray], value, *, mode: str = "set", opacity: float = 1.0,
                feather_m: float = 0.0) -> None:
        """Fill polygons; ``feather_m`` > 0 softens their edges (a Gaussian of that sigma on the coverage),
        so that one patch of ground blends into the next."""
        crop = self._crop(np.vstack(polys_m), 3.0 * feather_m)
        if crop is None:
            return
        r0, r1, c0, c1 = crop
        mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
        cv2.fillPoly(mask, [self._fixed(p, r0, c0) for p in polys_m], 255, cv2.LINE_AA, self.SHIFT)
        if feather_m > 0:
            mask = cv2.GaussianBlur(mask, (0, 0), feather_m / self.texel)
        self._add(crop, mask, value, mode, opacity)

    def union(self, value, *, polys_m: list[np.ndarray] = (), ellipses=None, mode: str = "set",
              opacity: float = 1.0) -> None:
        """Polygons and ellipses ``(centres (E, 2), semi-axes (E, 2), angles (E,) degrees)`` as one shape:
        where they overlap they are painted once (a shadow cast by two things is no darker)."""
        pts = [np.asarray(p, np.float64).reshape(-1, 2) for p in polys_m]
        pad = 0.0
        if ellipses is not None and len(ellipses[0]):
            pad = float(np.max(ellipses[1]))
            pts.append(np.asarray(ellipses[0], np.float64).reshape(-1, 2))
        if not pts:
            return
        crop = self._crop(np.vstack(pts), pad)
        if crop is None:
            return
        r0, r1, c0, c1 = crop
        mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
        for p in polys_m:  # one by one: fillPoly of several contours would leave their overlaps out
            cv2.fillPoly(mask, [self._fixed(p, r0, c0)], 255, cv2.LINE_AA, self.SHIFT)
        if ellipses is not None:
            self._draw_ellipses(mask, r0, c0, *ellipses)
        self._add(crop, mask, value, mode, opacity)

    def _draw_ellipses(self, mask, r0, c0, centres_m, axes_m, angles_deg) -> None:
        one = 1 << self.SHIFT
        for c, ax, an in zip(self._fixed(np.asarray(centres_m, np.float64).reshape(-1, 2), r0, c0),
                             np.asarray(axes_m).reshape(-1, 2), angles_deg):
            axes = (max(1, int(round(ax[0] / self.texel * one))), max(1, int(round(ax[1] / self.texel * one))))
            cv2.ellipse(mask, (int(c[0]), int(c[1])), axes, float(an), 0, 360, 255, -1, cv2.LINE_AA, self.SHIFT)

    def lines(self, lines_m: list[np.ndarray], width_m: float, value, *, mode: str = "set",
              opacity: float = 1.0) -> None:
        """Polylines ``width_m`` wide; lines thinner than a texel are drawn one texel wide, fainter."""
        if not lines_m:
            return
        crop = self._crop(np.vstack(lines_m), width_m)
        if crop is None:
            return
        r0, r1, c0, c1 = crop
        mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
        thick = width_m / self.texel
        cv2.polylines(mask, [self._fixed(p, r0, c0) for p in lines_m], False, 255,
                      max(1, int(round(thick))), cv2.LINE_AA, self.SHIFT)
        self._add(crop, mask, value, mode, opacity * min(1.0, thick))

    def ellipses(self, centres_m: np.ndarray, axes_m: np.ndarray, angles_deg: np.ndarray, value, *,
                 mode: str = "set", opacity: float = 1.0) -> None:
        centres_m = np.asarray(centres_m, np.float64).reshape(-1, 2)
        if not len(centres_m):
            return
        crop = self._crop(centres_m, float(np.max(axes_m)))
        if crop is None:
            return
        r0, r1, c0, c1 = crop
        mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
        self._draw_ellipses(mask, r0, c0, centres_m, axes_m, angles_deg)
        self._add(crop, mask, value, mode, opacity)


def _paint_ground(paint: list[_Paint], shade: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The ground texture, (Ht, Wt, 3) uint8: ``paint`` in order, times ``shade`` (Ht, Wt), blurred.

    Strip by strip of STRIP_ROWS rows, each with _BLUR_HALO_ROWS rows of its neighbours
    painted too, so that the blur of a strip equals the blur of the whole texture there.
    """
    ht, wt = shade.shape
    ground = np.empty((ht, wt, 3), np.uint8)
    for s0 in range(0, ht, STRIP_ROWS):
        s1 = min(ht, s0 + STRIP_ROWS)
        h0, h1 = max(0, s0 - _BLUR_HALO_ROWS), min(ht, s1 + _BLUR_HALO_ROWS)
        tex = np.zeros((h1 - h0, wt, 3), np.float32)
        for op in paint:
            op.apply(tex, h0, xs, ys)
        tex *= shade[h0:h1, :, None]
        # band-limit to about the pixel: hard texel edges would alias differently at every sub-pixel
        # phase, which no flow (nor warping by the true flow) can reproduce
        tex = cv2.GaussianBlur(tex, (0, 0), 0.5 * TEXELS_PER_PIXEL)[s0 - h0:s1 - h0]
        ground[s0:s1] = np.clip(np.rint(tex), 0, 255)
    return ground


# -- the road graph ------------------------------------------------------------------------

def _road_graph(ws, region: tuple[float, float, float, float], centre: np.ndarray, rng: np.random.Generator):
    """Junctions (N, 2), grid index of each (N, 2), and every grid edge as (a, b, curve, is_road, major).

    A grid ``road_spacing_m`` apart, turned by a random angle, junctions moved and edges bent
    by ``road_irregularity``; one row and one column near ``centre`` are main roads; minor
    edges are left out with ``road_drop_fraction`` where both ends keep at least two roads.
    """
    sp, irr = ws.road_spacing_m, ws.road_irregularity
    phi = rng.uniform(-0.25 * math.pi, 0.25 * math.pi)
    c, s = math.cos(phi), math.sin(phi)
    Rm = np.array([[c, -s], [s, c]])  # grid frame -> world
    x0, y0, x1, y1 = region
    corners = (np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]) - centre) @ Rm  # world -> grid frame
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    off = rng.uniform(0, sp, 2)
    ia = np.arange(math.floor((lo[0] - off[0]) / sp), math.ceil((hi[0] - off[0]) / sp) + 1)
    ja = np.arange(math.floor((lo[1] - off[1]) / sp), math.ceil((hi[1] - off[1]) / sp) + 1)
    ni, nj = len(ia), len(ja)
    gi, gj = np.meshgrid(np.arange(ni), np.arange(nj), indexing="ij")
    grid = np.stack([off[0] + ia[gi] * sp, off[1] + ja[gj] * sp], axis=-1).reshape(-1, 2)
    grid += rng.uniform(-1, 1, grid.shape) * 0.25 * irr * sp
    nodes = grid @ Rm.T + centre
    index = np.stack([gi.ravel(), gj.ravel()], axis=1)

    def nid(i, j):
        return i * nj + j

    near = np.argmin(np.hypot(*(nodes - centre).T))
    i_major = int(index[near, 0] + rng.integers(-1, 2))
    j_major = int(index[near, 1] + rng.integers(-1, 2))
    edges = []
    for i in range(ni):
        for j in range(nj):
            for di, dj in ((1, 0), (0, 1)):
                if i + di >= ni or j + dj >= nj:
                    continue
                a, b = nid(i, j), nid(i + di, j + dj)
                p0, p1 = nodes[a], nodes[b]
                d = p1 - p0
                normal = np.array([-d[1], d[0]])
                ctrl = 0.5 * (p0 + p1) + normal * rng.uniform(-1, 1) * 0.3 * irr
                major = (di == 0 and i == i_major) or (dj == 0 and j == j_major)
                edges.append([a, b, _bezier(p0, ctrl, p1, ROAD_SAMPLE_M), True, major])
    degree = np.zeros(len(nodes), int)
    for a, b, *_ in edges:
        degree[a] += 1
        degree[b] += 1
    for k in rng.permutation(len(edges)):
        a, b, _, _, major = edges[k]
        if not major and degree[a] > 2 and degree[b] > 2 and rng.uniform() < ws.road_drop_fraction:
            edges[k][3] = False
            degree[a] -= 1
            degree[b] -= 1
    return nodes, index, (ni, nj), edges, phi


def _cells(nodes, shape, edges):
    """Blocks of the grid: (i, j) -> closed polygon (P, 2) along the four bent edges, anticlockwise in the
    grid frame, and the indices of its four edges."""
    ni, nj = shape
    by_pair = {(a, b): k for k, (a, b, *_) in enumerate(edges)}
    out = {}
    for i in range(ni - 1):
        for j in range(nj - 1):
            n00, n10, n11, n01 = i * nj + j, (i + 1) * nj + j, (i + 1) * nj + j + 1, i * nj + j + 1
            ks = [by_pair[(n00, n10)], by_pair[(n10, n11)], by_pair[(n01, n11)], by_pair[(n00, n01)]]
            poly = np.vstack([edges[ks[0]][2], edges[ks[1]][2][1:], edges[ks[2]][2][::-1][1:],
                              edges[ks[3]][2][::-1][1:-1]])
            out[(i, j)] = (poly, ks)
    return out


def _inner_rect(poly: np.ndarray, yaw: float, margin_m: float):
    """A rectangle (cx, cy, sx, sy) at ``yaw`` inside ``poly`` with every corner at least ``margin_m`` from
    its boundary, shrunk from the polygon's bounding box in the turned frame; None if none is left."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = (poly - poly.mean(axis=0)) @ np.array([[c, -s], [s, c]])
    lo, hi = local.min(axis=0), local.max(axis=0)
    contour = poly.astype(np.float32).reshape(-1, 1, 2)
    for shrink in np.arange(0.0, 0.5 * min(hi - lo), 1.0):
        a, b = lo + shrink, hi - shrink
        ctr = poly.mean(axis=0) + (0.5 * (a + b)) @ np.array([[c, s], [-s, c]])
        corners = _rect_corners(ctr[0], ctr[1], b[0] - a[0], b[1] - a[1], yaw)
        if all(cv2.pointPolygonTest(contour, (float(p[0]), float(p[1])), True) >= margin_m for p in corners):
            return float(ctr[0]), float(ctr[1]), float(b[0] - a[0]), float(b[1] - a[1])
    return None


class _RoadIndex:
    """Road centre-line samples with their half widths, for clearance checks."""

    def __init__(self, roads: list[Road], bbox: tuple[float, float, float, float], pad_m: float):
        x0, y0, x1, y1 = bbox
        segs, half = [], []
        for r in roads:
            c = r.centre_m
            if (c[:, 0].max() < x0 - pad_m or c[:, 0].min() > x1 + pad_m
                    or c[:, 1].max() < y0 - pad_m or c[:, 1].min() > y1 + pad_m):
                continue
            segs.append(np.concatenate([c[:-1], c[1:]], axis=1))
            half.append(np.full(len(c) - 1, r.width_m / 2))
        self.segs = np.vstack(segs) if segs else np.zeros((0, 4))
        self.half = np.concatenate(half) if half else np.zeros(0)

    def clearance(self, points_m: np.ndarray) -> np.ndarray:
        """Distance (P,) from each point to the nearest road's edge (negative on a road)."""
        p = np.asarray(points_m, np.float64).reshape(-1, 2)
        if not len(self.segs):
            return np.full(len(p), np.inf)
        a, b = self.segs[:, :2], self.segs[:, 2:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(axis=1), 1e-12)
        t = np.clip(((p[:, None, :] - a[None]) * ab[None]).sum(axis=2) / L2, 0.0, 1.0)
        d = np.sqrt(((p[:, None, :] - a[None] - t[..., None] * ab[None]) ** 2).sum(axis=2))
        return (d - self.half[None]).min(axis=1)

    def rect_clear(self, corners: np.ndarray, margin_m: float) -> bool:
        """No road centre sample within (half width + margin) of the rectangle, by box distance."""
        if not len(self.segs):
            return True
        pts = self.segs[:, :2]
        d = point_rect_distance(pts, corners)
        return bool(np.all(d > self.half + margin_m))


def field_rows(rng: np.random.Generator, base: np.ndarray, along_rad: float) -> _Rows:
    """A field's row pattern: rows 1.6-3.2 m apart roughly along or across ``along_rad``, 2-5 gray
    levels deep (none in a third of the fields), bent by three waves 25-60 m long and 1.2-3 rad deep."""
    ang = along_rad + rng.uniform(-0.15, 0.15) + rng.choice([0.0, 0.5 * math.pi])
    beta, k = rng.uniform(0, 2 * math.pi, 3), 2 * math.pi / rng.uniform(25, 60, 3)
    waves = np.column_stack([k * np.cos(beta), k * np.sin(beta), rng.uniform(0, 2 * math.pi, 3),
                             rng.uniform(1.2, 3.0, 3)])
    period = float(rng.uniform(1.6, 3.2))
    amp = float(rng.uniform(2.0, 5.0) * (rng.uniform() < 0.67))
    return _Rows(np.asarray(base, np.float64), period, float(ang), amp, waves)


GROUND_MATERIALS = ("grass", "meadow", "soil", "gravel", "yard", "wood", "lawn", "verge", "paving", "asphalt",
                    "crop")
LAND = {
    "wheat": (160, 148, 106), "crop": (104, 120, 72), "young": (126, 132, 88), "ploughed": (116, 98, 80),
    "grass": (94, 110, 72), "meadow": (112, 118, 80), "soil": (128, 110, 88), "wood": (64, 74, 50),
    "concrete": (136, 134, 128), "asphalt": (108, 108, 112),
}


def build_world(spec, path: CameraPath, rng: np.random.Generator) -> World:
    """Lay out roads, blocks, buildings and trees around the flight footprint and paint the ground."""
    img, ws = spec.image, spec.world
    fx0, fy0, fx1, fy1 = ground_footprint(path, img.width_px, img.height_px)
    margin = 0.15 * max(fx1 - fx0, fy1 - fy0) + 20.0
    x0, y0, x1, y1 = fx0 - margin, fy0 - margin, fx1 + margin, fy1 + margin
    texel = spec.gsd_m() / TEXELS_PER_PIXEL
    # the renderer splits the ground into tiles of at most MAX_TEXTURE_PX; only a flight over
    # more than MAX_GROUND_TEXELS pays with a coarser texel
    texel = max(texel, math.sqrt((x1 - x0) * (y1 - y0) / MAX_GROUND_TEXELS))
    wt, ht = int(math.ceil((x1 - x0) / texel)), int(math.ceil((y1 - y0) / texel))
    wt += -wt % 4  # GL unpacks texture rows at 4-byte alignment: RGB rows must be a multiple of 4 px
    x1, y1 = x0 + wt * texel, y0 + ht * texel
    extent = (x0, y0, x1, y1)

    # the road graph reaches beyond the texture as far as a vehicle can drive in the sequence
    duration_s = (img.n_frames - 1) / img.fps
    reach = spec.vehicles.speed_range_mps[1] * duration_s + 2 * ws.road_spacing_m
    region = (x0 - reach, y0 - reach, x1 + reach, y1 + reach)
    centre = np.array([0.5 * (fx0 + fx1), 0.5 * (fy0 + fy1)])
    nodes, index, shape, edges, phi = _road_graph(ws, region, centre, rng)
    w_major, w_minor = ws.road_width_m, 0.75 * ws.road_width_m
    roads = [Road(centre_m=e[2], width_m=w_major if e[4] else w_minor, major=e[4], nodes=(e[0], e[1]))
             for e in edges if e[3]]
    road_index = _RoadIndex(roads, extent, 50.0)

    canvas = _Canvas(x0, y0, texel, wt, ht)
    cells = _cells(nodes, shape, edges)
    seen = (fx0, fy0, fx1, fy1)

    def overlaps(poly, box):
        return (poly[:, 0].max() > box[0] and poly[:, 0].min() < box[2]
                and poly[:, 1].max() > box[1] and poly[:, 1].min() < box[3])

    # -- materials: one tile each, sampled by every block with its own offset and tint -----------
    tiles = {name: material_tile(name, rng, texel, detail=ws.detail) for name in GROUND_MATERIALS}

    def material(name: str, gain=(1.0, 1.0, 1.0), under=None, *, draw: np.random.Generator = rng) -> MaterialPattern:
        off = tuple(int(v) for v in draw.integers(0, TILE_PX, 2))
        return MaterialPattern(tiles[name], x0, y0, texel, off, tuple(float(g) for g in gain), under)

    # -- land use, block by block ------------------------------------------------------------
    stalls: list[tuple[float, float, float]] = []
    kinds: dict[tuple[int, int], str] = {}
    row_angles: dict[tuple[int, int], float] = {}  # fields under a crop: the rows' direction, radians
    for key, (poly, ks) in cells.items():
        if not overlaps(poly, extent):
            continue
        r = rng.uniform()
        if r < ws.parking_fraction:
            kind = "parking"
        elif r < ws.parking_fraction + ws.built_fraction:
            kind = "yard"
        elif r < ws.parking_fraction + ws.built_fraction + ws.wood_fraction:
            kind = "wood"
        else:
            kind = ["field", "field", "field", "grass", "meadow", "soil"][int(rng.integers(0, 6))]
        kinds[key] = kind
        jitter = rng.uniform(0.9, 1.1) * (1.0 + rng.uniform(-0.03, 0.03, 3))  # brightness, a hint of hue
        if kind == "field":
            crop = ["wheat", "crop", "young", "ploughed"][int(rng.integers(0, 4))]
            e = poly[np.argmax(np.hypot(*(poly - poly[0]).T))] - poly[0]
            rows = field_rows(rng, np.asarray(LAND[crop]) * jitter, math.atan2(e[1], e[0]))
            if crop != "ploughed":
                row_angles[key] = rows.ang
            canvas.polygon([poly], material("crop", under=rows), feather_m=0.5)
        elif kind == "parking":
            canvas.polygon([poly], material("yard", jitter), feather_m=0.5)
            yaw = math.atan2(*(poly[1] - poly[0])[::-1])
            rect = _inner_rect(poly, yaw, w_major / 2 + 1.0)
            if rect is not None:
                stalls += _parking_lot(canvas, rect, yaw, rng, material("asphalt", rng.uniform(0.9, 1.1) * np.ones(3)))
        elif kind == "yard":
            canvas.polygon([poly], material("yard", jitter), feather_m=0.5)
            # lawns and gravel: irregular blobs with soft edges, not discs
            for _ in range(int(rng.integers(1, 4))):
                what = "gravel" if rng.uniform() < 0.25 else "lawn"
                canvas.polygon([_blob(poly, rng, 4, 12)], material(what, rng.uniform(0.88, 1.05) * np.ones(3)),
                               feather_m=float(rng.uniform(0.3, 0.9)))
        else:
            canvas.polygon([poly], material(kind, jitter), feather_m=0.5)
            if kind in ("grass", "meadow", "soil"):
                # patches of the neighbouring materials (worn, overgrown, damp), blending in over metres
                others = [m for m in ("grass", "meadow", "soil") if m != kind]
                for _ in range(int(rng.integers(0, 4))):
                    other = others[int(rng.integers(0, len(others)))]
                    canvas.polygon([_blob(poly, rng, 5, 16)], material(other, jitter),
                                   opacity=float(rng.uniform(0.5, 0.9)), feather_m=float(rng.uniform(1.0, 3.0)))

    # -- buildings, trees, hedges, woods ----------------------------------------------------------
    buildings = _place_buildings(ws.buildings, cells, kinds, seen, road_index, phi, rng)
    trees = _place_trees(ws, cells, kinds, edges, road_index, buildings, extent, rng)
    overpasses: list[Building] = []
    if spec.traffic.street_trees_per_km > 0 or spec.traffic.bridges > 0:
        from scenes.traffic import street_furniture  # scenes.traffic builds on this module

        # its own stream (the seed's sixth child), so the rest of the world does not change with it
        rng_street = np.random.Generator(np.random.PCG64(np.random.SeedSequence(spec.seed).spawn(6)[5]))
        trees, overpasses = street_furniture(spec, roads, buildings, trees, seen, rng_street)
    canopies = []
    if ws.trees.wood_density_per_ha > 0:
        for key, kind in kinds.items():
            if kind == "wood":
                c = canopy_mesh(cells[key][0], rng, inset_m=ws.road_width_m / 2 + 2.5,
                                density_per_ha=ws.trees.wood_density_per_ha,
                                crown_diameter_range_m=ws.trees.crown_diameter_range_m,
                                height_range_m=ws.trees.height_range_m)
                if c is not None:
                    canopies.append(c)

    # -- verges, sidewalks, roads, kerbs, markings, junctions (scenes.streets) ---------------------
    from scenes.streets import paint_streets  # here: scenes.streets builds on this module's helpers

    paint_streets(canvas, roads=roads, nodes_m=nodes, cells=cells, kinds=kinds, edges=edges,
                  widths_m=(w_major, w_minor), material=material, crosswalk_fraction=ws.crosswalk_fraction,
                  rng=rng, kerb_parking=spec.traffic.kerb_parking_per_km > 0, contrast=ws.edges,
                  # ``world.edges`` draws from the seed's ninth stream: the rest of the world is the same without it
                  rng_contrast=np.random.Generator(np.random.PCG64(np.random.SeedSequence(spec.seed).spawn(9)[8])))

    # -- small things on streets and in yards (scenes.streets.paint_clutter), their own stream (the seed's
    # seventh child): the rest of the world does not change with ``world.clutter`` ------------------
    light = spec.light
    flat_shadows = light.mode == "flat" and light.shadows
    clutter_shadows = []
    if ws.clutter > 0:
        from scenes.streets import paint_clutter

        to_sun = sun_direction(light.sun_elevation_deg, light.sun_azimuth_deg)
        rng_clutter = np.random.Generator(np.random.PCG64(np.random.SeedSequence(spec.seed).spawn(7)[6]))
        buildings = [_roof_rows(b, rng_clutter) for b in buildings]
        clutter_shadows = paint_clutter(
            canvas, roads=[r for r in roads if overlaps(r.centre_m, extent)], cells=cells,
            kinds=kinds, buildings=buildings, row_angles=row_angles,
            widths_m=(w_major, w_minor), clearance=road_index.clearance,
            material=lambda name, gain=(1.0, 1.0, 1.0): material(name, gain, draw=rng_clutter),
            density=ws.clutter, away=-to_sun[:2] / max(1e-9, to_sun[2]) if flat_shadows else None,
            rng=rng_clutter, kerb_parking=spec.traffic.kerb_parking_per_km > 0)

    # -- painted shadows of the static world (flat light only: sun light casts real ones) ------
    if flat_shadows:
        bridge_shadows = []
        if overpasses:
            from scenes.traffic import overpass_shadow_polygons

            bridge_shadows = overpass_shadow_polygons(overpasses, light)
        _paint_shadows(canvas, buildings, trees, canopies, light, extra_polys_m=bridge_shadows + clutter_shadows)

    xs = x0 + (np.arange(wt, dtype=np.float32) + 0.5) * texel  # texel centres
    ys = y0 + (np.arange(ht, dtype=np.float32) + 0.5) * texel
    shade = _multiscale_noise(rng, (ht, wt), texel)
    if ws.detail > 0:
        # light and soil at 2-4 m (``world.detail``), from the seed's eighth stream: the rest of the
        # world draws the same as without it
        rng_detail = np.random.Generator(np.random.PCG64(np.random.SeedSequence(spec.seed).spawn(8)[7]))
        shade += _multiscale_noise(rng_detail, (ht, wt), texel,
                                   octaves_m=tuple((c, a * ws.detail) for c, a in DETAIL_OCTAVES_M), grain=False)
    shade += 1.0
    ground = _paint_ground(canvas.ops, shade, xs, ys)
    del shade

    wall_textures, roof_textures = _building_textures(rng, texel, detail=ws.detail, edges=ws.edges)
    crown_textures = [crown_texture(rng, (255, 255, 255), detail=ws.detail)]  # leaves in gray: each crown's colour comes on top
    return World(extent_m=extent, texel_m=texel, ground_texture=ground, roads=roads, nodes_m=nodes,
                 road_width_m=w_major, buildings=buildings, trees=trees, stalls=stalls,
                 wall_textures=wall_textures, roof_textures=roof_textures, crown_textures=crown_textures,
                 canopies=canopies, canopy_texture=canopy_texture(rng) if canopies else None,
                 overpasses=overpasses, roof_tints=roof_tints(ws.edges),
                 parapet_tints=parapet_tints(ws.edges) if ws.edges > 0 else None)


def parapet_tints(edges: float) -> tuple[tuple[float, float, float], ...]:
    """The parapets' tints per roof variant at ``world.edges``: from 0.85 of the roof's tint (0) to PARAPET_DARK
    round a roof lighter than 0.6 and PARAPET_LIGHT round a darker one (1)."""
    out = []
    for t in roof_tints(edges):
        target = PARAPET_DARK if float(np.mean(t)) > 0.6 else PARAPET_LIGHT
        out.append(tuple(float((1.0 - edges) * 0.85 * a + edges * b) for a, b in zip(t, target)))
    return tuple(out)


def roof_tints(edges: float) -> tuple[tuple[float, float, float], ...]:
    """The roof tints per variant at ``world.edges`` (0: ROOF_TINTS, 1: ROOF_TINTS_EDGES), relative to the roof
    texture of :func:`_building_textures` at the same ``edges`` (lighter by ``1 + (ROOF_EDGES_GAIN - 1) edges``)."""
    gain = 1.0 + (ROOF_EDGES_GAIN - 1.0) * edges
    return tuple(tuple(float((1.0 - edges) * a / gain + edges * b) for a, b in zip(t0, t1))
                 for t0, t1 in zip(ROOF_TINTS, ROOF_TINTS_EDGES, strict=True))


def _blob(poly: np.ndarray, rng: np.random.Generator, r_lo_m: float, r_hi_m: float) -> np.ndarray:
    """An irregular blob (9, 2) somewhere in the block ``poly``, radii ``r_lo_m``-``r_hi_m``."""
    centre = poly.mean(axis=0) + rng.uniform(-0.3, 0.3, 2) * (poly.max(0) - poly.min(0))
    ang = np.sort(rng.uniform(0, 2 * math.pi, 9))
    rad = rng.uniform(r_lo_m, r_hi_m) * rng.uniform(0.6, 1.0, 9)
    return centre + np.column_stack([np.cos(ang), np.sin(ang)]) * rad[:, None]


def _parking_lot(canvas: _Canvas, rect, yaw: float, rng: np.random.Generator,
                 asphalt) -> list[tuple[float, float, float]]:
    """Asphalt (the paint value ``asphalt``), rows of perpendicular stalls 2.6 m x 5 m either side of
    6.5 m aisles, worn lines."""
    cx, cy, sx, sy = rect
    canvas.polygon([_rect_corners(cx, cy, sx, sy, yaw)], asphalt)
    c, s = math.cos(yaw), math.sin(yaw)
    ex, ey = np.array([c, s]), np.array([-s, c])
    origin = np.array([cx, cy]) - ex * sx / 2 - ey * sy / 2
    stall_w, stall_d, aisle = 2.6, 5.0, 6.5
    lines, stalls = [], []
    v = 0.5
    while v + stall_d <= sy - 0.5:
        u = 0.5
        lines.append(np.array([origin + ex * 0.5 + ey * v, origin + ex * (sx - 0.5) + ey * v]))
        while u + stall_w <= sx - 0.5:
            lines.append(np.array([origin + ex * u + ey * v, origin + ex * u + ey * (v + stall_d)]))
            p = origin + ex * (u + stall_w / 2) + ey * (v + stall_d / 2)
            stalls.append((float(p[0]), float(p[1]), yaw + 0.5 * math.pi))
            u += stall_w
        lines.append(np.array([origin + ex * u + ey * v, origin + ex * u + ey * (v + stall_d)]))
        v += stall_d + (aisle if len(lines) % 2 else 0.0)
    canvas.lines(lines, 0.12, MARK_RGB, opacity=float(rng.uniform(0.6, 0.85)))
    return stalls


def _place_buildings(bs, cells, kinds, seen, road_index: _RoadIndex, phi: float,
                     rng: np.random.Generator) -> list[Building]:
    """Up to ``bs.count`` buildings on yard blocks (those the camera sees first), each clear of every road
    by ROAD_CLEARANCE_M and of every other building by BUILDING_GAP_M."""
    if bs.count == 0:
        return []
    yards = [key for key, kind in kinds.items() if kind == "yard"]
    fx0, fy0, fx1, fy1 = seen
    in_view = [k for k in yards if (cells[k][0][:, 0].max() > fx0 and cells[k][0][:, 0].min() < fx1
                                    and cells[k][0][:, 1].max() > fy0 and cells[k][0][:, 1].min() < fy1)]
    order = [in_view[i] for i in rng.permutation(len(in_view))] + [k for k in yards if k not in in_view]
    if not order:
        return []
    out: list[Building] = []
    for k in range(bs.count):
        poly = cells[order[k % len(order)]][0]
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        for _attempt in range(30):
            sx, sy = rng.uniform(*bs.footprint_range_m, 2)
            yaw = phi + rng.uniform(-0.08, 0.08) + rng.choice([0.0, 0.5 * math.pi])
            cx, cy = rng.uniform(lo, hi)
            h = float(rng.uniform(*bs.height_range_m))
            corners = _rect_corners(cx, cy, sx, sy, yaw)
            if not all(cv2.pointPolygonTest(contour, (float(p[0]), float(p[1])), False) > 0 for p in corners):
                continue
            if not road_index.rect_clear(corners, ROAD_CLEARANCE_M):
                continue
            if any(rects_overlap(corners, o.corners_xy(), BUILDING_GAP_M) for o in out):
                continue
            out.append(Building(centre=(float(cx), float(cy), h / 2), size=(float(sx), float(sy), h),
                                yaw_rad=float(yaw), parts=_building_parts(sx, sy, h, rng),
                                roof_variant=int(rng.integers(0, len(ROOF_TINTS)))))
            break
    return out


def _building_parts(sx: float, sy: float, h: float, rng: np.random.Generator) -> tuple[Box, ...]:
    """The building's boxes in its own frame: the block, a parapet round the roof, roof units."""
    parts = [Box(centre=(0.0, 0.0, h / 2), size=(sx, sy, h))]
    t, ph = 0.3, 0.8  # parapet thickness and height
    parts += [Box(centre=(0.0, e * (sy / 2 - t / 2), h + ph / 2), size=(sx, t, ph)) for e in (-1, 1)]
    parts += [Box(centre=(e * (sx / 2 - t / 2), 0.0, h + ph / 2), size=(t, sy - 2 * t, ph)) for e in (-1, 1)]
    placed: list[np.ndarray] = []
    # vents, plant rooms, skylights, solar panels, dormers: more on a larger roof (one per 40 m2 or so,
    # as on KIT AIS's city roofs), up to 24
    for _ in range(min(24, int(rng.integers(2, 9)) + int(sx * sy / 60.0))):
        ux, uy, uh = rng.uniform(0.8, min(3.5, sx / 3)), rng.uniform(0.8, min(3.5, sy / 3)), rng.uniform(0.6, 2.2)
        cx = rng.uniform(-sx / 2 + t + 0.5 + ux / 2, sx / 2 - t - 0.5 - ux / 2)
        cy = rng.uniform(-sy / 2 + t + 0.5 + uy / 2, sy / 2 - t - 0.5 - uy / 2)
        corners = _rect_corners(cx, cy, ux, uy, 0.0)
        if any(rects_overlap(corners, o, 0.5) for o in placed):
            continue
        placed.append(corners)
        parts.append(Box(centre=(float(cx), float(cy), h + uh / 2), size=(float(ux), float(uy), float(uh))))
    return tuple(parts)


def _roof_rows(b: Building, rng: np.random.Generator) -> Building:
    """``b`` with a row of dormers or skylights along one or both long sides of its roof (as on KIT AIS's
    Munich blocks: 1.2-1.6 m wide, 2.8-3.6 m apart, a metre in from the parapet), where no roof unit stands."""
    sx, sy, h = b.size
    long_x = sx >= sy
    length, depth = (sx, sy) if long_x else (sy, sx)
    if length < 8.0 or depth < 6.0 or rng.uniform() > 0.6:
        return b
    units = [_rect_corners(p.centre[0], p.centre[1], p.size[0], p.size[1], 0.0) for p in b.parts[5:]]
    parts = list(b.parts)
    w, d, uh = rng.uniform(1.2, 1.6), rng.uniform(1.0, 1.4), rng.uniform(1.0, 1.5)
    step = rng.uniform(2.8, 3.6)
    sides = (-1, 1) if rng.uniform() < 0.5 else (int(rng.choice([-1, 1])),)
    for e in sides:
        across = e * (depth / 2 - 0.3 - 0.9 - d / 2)
        n = int((length - 2.0) // step)
        for k in range(n):
            along = (k - (n - 1) / 2) * step
            cx, cy = (along, across) if long_x else (across, along)
            ux, uy = (w, d) if long_x else (d, w)
            corners = _rect_corners(cx, cy, ux, uy, 0.0)
            if any(rects_overlap(corners, o, 0.3) for o in units):
                continue
            parts.append(Box(centre=(float(cx), float(cy), h + uh / 2), size=(float(ux), float(uy), float(uh))))
    return dataclasses.replace(b, parts=tuple(parts))


def _place_trees(ws, cells, kinds, edges, road_index: _RoadIndex, buildings: list[Building], extent,
                 rng: np.random.Generator) -> list[Tree]:
    """Single trees on grass, meadows and yards (deciduous with lobed crowns, or conifers); hedges of
    bushes along some field and grass block sides. (Woods are canopies: :func:`scenes.vegetation.canopy_mesh`.)
    Each trunk keeps clear of roads and buildings by the crown's reach."""
    ts = ws.trees
    x0, y0, x1, y1 = extent
    cand: list[dict] = []
    n_leafy = N_CROWN_VARIANTS - len(CONIFER_VARIANTS)
    for key, kind in kinds.items():
        poly, ks = cells[key]
        area_ha = abs(cv2.contourArea(poly.astype(np.float32))) / 1e4
        density = ts.density_per_ha if kind in ("grass", "meadow", "yard") else 0.0
        n = int(rng.poisson(density * area_ha))
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        for _ in range(n):
            x, y = rng.uniform(lo, hi)
            d = float(rng.uniform(*ts.crown_diameter_range_m))
            h = float(rng.uniform(max(ts.height_range_m[0], 0.6 * d), max(ts.height_range_m[1], 0.6 * d)))
            if rng.uniform() < ts.conifer_fraction:  # narrow and tall, the crown down to near the ground
                r, base = 0.3 * d, float(rng.uniform(0.4, 2.0))
                h = 1.2 * h
                cand.append(dict(x_m=float(x), y_m=float(y), height_m=h, crown_radius_m=r,
                                 crown_half_height_m=(h - base) / 2,
                                 variant=int(CONIFER_VARIANTS[int(rng.integers(0, len(CONIFER_VARIANTS)))]),
                                 lobes=conifer_lobe(height_m=h, radius_m=r, crown_base_m=base), conifer=True))
            else:
                half = min(max(0.5 * d, 0.36 * h), 0.45 * h)
                cand.append(dict(x_m=float(x), y_m=float(y), height_m=h, crown_radius_m=d / 2, crown_half_height_m=half,
                                 variant=int(rng.integers(0, n_leafy)),
                                 lobes=crown_lobes(rng, height_m=h, radius_m=d / 2, half_height_m=half)))
        if kind in ("field", "grass", "meadow"):
            for side in range(4):
                if rng.uniform() >= ts.hedge_fraction:
                    continue
                line = edges[ks[side]][2]
                inward = 1.0 if side in (0, 1) else -1.0  # the cell's polygon runs anticlockwise
                off = ws.road_width_m / 2 + 2.5
                row = _trim(_offset_right(line, -inward * off), start_m=off + 2, end_m=off + 2)
                s = polyline_arc_lengths(row)
                if s[-1] < 5:
                    continue
                # bushes 1.6-2.4 m wide, 2.2x as long along the row, 2.4 m apart: a closed hedge of lobes
                at = np.arange(0.0, s[-1], 2.4)
                hx, hy = np.interp(at, s, row[:, 0]), np.interp(at, s, row[:, 1])
                tx, ty = np.gradient(hx), np.gradient(hy)
                v = int(rng.integers(0, n_leafy))
                for x, y, dx, dy in zip(hx, hy, tx, ty):
                    d = float(rng.uniform(1.6, 2.4))
                    h = float(rng.uniform(1.6, 2.6))
                    yaw = math.atan2(dy, dx)
                    cand.append(dict(x_m=float(x), y_m=float(y), height_m=h, crown_radius_m=d / 2,
                                     crown_half_height_m=0.45 * h, variant=v, bush=True, yaw_rad=yaw, stretch=2.2,
                                     lobes=hedge_lobes(rng, height_m=h, radius_m=d / 2, length_m=2.2 * d, yaw_rad=yaw)))
    if not cand:
        return []
    arr = np.array([(c["x_m"], c["y_m"], c["crown_radius_m"] * max(1.0, c.get("stretch", 1.0))) for c in cand])
    inside = (arr[:, 0] > x0) & (arr[:, 0] < x1) & (arr[:, 1] > y0) & (arr[:, 1] < y1)
    ok = inside & (road_index.clearance(arr[:, :2]) > arr[:, 2] + 0.5)
    for b in buildings:
        ok &= point_rect_distance(arr[:, :2], b.corners_xy()) > arr[:, 2] + 0.5
    return [Tree(**c) for c, keep in zip(cand, ok) if keep]


def _paint_shadows(canvas: _Canvas, buildings: list[Building], trees: list[Tree], canopies: list[dict],
                   light, *, extra_polys_m=()) -> None:
    """Darken the ground to ``light.ambient`` of its sunlit value where a building, a tree (crown lobes
    and trunk, from the trunk's base on: :func:`scenes.vegetation.tree_shadow_shapes`), a wood's canopy
    or one of ``extra_polys_m`` (ground polygons (P, 2): footbridges' shadows) blocks the sun (flat light).
    All in one mask: where two shadows overlap the ground is no darker."""
    to_sun = sun_direction(light.sun_elevation_deg, light.sun_azimuth_deg)
    away = -to_sun[:2] / max(1e-9, to_sun[2])  # ground offset of a point's shadow per metre of height
    polys = []
    for b in buildings:
        c = b.corners_xy()
        hull = cv2.convexHull(np.vstack([c, c + away * b.size[2]]).astype(np.float32))[:, 0]
        polys.append(hull.astype(np.float64))
    for cp in canopies:
        # the outline swept along the sun by the rim's height: the outline, its shadow, the quads between
        o, off = cp["outline"], away * cp["edge_height_m"]
        polys += [o, o + off] + [np.array([o[i], o[(i + 1) % len(o)], o[(i + 1) % len(o)] + off, o[i] + off])
                                 for i in range(len(o))]
    ellipses, tree_polys = tree_shadow_shapes(trees, to_sun)
    canvas.union(float(light.ambient), polys_m=polys + list(extra_polys_m) + tree_polys, ellipses=ellipses, mode="mul")


def _building_textures(rng: np.random.Generator, texel: float, *, detail: float = 0.0, edges: float = 0.0):
    """A facade (floors 3 m apart with irregular windows) and a roof (membrane with stains), 128 x 128 texels
    of 0.1 m, repeated. ``detail`` (``world.detail``): the roof also has panels, vents, gravel and
    patched sheets 1-3 m wide, lighter and darker, ``8 detail`` to a tile (drawn from a child of
    ``rng``: one draw more). ``edges`` (``world.edges``): the roof is ``1 + (ROOF_EDGES_GAIN - 1) edges``
    times lighter (its tints, :func:`roof_tints`, bring each roof back to its own shade)."""
    n = 128
    g = 1.0 + 0.25 * _multiscale_noise(rng, (n, n), 0.1)
    tex = np.ones((n, n, 3), np.float32) * np.asarray((168, 160, 148), np.float32)
    for row in range(6, n, 30):  # one floor per 3 m; windows 1.2 m high, varied widths
        col = int(rng.integers(2, 8))
        while col < n - 8:
            w = int(rng.integers(8, 16))
            tex[row:row + 12, col:col + w] = (60, 66, 74) if rng.uniform() < 0.8 else (110, 112, 110)
            col += w + int(rng.integers(6, 14))
    wall = np.clip(np.rint(tex * g[..., None]), 0, 255).astype(np.uint8)
    g = 1.0 + 0.35 * _multiscale_noise(rng, (n, n), 0.1)
    # membrane sheets 1.6 m wide with darker welded seams, and a lighter strip along each (a roof seen
    # from above is panels and edges, not an even gray)
    seam = np.ones(n, np.float32)
    seam[::16] = 0.72
    seam[1::16] = 1.12
    g *= seam[None, :]
    if detail > 0:
        sub = np.random.Generator(np.random.PCG64(int(rng.integers(0, 2 ** 63))))
        panels = np.zeros((n, n), np.float32)  # log brightness
        for _ in range(int(round(8 * detail))):
            r, c = (int(v) for v in sub.integers(0, n, 2))
            h, w = (int(v) for v in sub.integers(8, 30, 2))
            gain = float(sub.choice([sub.uniform(0.6, 0.85), sub.uniform(1.12, 1.3)]))
            rows, cols = np.arange(r, r + h) % n, np.arange(c, c + w) % n  # the tile repeats: wrap
            panels[np.ix_(rows, cols)] += math.log(gain)
        # edges 0.3 m soft (about a pixel at the nominal GSD): a hard one would read as noise on the flat roofs
        g *= np.exp(cv2.GaussianBlur(np.pad(panels, 9, mode="wrap"), (0, 0), 3.0)[9:-9, 9:-9])
    # band-limited to about two texels (0.2 m): a seam is an overlap and its shadow, a few centimetres
    # wide; a one-texel line of 28 % depth aliased at the pixel and was counted as sensor noise
    # (realism.py's noise_sigma takes the flat half, where the roofs lie)
    g = cv2.GaussianBlur(np.pad(g, 4, mode="wrap"), (0, 0), 0.8)[4:-4, 4:-4]  # periodic, as the tile repeats
    base = np.asarray((150, 148, 144), np.float32) * (1.0 + (ROOF_EDGES_GAIN - 1.0) * edges)
    roof = np.clip(np.rint(base * g[..., None]), 0, 255).astype(np.uint8)
    return [wall], [roof]


# -- vehicles -----------------------------------------------------------------------------

def vehicle_boxes(length_m: float, width_m: float, height_m: float) -> list[Box]:
    """A car as three boxes in its own frame (x forward, z up, origin on the ground under its centre):
    the lower body, the glass cabin, and the roof on the cabin (painted like the body), so that from
    above one sees bonnet, windscreen, roof, rear window and boot."""
    hb, hc, hr = 0.5 * height_m, 0.45 * height_m, 0.05 * height_m
    lc, wc = 0.55 * length_m, 0.88 * width_m
    return [Box(centre=(0.0, 0.0, hb / 2), size=(length_m, width_m, hb)),
            Box(centre=(-0.06 * length_m, 0.0, hb + hc / 2), size=(lc, wc, hc)),
            Box(centre=(-0.1 * length_m, 0.0, hb + hc + hr / 2), size=(0.62 * lc, 0.94 * wc, hr))]


def box_mesh(box: Box, *, uv_scale_m: float | None = None) -> dict[str, np.ndarray]:
    """Triangles of a box: 24 vertices (4 per face) so each face has its own normal and UVs.

    Faces in the order -x, +x, -y, +y, -z, +z (two triangles each). UVs, when asked, are the
    face's two in-plane coordinates / ``uv_scale_m`` (a texture repeated at a fixed size in metres).
    """
    c = np.asarray(box.centre, float)
    h = np.asarray(box.size, float) / 2
    pos, nrm, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = [k for k in range(3) if k != axis]
            if sign < 0:
                a, b = b, a  # keep the winding anticlockwise seen from outside
            quad = []
            for da, db in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis] = sign * h[axis]
                p[a] = da * h[a]
                p[b] = db * h[b]
                quad.append(c + p)
            base = len(pos)
            n = np.zeros(3)
            n[axis] = sign
            for p in quad:
                pos.append(p)
                nrm.append(n)
                uv.append((p[a] / (uv_scale_m or 1.0), p[b] / (uv_scale_m or 1.0)))
            idx += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    out = {"positions": np.asarray(pos, np.float32), "normals": np.asarray(nrm, np.float32),
           "indices": np.asarray(idx, np.uint32)}
    if uv_scale_m is not None:
        out["texcoords"] = np.asarray(uv, np.float32)
    return out


MAX_PLACEMENT_TRIES = 80
MAX_TURN_DEG = 120.0  # vehicles do not take sharper turns at a junction


def _keeps_clear(vp: VehiclePath, others: list[VehiclePath], times_s: np.ndarray, clearance_m: float) -> bool:
    """Whether ``vp``'s centre stays ``clearance_m`` from every other vehicle's at every frame time."""
    if not others:
        return True
    mine = np.array([vp.pose(float(t))[:2] for t in times_s])
    for q in others:
        theirs = np.array([q.pose(float(t))[:2] for t in times_s])
        if np.min(np.hypot(*(mine - theirs).T)) < clearance_m:
            return False
    return True


def _directed(world: World, k: int, start_node: int) -> np.ndarray:
    r = world.roads[k]
    return r.centre_m if r.nodes[0] == start_node else r.centre_m[::-1]


def _walk(world: World, adj, k: int, node: int, length_m: float, prefer_turn: bool,
          rng: np.random.Generator) -> list[tuple[int, int]]:
    """Roads (index, entry node) driven after arriving at ``node`` along road ``k``, until ``length_m``."""
    out: list[tuple[int, int]] = []
    prev = _directed(world, k, world.roads[k].nodes[0] if world.roads[k].nodes[1] == node else world.roads[k].nodes[1])
    total = 0.0
    while total < length_m:
        d_in = prev[-1] - prev[-2]
        options = []
        for k2, other in adj.get(node, []):
            if k2 == k:
                continue
            nxt = _directed(world, k2, node)
            d_out = nxt[1] - nxt[0]
            turn = math.degrees(math.atan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], d_in @ d_out))
            if abs(turn) <= MAX_TURN_DEG:
                options.append((abs(turn), k2, other, nxt))
        if not options:
            break
        options.sort(key=lambda o: o[0])
        turning = [o for o in options if o[0] > 30.0]
        if prefer_turn and turning:
            pick = turning[int(rng.integers(0, len(turning)))]
        elif rng.uniform() < 0.75:
            pick = options[0]
        else:
            pick = options[int(rng.integers(0, len(options)))]
        _, k, other, nxt = pick
        out.append((k, node))
        total += polyline_arc_lengths(nxt)[-1]
        prev, node = nxt, other
    return out


def _join(world: World, legs: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The centre line of consecutive roads (index, entry node) with corners rounded at junctions
    (a quadratic Bezier from r before to r after the junction, r below the road width so that the
    rounded path stays on the asphalt); with each vertex's lane offset and each leg's first vertex."""
    pts, lane, starts = [], [], []
    lines = [_directed(world, k, n) for k, n in legs]
    widths = [world.roads[k].width_m for k, _ in legs]
    lengths = [polyline_arc_lengths(p)[-1] for p in lines]
    cut = [0.0] * (len(lines) + 1)
    for i in range(1, len(lines)):
        cut[i] = min(0.7 * min(widths[i - 1], widths[i]), 0.4 * lengths[i - 1], 0.4 * lengths[i])
    for i, (line, w) in enumerate(zip(lines, widths)):
        part = _trim(line, start_m=cut[i], end_m=cut[i + 1])
        if i > 0:
            corner = _bezier(pts[-1][-1], line[0], part[0], 0.5)[1:-1]
            pts.append(corner)
            lane.append(np.full(len(corner), min(widths[i - 1], w) / 4))
        starts.append(sum(len(p) for p in pts))
        pts.append(part)
        lane.append(np.full(len(part), w / 4))
    return np.vstack(pts), np.concatenate(lane), starts + [sum(len(p) for p in pts)]


def place_vehicles(spec, world: World, path: CameraPath, rng: np.random.Generator) -> list[VehiclePath]:
    """Put ``spec.vehicles.count`` vehicles on roads (or parking stalls) where the camera will see them.

    Each vehicle is aimed at the view of a random frame: it is on the road nearest a random
    point of that frame's footprint at that frame's time. Moving vehicles drive in the
    right-hand lane along a route through the road graph, turning at junctions (turning
    vehicles prefer to); parked ones stand in a stall or on a road's shoulder.
    """
    vs = spec.vehicles
    n = vs.count
    if n == 0:
        return []
    img = spec.image
    duration_s = (img.n_frames - 1) / img.fps
    n_parked = int(round(n * vs.parked_fraction))
    n_moving = n - n_parked
    n_turn = int(round(n_moving * vs.turning_fraction))
    n_acc = int(round(n_moving * vs.accelerating_fraction))
    n_stop = int(round(n_moving * vs.stopping_fraction))
    kinds = (["parked"] * n_parked + ["turning"] * n_turn + ["accelerating"] * n_acc
             + ["stopping"] * n_stop)
    kinds += ["constant"] * (n - len(kinds))
    kinds = kinds[:n]
    half_w_m = 0.35 * img.width_px * spec.gsd_m()
    half_h_m = 0.35 * img.height_px * spec.gsd_m()
    centre_ray = path.R_smooth[:, :, 2]
    lam = -path.C_smooth[:, 2] / centre_ray[:, 2]
    view_centre = path.C_smooth[:, :2] + lam[:, None] * centre_ray[:, :2]
    lo, hi = vs.speed_range_mps
    free_stalls = list(world.stalls)
    adj = world.adjacency()
    x0, y0, x1, y1 = world.extent_m
    near_roads = [k for k, r in enumerate(world.roads)
                  if r.centre_m[:, 0].max() > x0 and r.centre_m[:, 0].min() < x1
                  and r.centre_m[:, 1].max() > y0 and r.centre_m[:, 1].min() < y1]

    def nearest_road(p: np.ndarray) -> tuple[int, int]:
        best = (np.inf, 0, 0)
        for k in near_roads:
            d = np.hypot(*(world.roads[k].centre_m - p).T)
            j = int(np.argmin(d))
            if d[j] < best[0]:
                best = (float(d[j]), k, j)
        return best[1], best[2]

    def _candidate(i: int, kind: str) -> VehiclePath:
        k = int(rng.integers(0, img.n_frames))
        t_k = k / img.fps
        target = view_centre[k] + rng.uniform(-1, 1, 2) * np.array([half_w_m, half_h_m])
        colour = car_colour(rng)
        common = dict(vehicle_id=i + 1, size_m=(vs.length_m, vs.width_m, vs.height_m),
                      body_rgb=tuple(int(c) for c in colour), cabin_rgb=GLASS_RGB)
        backwards = bool(rng.integers(0, 2))
        if kind == "parked":
            if free_stalls:
                d2 = [(sx - target[0]) ** 2 + (sy - target[1]) ** 2 for sx, sy, _ in free_stalls]
                j = int(np.argmin(d2))
                sx, sy, th = free_stalls[j]
                if math.hypot(sx - target[0], sy - target[1]) < 2 * max(half_w_m, half_h_m):
                    free_stalls.pop(j)
                    th = th if backwards else th + math.pi
                    d = np.array([math.cos(th), math.sin(th)])
                    return VehiclePath(kind="parked", route_m=np.array([(sx, sy) - d, (sx, sy) + d]), s0_m=1.0,
                                       v0_mps=0.0, **common)
            # on the road's shoulder
            kr, j = nearest_road(target)
            line = world.roads[kr].centre_m[::-1] if backwards else world.roads[kr].centre_m
            j = len(line) - 1 - j if backwards else j
            j = min(max(j, 1), len(line) - 2)
            shoulder = world.roads[kr].width_m / 2 - vs.width_m / 2 - 0.3
            seg = _offset_right(line[j - 1:j + 2], shoulder)
            return VehiclePath(kind="parked", route_m=seg[[0, 2]], s0_m=float(np.hypot(*(seg[1] - seg[0]))),
                               v0_mps=0.0, **common)
        speed_kind = kind if kind in ("accelerating", "stopping") else "constant"
        v0 = rng.uniform(lo, 0.5 * (lo + hi)) if speed_kind == "accelerating" else rng.uniform(lo, hi)
        vp = VehiclePath(kind=speed_kind, route_m=np.array([[0.0, 0.0], [1.0, 0.0]]), s0_m=0.0, v0_mps=float(v0),
                         v_max_mps=float(hi), accel_mps2=vs.acceleration_mps2,
                         # stopping vehicles brake early enough to stand still before the end
                         t_stop_start_s=float(min(rng.uniform(0.1, 0.5) * duration_s,
                                                  max(0.0, duration_s - v0 / vs.acceleration_mps2 - 0.5))),
                         turning=kind == "turning", **common)
        d_k, d_end = vp.distance(t_k), vp.distance(duration_s)
        kr, j = nearest_road(target)
        a, b = world.roads[kr].nodes
        entry, leave = (b, a) if backwards else (a, b)
        line = _directed(world, kr, entry)
        j = len(line) - 1 - j if backwards else j
        s_on = polyline_arc_lengths(line)[j]
        after = _walk(world, adj, kr, leave, d_end - d_k + 30.0 - (polyline_arc_lengths(line)[-1] - s_on),
                      vp.turning, rng)
        before = _walk(world, adj, kr, entry, d_k + 30.0 - s_on, vp.turning, rng)
        # the roads before, driven the other way round: each entered at the far end of the walk
        legs = []
        for kb, nb in reversed(before):
            ra, rb = world.roads[kb].nodes
            legs.append((kb, rb if nb == ra else ra))
        legs.append((kr, entry))
        legs += after
        centre, lane, starts = _join(world, legs)
        route = _offset_right(centre, lane)
        mine = slice(starts[len(before)], starts[len(before) + 1])
        s_route = polyline_arc_lengths(route)
        m = mine.start + int(np.argmin(np.hypot(*(centre[mine] - line[j]).T)))
        return dataclasses.replace(vp, route_m=route, s0_m=float(s_route[m] - d_k))

    times_s = np.arange(img.n_frames) / img.fps
    clearance_m = vs.length_m + 1.0
    out: list[VehiclePath] = []
    for i, kind in enumerate(kinds):
        # Vehicles do not steer around each other, so a vehicle is placed only where its
        # whole path keeps clear of those placed before it: overlapping boxes would pass
        # through each other. Retries draw from the same Generator, so placement stays
        # deterministic; after MAX_PLACEMENT_TRIES the last candidate is kept.
        for _ in range(MAX_PLACEMENT_TRIES):
            vp = _candidate(i, kind)
            if _keeps_clear(vp, out, times_s, clearance_m):
                break
        out.append(vp)
    return out
