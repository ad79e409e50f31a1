"""How close synthetic footage is to real aerial video: image and scene statistics, synthetic / real.

    python benchmarks/realism.py [SEQ ...] [--frames N] [--seeds S ...] [--real DIR] [--image PNG] [--spectrum PNG]

``SEQ`` is a preset name or a scene YAML (rendered into ``$AEROBENCH_CACHE`` first as it stands:
a preset's own ``image.n_frames``, the sequence ``aerobench render`` and ``run`` make; ``--frames N``
renders N frames instead, which is another world, as the world and its traffic are laid out over
the whole flight's footprint; ``--seeds S ...`` renders it once per seed and pools the worlds, as
one world is a small sample of a preset) or a sequence folder (any: another branch's world, a real clip
written as a sequence folder); default ``realistic``. The real side is the three KIT AIS sequences in
``--real`` (default ``../shared/external/kit_ais`` beside the clone: nadir views of Munich streets, every
vehicle boxed in YOLO format; see ``SOURCES.md`` there).

Statistics (each a small pure function below, tested in ``tests/benchmarks/test_realism.py``):

image, no ground truth needed, per frame on gray levels 0..255 (the median over frames):
  - ``spectrum_slope``: slope of the radially averaged power spectrum in log-log between 1/64
    and 1/4 cycles per pixel (natural images: about -2);
  - ``gradient_median``, ``gradient_p90``: gradient magnitude (central differences), gray levels a px;
  - ``local_contrast``: median over the image of the standard deviation in 15 x 15 windows;
  - ``saturation``: mean HSV saturation ``(max - min) / max`` of the RGB frame;
  - ``noise_sigma``: Immerkaer's (1996) second-difference mask, ``sqrt(pi / 2)`` x the mean absolute
    response / 6, over the flatter half of the image (gray levels);
  - ``blockiness``: mean absolute difference across the 8 x 8 block boundaries over the mean
    inside the blocks (1 = none; JPEG / H.264 blocking raises it);
scene, from the boxes (KIT AIS labels; synthetic ``tracks.csv``, visible motor vehicles: ``MOTOR_CLASSES``,
as KIT AIS boxes no pedestrian and these frames no cyclist):
  - ``vehicles_per_mpx``: vehicles in view per megapixel;
  - ``moving_fraction``: synthetic: vehicles faster than ``MOVING_SPEED_MPS`` over the ground (a car
    stopped in a queue is not moving, as on the real side); real: of the boxes matched to a box of the
    next frame after registering the two frames by their global shift (phase correlation of the
    whole frames, refined by ECC where it stays within half a pixel of it), those whose residual displacement exceeds ``MOVING_THRESHOLD_PX`` (3 px at the
    real frames' own scale: the boxes' own jitter is 1-2 px);
  - ``vehicle_length_px``: median of the longer box side;
  - ``speed_px_per_frame``: median displacement of moving vehicles relative to the ground (synthetic:
    the track minus the camera's global shift; real: the residual of the matched boxes). Printed, not
    compared (``NOT_COMPARABLE``): KIT AIS does not give its frame interval.

Compared at the same vehicle size: every sequence (each synthetic one, and the real side as one) is
scaled down (``cv2.INTER_AREA``) until its median vehicle is as long as the shortest median among
them, and the size-dependent statistics (spectrum,
gradients, local contrast, saturation, vehicles per megapixel, speeds) are computed on the scaled
frames; noise and blockiness belong to the pixel grid of the sensor and its codec and are measured
at each side's own resolution. Each statistic is reported as synthetic / real with PASS when the
ratio lies within +/-25 % (``TOLERANCE``); with several sequences, each one's ratios alone follow
(the same real frames, the same common size). Then the real sequences' own moving fractions (how
much the statistic varies from one street to the next), and the power spectrum by octave of
wavelength at the common size, synthetic / real (where the slope's difference comes from). A
side-by-side crop (synthetic left, real right, at the matched scale) is written to ``--image``
for people, and with ``--spectrum`` a plot of the radially averaged spectra, at the common size
and at each side's own pixels.

Figures before and after issue 22's look and traffic work, and why each failing statistic fails:
``docs/realism.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TOLERANCE = 0.25
MOVING_THRESHOLD_PX = 3.0
# synthetic road users counted as vehicles: the classes the KIT AIS frames box (all their 2593 boxes are
# cars, buses and minibuses; no cyclist, and pedestrians are not a class there)
MOTOR_CLASSES = ("car", "van", "truck", "bus", "motorbike")
# a synthetic vehicle moves when its speed over the ground exceeds this: the real side calls a box moving
# when it moved over MOVING_THRESHOLD_PX between frames, which stopped cars in a queue do not; traffic's
# vehicles are mostly stopped (0) or under way (several m/s): at 0.5 / 1 / 2 m/s realistic's fraction is
# 0.14 / 0.13 / 0.10 and city's 0.11 / 0.09 / 0.09 (20 frames each, GENERATOR_VERSION 2.3.0)
MOVING_SPEED_MPS = 1.0
# statistics that cannot be compared, and why (printed with the table, never a PASS or FAIL)
NOT_COMPARABLE = {
    "speed_px_per_frame": "KIT AIS gives no frame interval: its px a frame are px per unknown seconds "
                          "(synthetic movers' median speed over the ground is printed in m/s instead)",
}
MATCH_GATE_PX = 25.0
KIT_AIS = Path(__file__).resolve().parents[2] / "shared" / "external" / "kit_ais"  # shared/ beside the clone
SPECTRUM_BAND_CYCLES_PER_PX = (1.0 / 64.0, 0.25)
# octave bands of wavelength, px at the common vehicle size, for the spectrum's power side by side
BANDS_PX = (2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0)
SPECTRUM_RINGS = np.geomspace(1.0 / 256.0, 0.5, 41)  # rings of the plotted spectrum, cycles per pixel
CONTRAST_WINDOW_PX = 15
BLOCK_PX = 8


# --------------------------------------------------------------------------- image statistics


def as_gray(img: np.ndarray) -> np.ndarray:
    """(H, W) float64 gray levels 0..255 of a (H, W) or (H, W, 3) RGB image (BT.601 weights)."""
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 3:
        return img.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    if img.ndim == 2:
        return img.astype(np.float64)
    raise ValueError(f"expected an (H, W) or (H, W, 3) image, got shape {img.shape}")


def power_spectrum(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power spectrum of a gray image under a Hann window: radial frequency and power of every bin.

    Parameters
    ----------
    gray : (H, W) float, gray levels; H, W >= 32

    Returns
    -------
    f : (H * W,) float64, cycles per pixel (0 .. 0.707)
    P : (H * W,) float64, ``|FFT|^2`` of the windowed, mean-free image over the window's energy
        (gray levels^2 per bin: images of other sizes compare)
    """
    g = np.asarray(gray, np.float64)
    if g.ndim != 2 or min(g.shape) < 32:
        raise ValueError(f"power_spectrum: expected an (H, W) image with H, W >= 32, got shape {g.shape}")
    h, w = g.shape
    win = np.outer(np.hanning(h), np.hanning(w))
    P = np.abs(np.fft.fft2((g - g.mean()) * win)) ** 2 / np.sum(win ** 2)
    f = np.hypot(np.fft.fftfreq(h)[:, None], np.fft.fftfreq(w)[None, :])
    return f.ravel(), P.ravel()


def radial_average(f: np.ndarray, P: np.ndarray, edges_cycles_per_px: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Mean frequency and mean power in each ring ``[edges[k], edges[k+1])`` (NaN for an empty ring)."""
    edges = np.asarray(edges_cycles_per_px, np.float64)
    which = np.digitize(f, edges) - 1
    ok = (which >= 0) & (which < len(edges) - 1)
    n = len(edges) - 1
    counts = np.bincount(which[ok], minlength=n).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        fm = np.bincount(which[ok], weights=f[ok], minlength=n) / counts
        pm = np.bincount(which[ok], weights=P[ok], minlength=n) / counts
    return fm, pm


def spectrum_slope(gray: np.ndarray, *, band_cycles_per_px: tuple[float, float] = SPECTRUM_BAND_CYCLES_PER_PX
                   ) -> float:
    """Slope of the radially averaged power spectrum ``P(f)`` against ``f`` in log-log.

    Parameters
    ----------
    gray : (H, W) float, gray levels; H, W >= 32
    band_cycles_per_px : (f_lo, f_hi), the frequencies fitted, cycles per pixel (below 1/64 the
        Hann window's leakage, above 1/4 noise and compression dominate)

    Returns
    -------
    float, the least-squares slope of ``log P`` on ``log f`` over the band (1/f^2 power: -2).
    """
    g = np.asarray(gray, np.float64)
    if g.ndim != 2 or min(g.shape) < 32:
        raise ValueError(f"spectrum_slope: expected an (H, W) image with H, W >= 32, got shape {g.shape}")
    return slope_of(*power_spectrum(g), band_cycles_per_px=band_cycles_per_px)


def slope_of(f: np.ndarray, P: np.ndarray, *, band_cycles_per_px: tuple[float, float] = SPECTRUM_BAND_CYCLES_PER_PX
             ) -> float:
    """:func:`spectrum_slope` of a spectrum from :func:`power_spectrum`: 24 log-spaced rings over the
    band (every octave weighs the same in the fit)."""
    lo, hi = band_cycles_per_px
    fm, pm = radial_average(f, P, np.geomspace(lo, hi, 25))
    keep = np.isfinite(pm) & (pm > 0)
    slope, _ = np.polyfit(np.log(fm[keep]), np.log(pm[keep]), 1)
    return float(slope)


def band_powers(f: np.ndarray, P: np.ndarray, *, bands_px: tuple[float, ...] = BANDS_PX) -> np.ndarray:
    """Mean power in octave bands of wavelength: ``bands_px[k] <= 1 / f < bands_px[k + 1]`` px, (len - 1,)."""
    edges = 1.0 / np.asarray(bands_px, np.float64)[::-1]
    return radial_average(f, P, edges)[1][::-1]


def gradient_magnitude(gray: np.ndarray) -> np.ndarray:
    """(H-2, W-2) float64 |grad I| by central differences, gray levels per pixel."""
    g = np.asarray(gray, np.float64)
    gx = 0.5 * (g[1:-1, 2:] - g[1:-1, :-2])
    gy = 0.5 * (g[2:, 1:-1] - g[:-2, 1:-1])
    return np.hypot(gx, gy)


def gradient_stats(gray: np.ndarray) -> tuple[float, float]:
    """(median, 90th percentile) of the gradient magnitude, gray levels per pixel."""
    m = gradient_magnitude(gray)
    return float(np.median(m)), float(np.percentile(m, 90))


def local_contrast(gray: np.ndarray, *, window_px: int = CONTRAST_WINDOW_PX) -> float:
    """Median over the image of the standard deviation of gray levels in ``window_px`` square windows."""
    if window_px < 2:
        raise ValueError(f"local_contrast: window_px expected >= 2, got {window_px}")
    g = np.asarray(gray, np.float32)
    mean = cv2.blur(g, (window_px, window_px), borderType=cv2.BORDER_REFLECT)
    sq = cv2.blur(g * g, (window_px, window_px), borderType=cv2.BORDER_REFLECT)
    var = np.maximum(sq.astype(np.float64) - mean.astype(np.float64) ** 2, 0.0)
    r = window_px // 2
    return float(np.median(np.sqrt(var[r:-r or None, r:-r or None])))


def saturation(rgb: np.ndarray) -> float:
    """Mean HSV saturation ``(max - min) / max`` of an (H, W, 3) RGB image (0 where max = 0), 0..1."""
    a = np.asarray(rgb, np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"saturation: expected an (H, W, 3) RGB image, got shape {a.shape}")
    mx, mn = a.max(axis=2), a.min(axis=2)
    s = np.divide(mx - mn, mx, out=np.zeros_like(mx), where=mx > 0)
    return float(s.mean())


# the mask of Immerkaer (1996), "Fast noise variance estimation": the difference of two Laplacians;
# it cancels every linear ramp, and white noise of std sigma comes out with std 6 sigma
IMMERKAER_MASK = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)


def noise_sigma(gray: np.ndarray, *, flat_fraction: float = 0.5) -> float:
    """Standard deviation of white noise in an image, gray levels (a robust Immerkaer estimate).

    The mask's response ``r`` is taken where the image is flattest (the ``flat_fraction`` of
    pixels with the smallest gradient, edges and texture excluded) and turned into a sigma as
    Immerkaer does, ``sqrt(pi / 2) mean|r| / 6`` (a median of ``|r|`` would be robust too, but on
    8-bit frames it moves in steps of a quarter gray level). On real footage texture finer than
    the mask counts as noise.
    """
    g = np.asarray(gray, np.float64)
    if g.ndim != 2 or min(g.shape) < 8:
        raise ValueError(f"noise_sigma: expected an (H, W) image with H, W >= 8, got shape {g.shape}")
    if not 0 < flat_fraction <= 1:
        raise ValueError(f"noise_sigma: flat_fraction expected in (0, 1], got {flat_fraction}")
    r = cv2.filter2D(g, cv2.CV_64F, IMMERKAER_MASK, borderType=cv2.BORDER_REFLECT)[2:-2, 2:-2]
    smooth = cv2.GaussianBlur(g, (0, 0), 2.0)
    grad = gradient_magnitude(smooth)[1:-1, 1:-1]
    flat = grad <= np.quantile(grad, flat_fraction)
    return float(np.sqrt(np.pi / 2) * np.abs(r[flat]).mean() / 6.0)


def blockiness(gray: np.ndarray, *, block_px: int = BLOCK_PX) -> float:
    """Mean |difference| of neighbours across block boundaries over the mean inside blocks (1 = none).

    Horizontal and vertical neighbours together; the grid starts at pixel 0 (as JPEG and H.264 place it).
    """
    g = np.asarray(gray, np.float64)
    if g.ndim != 2 or min(g.shape) < 2 * block_px:
        raise ValueError(f"blockiness: expected an (H, W) image of at least {2 * block_px} px a side, "
                         f"got shape {g.shape}")
    dx = np.abs(np.diff(g, axis=1))  # dx[:, j] = |I[:, j+1] - I[:, j]|: across a boundary when j+1 % 8 == 0
    dy = np.abs(np.diff(g, axis=0))
    bx = (np.arange(dx.shape[1]) + 1) % block_px == 0
    by = (np.arange(dy.shape[0]) + 1) % block_px == 0
    across = np.concatenate([dx[:, bx].ravel(), dy[by, :].ravel()])
    inside = np.concatenate([dx[:, ~bx].ravel(), dy[~by, :].ravel()])
    return float(across.mean() / max(inside.mean(), 1e-9))


# --------------------------------------------------------------------------- scene statistics


ECC_MAX_STEP_PX = 0.5


def global_shift_px(gray0: np.ndarray, gray1: np.ndarray) -> tuple[float, float]:
    """(dx, dy) px that frame 1 is moved by relative to frame 0: a ground point at p in frame 0 is at
    p + (dx, dy) in frame 1.

    Phase correlation (Hann window), refined by ECC for a translation (Evangelidis and Psarakis
    2008) when ECC converges within ``ECC_MAX_STEP_PX`` of it: phase correlation's sub-pixel peak
    is off by up to half a pixel on smooth texture, and ECC alone locks onto lane markings a
    period away on some KIT AIS frames (2-3 px off on MunichStreet02).
    """
    a = np.asarray(gray0, np.float32)
    b = np.asarray(gray1, np.float32)
    win = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, win)
    warp = np.float32([[1, 0, dx], [0, 1, dy]])
    try:
        _, warp = cv2.findTransformECC(a, b, warp, cv2.MOTION_TRANSLATION,
                                       (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4), None, 5)
    except cv2.error:
        return float(dx), float(dy)
    ex, ey = float(warp[0, 2]), float(warp[1, 2])
    if np.hypot(ex - dx, ey - dy) > ECC_MAX_STEP_PX:
        return float(dx), float(dy)
    return ex, ey


def match_boxes(c0: np.ndarray, c1: np.ndarray, shift_px: tuple[float, float], *,
                gate_px: float = MATCH_GATE_PX) -> list[tuple[int, int, float]]:
    """Mutual nearest neighbours between box centres of two frames after the global shift.

    Parameters
    ----------
    c0 : (N, 2), c1 : (M, 2) float, box centres (x, y) px in frame 0 and frame 1
    shift_px : (dx, dy), the ground's motion from frame 0 to frame 1
    gate_px : pairs farther apart than this (after the shift) are not matched

    Returns
    -------
    list of (i, j, residual_px): box i of frame 0 is box j of frame 1, moved ``residual_px``
    relative to the ground.
    """
    c0 = np.asarray(c0, np.float64).reshape(-1, 2)
    c1 = np.asarray(c1, np.float64).reshape(-1, 2)
    if not len(c0) or not len(c1):
        return []
    d = np.linalg.norm(c0[:, None, :] + np.asarray(shift_px)[None, None, :] - c1[None, :, :], axis=2)
    best1, best0 = d.argmin(axis=1), d.argmin(axis=0)
    return [(i, int(j), float(d[i, j])) for i, j in enumerate(best1) if best0[j] == i and d[i, j] <= gate_px]


@dataclass
class SceneBoxes:
    """The vehicles of one frame: centres (N, 2) and sizes (N, 2) = (w, h) px.

    ``moving`` (N,) bool where ``moving_known`` (N,) bool (a real box matched in the next frame),
    None when nothing is known; ``speeds_px`` the moving vehicles' displacement to the next frame
    relative to the ground, px.
    """

    centres: np.ndarray
    sizes: np.ndarray
    moving: np.ndarray | None = None
    moving_known: np.ndarray | None = None
    speeds_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    speeds_mps: np.ndarray = field(default_factory=lambda: np.zeros(0))


def read_yolo_boxes(path: Path, width_px: int, height_px: int) -> SceneBoxes:
    """Boxes of a YOLO label file (``class cx cy w h`` as fractions of the image) in pixels."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    a = np.array([[float(v) for v in r[1:5]] for r in rows], np.float64).reshape(-1, 4)
    scale = np.array([width_px, height_px])
    return SceneBoxes(centres=a[:, :2] * scale, sizes=a[:, 2:4] * scale)


# --------------------------------------------------------------------------- the two sides


@dataclass
class Side:
    """Frames (RGB uint8) and their boxes, of one side (synthetic or real)."""

    name: str
    frames: list[np.ndarray]
    boxes: list[SceneBoxes]


def real_side(root: Path) -> list[Side]:
    """The KIT AIS sequences under ``root``: frames in name order, boxes, and motion from box matching."""
    import re

    sides = []
    for seq in sorted(p for p in root.iterdir() if p.is_dir()):
        pngs = sorted(seq.glob("*.png"), key=lambda p: int(re.findall(r"(\d+)\.png$", p.name)[0]))
        if not pngs:
            continue
        frames, boxes = [], []
        for png in pngs:
            bgr = cv2.imread(str(png), cv2.IMREAD_COLOR)
            if bgr is None:
                raise SystemExit(f"{png}: cannot be read as an image")
            rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            frames.append(rgb)
            label = png.with_suffix(".txt")
            boxes.append(read_yolo_boxes(label, rgb.shape[1], rgb.shape[0]) if label.is_file()
                         else SceneBoxes(np.zeros((0, 2)), np.zeros((0, 2))))
        for k in range(len(frames) - 1):
            shift = global_shift_px(as_gray(frames[k]), as_gray(frames[k + 1]))
            pairs = match_boxes(boxes[k].centres, boxes[k + 1].centres, shift)
            moving = np.full(len(boxes[k].centres), False)
            known = np.full(len(boxes[k].centres), False)
            speeds = []
            for i, _, res in pairs:
                known[i] = True
                moving[i] = res > MOVING_THRESHOLD_PX
                if moving[i]:
                    speeds.append(res)
            boxes[k].moving, boxes[k].moving_known = moving, known
            boxes[k].speeds_px = np.asarray(speeds)
        sides.append(Side(seq.name, frames, boxes))
    if not sides:
        raise SystemExit(f"--real {root}: no sequence folders with PNG frames")
    return sides


def synthetic_sides(arg: str, frames: int | None = None, seeds: list[int] | None = None) -> Side:
    """:func:`synthetic_side` of ``arg`` once per seed (``seeds`` None: its own), pooled into one side.

    One world is a small sample: a preset's saturation and vehicle density change by factors of
    1.5-3, its moving fraction by up to 25, from one seed to another (``docs/realism.md``); pooled
    over several seeds the statistics describe the preset, not one of its worlds. A sequence folder
    takes no seeds.
    """
    if not seeds or Path(arg).is_dir():
        return synthetic_side(arg, frames)
    parts = [synthetic_side(arg, frames, seed=s) for s in seeds]
    return Side(f"{Path(arg).stem} seeds {', '.join(str(s) for s in seeds)}",
                [f for p in parts for f in p.frames], [b for p in parts for b in p.boxes])


def synthetic_side(arg: str, frames: int | None = None, *, seed: int | None = None) -> Side:
    """A sequence folder, or a preset / scene YAML rendered into the cache first.

    ``frames`` None renders the spec as it stands (a preset's own ``image.n_frames``: the sequence
    ``aerobench render`` and ``run`` make, from the same cache); a number renders that many frames
    instead, which is another scene (the world and its traffic are laid out over the whole
    flight's footprint), and reads at most that many of a folder.
    """
    from scenes import cached_sequence, load_scene_spec
    from scenes.sequence import Sequence

    path = Path(arg)
    if not (path.is_dir() and (path / "frames").is_dir()):
        overrides = {} if frames is None else {"image.n_frames": frames}
        if seed is not None:
            overrides["seed"] = seed
        spec = load_scene_spec(arg, overrides)
        cache = Path(os.environ.get("AEROBENCH_CACHE", Path.home() / ".cache" / "aerobench"))
        path = cached_sequence(spec, cache)
    seq = Sequence(path)
    n = len(seq) if frames is None else min(len(seq), frames)
    imgs = [seq.frame(i) for i in range(n)]
    boxes = []
    tracks = seq.tracks if (path / "tracks.csv").is_file() else None
    cam = seq.camera if (path / "camera.csv").is_file() else None
    for i in range(n):
        if tracks is None:
            boxes.append(SceneBoxes(np.zeros((0, 2)), np.zeros((0, 2))))
            continue
        t = tracks[tracks["frame"] == i]
        if "visible" in t:  # real footage's annotations may not say
            t = t[t["visible"] > 0]
        if "class" in t:
            t = t[t["class"].isin(MOTOR_CLASSES)]
        if not {"bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"} <= set(t.columns):
            boxes.append(SceneBoxes(t[["x_px", "y_px"]].to_numpy(float), np.full((len(t), 2), np.nan)))
            continue
        x0, y0, x1, y1 = (t[c].to_numpy(float) for c in ("bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"))
        # boxes are continuous (pixel-centre coordinates): their size is x1 - x0
        b = SceneBoxes(centres=t[["x_px", "y_px"]].to_numpy(float), sizes=np.column_stack([x1 - x0, y1 - y0]))
        if "speed_mps" in t:
            speed = t["speed_mps"].to_numpy(float)
            b.moving, b.moving_known = speed > MOVING_SPEED_MPS, np.isfinite(speed)
            b.speeds_mps = speed[b.moving & b.moving_known]
        elif "parked" in t:
            b.moving, b.moving_known = t["parked"].to_numpy(int) == 0, np.full(len(t), True)
        if cam is not None and i + 1 < n and b.moving is not None:
            nxt = tracks[tracks["frame"] == i + 1].set_index("vehicle_id")
            row = cam[cam["frame"] == i].iloc[0]
            g = np.array([row["global_dx_px"], row["global_dy_px"]], float)
            sp = []
            for vid, x, y, mv in zip(t["vehicle_id"], t["x_px"], t["y_px"], b.moving):
                if mv and vid in nxt.index and nxt.loc[vid].get("visible", 1) > 0:
                    sp.append(float(np.hypot(nxt.loc[vid, "x_px"] - x - g[0], nxt.loc[vid, "y_px"] - y - g[1])))
            b.speeds_px = np.asarray(sp)
        boxes.append(b)
    return Side(path.name, imgs, boxes)


def median_length_px(sides: list[Side]) -> float:
    """Median of the longer box side over every box of ``sides``, px (NaN without boxes)."""
    lengths = np.concatenate([b.sizes.max(axis=1) for s in sides for b in s.boxes if len(b.sizes)] or [np.zeros(0)])
    lengths = lengths[np.isfinite(lengths)]
    return float(np.median(lengths)) if lengths.size else float("nan")


def scaled(img: np.ndarray, s: float) -> np.ndarray:
    if s == 1.0:
        return img
    h, w = img.shape[:2]
    return cv2.resize(img, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)


def side_statistics(sides: list[Side], scale: float | list[float], *, native_spectrum: bool = False) -> dict:
    """Every statistic of one side; ``scale`` the factor its frames are resized by to match vehicle size
    (one for all its sequences, or one per sequence).

    The statistics are floats (medians over frames, or counts over all of them); besides them
    ``band_power`` (len(BANDS_PX) - 1,) is the mean power in each octave band of wavelength at the
    common size and ``spectrum_f``, ``spectrum_P`` the radially averaged spectrum there
    (``SPECTRUM_RINGS``), both geometric means over frames; with ``native_spectrum`` also
    ``native_f``, ``native_P`` at each frame's own pixels.
    """
    scales = list(scale) if isinstance(scale, (list, tuple)) else [scale] * len(sides)
    if len(scales) != len(sides):
        raise ValueError(f"side_statistics: expected one scale per sequence ({len(sides)}), got {len(scales)}")
    per: dict[str, list[float]] = {k: [] for k in ("spectrum_slope", "gradient_median", "gradient_p90",
                                                   "local_contrast", "saturation", "noise_sigma", "blockiness")}
    n_boxes, mpx, moving, known, lengths, speeds, speeds_mps = 0, 0.0, 0, 0, [], [], []
    bands, rings, native = [], [], []
    for side, scale in zip(sides, scales):
        for img, b in zip(side.frames, side.boxes):
            small = scaled(img, scale)
            g_small, g_native = as_gray(small), as_gray(img)
            f, P = power_spectrum(g_small)
            per["spectrum_slope"].append(slope_of(f, P))
            bands.append(band_powers(f, P))
            rings.append(radial_average(f, P, SPECTRUM_RINGS))
            if native_spectrum:
                native.append(radial_average(*power_spectrum(g_native), SPECTRUM_RINGS))
            med, p90 = gradient_stats(g_small)
            per["gradient_median"].append(med)
            per["gradient_p90"].append(p90)
            per["local_contrast"].append(local_contrast(g_small))
            per["saturation"].append(saturation(small))
            per["noise_sigma"].append(noise_sigma(g_native))
            per["blockiness"].append(blockiness(g_native))
            n_boxes += len(b.centres)
            mpx += small.shape[0] * small.shape[1] / 1e6
            if len(b.sizes) and np.isfinite(b.sizes).all():
                lengths.append(b.sizes.max(axis=1) * scale)
            if b.moving is not None:
                k = b.moving_known
                moving += int(b.moving[k].sum())
                known += int(k.sum())
            speeds.append(np.asarray(b.speeds_px) * scale)
            speeds_mps.append(np.asarray(b.speeds_mps))
    out = {k: float(np.median(v)) for k, v in per.items()}
    out["vehicles_per_mpx"] = n_boxes / mpx if mpx else float("nan")
    out["moving_fraction"] = moving / known if known else float("nan")
    out["vehicle_length_px"] = float(np.median(np.concatenate(lengths))) if lengths else float("nan")
    sp = np.concatenate(speeds) if speeds else np.zeros(0)
    out["speed_px_per_frame"] = float(np.median(sp)) if sp.size else float("nan")
    sm = np.concatenate(speeds_mps) if speeds_mps else np.zeros(0)
    out["speed_mps"] = float(np.median(sm)) if sm.size else float("nan")  # printed, not compared

    def geomean(rows):  # over frames, column by column; NaN where no frame has a value (a ring too wide)
        if not len(rows):
            return np.zeros(0)
        with np.errstate(divide="ignore", invalid="ignore"):
            logs = np.log(np.asarray(rows, np.float64))
            ok = np.isfinite(logs)
            return np.exp(np.where(ok, logs, 0.0).sum(axis=0) / ok.sum(axis=0))

    out["band_power"] = geomean(bands)
    out["spectrum_f"], out["spectrum_P"] = (geomean([r[0] for r in rings]), geomean([r[1] for r in rings]))
    if native_spectrum:
        out["native_f"], out["native_P"] = geomean([r[0] for r in native]), geomean([r[1] for r in native])
    return out


UNITS = {"spectrum_slope": "", "gradient_median": "gray/px", "gradient_p90": "gray/px", "local_contrast": "gray",
         "saturation": "0..1", "noise_sigma": "gray", "blockiness": "ratio", "vehicles_per_mpx": "1/Mpx",
         "moving_fraction": "0..1", "vehicle_length_px": "px", "speed_px_per_frame": "px/frame"}


def verdict(ratio: float, *, tolerance: float = TOLERANCE) -> str:
    """PASS when ``ratio`` (synthetic / real) is within ``1 +/- tolerance``; n/a when not a number."""
    if not np.isfinite(ratio):
        return "n/a"
    return "PASS" if abs(ratio - 1.0) <= tolerance else "FAIL"


def side_by_side(synthetic: np.ndarray, real: np.ndarray, *, crop_px: int = 256,
                 centres: tuple[np.ndarray | None, np.ndarray | None] = (None, None)) -> np.ndarray:
    """Square crops of the two images (``crop_px`` or smaller), next to each other with a white gap.

    Each crop is centred on the median of that image's vehicle ``centres`` (N, 2) px when given
    (so that vehicles of the same size stand side by side), else on the image centre.
    """
    def crop(img, c):
        h, w = img.shape[:2]
        n = min(crop_px, h, w)
        cx, cy = (np.median(c, axis=0) if c is not None and len(c) else (w / 2, h / 2))
        x = int(np.clip(round(cx - n / 2), 0, w - n))
        y = int(np.clip(round(cy - n / 2), 0, h - n))
        return img[y:y + n, x:x + n]

    a, b = crop(synthetic, centres[0]), crop(real, centres[1])
    h = max(a.shape[0], b.shape[0])
    canvas = np.full((h, a.shape[1] + 8 + b.shape[1], 3), 255, np.uint8)
    canvas[:a.shape[0], :a.shape[1]] = a
    canvas[:b.shape[0], a.shape[1] + 8:] = b
    return canvas


def moving_fraction(sides: list[Side]) -> float:
    """Moving vehicles over vehicles whose motion is known, all frames of ``sides`` together (NaN: none known)."""
    moving = known = 0
    for side in sides:
        for b in side.boxes:
            if b.moving is not None:
                moving += int(b.moving[b.moving_known].sum())
                known += int(b.moving_known.sum())
    return moving / known if known else float("nan")


def plot_spectra(path: str, real: dict, synthetic: list[dict], labels: list[str], *, target_px: float,
                 lengths_px: tuple[float, list[float]]) -> None:
    """Radially averaged spectra of the real side and of each synthetic sequence, written to ``path`` (PNG).

    Power times ``f^2`` (flat for a 1/f^2 spectrum), normalised at one cycle per vehicle length,
    against cycles per median vehicle length: solid at the common vehicle size (what the statistics
    see; the fitted band shaded), dashed at each side's own pixels.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    L_real, L_synth = lengths_px
    for name, st, L, ls_colour in [("KIT AIS", real, L_real, "k")] + [
            (lab, st, L, None) for lab, st, L in zip(labels, synthetic, L_synth)]:
        for key_f, key_P, length, style in (("spectrum_f", "spectrum_P", target_px, "-"),
                                            ("native_f", "native_P", L, "--")):
            if key_f not in st:
                continue
            f, P = st[key_f], st[key_P]
            ok = np.isfinite(f) & np.isfinite(P) & (P > 0)
            fv = f[ok] * length
            y = P[ok] * f[ok] ** 2
            y = y / np.exp(np.interp(0.0, np.log(fv), np.log(y)))
            line = ax.loglog(fv, y, style, color=ls_colour,
                             label=f"{name}, {'common size' if style == '-' else 'own pixels'}")[0]
            ls_colour = ls_colour or line.get_color()
        ls_colour = None
    lo, hi = SPECTRUM_BAND_CYCLES_PER_PX
    ax.axvspan(lo * target_px, hi * target_px, alpha=0.08, label="slope fitted (common size)")
    ax.set_xlabel("cycles per median vehicle length")
    ax.set_ylabel("P(f) f^2, 1 at one cycle per vehicle")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequences", nargs="*", default=["realistic"],
                    help="presets, scene YAML files or sequence folders (default: realistic)")
    ap.add_argument("--frames", type=int, default=None,
                    help="render each preset or YAML with this many frames instead of its own image.n_frames "
                         "(another world: it is laid out over the flight's footprint)")
    ap.add_argument("--spectrum", default=None, help="also plot the radially averaged power spectra here, PNG")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="render each preset or YAML once per seed and pool them (default: its own seed)")
    ap.add_argument("--real", default=str(KIT_AIS), help="folder of KIT AIS sequences (default %(default)s)")
    ap.add_argument("--image", default="realism_side_by_side.png", help="the side-by-side crop, PNG")
    args = ap.parse_args(argv)
    if args.frames is not None and args.frames < 2:
        ap.error(f"--frames: expected at least 2, got {args.frames}")
    real_root = Path(args.real)
    if not real_root.is_dir():
        ap.error(f"--real: {real_root}: no such folder")
    real = real_side(real_root)
    synth = [synthetic_sides(s, args.frames, args.seeds) for s in args.sequences]
    # every sequence, synthetic and real, is scaled down to the smallest median vehicle among them (one
    # factor for the whole real side: its three sequences share a camera); sequences at other ground
    # sampling distances are so compared at the same vehicle size each, not at a pooled median
    L_each = [median_length_px([s]) for s in synth]
    L_r = median_length_px(real)
    target = min([v for v in L_each + [L_r] if np.isfinite(v)] or [1.0])
    s_each = [min(1.0, target / v) if np.isfinite(v) else 1.0 for v in L_each]
    s_real = min(1.0, target / L_r) if np.isfinite(L_r) else 1.0
    stats_s = side_statistics(synth, s_each, native_spectrum=args.spectrum is not None)
    stats_r = side_statistics(real, s_real, native_spectrum=args.spectrum is not None)
    labels = [Path(a).stem if a.endswith((".yaml", ".yml")) else Path(a).name for a in args.sequences]
    each = ([side_statistics([s], [f], native_spectrum=args.spectrum is not None) for s, f in zip(synth, s_each)]
            if len(synth) > 1 else [stats_s])
    for s, v, f in zip(synth, L_each, s_each):
        print(f"synthetic: {s.name} ({len(s.frames)} frames), median vehicle {v:.1f} px, scaled by {f:.3f}")
    print(f"real: KIT AIS {', '.join(s.name for s in real)} ({sum(len(s.frames) for s in real)} frames), median "
          f"vehicle {L_r:.1f} px, scaled by {s_real:.3f}")
    print(f"compared at the same median vehicle length ({target:.1f} px); noise_sigma and blockiness at each "
          f"side's own resolution")
    print()
    print(f"| statistic | unit | synthetic | real | synthetic / real | within +/-{TOLERANCE:.0%} |")
    print("|---|---|---|---|---|---|")
    failed, scored = [], 0
    for k in UNITS:
        a, b = stats_s[k], stats_r[k]
        ratio = a / b if np.isfinite(a) and np.isfinite(b) and b != 0 else float("nan")
        v = "not comparable" if k in NOT_COMPARABLE else verdict(ratio)
        scored += k not in NOT_COMPARABLE
        if v == "FAIL":
            failed.append(k)
        print(f"| {k} | {UNITS[k]} | {a:.3f} | {b:.3f} | {ratio:.3f} | {v} |")
    print()
    print(f"{scored - len(failed)} of {scored} comparable statistics within +/-{TOLERANCE:.0%}"
          + (f"; failing: {', '.join(failed)}" if failed else ""))
    for k, why in NOT_COMPARABLE.items():
        print(f"not comparable: {k}: {why}")
    print(f"synthetic moving vehicles' median speed over the ground: {stats_s['speed_mps']:.1f} m/s "
          f"({MOTOR_CLASSES} over {MOVING_SPEED_MPS} m/s)")
    if len(synth) > 1:
        print()
        print("each synthetic sequence alone, against the same real frames at the same vehicle size "
              "(synthetic / real):")
        print()
        print("| statistic | real | " + " | ".join(labels) + " |")
        print("|---|---|" + "---|" * len(labels))
        for k in UNITS:
            b = stats_r[k]
            cells = [f"{e[k] / b:.3f} {'n/c' if k in NOT_COMPARABLE else verdict(e[k] / b)}"
                     if np.isfinite(e[k]) and np.isfinite(b) and b else "n/a" for e in each]
            print(f"| {k} | {b:.3f} | " + " | ".join(cells) + " |")
    print()
    print("the real sequences' own moving fractions: " + ", ".join(
        f"{s.name} {moving_fraction([s]):.3f}" for s in real) + " (the spread one street to the next)")
    print()
    print(f"power spectrum by octave of wavelength at the common size (px; a vehicle is {target:.1f} px), "
          "geometric mean over frames, synthetic / real:")
    print()
    print("| wavelength px | vehicle lengths | real power | " + " | ".join(labels if len(synth) > 1 else ["synthetic"])
          + (" | pooled |" if len(synth) > 1 else " |"))
    print("|---|---|---|" + "---|" * (len(labels) + (len(synth) > 1) if len(synth) > 1 else 1))
    for k in range(len(BANDS_PX) - 1):
        lo, hi = BANDS_PX[k], BANDS_PX[k + 1]
        pr = stats_r["band_power"][k]
        cells = [f"{e['band_power'][k] / pr:.2f}" for e in each] + ([f"{stats_s['band_power'][k] / pr:.2f}"]
                                                                     if len(synth) > 1 else [])
        print(f"| {lo:g}-{hi:g} | {lo / target:.2f}-{hi / target:.2f} | {pr:.3g} | " + " | ".join(cells) + " |")
    if args.spectrum:
        plot_spectra(args.spectrum, stats_r, each, labels, target_px=target,
                     lengths_px=(L_r, L_each))
        print(f"spectra (power x f^2 against cycles per vehicle length): {args.spectrum}")
    pic = side_by_side(scaled(synth[0].frames[0], s_each[0]), scaled(real[0].frames[0], s_real),
                       centres=(synth[0].boxes[0].centres * s_each[0], real[0].boxes[0].centres * s_real))
    cv2.imwrite(args.image, cv2.cvtColor(pic, cv2.COLOR_RGB2BGR))
    print(f"side by side (synthetic left, real right, same vehicle size): {args.image}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
