"""Per-frame detection precision and recall against the ground-truth boxes of the vehicles that move.

A pair's detections (``PairEstimate.detections``, found on frame i of the pair i -> i+1)
are matched one-to-one to the boxes of frame i's visible vehicles by the Hungarian
method, maximising the number of matches, on the rules of
:mod:`harness.metrics.matching`: a detection with a box (an
:class:`algorithms.tracking.Detection`, fields ``x0_px .. y1_px`` after ``x_px, y_px,
area_px``, an inclusive pixel range) matches at IoU >= 0.5; a detection without one
(the tuple ``(x_px, y_px, area_px)``) when its centre lies inside the box.

Which vehicles count: the tracking metrics' counted objects
(:func:`harness.metrics.objects.counted_objects`: visible rows of a vehicle class that a
``moving`` column, else ``parked`` == 0, says move), and for detection one rule more: a
vehicle that is not parked but slower than :data:`MOVING_MIN_MPS` in that frame
(``speed_mps``, a car waiting at a light; only where no ``moving`` column exists) does
not move either: a motion detector cannot see it in that pair. Rows are ``region``
"moving" then. Where neither column exists (real footage whose boxes do not say) every
visible vehicle counts and rows are ``region`` "all". A detection on a vehicle that does
not count is a false positive (pedestrians and cyclists too), with one exception: a
moving vehicle's row of low visibility (:func:`harness.metrics.objects.low_visibility`:
mostly outside the image or hidden), as in the tracking metrics, is matched with the
counted ones and a detection it takes is left out of the detections (neither true nor
false). Only vehicles with a finite box are truth; without any box column there are no rows.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness.metrics.matching import BOX_COLUMNS, correspondence
from harness.metrics.objects import counted_objects, low_visibility
from harness.metrics.registry import _row, register_metric
from harness.metrics.matching import _linear_sum_assignment

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
    keep = counted_objects(truth) & np.isfinite(
        np.stack([truth[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1)).all(axis=1)
    if "moving" in truth.columns:
        return keep, "moving"
    if "parked" in truth.columns:
        if "speed_mps" in truth.columns:
            keep &= pd.to_numeric(truth["speed_mps"], errors="coerce").to_numpy() >= MOVING_MIN_MPS
        return keep, "moving"
    return keep, "all"


def detection_counts(detections, truth_frame: pd.DataFrame) -> tuple[int, int, int, str]:
    """``(matches, detections, vehicles, region)`` of one frame: the one-to-one matches of the detections
    with the counted vehicles' boxes (see the module docstring)."""
    counted, region = moving_vehicles(truth_frame)
    tb_all = np.stack([truth_frame[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1).reshape(-1, 4)
    low = low_visibility(truth_frame) & np.isfinite(tb_all).all(axis=1) & ~counted
    n_true = int(counted.sum())
    tb = np.concatenate([tb_all[counted], tb_all[low]])  # the counted vehicles first, then the low-visibility rows
    centres, boxes = detection_boxes(detections)
    matches = ignored = 0
    if len(tb) and len(centres):
        P = np.stack([(tb[:, 0] + tb[:, 2]) / 2, (tb[:, 1] + tb[:, 3]) / 2], 1)
        # the gate is unused: every counted vehicle has a box
        _, ok, cost, _ = correspondence(P, tb, centres, boxes, gate_px=1.0)
        if ok.any():
            ia, ib = _linear_sum_assignment(np.where(ok, cost, 1e6))
            hit = ok[ia, ib]
            matches = int((hit & (ia < n_true)).sum())
            ignored = int((hit & (ia >= n_true)).sum())
    return matches, len(centres) - ignored, n_true, region


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
