"""The world: a textured ground with roads, fields, parking lots and roofs; buildings; vehicles.

Everything is generated deterministically from ``numpy.random.Generator``s
derived from the spec seed. The ground texture's texel is finer than the
camera's ground sampling distance (GSD), so every image pixel sees detail:
optical flow needs gradients, and a blurry ground would make the benchmark lie.

No OpenGL here: meshes are plain arrays that :mod:`scenes.render` uploads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from scenes.motion import CameraPath, VehiclePath

__all__ = [
    "Box",
    "World",
    "build_world",
    "place_vehicles",
    "vehicle_boxes",
    "box_mesh",
    "ground_footprint",
]

# texel = GSD / TEXELS_PER_PIXEL: a little finer than a pixel, so the texture never looks blurred
TEXELS_PER_PIXEL = 1.5
MAX_TEXTURE_PX = 4096  # per ground tile uploaded to GL
MAX_GROUND_TEXELS = 60_000_000
ROAD_RGB = (72, 72, 78)
MARK_RGB = (235, 235, 228)
CAR_COLOURS = [(235, 235, 235), (25, 25, 30), (170, 172, 178), (190, 30, 30), (30, 60, 170),
               (30, 100, 50), (225, 190, 40), (120, 70, 40), (240, 120, 20)]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in its own frame: centre (3,) and size (3,) in metres."""

    centre: tuple[float, float, float]
    size: tuple[float, float, float]


@dataclass
class World:
    extent_m: tuple[float, float, float, float]  # x0, y0, x1, y1
    texel_m: float
    ground_texture: np.ndarray  # (Ht, Wt, 3) uint8; row r <-> y = y0 + (r + 0.5) * texel
    road_x_m: np.ndarray  # centre lines of roads running north-south (x = const)
    road_y_m: np.ndarray  # centre lines of roads running east-west (y = const)
    road_width_m: float
    buildings: list[Box] = field(default_factory=list)  # in world coordinates, on the ground
    building_texture: np.ndarray | None = None
    stalls: list[tuple[float, float, float]] = field(default_factory=list)  # parking: x, y, theta


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


def _multiscale_noise(rng: np.random.Generator, shape: tuple[int, int], texel_m: float) -> np.ndarray:
    """Sum of octaves from 40 m down to one texel; fine octaves keep detail at the GSD.

    Each octave, value noise clipped to [-1, 1] and weighted, is added strip by strip
    in place, so only the sum and one octave are ever whole in memory.
    """
    h, w = shape
    total = np.zeros(shape, np.float32)
    # grain at about one image pixel (TEXELS_PER_PIXEL texels): detail at the GSD, yet smooth
    # enough inside a pixel that resampling at another sub-pixel phase changes it little
    octaves = [(cell_m / texel_m, amp) for cell_m, amp in ((40.0, 0.35), (10.0, 0.25), (3.0, 0.2), (1.0, 0.15))
               if cell_m / texel_m >= 2] + [(TEXELS_PER_PIXEL, 0.12)]
    for cell_px, amp in octaves:
        big = _noise_upsampled(rng, shape, cell_px)
        for r0 in range(0, h, STRIP_ROWS):
            octave = big[r0:min(h, r0 + STRIP_ROWS), :w]
            np.clip(octave, -1.0, 1.0, out=octave)
            octave *= amp
            total[r0:r0 + STRIP_ROWS] += octave
        del big, octave  # the last strip's view would keep this octave alive through the next
    return total


def _road_lines(rng: np.random.Generator, lo: float, hi: float, spacing: float) -> np.ndarray:
    offset = rng.uniform(0, spacing)
    first = math.floor((lo - offset) / spacing)
    last = math.ceil((hi - offset) / spacing)
    return np.array([offset + k * spacing for k in range(first, last + 1)], float)


@dataclass(frozen=True)
class _Stripes:
    """A field's ploughed stripes: ``base + 28 sin(2 pi (x cos(ang) + y sin(ang)) / period)``."""

    base: np.ndarray  # (3,) RGB
    period: float  # metres
    ang: float  # radians


@dataclass(frozen=True)
class _Paint:
    """Paint ``value`` on the texels ``[rows, cols]`` (a slice or a boolean mask each, never both masks)."""

    rows: slice | np.ndarray
    cols: slice | np.ndarray
    value: object  # an RGB triple, a grey level, or _Stripes

    def apply(self, buf: np.ndarray, r0: int, xs: np.ndarray, ys: np.ndarray) -> None:
        """Paint onto ``buf``, the texture's rows ``r0 .. r0 + len(buf)`` (float32, (n, Wt, 3))."""
        r1 = r0 + buf.shape[0]
        if isinstance(self.rows, slice):
            a, b = max(self.rows.start, r0), min(self.rows.stop, r1)
            if b <= a:
                return
            local, rows_g = slice(a - r0, b - r0), slice(a, b)
        else:
            local = rows_g = self.rows[r0:r1]
        if isinstance(self.value, _Stripes):
            st = self.value
            X, Y = np.meshgrid(xs[self.cols], ys[rows_g])
            stripes = np.sin(2 * math.pi * (X * math.cos(st.ang) + Y * math.sin(st.ang)) / st.period)
            buf[local, self.cols] = st.base + 28.0 * stripes[..., None]
        else:
            buf[local, self.cols] = self.value


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


def build_world(spec, path: CameraPath, rng: np.random.Generator) -> World:
    """Lay out roads and blocks around the flight footprint and paint the ground texture."""
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

    sp, rw = ws.road_spacing_m, ws.road_width_m
    road_x = _road_lines(rng, x0, x1, sp)
    road_y = _road_lines(rng, y0, y1, sp)

    xs = x0 + (np.arange(wt, dtype=np.float32) + 0.5) * texel  # texel centres
    ys = y0 + (np.arange(ht, dtype=np.float32) + 0.5) * texel

    def cols(a: float, b: float) -> slice:
        return slice(max(0, int(math.floor((a - x0) / texel))), max(0, min(wt, int(math.ceil((b - x0) / texel)))))

    def rows(a: float, b: float) -> slice:
        return slice(max(0, int(math.floor((a - y0) / texel))), max(0, min(ht, int(math.ceil((b - y0) / texel)))))

    # The layout is drawn first as a list of paint operations (every random draw in order);
    # the texture is then painted from that list a strip of rows at a time, so no float copy
    # of the whole ground is ever in memory.
    paint: list[_Paint] = []

    # blocks between roads
    bx = np.concatenate([[x0 - sp], road_x, [x1 + sp]])
    by = np.concatenate([[y0 - sp], road_y, [y1 + sp]])
    stalls: list[tuple[float, float, float]] = []
    block_kinds: list[tuple[str, tuple[float, float, float, float]]] = []
    for i in range(len(bx) - 1):
        for j in range(len(by) - 1):
            bxa, bxb = bx[i] + rw / 2, bx[i + 1] - rw / 2
            bya, byb = by[j] + rw / 2, by[j + 1] - rw / 2
            if bxb <= x0 or bxa >= x1 or byb <= y0 or bya >= y1:
                continue
            r = rng.uniform()
            if r < ws.parking_fraction:
                kind = "parking"
            elif r < ws.parking_fraction + ws.roof_fraction:
                kind = "roof"
            else:
                kind = "field" if rng.uniform() < 0.6 else "grass"
            block_kinds.append((kind, (bxa, bya, bxb, byb)))
            cs, rs = cols(bxa, bxb), rows(bya, byb)
            if cs.stop <= cs.start or rs.stop <= rs.start:
                continue
            if kind == "field":
                base = np.array([rng.uniform(70, 150), rng.uniform(100, 170), rng.uniform(30, 80)])
                period = rng.uniform(1.2, 3.5)
                ang = rng.choice([0.0, 0.5 * math.pi]) + rng.uniform(-0.3, 0.3)
                paint.append(_Paint(rs, cs, _Stripes(base, period, ang)))
            elif kind == "grass":
                paint.append(_Paint(rs, cs, np.array([rng.uniform(50, 90), rng.uniform(90, 130), rng.uniform(40, 70)])))
            elif kind == "roof":
                g = rng.uniform(120, 190)
                paint.append(_Paint(rs, cs, (g, g, g * rng.uniform(0.92, 1.05))))
                # roof furniture: small boxes of another shade
                for _ in range(int(rng.integers(3, 12))):
                    cx, cy = rng.uniform(bxa, bxb), rng.uniform(bya, byb)
                    hw, hh = rng.uniform(0.5, 2.5), rng.uniform(0.5, 2.5)
                    paint.append(_Paint(rows(cy - hh, cy + hh), cols(cx - hw, cx + hw), g + rng.choice([-60.0, 50.0])))
            else:  # parking lot: asphalt, rows of perpendicular stalls 2.7 m x 5 m, 7 m aisles
                paint.append(_Paint(rs, cs, (95, 95, 100)))
                stall_w, stall_d, aisle = 2.7, 5.0, 7.0
                yrow = bya + 1.0
                while yrow + stall_d <= byb - 1.0:
                    paint.append(_Paint(rows(yrow - 0.1, yrow + 0.1), cols(bxa + 1, bxb - 1), MARK_RGB))
                    xl = bxa + 1.0
                    while xl + stall_w <= bxb - 1.0:
                        paint.append(_Paint(rows(yrow, yrow + stall_d), cols(xl - 0.075, xl + 0.075), MARK_RGB))
                        stalls.append((xl + stall_w / 2, yrow + stall_d / 2, 0.5 * math.pi))
                        xl += stall_w
                    paint.append(_Paint(rows(yrow, yrow + stall_d), cols(xl - 0.075, xl + 0.075), MARK_RGB))
                    yrow += stall_d + aisle

    # roads on top: asphalt, solid edge lines, dashed centre line (3 m dash, 6 m gap)
    every_row, every_col = slice(0, ht), slice(0, wt)
    for rx in road_x:
        paint.append(_Paint(every_row, cols(rx - rw / 2, rx + rw / 2), ROAD_RGB))
        for e in (-1, 1):
            paint.append(_Paint(every_row, cols(rx + e * (rw / 2 - 0.45), rx + e * (rw / 2 - 0.25)), MARK_RGB))
    for ry in road_y:
        paint.append(_Paint(rows(ry - rw / 2, ry + rw / 2), every_col, ROAD_RGB))
        for e in (-1, 1):
            paint.append(_Paint(rows(ry + e * (rw / 2 - 0.45), ry + e * (rw / 2 - 0.25)), every_col, MARK_RGB))
    dash = (np.mod(ys, 9.0) < 3.0)
    for rx in road_x:
        paint.append(_Paint(dash, cols(rx - 0.12, rx + 0.12), MARK_RGB))
    dash = (np.mod(xs, 9.0) < 3.0)
    for ry in road_y:
        paint.append(_Paint(rows(ry - 0.12, ry + 0.12), dash, MARK_RGB))
    # intersections: plain asphalt
    for rx in road_x:
        for ry in road_y:
            paint.append(_Paint(rows(ry - rw / 2, ry + rw / 2), cols(rx - rw / 2, rx + rw / 2), ROAD_RGB))

    shade = _multiscale_noise(rng, (ht, wt), texel)
    shade += 1.0
    ground = _paint_ground(paint, shade, xs, ys)
    del shade

    buildings = _place_buildings(spec, block_kinds, (fx0, fy0, fx1, fy1), rng)
    btex = None
    if buildings:
        n = 256
        g = 150 + 40 * _multiscale_noise(rng, (n, n), texel)
        btex = np.clip(np.rint(np.stack([g, g * 0.97, g * 0.92], axis=-1)), 0, 255).astype(np.uint8)
    return World(extent_m=(x0, y0, x1, y1), texel_m=texel, ground_texture=ground, road_x_m=road_x,
                 road_y_m=road_y, road_width_m=rw, buildings=buildings, building_texture=btex, stalls=stalls)


def _place_buildings(spec, block_kinds, footprint, rng: np.random.Generator) -> list[Box]:
    b = spec.world.buildings
    if b.count == 0:
        return []
    fx0, fy0, fx1, fy1 = footprint
    # prefer blocks that the camera sees, so the parallax is on screen
    seen = [rect for kind, rect in block_kinds if kind != "parking"
            and rect[2] > fx0 and rect[0] < fx1 and rect[3] > fy0 and rect[1] < fy1]
    if not seen:
        return []
    out: list[Box] = []
    order = rng.permutation(len(seen))
    for k in range(b.count):
        bxa, bya, bxb, byb = seen[order[k % len(seen)]]
        margin = 2.0
        wmax, hmax = bxb - bxa - 2 * margin, byb - bya - 2 * margin
        if wmax < 2 or hmax < 2:
            continue
        for _attempt in range(10):  # buildings must not intersect: coplanar faces would z-fight
            sx = min(rng.uniform(*b.footprint_range_m), wmax)
            sy = min(rng.uniform(*b.footprint_range_m), hmax)
            cx = rng.uniform(bxa + margin + sx / 2, bxb - margin - sx / 2)
            cy = rng.uniform(bya + margin + sy / 2, byb - margin - sy / 2)
            h = rng.uniform(*b.height_range_m)
            if all(abs(cx - o.centre[0]) > (sx + o.size[0]) / 2 + 1.0
                   or abs(cy - o.centre[1]) > (sy + o.size[1]) / 2 + 1.0 for o in out):
                out.append(Box(centre=(cx, cy, h / 2), size=(sx, sy, h)))
                break
    return out


def vehicle_boxes(length_m: float, width_m: float, height_m: float) -> list[Box]:
    """A car as two boxes in its own frame (x forward, z up): body and a cabin of another shade."""
    hb, hc = 0.55 * height_m, 0.45 * height_m
    return [Box(centre=(0.0, 0.0, hb / 2), size=(length_m, width_m, hb)),
            Box(centre=(-0.08 * length_m, 0.0, hb + hc / 2), size=(0.55 * length_m, 0.88 * width_m, hc))]


def box_mesh(box: Box, *, uv_scale_m: float | None = None) -> dict[str, np.ndarray]:
    """Triangles of a box: 24 vertices (4 per face) so each face has its own normal and UVs.

    UVs, when asked, are the face's two in-plane world coordinates / ``uv_scale_m``
    (a texture repeated at a fixed size in metres).
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


def _snap_to_road(lines: np.ndarray, value: float) -> float:
    return float(lines[np.argmin(np.abs(lines - value))])


MAX_PLACEMENT_TRIES = 25


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


def place_vehicles(spec, world: World, path: CameraPath, rng: np.random.Generator) -> list[VehiclePath]:
    """Put ``spec.vehicles.count`` vehicles on roads (or parking stalls) where the camera will see them.

    Each vehicle is aimed at the view of a random frame: it is at a random point
    of that frame's footprint at that frame's time (turning vehicles start their
    turn there). Moving vehicles keep to the right-hand lane.
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
    lane_m = world.road_width_m / 4
    radius_m = max(6.0, 0.75 * world.road_width_m)
    lo, hi = vs.speed_range_mps
    free_stalls = list(world.stalls)

    def _candidate(i: int, kind: str) -> VehiclePath:
            k = int(rng.integers(0, img.n_frames))
            t_k = k / img.fps
            target = view_centre[k] + rng.uniform(-1, 1, 2) * np.array([half_w_m, half_h_m])
            colour = CAR_COLOURS[int(rng.integers(0, len(CAR_COLOURS)))]
            body = np.asarray(colour, float)
            cabin = body * 0.5 if body.mean() > 90 else body + 90
            common = dict(vehicle_id=i + 1, size_m=(vs.length_m, vs.width_m, vs.height_m),
                          body_rgb=tuple(int(c) for c in body), cabin_rgb=tuple(int(min(255, c)) for c in cabin))
            along_x = bool(rng.integers(0, 2))
            sign = 1.0 if rng.integers(0, 2) else -1.0
            if kind == "parked":
                if free_stalls:
                    d2 = [(sx - target[0]) ** 2 + (sy - target[1]) ** 2 for sx, sy, _ in free_stalls]
                    j = int(np.argmin(d2))
                    sx, sy, th = free_stalls.pop(j)
                    if math.hypot(sx - target[0], sy - target[1]) < 2 * max(half_w_m, half_h_m):
                        th = th if rng.integers(0, 2) else th + math.pi
                        return VehiclePath(kind="parked", p0=np.array([sx, sy]),
                                           d0=np.array([math.cos(th), math.sin(th)]), v0_mps=0.0, **common)
                # roadside parking on the shoulder
                shoulder = world.road_width_m / 2 - vs.width_m / 2 - 0.6
                if along_x:
                    ry = _snap_to_road(world.road_y_m, target[1])
                    d0 = np.array([sign, 0.0])
                    p = np.array([target[0], ry - sign * shoulder])
                else:
                    rx = _snap_to_road(world.road_x_m, target[0])
                    d0 = np.array([0.0, sign])
                    p = np.array([rx + sign * shoulder, target[1]])
                return VehiclePath(kind="parked", p0=p, d0=d0, v0_mps=0.0, **common)
            if along_x:
                d0 = np.array([sign, 0.0])
                ry = _snap_to_road(world.road_y_m, target[1])
                on_lane = np.array([target[0], ry - sign * lane_m])  # right of +x is -y
            else:
                d0 = np.array([0.0, sign])
                rx = _snap_to_road(world.road_x_m, target[0])
                on_lane = np.array([rx + sign * lane_m, target[1]])  # right of +y is +x
            speed_kind = kind if kind in ("accelerating", "stopping") else "constant"
            if speed_kind == "accelerating":
                v0 = rng.uniform(lo, 0.5 * (lo + hi))
            else:
                v0 = rng.uniform(lo, hi)
            vp = VehiclePath(kind=speed_kind, p0=on_lane, d0=d0, v0_mps=float(v0), v_max_mps=float(hi),
                             accel_mps2=vs.acceleration_mps2,
                             # stopping vehicles brake early enough to stand still before the end
                             t_stop_start_s=float(min(rng.uniform(0.1, 0.5) * duration_s,
                                                      max(0.0, duration_s - v0 / vs.acceleration_mps2 - 0.5))),
                             radius_m=radius_m, **common)
            if kind == "turning":
                turn = 1 if rng.integers(0, 2) else -1
                cross = world.road_x_m if along_x else world.road_y_m
                long_target = float(on_lane @ d0)
                cross_long = np.sort(cross * sign)  # road centre coordinates along d0
                ahead = cross_long[cross_long > long_target + radius_m + lane_m]
                if ahead.size:
                    start_long = float(ahead[0]) + turn * lane_m - radius_m
                    on_lane = on_lane + (start_long - long_target) * d0
                    vp.turn = turn
            s_k = vp.distance(t_k)
            vp.p0 = on_lane - s_k * d0
            vp.s_turn_m = s_k
            return vp

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
