"""Global motion and stabilisation: shift error, residual jitter, Liu et al. 2013's scores."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from algorithms.jitter import least_squares_line
from harness.metrics.registry import _row, register_metric

register_metric("shift_error", "px", higher_is_better=False, weighting="per frame pair, mean over pairs",
                description="|estimated global shift - true global shift| (camera.csv global_dx/dy_px)")
register_metric("jitter_residual_rms", "px", higher_is_better=False, weighting="per frame, RMS over frames",
                reduce="rms", description="RMS of estimated jitter minus detrended true jitter "
                "(jitter left after remove_jitter)")
_SEQ = "per sequence (the paper's per-video score), mean over sequences"
register_metric("stab_cropping_ratio", "ratio", higher_is_better=True, weighting=_SEQ,
                description="share of the frame kept (as a uniform zoom) by the crop inside every corrected "
                "frame (Liu 2013 cropping ratio, for a translation correction)")
register_metric("stab_distortion", "ratio", higher_is_better=True, weighting=_SEQ,
                description="worst eigenvalue ratio of the correction's affine part (Liu 2013); 1 for a "
                "translation correction by construction")
register_metric("stab_stability", "ratio", higher_is_better=True, weighting=_SEQ,
                description="share of the stabilised video's frame-to-frame motion energy in the 2nd-6th "
                "lowest frequencies, smaller axis (Liu 2013 stability score)")


def shift_rows(shifts_px: np.ndarray, camera: pd.DataFrame) -> list[dict]:
    """``shift_error`` per pair ``i -> i+1``: |shifts_px[i] - (global_dx_px, global_dy_px)[i]|.

    Pairs whose truth is empty (the last frame) or whose estimate is NaN are skipped.
    """
    s = np.asarray(shifts_px, np.float64).reshape(-1, 2)
    cam = camera.sort_values("frame")
    # whole columns once: a pandas row lookup per pair cost more than the rest of the sequence scoring
    true = cam[["global_dx_px", "global_dy_px"]].to_numpy(np.float64)
    frames = cam["frame"].to_numpy()
    rows = []
    for i in range(min(len(s), len(cam))):
        t = true[i]
        if not (np.isfinite(t).all() and np.isfinite(s[i]).all()):
            continue
        err = float(np.hypot(*(s[i] - t)))
        rows.append(_row("shift_error", err, err, 1, motion="global", frame=int(frames[i])))
    return rows


def detrend(y: np.ndarray) -> np.ndarray:
    """``y`` minus its own least-squares line ``a + b i`` over the index i, column by column."""
    y = np.asarray(y, np.float64)
    return y - least_squares_line(y)


def jitter_rows(jitter_px: np.ndarray, camera: pd.DataFrame) -> list[dict]:
    """``jitter_residual_rms`` per frame: the jitter left after ``remove_jitter``.

    The true jitter J (camera.csv ``jitter_x_px, jitter_y_px``, shape (N, 2)) has
    its own least-squares line removed (an offset or linear drift of the truth is
    flight line, not jitter): J' = J - line(J). The residual of frame i is
    r_i = jitter_px[i] - J'_i (the estimated jitter is what the correction
    removes, so r_i is what stays in the stabilised video). Row: value |r_i|,
    sum |r_i|^2, count 1; the aggregate is sqrt(sum |r_i|^2 / N).
    """
    est = np.asarray(jitter_px, np.float64).reshape(-1, 2)
    cam = camera.sort_values("frame").reset_index(drop=True)
    if len(cam) != len(est):
        raise ValueError(f"jitter_px: expected {len(cam)} frames (camera.csv), got {len(est)}")
    truth = detrend(cam[["jitter_x_px", "jitter_y_px"]].to_numpy(np.float64))
    r = est - truth
    rows = []
    for i, f in enumerate(cam["frame"].to_numpy()):
        if not np.isfinite(r[i]).all():
            continue
        sq = float(r[i] @ r[i])
        rows.append(_row("jitter_residual_rms", math.sqrt(sq), sq, 1, motion="jitter", frame=int(f)))
    return rows


def stabilisation_scores(correction_px: np.ndarray, true_shifts_px: np.ndarray, frame_shape_px) -> dict:
    """Cropping ratio, distortion and stability of a translation-corrected video (Liu et al. 2013).

    Liu, Yuan, Tan, Sun, "Bundled camera paths for video stabilization", ACM TOG
    32(4) 2013, sec. 6: a homography B_t is fitted between each input frame and
    its stabilised output. *Cropping ratio*: the scale component of B_t (the
    area kept after cropping the empty borders, as a zoom), averaged over frames.
    *Distortion*: the anisotropy of B_t, the ratio of the two eigenvalues of its
    affine part, the worst (smallest) over frames. *Stability*: the frame-to-frame
    motion of the stabilised video is analysed in the frequency domain; the share
    of the energy in the lowest frequencies (the 2nd to 6th, DC excluded) of all
    energy, the smaller over its components.

    Adapted to what this pipeline estimates, a translation ``correction_px[i]``
    applied to frame i (thesis 3.2):

    * B_i is a translation, whose scale is 1, so the zoom that removes the empty
      borders is set by the correction's extent instead: one crop window must
      lie inside every corrected frame, (W - range_x) x (H - range_y) with
      range = max - min of the correction per axis; the uniform zoom that fills
      the frame with it is ``min((W - range_x) / W, (H - range_y) / H)``, the
      cropping ratio of every frame and so of the video (1: nothing cropped).
    * The affine part of a translation is the identity, both eigenvalues 1:
      the distortion is 1 by construction. It is computed from that model, not
      assumed, so a richer correction model would report its own.
    * Stability uses the motion the viewer sees, the true camera shift of each
      pair plus the change of correction, ``d_i = s_true_i + c_{i+1} - c_i``
      (x and y are the components; no rotation is corrected). Energy
      ``E_k = |FFT(d)_k|^2``; per axis ``sum_{k=1..5} E_k / sum_{k>=1} E_k``;
      the score is the smaller over x and y. An axis with no energy above DC
      (a static or constant-velocity output, nothing shakes) scores 1. With
      fewer than 12 pairs the low band is the whole spectrum: NaN (no row).

    Parameters
    ----------
    correction_px : ndarray, (N, 2) float
        Per-frame correction (dx, dy), px.
    true_shifts_px : ndarray, (N-1, 2) float
        True global shift of each pair i -> i+1 (camera.csv ``global_dx_px, global_dy_px``), px.
    frame_shape_px : (H, W)
        Frame size in pixels.

    Returns
    -------
    dict with ``cropping_ratio``, ``distortion``, ``stability`` (floats in [0, 1]).
    """
    c = np.asarray(correction_px, np.float64).reshape(-1, 2)
    s = np.asarray(true_shifts_px, np.float64).reshape(-1, 2)
    if len(s) != len(c) - 1:
        raise ValueError(f"true_shifts_px: expected {len(c) - 1} pair shifts for {len(c)} frames, got {len(s)}")
    h, w = (float(v) for v in frame_shape_px)
    if not (h > 0 and w > 0):
        raise ValueError(f"frame_shape_px: expected (H, W) > 0, got {tuple(frame_shape_px)}")
    extent = c.max(axis=0) - c.min(axis=0) if len(c) else np.zeros(2)
    crop = max(0.0, min((w - extent[0]) / w, (h - extent[1]) / h))
    # affine part of each frame's correction model (a translation: the identity); distortion = min over frames
    # of the eigenvalue ratio (smaller / larger) of its 2x2 linear part
    distortion = 1.0
    for _ in range(len(c)):
        A = np.eye(2)
        ev = np.sort(np.abs(np.linalg.eigvals(A)))
        distortion = min(distortion, float(ev[0] / ev[-1]))
    d = s + np.diff(c, axis=0)
    scores = []
    for axis in (0, 1):
        E = np.abs(np.fft.rfft(d[:, axis])) ** 2
        full = float(E[1:].sum())
        # "static" within rounding: the motion's spread is below 1e-9 px
        if len(E) <= 6:
            # the 2nd-6th lowest frequencies are the whole spectrum: the share is 1 whatever the motion
            scores.append(math.nan)
        elif full <= (1e-9 ** 2) * len(d) ** 2:
            scores.append(1.0)
        else:
            scores.append(float(E[1:6].sum()) / full)
    return {"cropping_ratio": float(crop), "distortion": distortion, "stability": float(min(scores))}


def stabilisation_rows(correction_px: np.ndarray, camera: pd.DataFrame, frame_shape_px) -> list[dict]:
    """``stab_cropping_ratio``, ``stab_distortion``, ``stab_stability`` of a sequence (one row each).

    See :func:`stabilisation_scores`; the true shifts come from camera.csv. Each
    row is one sequence (sum = value, count = 1): aggregates are means over sequences.
    """
    cam = camera.sort_values("frame").reset_index(drop=True)
    true = cam[["global_dx_px", "global_dy_px"]].to_numpy(np.float64)[:-1]
    if not np.isfinite(true).all():
        return []
    sc = stabilisation_scores(correction_px, true, frame_shape_px)
    return [_row(f"stab_{k}", v, v, 1, motion="jitter") for k, v in sc.items() if math.isfinite(v)]
