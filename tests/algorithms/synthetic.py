"""Synthetic textured frames with exactly known motion, for the flow tests, and the box IoU the detection tests use.

A frame is a sum of random plane waves, evaluated analytically, so any affine
motion, sub-pixel included, is exact: ``frame1(A x) = frame0(x)`` for the
motion ``A`` that maps frame-t points to frame-t+1 points.
"""

from __future__ import annotations

import numpy as np


def wave_texture(rng: np.random.Generator, shape: tuple[int, int], *, motion: np.ndarray | None = None,
                 n_waves: int = 40, max_cycles_per_px: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """Frames t and t+1, ``shape`` float32 in 0..255, of one random texture moved by ``motion``.

    ``motion`` is a (3, 3) affine matrix mapping frame-t points ``(x, y, 1)`` to
    frame-t+1 points (default: identity).
    """
    h, w = shape
    theta = rng.uniform(0, 2 * np.pi, n_waves)
    freq = rng.uniform(0.01, max_cycles_per_px, n_waves)
    k = 2 * np.pi * freq[:, None] * np.stack([np.cos(theta), np.sin(theta)], axis=1)  # (n, 2) rad/px
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    amp = rng.uniform(0.5, 1.0, n_waves)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)

    def render(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        img = np.zeros_like(x)
        for kk, ph, a in zip(k, phase, amp):
            img += a * np.cos(kk[0] * x + kk[1] * y + ph)
        return img

    M = np.eye(3) if motion is None else np.asarray(motion, dtype=np.float64)
    Minv = np.linalg.inv(M)
    x0 = Minv[0, 0] * xs + Minv[0, 1] * ys + Minv[0, 2]
    y0 = Minv[1, 0] * xs + Minv[1, 1] * ys + Minv[1, 2]
    f0, f1 = render(xs, ys), render(x0, y0)
    lo, hi = f0.min(), f0.max()
    scale = 200.0 / (hi - lo)
    return ((f0 - lo) * scale + 25).astype(np.float32), ((f1 - lo) * scale + 25).astype(np.float32)


def translation(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def rotation_about(cx: float, cy: float, degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return translation(cx, cy) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ translation(-cx, -cy)


def affine_field(M: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The exact flow ``M x - x`` at every pixel centre, ``(H, W, 2)``."""
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return np.stack([M[0, 0] * xs + M[0, 1] * ys + M[0, 2] - xs,
                     M[1, 0] * xs + M[1, 1] * ys + M[1, 2] - ys], axis=-1)


def box_iou(d, box) -> float:
    """IoU of a detection's inclusive box (``x0_px .. y1_px``) with an inclusive box ``(x0, y0, x1, y1)``, px."""
    iw = min(d.x1_px, box[2]) - max(d.x0_px, box[0]) + 1
    ih = min(d.y1_px, box[3]) - max(d.y0_px, box[1]) + 1
    if iw <= 0 or ih <= 0:
        return 0.0
    a = (d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1) + (box[2] - box[0] + 1) * (box[3] - box[1] + 1)
    return iw * ih / (a - iw * ih)
