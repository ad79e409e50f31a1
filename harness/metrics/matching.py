"""When an estimate corresponds to a true vehicle: the box-aware geometry under CLEAR-MOT, IDF1, HOTA and
the detection scores, in one place.

Three rules, chosen per (vehicle, estimate) pair by what each side carries:

==========================  ===================================  ===============  ====================
truth / estimate            corresponds when                     cost (matching)  similarity S (HOTA)
==========================  ===================================  ===============  ====================
box / box                   IoU >= :data:`IOU_MIN` (0.5)          1 - IoU          IoU
box / point                 the point lies inside the box        n                max(0, 1 - n)
no box / point or box       centre distance d <= ``gate_px``     d / gate_px      max(0, 1 - d / gate_px)
==========================  ===================================  ===============  ====================

``n = max(|dx| / (w / 2), |dy| / (h / 2))`` is the point's offset from the box centre in
half-extents (the L-infinity distance normalised by the box: 0 at the centre, 1 on the
border), so "inside" is ``n <= 1`` and the similarity falls linearly from the centre to
the border, as the gate's ramp falls from the true centre to the gate. Every cost lies
in [0, 1]: the Hungarian method compares them across rules. IoU is the MOTChallenge
rule (py-motmetrics' ``iou_matrix`` with ``max_iou=0.5``); the point rule is the
natural one for a point tracker against boxed truth. Boxes are continuous rectangles
``[x0, x1] x [y0, y1]`` in pixel-centre coordinates (tracks.csv's ``bbox_*_px``: the
extent of the vehicle's projected corners, clipped to the image); a :class:`algorithms.tracking.Detection`'s
box is an inclusive pixel range and becomes ``[x0 - 0.5, x1 + 0.5]``. A box with a NaN
corner is no box.
"""

from __future__ import annotations

import numpy as np

BOX_COLUMNS = ("bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px")
IOU_MIN = 0.5

__all__ = ["BOX_COLUMNS", "IOU_MIN", "box_iou", "box_offset", "correspondence", "boxes_of"]


def _linear_sum_assignment(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`scipy.optimize.linear_sum_assignment`, imported on first use (scipy.optimize takes 0.7 s
    to import, and most processes that import this module never match tracks)."""
    from scipy.optimize import linear_sum_assignment as lsa

    return lsa(cost)


def boxes_of(df, mask=None) -> np.ndarray:
    """``(N, 4)`` float64 ``x0, y0, x1, y1`` of the rows of ``df`` (NaN where it has no box columns)."""
    n = len(df) if mask is None else int(np.count_nonzero(mask))
    if not all(c in df.columns for c in BOX_COLUMNS):
        return np.full((n, 4), np.nan)
    out = np.stack([df[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1)
    return out if mask is None else out[mask]


def box_iou(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Intersection over union of every box of ``A`` (V, 4) with every box of ``B`` (T, 4): (V, T) float64.

    Boxes ``x0, y0, x1, y1`` (continuous, px). Zero where they do not overlap or either
    has no area; NaN where either has a NaN corner.
    """
    A = np.asarray(A, np.float64).reshape(-1, 4)[:, None, :]
    B = np.asarray(B, np.float64).reshape(-1, 4)[None, :, :]
    iw = np.minimum(A[..., 2], B[..., 2]) - np.maximum(A[..., 0], B[..., 0])
    ih = np.minimum(A[..., 3], B[..., 3]) - np.maximum(A[..., 1], B[..., 1])
    inter = np.clip(iw, 0, None) * np.clip(ih, 0, None)
    area_a = (A[..., 2] - A[..., 0]) * (A[..., 3] - A[..., 1])
    area_b = (B[..., 2] - B[..., 0]) * (B[..., 3] - B[..., 1])
    union = area_a + area_b - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / np.where(union > 0, union, 1.0), np.where(np.isnan(union), np.nan, 0.0))


def box_offset(B: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Offset ``n`` (V, T) of every point of ``Q`` (T, 2) from the centre of every box of ``B`` (V, 4).

    ``n = max(|dx| / (w / 2), |dy| / (h / 2))``: <= 1 inside the box (border included).
    A box without extent on an axis gives 0 there for a point on its line, else inf.
    """
    B = np.asarray(B, np.float64).reshape(-1, 4)[:, None, :]
    Q = np.asarray(Q, np.float64).reshape(-1, 2)[None, :, :]
    n = np.zeros(np.broadcast_shapes(B.shape[:2], Q.shape[:2]))
    for lo, hi, k in ((0, 2, 0), (1, 3, 1)):
        half = (B[..., hi] - B[..., lo]) / 2
        d = np.abs(Q[..., k] - (B[..., lo] + B[..., hi]) / 2)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.where(half > 0, d / np.where(half > 0, half, 1.0), np.where(d == 0, 0.0, np.inf))
        n = np.maximum(n, np.where(np.isnan(half) | np.isnan(d), np.nan, r))
    return n


def correspondence(P: np.ndarray, true_boxes: np.ndarray, Q: np.ndarray, est_boxes: np.ndarray, *,
                   gate_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Distance, feasibility, cost and similarity of every (vehicle, estimate) pair of a frame.

    Parameters
    ----------
    P : (V, 2) float
        True centres ``x_px, y_px``.
    true_boxes : (V, 4) float
        True boxes ``x0, y0, x1, y1`` (NaN: none).
    Q : (T, 2) float
        Estimated positions (``x_filt_px, y_filt_px``).
    est_boxes : (T, 4) float
        Estimated boxes (NaN: a point estimate).
    gate_px : float
        The distance gate for a vehicle without a box, px (> 0).

    Returns
    -------
    dist_px, feasible, cost, sim : (V, T)
        Centre distance |Q - P| (px, float64; the MOTP distance whatever the rule), bool,
        float64 cost in [0, 1] (inf where not feasible), float64 similarity in [0, 1]
        (see the module docstring).
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    P = np.asarray(P, np.float64).reshape(-1, 2)
    Q = np.asarray(Q, np.float64).reshape(-1, 2)
    tb = np.asarray(true_boxes, np.float64).reshape(-1, 4)
    eb = np.asarray(est_boxes, np.float64).reshape(-1, 4)
    dist = np.hypot(P[:, None, 0] - Q[None, :, 0], P[:, None, 1] - Q[None, :, 1]).reshape(len(P), len(Q))
    t_box = np.isfinite(tb).all(axis=1)[:, None]
    e_box = np.isfinite(eb).all(axis=1)[None, :]
    cost = dist / gate_px
    sim = np.maximum(0.0, 1.0 - cost)
    feasible = dist <= gate_px
    if t_box.any():
        n = box_offset(tb, Q)
        point = t_box & ~e_box
        cost = np.where(point, n, cost)
        sim = np.where(point, np.maximum(0.0, 1.0 - n), sim)
        feasible = np.where(point, n <= 1.0, feasible)
        if e_box.any():
            iou = box_iou(tb, eb)
            both = t_box & e_box
            cost = np.where(both, 1.0 - iou, cost)
            sim = np.where(both, iou, sim)
            # as py-motmetrics decides it: the distance 1 - IoU within 1 - 0.5
            feasible = np.where(both, 1.0 - iou <= 1.0 - IOU_MIN, feasible)
    feasible = np.asarray(feasible, bool) & np.isfinite(cost)
    return dist, feasible, np.where(feasible, cost, np.inf), np.nan_to_num(sim, nan=0.0)
