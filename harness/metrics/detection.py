"""Per-frame detection precision and recall against the ground-truth boxes of the vehicles that move.

A pair's detections (``PairEstimate.detections``, found on frame i of the pair i -> i+1)
are matched one-to-one to the boxes of frame i's visible vehicles by the Hungarian
method, maximising the number of matches, on the rules of
:mod:`harness.metrics.matching`: a detection with a box (an
:class:`algorithms.tracking.Detection`, fields ``x0_px .. y1_px`` after ``x_px, y_px,
area_px``, an inclusive pixel range) matches at IoU >= 0.5; a detection without one
(the tuple ``(x_px, y_px, area_px)``) when its centre lies inside the box.

Which vehicles count: those that move, where that is known. A ``moving`` column (0/1)
of tracks.csv says it; else ``parked`` (0/1), and a vehicle that is not parked but
slower than :data:`MOVING_MIN_MPS` (``speed_mps``, a car waiting at a light) does not
move either: a motion detector cannot see it. Rows are ``region`` "moving" then. Where
neither column exists (real footage whose boxes do not say) every visible vehicle counts
and rows are ``region`` "all". A detection on a vehicle that does not count is a false
positive. Only vehicles with a finite box are truth; without any box column there are
no rows.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness.metrics.matching import BOX_COLUMNS, correspondence
from harness.metrics.registry import _row, register_metric
from harness.metrics.trajectories import _linear_sum_assignment

MOVING_MIN_MPS = 0.5

_DET = "per frame pair, pooled over frames (sums of matches, detections and vehicles)"
register_metric("det_precision", "%", higher_is_better=True, weighting=_DET + "; per detection", reduce="rate",
                description="share of a pair's detections (motion regions) that fall on a moving vehicle: IoU >= 0.5 "
                "with its box for a boxed detection, the centre inside it for a point, one-to-one")
register_metric("det_recall", "%", higher_is_better=True, weighting=_DET + "; per moving vehicle-frame",
                reduce="rate", description="share of the moving vehicles visible in the pair's first frame that a "
                "detection matches (same rule as det_precision)")

__all__ = ["MOVING_MIN_MPS", "detection_boxes", "moving_vehicles", "detection_counts", "detection_rows"]


def detection_boxes(detections) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(K, 2)`` and boxes ``(K, 4)`` (continuous ``x0, y0, x1, y1``; NaN: none) of detections.

    A detection is indexable: ``d[0], d[1]`` its centre (px); with 7 or more fields,
    ``d[3:7]`` its inclusive pixel box, which covers ``[x0 - 0.5, x1 + 0.5]``.
    """
    n = len(detections)
    centres = np.full((n, 2), np.nan)
    boxes = np.full((n, 4), np.nan)
    for k, d in enumerate(detections):
        centres[k] = float(d[0]), float(d[1])
        if len(d) >= 7:
            boxes[k] = float(d[3]) - 0.5, float(d[4]) - 0.5, float(d[5]) + 0.5, float(d[6]) + 0.5
    return centres, boxes


def moving_vehicles(truth: pd.DataFrame) -> tuple[np.ndarray, str]:
    """Which rows of tracks.csv count for detection, and the region name ("moving" or "all").

    Visible rows with a finite box; of those the moving ones where ``moving`` or ``parked``
    says (see the module docstring).
    """
    if not all(c in truth.columns for c in BOX_COLUMNS):
        return np.zeros(len(truth), bool), "all"
    keep = truth["visible"].astype(bool).to_numpy() & np.isfinite(
        np.stack([truth[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1)).all(axis=1)
    if "moving" in truth.columns:
        return keep & (pd.to_numeric(truth["moving"], errors="coerce").to_numpy() == 1), "moving"
    if "parked" in truth.columns:
        moving = pd.to_numeric(truth["parked"], errors="coerce").to_numpy() == 0
        if "speed_mps" in truth.columns:
            moving &= pd.to_numeric(truth["speed_mps"], errors="coerce").to_numpy() >= MOVING_MIN_MPS
        return keep & moving, "moving"
    return keep, "all"


def detection_counts(detections, truth_frame: pd.DataFrame) -> tuple[int, int, int, str]:
    """``(matches, detections, vehicles, region)`` of one frame: the one-to-one matches of the detections
    with the counted vehicles' boxes (see the module docstring)."""
    counted, region = moving_vehicles(truth_frame)
    t = truth_frame[counted]
    tb = np.stack([t[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1) if len(t) else np.zeros((0, 4))
    centres, boxes = detection_boxes(detections)
    matches = 0
    if len(t) and len(centres):
        P = np.stack([(tb[:, 0] + tb[:, 2]) / 2, (tb[:, 1] + tb[:, 3]) / 2], 1)
        # the gate is unused: every counted vehicle has a box
        _, ok, cost, _ = correspondence(P, tb, centres, boxes, gate_px=1.0)
        if ok.any():
            ia, ib = _linear_sum_assignment(np.where(ok, cost, 1e6))
            matches = int(ok[ia, ib].sum())
    return matches, len(centres), len(t), region


def detection_rows(detections, truth_frame: pd.DataFrame | None, *, frame: int) -> list[dict]:
    """``det_precision`` and ``det_recall`` of one pair's detections against frame ``frame``'s truth.

    ``truth_frame``: tracks.csv rows of that frame (None, or no box columns: no rows).
    Rows: ``motion`` "detection", ``region`` "moving" or "all", sum = matches, count =
    detections (precision) or counted vehicles (recall); reduce ``rate`` pools them.
    """
    if detections is None or truth_frame is None or not all(c in truth_frame.columns for c in BOX_COLUMNS):
        return []
    tp, n_det, n_true, region = detection_counts(detections, truth_frame)
    kw = {"region": region, "motion": "detection", "frame": int(frame)}
    nan = float("nan")
    return [_row("det_precision", 100.0 * tp / n_det if n_det else nan, tp, n_det, **kw),
            _row("det_recall", 100.0 * tp / n_true if n_true else nan, tp, n_true, **kw)]
