"""Which rows of the ground truth the tracking and detection metrics count, and which are distractors.

The pipelines detect and track vehicles that move, so that is what they are scored on.

Counted objects (truth the metrics count: a miss when no estimate matches them):
    visible rows of tracks.csv of a vehicle class (:data:`VEHICLE_CLASSES`; a table
    without ``class`` reads as all ``car``) that move in the sequence: a ``moving``
    column (0/1) says it where present; else ``parked`` (0/1: a parked car is not
    counted, a car queued at a light is, whatever its speed in that frame); without
    either (real footage, a MOTChallenge ``gt.txt``) every row counts: the annotation
    decides. A vehicle that stands still through the whole sequence (a ``speed_mps``
    column whose every visible row of that vehicle is below :data:`STATIC_SPEED_MPS`: a car
    queued at a red light from the first frame to the last) is not counted but is a
    distractor, below.

Distractors (the MOT16 devkit's treatment, Milan et al. 2016, sec. 3.3): visible rows of
:data:`DISTRACTOR_CLASSES` (pedestrians and cyclists in a vehicle benchmark), of vehicles
that never move in the sequence (MOT16's "static person" is a distractor for the same
reason: from the clip alone nothing tells it from a parked one, so neither finding it nor
missing it is scored), and the
rows of real footage's ``ignore.csv`` (:attr:`scenes.sequence.Sequence.ignore_regions`,
ignored objects and regions). In every frame the estimates are assigned one-to-one to
the counted objects and distractors together (Hungarian method on the box-aware rules
of :mod:`harness.metrics.matching`); an estimate assigned to a distractor is removed
from that frame, and so is one that no counted object took whose position lies inside
an ignore region (a region may hold many estimates). A distractor is never a miss.

Low visibility (synthetic truth, :func:`low_visibility`): a row that would be a counted object but
whose ``visible_fraction`` is below :data:`MIN_VISIBLE_FRACTION` (0.5: most of the vehicle outside
the image or hidden, under a tree crown, a bridge or another vehicle) is a distractor, not a
counted object: neither finding it nor missing it is scored. Its box is the part in the image
(tracks.csv boxes are clipped to the image, as an annotator draws them), which the half it shows
may not fill. KITTI's "hard" level leaves out objects truncated by more than 50 % the same way
(Geiger et al. 2012). Real annotation (a ``gt.txt``: no ``speed_mps`` column) decides for itself
what counts, by its flags: its visibility is read but not cut on, as the MOT16 devkit's official
evaluation (``minvis`` 0) and TrackEval do, so a figure on real footage is theirs; ``aerobench
export`` writes synthetic truth's low-visibility rows with flag 0 (ignored), so that the real path
scores an export as the synthetic path scores the sequence. As the boxes are the image's, an
estimate beyond the image border (a point tracker that follows a vehicle out of view, a track box
coasting past the edge) lies in no box: a point there is a false positive, as a track of a vehicle
wholly out of view always was, and a box reaching far past the edge may miss IoU 0.5.

Parked vehicles are neither: a track on a parked car is a false positive (a real clip's
"moving vehicles" truth counts it so).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness.metrics.matching import BOX_COLUMNS, _linear_sum_assignment, box_offset, boxes_of, correspondence

VEHICLE_CLASSES = ("car", "van", "truck", "bus", "motorbike")
DISTRACTOR_CLASSES = ("cyclist", "pedestrian")
# A vehicle whose speed stays below this in every visible row of the sequence never moves in it (walking pace is
# 1.4 m/s; the traffic model's queued cars read 0, a creeping one a few tenths): a distractor, not a counted object.
STATIC_SPEED_MPS = 0.5
# A counted row whose visible_fraction is below this is a distractor (module docstring).
MIN_VISIBLE_FRACTION = 0.5

__all__ = ["VEHICLE_CLASSES", "DISTRACTOR_CLASSES", "STATIC_SPEED_MPS", "MIN_VISIBLE_FRACTION", "truth_classes", "static_vehicles",
           "low_visibility", "counted_objects", "distractor_objects", "distractor_table", "keep_estimates"]


def truth_classes(truth: pd.DataFrame) -> np.ndarray:
    """``(N,)`` object array of each row's class; ``car`` without a ``class`` column or where it is empty."""
    if "class" not in truth.columns:
        return np.full(len(truth), "car", dtype=object)
    return truth["class"].fillna("car").astype(str).str.strip().str.lower().to_numpy(object)


def _visible(truth: pd.DataFrame) -> np.ndarray:
    return pd.to_numeric(truth["visible"], errors="coerce").fillna(0).to_numpy() != 0


def _moving_vehicles(truth: pd.DataFrame) -> np.ndarray:
    """``(N,)`` bool: visible rows of a vehicle class that the ``moving`` or ``parked`` column (if any) calls moving."""
    keep = _visible(truth) & np.isin(truth_classes(truth), VEHICLE_CLASSES)
    if "moving" in truth.columns:
        return keep & (pd.to_numeric(truth["moving"], errors="coerce").to_numpy() == 1)
    if "parked" in truth.columns:
        return keep & (pd.to_numeric(truth["parked"], errors="coerce").to_numpy() == 0)
    return keep


def static_vehicles(truth: pd.DataFrame) -> np.ndarray:
    """``(N,)`` bool: rows of moving-vehicle truth whose vehicle stands still through the whole sequence.

    A vehicle (``vehicle_id``) not parked whose ``speed_mps`` is below :data:`STATIC_SPEED_MPS`
    in every visible row; all False without ``speed_mps`` or ``vehicle_id`` (real annotations).
    """
    rows = _moving_vehicles(truth)
    if "speed_mps" not in truth.columns or "vehicle_id" not in truth.columns or not rows.any():
        return np.zeros(len(truth), bool)
    speed = pd.to_numeric(truth["speed_mps"], errors="coerce").to_numpy(np.float64)
    ids = truth["vehicle_id"].to_numpy()
    moved = pd.Series(np.where(rows, np.nan_to_num(speed, nan=np.inf), -np.inf)).groupby(ids).transform("max")
    return rows & (moved.to_numpy() < STATIC_SPEED_MPS)


def low_visibility(truth: pd.DataFrame, *, min_visible_fraction: float = MIN_VISIBLE_FRACTION) -> np.ndarray:
    """``(N,)`` bool: rows of synthetic moving-vehicle truth whose ``visible_fraction`` is below ``min_visible_fraction``.

    Rows that the moving-vehicle rule (visible, a vehicle class, ``moving`` / ``parked``) keeps,
    whose ``visible_fraction`` (0..1) is below the threshold (a missing value reads as 1, fully
    visible); all False without the column, with ``min_visible_fraction`` 0, or for real
    annotation (no ``speed_mps`` column: its flags say what counts; module docstring).
    """
    if not 0.0 <= min_visible_fraction <= 1.0:
        raise ValueError(f"min_visible_fraction: expected 0..1, got {min_visible_fraction}")
    if ("visible_fraction" not in truth.columns or "speed_mps" not in truth.columns
            or min_visible_fraction == 0.0):
        return np.zeros(len(truth), bool)
    vf = pd.to_numeric(truth["visible_fraction"], errors="coerce").fillna(1.0).to_numpy(np.float64)
    return _moving_vehicles(truth) & (vf < min_visible_fraction)


def counted_objects(truth: pd.DataFrame, *, min_visible_fraction: float = MIN_VISIBLE_FRACTION) -> np.ndarray:
    """``(N,)`` bool: the rows of tracks.csv that are counted objects (see the module docstring)."""
    return (_moving_vehicles(truth) & ~static_vehicles(truth)
            & ~low_visibility(truth, min_visible_fraction=min_visible_fraction))


def distractor_objects(truth: pd.DataFrame, *, min_visible_fraction: float = MIN_VISIBLE_FRACTION) -> np.ndarray:
    """``(N,)`` bool: visible rows of tracks.csv that are distractors: a distractor class (pedestrian, cyclist),
    a vehicle that never moves in the sequence (:func:`static_vehicles`) or a moving vehicle's row of low
    visibility (:func:`low_visibility`)."""
    return ((_visible(truth) & np.isin(truth_classes(truth), DISTRACTOR_CLASSES)) | static_vehicles(truth)
            | low_visibility(truth, min_visible_fraction=min_visible_fraction))


def distractor_table(truth: pd.DataFrame, ignore: pd.DataFrame | None = None) -> pd.DataFrame:
    """Every distractor of a sequence: ``frame, x_px, y_px, bbox_x0_px .. bbox_y1_px, region`` (bool).

    The distractor rows of ``truth`` (``region`` False) and the rows of ``ignore``
    (ignore.csv: ``frame, bbox_x0_px .. bbox_y1_px``; centre = box centre; ``region`` True).
    """
    cols = ["frame", "x_px", "y_px", *BOX_COLUMNS, "region"]
    d = distractor_objects(truth)
    b = boxes_of(truth, d)
    parts = [pd.DataFrame({"frame": truth["frame"].to_numpy(np.int64)[d],
                           "x_px": truth["x_px"].to_numpy(np.float64)[d], "y_px": truth["y_px"].to_numpy(np.float64)[d],
                           **{c: b[:, k] for k, c in enumerate(BOX_COLUMNS)}, "region": False})]
    if ignore is not None and len(ignore):
        missing = [c for c in ("frame", *BOX_COLUMNS) if c not in ignore.columns]
        if missing:
            raise ValueError(f"ignore regions: expected columns frame, {', '.join(BOX_COLUMNS)}; missing {missing}")
        ib = boxes_of(ignore)
        parts.append(pd.DataFrame({"frame": ignore["frame"].to_numpy(np.int64),
                                   "x_px": (ib[:, 0] + ib[:, 2]) / 2, "y_px": (ib[:, 1] + ib[:, 3]) / 2,
                                   **{c: ib[:, k] for k, c in enumerate(BOX_COLUMNS)}, "region": True}))
    return pd.concat(parts, ignore_index=True)[cols]


def keep_estimates(P: np.ndarray, true_boxes: np.ndarray, Q: np.ndarray, est_boxes: np.ndarray,
                   DP: np.ndarray, distractor_boxes: np.ndarray, region: np.ndarray, *, gate_px: float) -> np.ndarray:
    """``(T,)`` bool: the estimates of one frame that stay after distractor removal (module docstring).

    Parameters
    ----------
    P, true_boxes : (V, 2), (V, 4) float
        Centres and boxes (NaN: none) of the frame's counted objects, px.
    Q, est_boxes : (T, 2), (T, 4) float
        Estimated positions and boxes (NaN: a point), px.
    DP, distractor_boxes : (D, 2), (D, 4) float
        Centres and boxes of the frame's distractors, px.
    region : (D,) bool
        The distractor is an ignore region (an estimate inside it is removed unless a counted
        object took it).
    gate_px : float
        The gate of :func:`harness.metrics.matching.correspondence`.
    """
    keep = np.ones(len(Q), bool)
    if len(DP) == 0 or len(Q) == 0:
        return keep
    V = len(P)
    _, ok, cost, _ = correspondence(np.concatenate([np.reshape(P, (-1, 2)), DP]),
                                    np.concatenate([np.reshape(true_boxes, (-1, 4)), distractor_boxes]),
                                    Q, est_boxes, gate_px=gate_px)
    taken = np.zeros(len(Q), bool)
    if ok.any():
        ia, ib = _linear_sum_assignment(np.where(ok, cost, 1e6))
        hit = ok[ia, ib]
        ia, ib = ia[hit], ib[hit]
        taken[ib[ia < V]] = True
        keep[ib[ia >= V]] = False
    region = np.asarray(region, bool)
    if region.any():
        inside = (np.nan_to_num(box_offset(distractor_boxes[region], Q), nan=np.inf) <= 1.0).any(axis=0)
        keep &= ~(inside & ~taken)
    return keep
