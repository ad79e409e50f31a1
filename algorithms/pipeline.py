"""The pipeline: global motion -> jitter -> compensation -> flow -> threshold -> spatial -> temporal -> tracking.

A :class:`Pipeline` is a frozen, validated description built from a plain dict
(as YAML suites hold it, see :func:`Pipeline.from_dict`), and runs on any
indexable of frames (:meth:`Pipeline.run`), streaming:

1. pass 1: the global shift of every pair t -> t+1 (thesis 3.1), then jitter
   removal over the whole path (thesis 3.2);
2. pass 2, pair by pair: frame t+1 is compensated by the global model (the
   pass-1 shift, or an affine / homography fit of the pair) so that it lines
   up with frame t, the local flow is computed on (frame t, compensated t+1)
   and composed exactly with the global model into the total flow, then
   threshold, spatial filter (eq. 4.11), temporal filter (eq. 4.12, a window
   of three pairs), moving-region detections and tracking.

Each pair's :class:`PairEstimate` is yielded as soon as its temporal window is
complete (one pair later), then a final :class:`SequenceEstimate`. Frames are
read with ``frames[i]`` when needed and converted to gray once for both passes
(:class:`algorithms.shared_work.SharedWork`, bounded by bytes; several pipelines
on the same frames share one, and with it pass 1 and the compensated frames);
three pairs of fields are held, whatever the sequence length.

Composition: with the shift ``s``, compensated frame ``I1'(x) = I1(x + s)`` and
local flow ``w`` (``I1'(x + w) ~ I0(x)``) give ``total = s + w``. With a matrix
``M`` mapping frame-t points to frame-t+1 points, ``I1'(x) = I1(M x)`` and
``total(x) = M(x + w(x)) - x``.
"""

from __future__ import annotations

import copy
import math
import time
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numba
import numpy as np
import pandas as pd

from algorithms.flow import FLOW_DTYPE
from algorithms.filters import zero_outside
from algorithms.global_motion import affine_global_motion, global_flow, is_translation
from algorithms.jitter import cumulative_path
from algorithms.pipeline_spec import (COMPENSATION_MODELS, PipelineError, builtin_pipelines, pipeline_hash,
                                      resolve_pipeline)
from algorithms.registry import STAGES, get_stage, register_stage
from algorithms.shared_work import SharedWork
from algorithms.detection import (DETECTION_DEFAULTS, clip_shadow_direction, drop_parts_inside, fill_lane,
                                  ground_fit_at, image_yaw_rad, shadow_lean, trim_toward, turn)
from algorithms.long_baseline import (ParallaxChains, compose_models, long_baseline_detections, merge_detections,
                                      register_into, registration_fix)
from algorithms.sequence_size import equivalent_gsd, relative_size_keep, typical_mover
from algorithms.tracking import TRACK_COLUMNS, MultiTargetTracker, PointTracker, boxes_in_image, motion_mask

__all__ = ["Pipeline", "PipelineError", "PairEstimate", "SequenceEstimate", "PIPELINES",
           "GLOBAL_MOTION_METHODS", "COMPENSATION_MODELS", "get_pipeline", "pipeline_hash"]

# The trackers are classes of algorithms.tracking, registered here beside the other stages the pipeline
# resolves by kind and name (global_motion and flow by the names a pipeline dict gives).
register_stage("tracking", name="point")(PointTracker)
register_stage("tracking", name="multi")(MultiTargetTracker)
# global shift methods usable in pass 1: (frame0, frame1, **params) -> .shift_px, .valid (the registry's table)
GLOBAL_MOTION_METHODS = STAGES["global_motion"]
# the stage functions the pipeline runs where its dict names no method
_STAGE = {"jitter": "remove_jitter", "threshold": "threshold_flow", "spatial": "spatial_filter",
          "temporal": "temporal_filter", "detection": "detect_vehicles"}


def _in_path_frame(dets: list, field: np.ndarray, valid: np.ndarray, ground_model: str) -> list:
    """The detections with their motion in the multi-target tracker's coordinates (image minus the camera path).

    A detection's ``(u_px, v_px)`` is its motion over the ground: the local flow less the ground fit
    (:func:`algorithms.detection.ground_residual`). The frames were compensated by the pair's global model, which
    leaves the ground a residual where the model does not follow it (perspective, rotation, a shift that tall roofs
    pulled), and the tracker's coordinates move with that model: there a vehicle moves by its motion over the
    ground plus the ground's residual at its place. Unchanged with ``ground_model`` none (no fit: the flow is
    the motion in those coordinates already).

    Fed the motion over the ground, the constant-velocity filter held a box a steady 1-1.5 px off its detections
    there. benchmarks/tracking_quality.py --frames 30, MOTA without -> with (dis / pyramidal-hs / -lk / tv-l1 /
    farneback): urban-parallax 0.717 / 0.811 / 0.805 / 0.780 / 0.730 -> 0.818 / 0.862 / 0.849 / 0.824 / 0.761;
    fast-vehicles pyramidal-hs 0.716 -> 0.724, farneback 0.724 -> 0.735; nominal, realistic, city unchanged;
    thesis-lk / thesis-hs (with min_box_m2, from main) urban-parallax 0.610 / 0.170 -> 0.623 / 0.346, city 0.258 /
    0.262 -> 0.400 / 0.279, nominal 0.738 / 0.401 -> 0.802 / 0.488, realistic 0.624 / 0.630 -> 0.646 / 0.619,
    fast-vehicles 0.504 / 0.627 -> 0.541 / 0.705. KIT AIS (--kit-ais) pseudo-MOT MOTA dis -0.702 -> -0.673,
    pyramidal-lk -0.778 -> -0.704, farneback -0.796 -> -0.745, pyramidal-hs -0.980 -> -0.967, tv-l1 -0.423 ->
    -0.426 (detections unchanged); 1080p city stand-in (aerobench eval-video, a hovering camera) unchanged: dis
    0.483, pyramidal-hs 0.489, tv-l1 0.470, farneback 0.422, pyramidal-lk 0.369. urban-parallax --seed 2: dis 0.873 ->
    0.880, pyramidal-hs 0.725 -> 0.775.
    """
    if ground_model == "none" or not dets:
        return dets
    g = ground_fit_at(field, valid, [(d.x_px, d.y_px) for d in dets], model=ground_model)
    return [d._replace(u_px=d.u_px + gx, v_px=d.v_px + gy) if len(d) >= 9 else d for d, (gx, gy) in zip(dets, g)]


def _stage(kind: str):
    return get_stage(kind, _STAGE[kind])


# ---------------------------------------------------------------------------------------------
# estimates


@dataclass
class PairEstimate:
    """What the pipeline estimates for pair t -> t+1 (fields in frame t pixels, float32 px).

    Attributes
    ----------
    index : int
        t.
    global_shift_px : (2,) float64
        Pass-1 global shift (dx, dy) of the pair (after replacing an invalid one, see ``global_valid``).
    global_valid : bool
        False when the global motion method found no clear peak; the shift is
        then the median of the valid shifts of the sequence.
    flow_global : (H, W, 2)
        The field of the global model used for compensation: the camera-induced
        motion as the pipeline sees it (the pass-1 shift for ``"none"``/``"shift"``).
    flow_total : (H, W, 2)
        Global and local composed exactly (for ``"none"``: the flow on the raw pair).
    flow_local : (H, W, 2)
        The flow method's output on (frame t, compensated frame t+1).
    flow_filtered : (H, W, 2)
        ``flow_local`` after threshold, spatial and temporal filters (zero where deleted).
    valid : (H, W) bool
        Flow method's valid mask and the compensated sample inside frame t+1.
    motion_mask : (H, W) bool
        ``valid & |f| >= detection.min_magnitude_px`` for the field ``f`` detection runs on
        (``detection.field``: ``flow_filtered`` or ``flow_local``).
    detections : list of :class:`~algorithms.detection.Detection`
        The moving vehicles :func:`~algorithms.detection.detect_vehicles` finds in that field
        (centre, area, box, mean local flow; ``area_m2`` with a ground sampling distance).
    stage_ms : dict
        Wall time per stage, ms.
    """

    index: int
    global_shift_px: np.ndarray
    global_valid: bool
    flow_global: np.ndarray
    flow_total: np.ndarray
    flow_local: np.ndarray
    flow_filtered: np.ndarray
    valid: np.ndarray
    motion_mask: np.ndarray
    detections: list
    stage_ms: dict


@dataclass
class SequenceEstimate:
    """Sequence-level estimates, yielded after the last :class:`PairEstimate`.

    shifts_px (N-1, 2), shifts_valid (N-1,) bool, cumulative_px / flight_line_px /
    correction_px / jitter_px (N, 2) as in :class:`~algorithms.jitter.JitterResult`
    (float64 px), tracks: DataFrame with ``TRACK_COLUMNS``, stage_ms: totals per stage,
    frame_shape_px: (H, W) of the frames, trackers: the ``source`` of each tracker that ran
    ("point" with seeds, "multi"), whether or not it output a row, px_scale: the factor the px
    sizes were scaled by (``detection.px_scale``, :func:`px_scale_factor`, :func:`vehicle_scale`).
    """

    shifts_px: np.ndarray
    shifts_valid: np.ndarray
    cumulative_px: np.ndarray
    flight_line_px: np.ndarray
    correction_px: np.ndarray
    jitter_px: np.ndarray
    tracks: pd.DataFrame
    pipeline: str = ""
    pipeline_hash: str = ""
    stage_ms: dict = field(default_factory=dict)
    frame_shape_px: tuple[int, int] | None = None
    trackers: tuple[str, ...] = ()
    px_scale: float = 1.0


# ---------------------------------------------------------------------------------------------
# the pipeline


def _compensate(g1: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``I1'(x) = I1(M x)``; returns (compensated frame, flow_global, inside)."""
    h, w = g1.shape
    fg = global_flow(M, (h, w))
    if np.allclose(M[2], [0, 0, 1]):
        warped = cv2.warpAffine(g1, M[:2], (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REPLICATE)
    else:
        warped = cv2.warpPerspective(g1, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_REPLICATE)

    xs, ys = np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)
    if is_translation(M):
        # fg's u depends on x only and v on y only: test one row and one column, the same float32 sums
        X, Y = xs + fg[0, :, 0], ys + fg[:, 0, 1]
        inside = (((Y >= -1e-3) & (Y <= h - 1 + 1e-3))[:, None]
                  & ((X >= -1e-3) & (X <= w - 1 + 1e-3))[None, :])
        return warped, fg, inside
    X, Y = xs[None, :] + fg[..., 0], ys[:, None] + fg[..., 1]
    inside = (X >= -1e-3) & (X <= w - 1 + 1e-3) & (Y >= -1e-3) & (Y <= h - 1 + 1e-3)
    return warped, fg, inside


def _compose(M: np.ndarray, w_local: np.ndarray, is_shift: bool) -> np.ndarray:
    """total(x) = M(x + w(x)) - x (for a shift: s + w)."""
    if is_shift:  # each component plus its float32 shift, written once
        w32 = np.ascontiguousarray(w_local, dtype=np.float32)
        out = np.empty(w32.shape, dtype=np.float32)
        _add_shift(w32.reshape(-1), np.float32(M[0, 2]), np.float32(M[1, 2]), out.reshape(-1))
        return out
    h, w = w_local.shape[:2]
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    px, py = xs + w_local[..., 0], ys + w_local[..., 1]
    Z = M[2, 0] * px + M[2, 1] * py + M[2, 2]
    out = np.empty((h, w, 2), dtype=FLOW_DTYPE)
    out[..., 0] = (M[0, 0] * px + M[0, 1] * py + M[0, 2]) / Z - xs
    out[..., 1] = (M[1, 0] * px + M[1, 1] * py + M[1, 2]) / Z - ys
    return out


@numba.njit(cache=True)
def _add_shift(w, su, sv, out) -> None:
    """Flat (2 n,) float32: ``out = w + (su, sv)`` per vector (numpy's two strided adds took 3x as long)."""
    for k in range(w.size // 2):
        out[2 * k] = w[2 * k] + su
        out[2 * k + 1] = w[2 * k + 1] + sv


class _FirstFrames:
    """The first ``k`` frames of a :class:`SharedWork`, gray (its cache serves both runs)."""

    def __init__(self, shared: SharedWork, k: int):
        self._shared, self._k = shared, int(k)

    def __len__(self) -> int:
        return self._k

    def __getitem__(self, i: int) -> np.ndarray:
        if not 0 <= i < self._k:
            raise IndexError(i)
        return self._shared.gray(i)


def _translation(s) -> np.ndarray:
    M = np.eye(3)
    M[0, 2], M[1, 2] = float(s[0]), float(s[1])
    return M


# The px keys of the detection stage and the multi-target tracker that are lengths ("length": times the factor)
# or areas ("area": times its square) in the image, given for a frame whose shorter side is 480 px
# (`detection.px_scale`). A larger frame of the same view sees vehicles, their motion per frame, the camera
# rotation's residual and parallax all larger by the same factor (at 1920x1080 the built-in sizes found 39
# regions a pair on a city scene, 80 % of them on no vehicle, the rotation's residual at the borders:
# benchmarks/heldout_rehearsal.md). Thresholds on velocity differences against the flow's own noise
# (split_px, merge_px, parallax_perp_px) are not scaled: a method's noise in px does not grow with the frame.
PX_SCALED_KEYS = {
    "detection": {"min_magnitude_px": "length", "open_px": "length", "close_px": "length", "min_area_px": "area",
                  "max_area_px": "area", "merge_gap_px": "length", "border_px": "length", "refine_px": "length",
                  "box_reach_px": "length", "gap_split_width_px": "length", "gap_split_length_px": "length",
                  "refine_wide_px": "length", "shadow_lead_px": "length"},
    "long_baseline": {"min_displacement_px": "length", "max_speed_px": "length", "min_box_px": "area"},
    "multi": {"gate_px": "length", "min_travel_px": "length", "sigma_meas_px": "length", "hold_search_px": "length"},
}
PX_REFERENCE_SIDE = 480


# `px_scale: auto` on a frame larger than the reference: the median longer side of the detections on the first
# SIZE_SAMPLE_PAIRS pairs (found with the frame's factor) over VEHICLE_REFERENCE_PX, the same statistic where the
# px sizes were tuned (the presets' cars are 22-36 px long at factor 1; the 1080p city and realistic stand-ins at
# 0.066-0.072 m a pixel give 79-80 px at 2.25, the city seen from twice as high 40 px).
# Within SIZE_SAME_REL of the frame's factor the frame's factor stays: the median of a few pairs' boxes scatters by
# 10-20 % (vehicles' parts, two joined), no evidence that the frame's assumption is wrong (the 960x540 `city`, right
# at its 1.125, was given 1.0-1.1 by it: MOTA -0.02 to +0.01 by pipeline).
# Cars under SIZE_SAME_REL of the reference take the factor below 1: the square root of the sample's factor, at least
# VEHICLE_SCALE_MIN. The 1080p city-wide worlds (cars 41 px in the sample, factor 1.17) shrunk to 960x540 (JPEG 85;
# cars 20-22 px in the sample, 0.57-0.63) scored dis MOTA 0.17 pooled at their frame's 1.125, and 0.22 / 0.35 /
# 0.41 / 0.38 / 0.34 at 1.0 / 0.88 / 0.75 / 0.55 / 0.4 (a car creeping 0.5 px a frame at 1080p creeps 0.25 px
# there, and the detections went from 1,808 in 100 frames to 478 at 1.125); the sample's factor itself gave 0.37
# (pyramidal-hs 0.29 -> 0.36, pyramidal-lk 0.30 -> 0.36, farneback 0.28 -> 0.32), its square root 0.41 (0.31, 0.32,
# 0.29: the best pipeline gains most with the root, the others less than with the factor itself). Shrunk to
# 1344x756 (samples 26-29 px, 0.74-0.83) they scored 0.477 at 1 (the old floor), 0.452 at the sample's factor,
# 0.469 at its root, 0.485 as here (the one at 0.83 keeps 1); pyramidal-hs there 0.381 at 1 and 0.355 as here (its
# world 3 samples under 0.8 and loses 0.06), a cost this rule has at that size. Frames no larger than the reference
# keep 1 (Pipeline.run samples only larger ones): the presets' cars, on which the sizes were tuned at 1, sample
# 23-33 px.
VEHICLE_REFERENCE_PX = 35.0
VEHICLE_SCALE_MIN = 0.5
SIZE_SAMPLE_PAIRS = 8
SIZE_SAMPLE_MIN = 10
SIZE_SAME_REL = 0.8


def px_scale_factor(setting, frame_shape) -> float:
    """The factor of :data:`PX_SCALED_KEYS` for a frame ``(H, W)`` as its size alone sets it: ``"auto"`` and
    ``"frame"``, the shorter side over :data:`PX_REFERENCE_SIDE` (1 at 640x480, 2.25 at 1920x1080), never below
    1 (a smaller frame is more often a crop than a wider view, and the flow's noise in px, which the sizes as
    given are set against, does not shrink with it); a number, itself. :meth:`Pipeline.run` lowers ``"auto"``
    on a larger frame where the sequence's vehicles are smaller than that assumes (:func:`vehicle_scale`),
    below 1 too where they are smaller than the reference's."""
    if setting in ("auto", "frame"):
        return max(1.0, min(int(frame_shape[0]), int(frame_shape[1])) / PX_REFERENCE_SIDE)
    return float(setting)


def vehicle_scale(long_sides_px, frame_factor: float) -> float:
    """The factor ``px_scale: auto`` takes from the longer sides (px) of detections found at ``frame_factor``: their
    median over :data:`VEHICLE_REFERENCE_PX`, where it is under :data:`SIZE_SAME_REL` times ``frame_factor``; else
    (and with fewer than :data:`SIZE_SAMPLE_MIN` sides) ``frame_factor`` itself. A median under the reference
    gives 1 within :data:`SIZE_SAME_REL` of it, and below that its factor's square root, at least
    :data:`VEHICLE_SCALE_MIN`.

    A frame of 1920x1080 is not always the view of 640x480 at a higher resolution: a real clip of a junction
    from higher up holds more vehicles, each fewer pixels long (at 0.13 m a pixel a car is 35-40 px, half what
    the frame's factor expects), and the factor's size limits then reject them (a car's box under the long
    baseline's ``min_box_px``) while its reach joins neighbours. Cars under the reference's 35 px (a clip at
    half that resolution) also move fewer pixels a frame, and a slow one stays under the motion thresholds of
    factor 1: the factor follows them below 1, but only half the way on a log scale, since the flow's noise in
    px, which the motion thresholds are also set against, does not shrink with the cars. Never above the frame's
    factor: a detection of a vehicle's part, or of two joined, must not raise the sizes beyond what the frame
    already allows.
    """
    sides = np.asarray(long_sides_px, dtype=np.float64)
    if sides.size < SIZE_SAMPLE_MIN:
        return float(frame_factor)
    factor = float(np.median(sides)) / VEHICLE_REFERENCE_PX
    if factor >= SIZE_SAME_REL * frame_factor:
        return float(frame_factor)
    if factor >= SIZE_SAME_REL:  # within the scatter of 1 too: the sizes as tuned
        return float(max(1.0, factor))
    # below: between the vehicles' factor (the sizes') and the flow noise's 1 (their geometric mean)
    return float(max(VEHICLE_SCALE_MIN, np.sqrt(factor)))


def scale_px(params: Mapping, kinds: Mapping[str, str], factor: float) -> dict:
    """``params`` with the keys of ``kinds`` times ``factor`` (lengths) or its square (areas); integers stay
    integers (at least 1 where they were), None stays None."""
    out = dict(params)
    if factor == 1.0:
        return out
    for key, kind in kinds.items():
        v = out.get(key)
        if v is None or isinstance(v, bool):
            continue
        scaled = v * (factor if kind == "length" else factor * factor)
        out[key] = max(1 if v >= 1 else 0, int(round(scaled))) if isinstance(v, (int, np.integer)) else float(scaled)
    return out


def _ms(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3


@dataclass(frozen=True)
class Pipeline:
    """A validated pipeline description; build with :meth:`from_dict`, run with :meth:`run`.

    The dict (as YAML holds it)::

        name: thesis-lk
        description: one line
        global_motion: {method: ncc_global_motion, params: {max_shift: 16, subpixel: false}}
        jitter: {model: line | smooth, window_frames: 15, polyorder: 2, iterations: 1}   # or null
        compensation: none | shift | affine | homography     # or {model: affine, params: {...}}
        flow: {method: lucas_kanade, params: {window: 15}}    # any name registered as a flow stage
        threshold: {direction: -90, tolerance_deg: 45, min_magnitude_px: 0.0, max_magnitude_px: null}  # or null
        spatial: true        # eq. 4.11
        temporal: true       # eq. 4.12
        detection: {field: local | filtered, gsd_m_per_px: null, <keys of algorithms.detection.DETECTION_DEFAULTS>,
                    long_baseline: {<keys of algorithms.long_baseline.LONG_BASELINE_DEFAULTS>}}  # frames: 0 is off
        tracking: {point: true | {field: filtered | local, kalman: {x0, p0, q, r}, recentre_px: null | 12.0,
                                  filter: flow | position, sigma_accel_px: 0.5, sigma_meas_px: 1.0,
                                  correlation: null | {template_px: 15, search_px: 3, min_ncc: 0.5, renew_ncc: 0.8}},
                   multi: null | {<keys of algorithms.tracking.MULTI_DEFAULTS>}}

    Method parameters are checked against the function's keyword parameters.
    Unknown keys, unknown names and wrong types raise :class:`PipelineError`
    naming the field. The point tracker samples the filtered local flow as
    Appendix B does (``field: filtered``; the pixel-by-pixel temporal filter
    shrinks the flow of targets moving more than their size per frame) or the
    raw local flow (``field: local``). ``recentre_px`` moves the point each frame to the
    centroid of the region that moves like it before sampling (closing the loop that
    flow integration leaves open; null: the thesis's open loop); ``filter: flow`` is the
    thesis's scalar Kalman filter on the sampled flow (``kalman``), ``filter: position``
    a constant-velocity filter of the positions in the ground frame (``sigma_accel_px``,
    ``sigma_meas_px``). ``correlation`` places the point by NCC of its template around the
    flow's prediction (thesis 4.1, :class:`~algorithms.tracking.PointTracker`; null: flow
    alone). ``jitter.iterations > 1`` re-measures the global shifts on
    the corrected frames (one more pass over the frames per round).
    """

    config: Mapping[str, Any]

    def __hash__(self) -> int:
        return hash(self.hash)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Pipeline":
        """Validate ``d`` (see the class docstring) and resolve its defaults; raises :class:`PipelineError`."""
        return cls(resolve_pipeline(d))

    def to_dict(self) -> dict:
        """The resolved description (defaults filled), a fresh copy."""
        return copy.deepcopy(dict(self.config))

    @property
    def name(self) -> str:
        return self.config["name"]

    @property
    def description(self) -> str:
        return self.config["description"]

    @property
    def hash(self) -> str:
        return pipeline_hash(self.config)

    # -- pass 1 -----------------------------------------------------------------------------

    def _global_shifts(self, shared: SharedWork, n: int, correction: np.ndarray | None = None):
        gm = self.config["global_motion"]
        return shared.global_shifts(gm["method"], gm["params"], correction,
                                    lambda: self._measure_shifts(shared, n, correction))

    def _measure_shifts(self, shared: SharedWork, n: int, correction: np.ndarray | None):
        gm = self.config["global_motion"]
        fn, params = get_stage("global_motion", gm["method"]), gm["params"]
        shifts, valid, times = np.zeros((n - 1, 2)), np.zeros(n - 1, bool), np.zeros(n - 1)

        def load(i):
            g = shared.gray(i)
            if correction is not None:  # frame i displaced by correction[i]: I'(x) = I(x - c)
                g, _, _ = _compensate(g, _translation(-correction[i]))
            return g

        g0 = load(0)
        for t in range(n - 1):
            g1 = load(t + 1)
            t0 = time.perf_counter()
            res = fn(g0, g1, **params)
            times[t] = _ms(t0)
            shifts[t], valid[t] = res.shift_px, bool(res.valid)
            g0 = g1
        if not valid.all():
            # no clear peak: assume the flight went on at its typical speed
            shifts[~valid] = np.median(shifts[valid], axis=0) if valid.any() else 0.0
        return shifts, valid, times

    # -- the px scale from the vehicles' size ---------------------------------------------------

    def _vehicle_scale(self, shared: SharedWork, n: int, frame_factor: float, gsd_m_per_px) -> float:
        """:func:`vehicle_scale` of the detections of this pipeline (at ``frame_factor``, without the long baseline
        and the trackers) on the first :data:`SIZE_SAMPLE_PAIRS` pairs."""
        d = self.to_dict()
        d["detection"]["px_scale"] = float(frame_factor)
        d["detection"]["long_baseline"].update(frames=0, slow_frames=0)
        d["tracking"] = {"point": False, "multi": None}
        first = _FirstFrames(shared, min(n, SIZE_SAMPLE_PAIRS + 1))
        sides = [max(det.x1_px - det.x0_px, det.y1_px - det.y0_px) + 1.0
                 for est in Pipeline.from_dict(d).run(first, gsd_m_per_px=gsd_m_per_px)
                 if isinstance(est, PairEstimate) for det in est.detections]
        return vehicle_scale(sides, frame_factor)

    # -- run ---------------------------------------------------------------------------------

    def run(self, frames: Sequence, *, seeds: Sequence[tuple] | None = None, shared: SharedWork | None = None,
            gsd_m_per_px: float | None = None) -> Iterator[PairEstimate | SequenceEstimate]:
        """Run on ``frames`` (``len`` and ``frames[i]``), yielding a PairEstimate per pair, then a SequenceEstimate.

        Parameters
        ----------
        frames : indexable of (H, W) or (H, W, 3) arrays
            Read on demand; at least two frames.
        seeds : sequence of (vehicle_id, x_px, y_px), optional
            Pixels of frame 0 for the thesis point tracker (``tracking.point``).
        shared : SharedWork, optional
            What the pipelines run on these same ``frames`` compute once (gray frames, pass-1
            shifts, compensated frames; :mod:`algorithms.shared_work`). Without it the run has
            one of its own, so a frame is still decoded once for both passes. The estimates
            are the same, bit for bit, with or without it.
        gsd_m_per_px : float, optional
            Ground sampling distance of the frames, m/px (e.g. from a sequence's intrinsics and
            altitude): detections get an area in m^2 and the m^2 size limits apply. Default:
            the pipeline's ``detection.gsd_m_per_px`` (null: sizes in px only).

        Yields
        ------
        PairEstimate
            One per pair t = 0 .. N-2, in order, each as soon as its temporal window is complete.
        SequenceEstimate
            Exactly one, last. Consumers tell the two apart with ``isinstance`` (two types,
            two roles: the pair's fields are scored and dropped, the sequence's paths and
            tracks are scored once).
        """
        n = len(frames)
        if n < 2:
            raise ValueError(f"frames: expected at least 2 frames, got {n}")
        if shared is None:
            shared = SharedWork(frames)
        elif shared.frames is not frames:
            raise ValueError("shared: expected the SharedWork made for these frames (SharedWork(frames))")
        cfg = self.config
        totals: dict[str, float] = {}
        # every stage is resolved through algorithms.registry, the built-ins and plugins' alike
        remove_jitter, threshold_flow = _stage("jitter"), _stage("threshold")
        spatial_filter, temporal_filter, detect_vehicles = (_stage("spatial"), _stage("temporal"),
                                                            _stage("detection"))
        point_tracker, multi_tracker = get_stage("tracking", "point"), get_stage("tracking", "multi")

        # pass 1: global shifts of all pairs, jitter over the whole path
        shifts, shifts_valid, gm_ms = self._global_shifts(shared, n)
        t0 = time.perf_counter()
        if cfg["jitter"] is not None:
            j = cfg["jitter"]
            jit = remove_jitter(
                shifts, model=j["model"], window_frames=j["window_frames"], polyorder=j["polyorder"],
                iterations=j["iterations"],
                reestimate=(lambda corr: self._global_shifts(shared, n, corr)[0]) if j["iterations"] > 1 else None)
            cumulative, line, correction, jitter = (jit.cumulative_px, jit.flight_line_px, jit.correction_px,
                                                    jit.jitter_px)
        else:
            cumulative = cumulative_path(shifts)
            line, correction, jitter = cumulative.copy(), np.zeros_like(cumulative), np.zeros_like(cumulative)
        totals["jitter"] = _ms(t0)

        flow_fn, flow_params = get_stage("flow", cfg["flow"]["method"]), cfg["flow"]["params"]
        comp = cfg["compensation"]
        thr, det_cfg, track_cfg = cfg["threshold"], cfg["detection"], cfg["tracking"]
        px = px_scale_factor(det_cfg["px_scale"], shared.gray(0).shape)
        if det_cfg["px_scale"] == "auto" and px > 1.0:  # a frame of the reference's size keeps 1: no sample
            px = self._vehicle_scale(shared, n, px, gsd_m_per_px)
        det_params = scale_px({k: det_cfg[k] for k in DETECTION_DEFAULTS}, PX_SCALED_KEYS["detection"], px)
        gsd = det_cfg["gsd_m_per_px"] if gsd_m_per_px is None else float(gsd_m_per_px)
        long_cfg = scale_px(det_cfg["long_baseline"], PX_SCALED_KEYS["long_baseline"], px)
        # frames t-k .. t-1 (gray, the pair's model), oldest first: the long baseline's frame t-k and models
        history: deque = deque(maxlen=max(1, long_cfg["frames"], long_cfg["slow_frames"]))
        # each baseline's chains of what its parallax tests rejected (long_baseline.parallax_trend; ParallaxChains)
        parallax_chains = ({stage: ParallaxChains(min_change=long_cfg["parallax_trend"],
                                                  min_frames=long_cfg["parallax_trend_frames"],
                                                  snr=long_cfg["parallax_trend_snr"])
                            for stage in ("frames", "slow_frames")} if long_cfg["parallax_trend"] > 0 else {})
        # (box area px^2, speed px/frame) of the detections so far: the typical mover (detection.sequence_size)
        size_cfg = det_cfg["sequence_size"]
        sizes: deque = deque(maxlen=size_cfg["history"])
        relative_sizes = size_cfg["small_rel"] > 0 or size_cfg["large_rel"] > 0
        # no ground sampling distance: the m^2 limits at the one that makes the typical mover vehicle_m2 (sequence_size)
        gsd_from_movers = gsd is None and size_cfg["vehicle_m2"] is not None
        # one sun over the clip (detection.shadow_scope clip): every pair's shadow leans and motions in frame 0's
        # axes, and the camera's yaw from frame 0 to the pair's frame t (the pair models' turns summed)
        clip_shadow = det_params["shadow_trim_rel"] > 0 and det_params["shadow_scope"] == "clip"
        shadow_votes: list[tuple[np.ndarray, np.ndarray]] = []
        shadow = {"direction": np.zeros(2)}  # the clip's shadow so far, in frame 0's axes (zero: none)
        shadow_kw = dict(max_rel=det_params["shadow_trim_rel"], ratio_lo=det_params["shadow_ratio_lo"],
                         ratio_hi=det_params["shadow_ratio_hi"], lead_px=det_params["shadow_lead_px"])
        yaw = {"rad": 0.0}
        points = []
        point_cfg = track_cfg["point"] if isinstance(track_cfg["point"], Mapping) else {}
        point_field = "flow_local" if point_cfg.get("field") == "local" else "filtered"
        if track_cfg["point"] and seeds:
            kal = point_cfg.get("kalman")
            points = [point_tracker(float(x), float(y), track_id=i, seed_vehicle_id=vid, kalman=kal,
                                   recentre_px=point_cfg.get("recentre_px"), correlation=point_cfg.get("correlation"),
                                   position_filter={k: point_cfg[k] for k in ("sigma_accel_px", "sigma_meas_px")}
                                   if point_cfg.get("filter") == "position" else None)
                      for i, (vid, x, y) in enumerate(seeds)]
        multi = (multi_tracker(**scale_px(track_cfg["multi"], PX_SCALED_KEYS["multi"], px))
                 if track_cfg["multi"] is not None else None)

        def estimate_pair(t: int, g0: np.ndarray, g1: np.ndarray) -> dict:
            ms: dict[str, float] = {"global_motion": float(gm_ms[t])}
            t0 = time.perf_counter()
            M, is_shift = _translation(shifts[t]), True
            if comp["model"] in ("affine", "homography"):
                model = affine_global_motion(g0, g1, model=comp["model"], **comp["params"])
                if model.valid:  # else keep the pass-1 shift
                    M, is_shift = np.asarray(model.matrix, dtype=np.float64), False
            if comp["model"] == "none":
                g1c, inside, fg = g1, np.ones(g0.shape, bool), global_flow(M, g0.shape)
            else:
                g1c, fg, inside = shared.compensated(t, comp["model"], M, lambda: _compensate(g1, M))
            ms["compensation"] = _ms(t0)
            t0 = time.perf_counter()
            w_local, valid = flow_fn(g0, g1c, **flow_params)
            ms["flow"] = _ms(t0)
            t0 = time.perf_counter()
            total = w_local.astype(np.float32, copy=True) if comp["model"] == "none" else _compose(M, w_local, is_shift)
            valid = np.asarray(valid, bool) & inside
            ms["compose"] = _ms(t0)
            t0 = time.perf_counter()
            if thr is not None:
                cleaned, _ = threshold_flow(w_local, valid=valid, **thr)
            else:
                cleaned = zero_outside(w_local, valid)  # np.where's values, one pass
            ms["threshold"] = _ms(t0)
            t0 = time.perf_counter()
            if cfg["spatial"]:
                cleaned = spatial_filter(cleaned)
            ms["spatial"] = _ms(t0)
            return {"index": t, "flow_global": fg, "flow_total": total, "flow_local": w_local, "valid": valid,
                    "cleaned": cleaned, "stage_ms": ms, "gray": (g0, g1), "compensated": (g0, g1c),
                    "global_px": shifts[t] if is_shift else fg,
                    "matrix": M if comp["model"] != "none" else np.eye(3)}

        def finish(prev: dict | None, cur: dict, nxt: dict | None) -> PairEstimate:
            ms, t = cur["stage_ms"], cur["index"]
            t0 = time.perf_counter()
            if cfg["temporal"]:
                filtered = temporal_filter(prev and prev["cleaned"], cur["cleaned"], nxt and nxt["cleaned"])
            else:
                filtered = cur["cleaned"]
            ms["temporal"] = _ms(t0)
            t0 = time.perf_counter()
            det_field = filtered if det_cfg["field"] == "filtered" else cur["flow_local"]
            mask = motion_mask(det_field, cur["valid"], det_cfg["min_magnitude_px"])
            # frame t-1 in frame t's pixels, I_{t-1}(M^-1 x) (cv2 inverts M without WARP_INVERSE_MAP): the
            # detection's box test over three frames
            before = None
            if prev is not None and "gray0" in prev and det_cfg["box_three_frames"] and det_cfg["box_from_frames"]:
                gp, Mp = prev["gray0"], prev["matrix"]
                size = (gp.shape[1], gp.shape[0])
                before = (cv2.warpAffine(gp, Mp[:2], size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                          if np.allclose(Mp[2], [0, 0, 1]) else
                          cv2.warpPerspective(gp, Mp, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
            gsd_pair = gsd
            if gsd_from_movers and len(sizes) >= size_cfg["min_history"]:
                gsd_pair = equivalent_gsd(typical_mover([a for a, _ in sizes], [v for _, v in sizes])[0],
                                          size_cfg["vehicle_m2"])
            dets = detect_vehicles(det_field, cur["valid"], global_flow_px=cur["global_px"],
                                   frames=cur["compensated"], prev_frame=before, gsd_m_per_px=gsd_pair, **det_params)
            if clip_shadow and dets:
                # one sun: the pair's votes in frame 0's axes (the long pair's boxes, found over six frames, do not vote)
                _, lean = shadow_lean(cur["compensated"][0], dets, **shadow_kw)
                motion = np.array([(d.u_px, d.v_px) for d in dets], dtype=np.float64)
                shadow_votes.append((turn(lean, -yaw["rad"]), turn(motion, -yaw["rad"])))
                shadow["direction"] = clip_shadow_direction(np.concatenate([v[0] for v in shadow_votes]),
                                                            np.concatenate([v[1] for v in shadow_votes]),
                                                            vote=det_params["shadow_vote"],
                                                            min_votes=det_params["shadow_clip_min_votes"])
            # the clip's direction in frame t's axes
            shadow_at_t = turn(shadow["direction"], yaw["rad"])
            yaw["rad"] += image_yaw_rad(cur["matrix"])
            def slow_movers(k: int, stage: str) -> list:
                # frame t against frame t-k registered into it (algorithms.long_baseline); frame t-m, m = k // 2:
                # the consistency of the creep (long_baseline_detections' mid_frame)
                models = [m for _, m in list(history)[-k:]]
                C = compose_models(models)
                g_old, inside = register_into(history[-k][0], C, margin_px=det_params["border_px"])
                g_t = cur["gray"][0]
                m_mid = k // 2 if long_cfg["mid_check"] else 0
                C_mid = compose_models(models[-m_mid:]) if m_mid else None
                w_long, v_long = flow_fn(g_t, g_old, **{**flow_params, **long_cfg["flow_params"]})
                fix = (registration_fix(w_long, np.asarray(v_long, bool) & inside, tol_px=long_cfg["reregister_px"])
                       if long_cfg["reregister_px"] > 0 else None)
                if fix is not None:
                    # a camera that turns: frame t-k (and t-m, by m / k of the fix) registered again, the flow again
                    C = np.linalg.inv(fix) @ C
                    g_old, inside = register_into(history[-k][0], C, margin_px=det_params["border_px"])
                    if m_mid:
                        C_mid = np.linalg.inv(np.eye(3) + (fix - np.eye(3)) * (m_mid / k)) @ C_mid
                    w_long, v_long = flow_fn(g_t, g_old, **{**flow_params, **long_cfg["flow_params"]})
                mid = (register_into(history[-m_mid][0], C_mid)[0], m_mid) if m_mid else None
                return long_baseline_detections(
                    w_long, np.asarray(v_long, bool) & inside, baseline_frames=k, frames=(g_t, g_old),
                    composed=C, min_displacement_px=long_cfg["min_displacement_px"],
                    max_speed_px=long_cfg["max_speed_px"], ground_model=long_cfg["ground_model"],
                    gsd_m_per_px=gsd_pair, detection_params=det_params, pair_flow=cur["flow_local"],
                    pair_valid=cur["valid"], min_box_px=long_cfg["min_box_px"],
                    parallax_max_ratio=long_cfg["parallax_max_ratio"], mid_frame=mid,
                    parallax_chains=parallax_chains.get(stage), frame=t)

            # what a long pair kept only because its parallax chain's ratio changed (ParallaxChains): added last, where
            # nothing else lies, and never in place of a pair's box (a moving car's long box holds its trail)
            by_trend: list[tuple[int, list]] = []

            def slow_movers_kept(k: int, stage: str) -> list:
                found, chains = slow_movers(k, stage), parallax_chains.get(stage)
                if chains is None:
                    return found
                kept = [chains.kept(d) for d in found]
                by_trend.append((k, [d for d, x in zip(found, kept) if x]))
                return [d for d, x in zip(found, kept) if not x]

            if long_cfg["frames"] >= 2 and len(history) >= 2:
                # slow movers over the first baseline (over the frames there are, at the sequence's start)
                k = min(len(history), long_cfg["frames"])
                dets = merge_detections(dets, slow_movers_kept(k, "frames"), baseline_frames=k,
                                        nms_iou=det_params["nms_iou"], max_speed_px=long_cfg["max_speed_px"],
                                        replace_rel=long_cfg["replace_rel"])
            k = min(len(history), long_cfg["slow_frames"])
            if long_cfg["slow_frames"] and k >= min(long_cfg["slow_frames"], long_cfg["frames"] + 2):
                # slower ones over the second, longer baseline, where none of the above lies (at the sequence's start
                # over the frames there are, once they are two more than the first baseline's)
                dets = merge_detections(dets, slow_movers_kept(k, "slow_frames"), baseline_frames=k,
                                        nms_iou=det_params["nms_iou"], max_speed_px=long_cfg["max_speed_px"],
                                        replace_rel=0)
            for k, kept in by_trend:
                dets = merge_detections(dets, kept, baseline_frames=k, nms_iou=det_params["nms_iou"],
                                        max_speed_px=long_cfg["max_speed_px"], replace_rel=0)
            if clip_shadow and dets and np.any(shadow_at_t):
                # the merged boxes lose their shadow: a slow mover's box from the long pair holds it as the pair's
                # does, and trimmed before the merge the pair's box no longer replaced or suppressed the long pair's
                # of the same vehicle (two boxes, a false positive)
                bands, _ = shadow_lean(cur["compensated"][0], dets, **shadow_kw)
                dets = trim_toward(dets, bands, shadow_at_t, diagonal_deg=det_params["shadow_diagonal_deg"])
            if det_params["lane_fill_rel"] > 0 and dets:
                # a uniform roof the flow could not see: the boxes grow along their lanes over it (detection.fill_lane)
                dets = fill_lane(cur["compensated"][0], dets, next_gray=cur["compensated"][1],
                                 max_rel=det_params["lane_fill_rel"], line_frac=det_params["lane_fill_line"],
                                 road_k=det_params["lane_fill_road_k"])
            if relative_sizes or gsd_from_movers:
                # pedestrians, posts, roofs: far from the size of the sequence's vehicles (algorithms.sequence_size)
                sizes.extend(((d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1), math.hypot(d.u_px, d.v_px))
                             for d in dets)
                if relative_sizes and len(sizes) >= size_cfg["min_history"]:
                    area, speed = typical_mover([a for a, _ in sizes], [v for _, v in sizes])
                    keep = relative_size_keep(dets, area, speed, small_rel=size_cfg["small_rel"],
                                              slow_rel=size_cfg["slow_rel"], large_rel=size_cfg["large_rel"])
                    dets = [d for d, k in zip(dets, keep) if k]
            if det_params["nms_inside"] > 0 and dets:
                # a part inside its mover's box: NMS by IoU keeps it, the lane fill may grow two parts into one
                dets = drop_parts_inside(dets, det_params["nms_inside"], merge_px=det_params["merge_px"],
                                         merge_rel=det_params["merge_rel"])
            ms["detection"] = _ms(t0)
            t0 = time.perf_counter()
            for p in points:
                p.step(shifts[t], filtered if point_field == "filtered" else cur["flow_local"], cur["valid"],
                       frames=cur["gray"])
            if multi is not None:
                multi.step(t, _in_path_frame(dets, det_field, cur["valid"], det_cfg["ground_model"]),
                           offset_px=cumulative[t], image=cur["gray"][0])
            ms["tracking"] = _ms(t0)
            for k, v in ms.items():
                totals[k] = totals.get(k, 0.0) + v
            return PairEstimate(index=t, global_shift_px=shifts[t].copy(), global_valid=bool(shifts_valid[t]),
                                flow_global=cur["flow_global"], flow_total=cur["flow_total"],
                                flow_local=cur["flow_local"], flow_filtered=filtered, valid=cur["valid"],
                                motion_mask=mask, detections=dets, stage_ms=ms)

        # pass 2: pair by pair, a window of three pairs for the temporal filter
        window: list[dict] = []  # [pair t-1 (or nothing), pair t, pair t+1]
        prev_done: dict | None = None
        g0 = shared.gray(0)
        frame_shape = (int(g0.shape[0]), int(g0.shape[1]))
        for t in range(n - 1):
            g1 = shared.gray(t + 1)
            window.append(estimate_pair(t, g0, g1))
            g0 = g1
            if len(window) == 2:
                cur, nxt = window
                yield finish(prev_done, cur, nxt)
                # all the next pair's temporal filter and box test need
                prev_done = {"cleaned": cur["cleaned"], "gray0": cur["gray"][0], "matrix": cur["matrix"]}
                history.append((cur["gray"][0], cur["matrix"]))
                window = [nxt]
                del cur, nxt
        yield finish(prev_done, window[0], None)
        if multi is not None:
            multi.extrapolate(n - 1, offset_px=cumulative[n - 1], image=g0)
        del window, prev_done, g0

        rows = [r for p in points for r in p.rows()] + (multi.rows() if multi is not None else [])
        tracks = pd.DataFrame(rows, columns=list(TRACK_COLUMNS))
        box_cols = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]
        tracks[box_cols] = boxes_in_image(tracks[box_cols].to_numpy(np.float64), frame_shape)
        yield SequenceEstimate(shifts_px=shifts, shifts_valid=shifts_valid, cumulative_px=cumulative,
                               flight_line_px=line, correction_px=correction, jitter_px=jitter, tracks=tracks,
                               pipeline=self.name, pipeline_hash=self.hash, frame_shape_px=frame_shape,
                               stage_ms={"global_motion": float(gm_ms.sum()), **totals},
                               trackers=(("point",) if points else ()) + (("multi",) if multi is not None else ()),
                               px_scale=float(px))


# ---------------------------------------------------------------------------------------------
# built-in pipelines: algorithms/pipelines/<name>.yaml, name -> the plain dict a YAML suite would hold

PIPELINES: dict[str, dict] = builtin_pipelines()


def get_pipeline(name: str) -> Pipeline:
    """The built-in pipeline ``name``, validated."""
    if name not in PIPELINES:
        raise KeyError(f"unknown pipeline {name!r}; valid: {', '.join(sorted(PIPELINES))}")
    return Pipeline.from_dict(PIPELINES[name])
