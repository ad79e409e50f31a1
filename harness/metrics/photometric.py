"""Metrics that need no ground truth: the photometric residual of the total flow, and the stabilised
video's inter-frame fidelity (ITF). They score real footage as they score the synthetic scenes.

Photometric residual (a stand-in for the endpoint error where no flow truth exists). For a
pair (I0, I1) on gray 0..255 and an estimated total flow w, per pixel x

    r(x) = |I1(x + w(x)) - I0(x)|             (I1 sampled bilinearly)
    rho(r) = sqrt(r^2 + eps^2) - eps          (Charbonnier, eps = 1 gray level: L1-like, robust to
                                               the few large residuals of specularities and noise)

averaged over the pixels that (a) land inside frame 1 under w, and (b) pass a forward-backward
consistency check, which takes occluded and disoccluded pixels out (no flow explains them):

    |f(x) + b(x + f(x))|^2 <= 0.01 (|f(x)|^2 + |b(x + f(x))|^2) + 0.5    (Sundaram, Brox, Keutzer 2010)

The backward flow: running each pipeline's own method on the reversed pair would double the cost
of every cell. Instead one *reference* pair of flows, OpenCV's DIS (medium preset) forward and
backward, is computed once per frame pair and shared by every pipeline scored on it
(:func:`prepare_photometric`): the check marks the pixels the reference sees as occluded or
inconsistent, and every pipeline is scored on the same pixels, so a method cannot improve its
residual by being inconsistent where it is wrong (a check on its own flows would drop exactly its
worst pixels), and the ranking compares like with like. Its cost is two DIS runs a pair (about
10-25 ms each at 640 x 480), whatever the number of pipelines.

ITF (inter-frame transformation fidelity; Marcenaro, Vernazza, Regazzoni 2001): the mean over pairs
of the PSNR between consecutive stabilised frames, ``10 log10(255^2 / MSE)``, the stabilised frame i
being frame i displaced by ``correction_px[i]`` (thesis 3.2). It is computed on the relative
displacement: frame i+1 sampled at ``x - (c_{i+1} - c_i)`` against frame i, over the pixels both
cover. A translation-only stabiliser leaves the flight line's own motion in the video, so ITF rises
as the correction leaves less shake, not to the value of a static camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from algorithms.flow import check_flow
from harness.metrics.registry import _row, register_metric

CHARBONNIER_EPS = 1.0  # gray levels
FB_ALPHA1, FB_ALPHA2 = 0.01, 0.5  # Sundaram et al. 2010, sec. 4.1

_PHO = "per pixel inside frame 1 and passing the reference forward-backward check, pooled over pairs"
register_metric("photo_residual", "gray", higher_is_better=False, weighting=_PHO,
                description="photometric residual of the total flow: mean Charbonnier |I1(x + w) - I0(x)| "
                "(eps 1, gray 0..255) over non-occluded pixels; needs no flow truth")
register_metric("photo_coverage", "%", higher_is_better=True, weighting="per pixel of frame 0, pooled over pairs",
                reduce="rate", description="share of pixels the photometric residual scores (inside frame 1 "
                "under the flow and consistent under the reference forward-backward check)")
register_metric("stab_itf", "dB", higher_is_better=True, weighting="per frame pair, mean over pairs",
                description="inter-frame transformation fidelity: mean PSNR of consecutive stabilised frames "
                "(gray 0..255, over the pixels both cover); needs no truth")

__all__ = ["CHARBONNIER_EPS", "PreparedPhotometric", "prepare_photometric", "photometric_rows",
           "charbonnier", "reference_consistency", "psnr_shifted", "itf_rows"]


def charbonnier(r: np.ndarray, *, eps: float = CHARBONNIER_EPS) -> np.ndarray:
    """``sqrt(r^2 + eps^2) - eps``: 0 at 0, ~|r| - eps for |r| >> eps. float64."""
    r = np.asarray(r, np.float64)
    return np.sqrt(r * r + eps * eps) - eps


def _to_uint8(gray: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(gray), 0, 255).astype(np.uint8)


def _sample(img: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``img`` sampled at ``x + flow(x)`` (bilinear) and whether that point lies inside ``img``."""
    h, w = img.shape
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = gx + flow[..., 0], gy + flow[..., 1]
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    out = cv2.remap(np.ascontiguousarray(img, np.float32), mx, my, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out, inside


def reference_consistency(gray0: np.ndarray, gray1: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of frame 0 whose reference forward flow (DIS, medium) lands inside frame 1
    and is consistent with the backward flow there (see the module docstring)."""
    a, b = _to_uint8(gray0), _to_uint8(gray1)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    f = dis.calc(a, b, None)
    bwd = dis.calc(b, a, None)
    bw_at, inside = _sample(bwd[..., 0], f)
    bv_at, _ = _sample(bwd[..., 1], f)
    du, dv = f[..., 0] + bw_at, f[..., 1] + bv_at
    lhs = du * du + dv * dv
    rhs = FB_ALPHA1 * (f[..., 0] ** 2 + f[..., 1] ** 2 + bw_at ** 2 + bv_at ** 2) + FB_ALPHA2
    return inside & (lhs <= rhs)


@dataclass(frozen=True, eq=False)
class PreparedPhotometric:
    """What every pipeline's photometric residual on one pair shares (:func:`prepare_photometric`).

    gray0, gray1 : (H, W) float32, gray 0..255; consistent : (H, W) bool (reference check).
    """

    gray0: np.ndarray
    gray1: np.ndarray
    consistent: np.ndarray


def prepare_photometric(gray0: np.ndarray, gray1: np.ndarray) -> PreparedPhotometric:
    """The frames of a pair as float32 gray 0..255 and the reference forward-backward check, once per pair."""
    g0, g1 = np.asarray(gray0, np.float32), np.asarray(gray1, np.float32)
    if g0.ndim != 2 or g0.shape != g1.shape:
        raise ValueError(f"gray frames: expected two (H, W) arrays of one shape, got {g0.shape} and {g1.shape}")
    return PreparedPhotometric(g0, g1, reference_consistency(g0, g1))


def photometric_rows(flow_total: np.ndarray, prepared: PreparedPhotometric, *, frame: int) -> list[dict]:
    """``photo_residual`` and ``photo_coverage`` of one pair's total flow (``motion`` "photometric")."""
    f = check_flow(flow_total, name="flow_total", shape=prepared.gray0.shape)
    warped, inside = _sample(prepared.gray1, np.asarray(f, np.float32))
    mask = inside & prepared.consistent
    n = int(np.count_nonzero(mask))
    total = float(charbonnier(warped[mask] - prepared.gray0[mask]).sum())
    kw = {"region": "all", "motion": "photometric", "frame": int(frame)}
    size = mask.size
    return [_row("photo_residual", total / n if n else math.nan, total, n, **kw),
            _row("photo_coverage", 100.0 * n / size, n, size, **kw)]


def psnr_shifted(gray0: np.ndarray, gray1: np.ndarray, delta_px) -> float:
    """PSNR (dB, peak 255) of ``gray0`` against ``gray1`` sampled at ``x - delta_px`` (bilinear), over the
    pixels where that point lies inside ``gray1``; inf for identical pixels, NaN when none overlap."""
    g0 = np.asarray(gray0, np.float32)
    h, w = g0.shape
    dx, dy = (float(v) for v in delta_px)
    # out(x) = gray1(x - delta): one affine warp (a translation), the covered pixels a rectangle
    warped = cv2.warpAffine(np.ascontiguousarray(gray1, np.float32), np.array([[1, 0, -dx], [0, 1, -dy]]), (w, h),
                            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    # the covered pixels x with 0 <= x - delta <= size - 1: a rectangle of rows y0:y1, columns x0:x1
    x0, x1 = max(0, math.ceil(dx)), min(w, math.floor(w - 1 + dx) + 1)
    y0, y1 = max(0, math.ceil(dy)), min(h, math.floor(h - 1 + dy) + 1)
    if x1 <= x0 or y1 <= y0:
        return math.nan
    d = (warped[y0:y1, x0:x1].astype(np.float64) - g0[y0:y1, x0:x1]).ravel()
    mse = float(d @ d) / d.size
    return math.inf if mse == 0 else 10.0 * math.log10(255.0 ** 2 / mse)


def itf_rows(psnr_db) -> list[dict]:
    """``stab_itf`` rows from the per-pair PSNRs of a stabilised sequence (one row per pair, ``frame`` i).

    A non-finite PSNR (no overlap, or identical frames) gives no row.
    """
    return [_row("stab_itf", p, p, 1, motion="jitter", frame=int(i)) for i, p in enumerate(psnr_db) if math.isfinite(p)]
