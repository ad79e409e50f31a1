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
read with ``frames[i]`` when needed; at most two frames and three pairs of
fields are held, whatever the sequence length.

Composition: with the shift ``s``, compensated frame ``I1'(x) = I1(x + s)`` and
local flow ``w`` (``I1'(x + w) ~ I0(x)``) give ``total = s + w``. With a matrix
``M`` mapping frame-t points to frame-t+1 points, ``I1'(x) = I1(M x)`` and
``total(x) = M(x + w(x)) - x``.
"""

from __future__ import annotations

import copy
import hashlib
import inspect
import json
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import pandas as pd

import algorithms.horn_schunck_flow  # noqa: F401  (fills FLOW_METHODS)
import algorithms.lucas_kanade_flow  # noqa: F401
import algorithms.reference  # noqa: F401
import algorithms.tv_l1_flow  # noqa: F401
from algorithms.filters import spatial_filter, temporal_filter, threshold_flow
from algorithms.flow import FLOW_DTYPE, as_gray
from algorithms.global_motion import affine_global_motion, global_flow, ncc_global_motion
from algorithms.jitter import JITTER_MODELS, cumulative_path, remove_jitter
from algorithms.registry import FLOW_METHODS
from algorithms.tracking import TRACK_COLUMNS, MultiTargetTracker, PointTracker, detect_moving_objects

__all__ = ["Pipeline", "PipelineError", "PairEstimate", "SequenceEstimate", "PIPELINES",
           "GLOBAL_MOTION_METHODS", "COMPENSATION_MODELS", "get_pipeline", "pipeline_hash"]

# Global shift methods usable in pass 1, by the name YAML uses: (frame0, frame1, **params) -> .shift_px, .valid
GLOBAL_MOTION_METHODS: dict[str, Callable] = {"ncc_global_motion": ncc_global_motion}
COMPENSATION_MODELS = ("none", "shift", "affine", "homography")


class PipelineError(ValueError):
    """A pipeline description is invalid; the message names the field."""


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
        ``valid & |flow_filtered| >= detection.min_magnitude_px``.
    detections : list of (x_px, y_px, area_px)
        Connected regions of ``motion_mask`` of at least ``detection.min_area_px``.
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
    frame_shape_px: (H, W) of the frames.
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


# ---------------------------------------------------------------------------------------------
# validation

_DEFAULTS: dict[str, Any] = {
    "description": "",
    "global_motion": {"method": "ncc_global_motion", "params": {}},
    "jitter": {"model": "line"},
    "compensation": "shift",
    "threshold": None,
    "spatial": False,
    "temporal": False,
    "detection": {},
    "tracking": {"point": True, "multi": None},
}
_TOP_KEYS = ("name", "description", "global_motion", "jitter", "compensation", "flow", "threshold",
             "spatial", "temporal", "detection", "tracking")
_JITTER_DEFAULTS = {"model": "line", "window_frames": 15, "polyorder": 2, "iterations": 1}
_DETECTION_DEFAULTS = {"min_magnitude_px": 0.5, "min_area_px": 20}
_THRESHOLD_DEFAULTS = {"direction": None, "tolerance_deg": 45.0, "min_magnitude_px": 0.0, "max_magnitude_px": None}
_MULTI_DEFAULTS = {"gate_px": 8.0, "birth_hits": 3, "death_misses": 3, "sigma_accel_px": 0.5,
                   "sigma_meas_px": 1.0, "sigma_vel0_px": 5.0}
_KALMAN_KEYS = ("x0", "p0", "q", "r")


def _type_name(v: Any) -> str:
    return type(v).__name__


def _check_value(where: str, v: Any, default: Any) -> Any:
    """Check ``v`` against the type of ``default`` (None default: any finite JSON-like value)."""
    if isinstance(v, float) and not math.isfinite(v):
        raise PipelineError(f"{where}: expected a finite number, got {v}")
    if isinstance(default, bool):
        if not isinstance(v, bool):
            raise PipelineError(f"{where}: expected true/false, got {v!r} ({_type_name(v)})")
    elif isinstance(default, int):
        if isinstance(v, bool) or not isinstance(v, int):
            raise PipelineError(f"{where}: expected an integer, got {v!r} ({_type_name(v)})")
    elif isinstance(default, float):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise PipelineError(f"{where}: expected a number, got {v!r} ({_type_name(v)})")
        v = float(v)
    elif isinstance(default, str):
        if not isinstance(v, str):
            raise PipelineError(f"{where}: expected a string, got {v!r} ({_type_name(v)})")
    elif isinstance(v, (list, tuple)):
        v = [_check_value(f"{where}[{i}]", x, None) for i, x in enumerate(v)]
    return v


def _mapping(where: str, v: Any) -> dict:
    if not isinstance(v, Mapping):
        raise PipelineError(f"{where}: expected a mapping, got {v!r} ({_type_name(v)})")
    return dict(v)


def _fill(where: str, given: Any, defaults: Mapping) -> dict:
    """Defaults overlaid by ``given``; unknown keys and wrong types are errors."""
    given = _mapping(where, given)
    for k in given:
        if k not in defaults:
            raise PipelineError(f"{where}.{k}: unknown key; valid: {', '.join(defaults)}")
    return {k: _check_value(f"{where}.{k}", given[k], d) if k in given else copy.deepcopy(d)
            for k, d in defaults.items()}


def _method_params(where: str, fn: Callable, params: Any, *, skip: tuple[str, ...] = ()) -> dict:
    """Check ``params`` against the keyword parameters of ``fn`` (after its two frames)."""
    params = _mapping(where, params)
    sig = list(inspect.signature(fn).parameters.values())[2:]
    accepted = {p.name: p.default for p in sig if p.name not in skip
                and p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)}
    out = {}
    for k, v in params.items():
        if k not in accepted:
            raise PipelineError(f"{where}.{k}: unknown parameter of {fn.__name__}; valid: {', '.join(accepted)}")
        d = accepted[k]
        out[k] = _check_value(f"{where}.{k}", v, None if d is inspect.Parameter.empty else d)
    return out


def _method_section(where: str, v: Any, table: Mapping[str, Callable], what: str,
                    skip: tuple[str, ...] = ()) -> dict:
    sec = _mapping(where, v)
    for k in sec:
        if k not in ("method", "params"):
            raise PipelineError(f"{where}.{k}: unknown key; valid: method, params "
                                f"(method parameters go under {where}.params)")
    if "method" not in sec:
        raise PipelineError(f"{where}.method: missing; valid: {', '.join(sorted(table)) or '(none registered)'}")
    name = sec["method"]
    if not isinstance(name, str) or name not in table:
        raise PipelineError(f"{where}.method: unknown {what} {name!r}; valid: "
                            f"{', '.join(sorted(table)) or '(none registered)'}")
    return {"method": name, "params": _method_params(f"{where}.params", table[name], sec.get("params", {}),
                                                    skip=skip)}


def _validate(d: Any) -> dict:
    d = _mapping("pipeline", d)
    for k in d:
        if k not in _TOP_KEYS:
            raise PipelineError(f"{k}: unknown key; valid: {', '.join(_TOP_KEYS)}")
    for k in ("name", "flow"):
        if k not in d:
            raise PipelineError(f"{k}: missing (required)")
    out: dict[str, Any] = {}
    if not isinstance(d["name"], str) or not d["name"]:
        raise PipelineError(f"name: expected a non-empty string, got {d['name']!r}")
    out["name"] = d["name"]
    out["description"] = _check_value("description", d.get("description", ""), "")
    out["global_motion"] = _method_section("global_motion", d.get("global_motion", _DEFAULTS["global_motion"]),
                                           GLOBAL_MOTION_METHODS, "global motion method")
    j = d.get("jitter", _DEFAULTS["jitter"])
    if j is not None:
        j = _fill("jitter", j, _JITTER_DEFAULTS)
        if j["model"] not in JITTER_MODELS:
            raise PipelineError(f"jitter.model: expected one of {', '.join(JITTER_MODELS)}, got {j['model']!r}")
        if j["iterations"] < 1:
            raise PipelineError(f"jitter.iterations: expected >= 1, got {j['iterations']}")
        if j["window_frames"] < 3 or j["window_frames"] % 2 == 0:
            raise PipelineError(f"jitter.window_frames: expected an odd integer >= 3, got {j['window_frames']}")
    out["jitter"] = j
    c = d.get("compensation", _DEFAULTS["compensation"])
    c = {"model": c} if isinstance(c, str) else _mapping("compensation", c)
    for k in c:
        if k not in ("model", "params"):
            raise PipelineError(f"compensation.{k}: unknown key; valid: model, params")
    if c.get("model") not in COMPENSATION_MODELS:
        raise PipelineError(f"compensation.model: expected one of {', '.join(COMPENSATION_MODELS)}, "
                            f"got {c.get('model')!r}")
    if c["model"] in ("affine", "homography"):
        c["params"] = _method_params("compensation.params", affine_global_motion, c.get("params", {}),
                                     skip=("model",))
    elif c.get("params"):
        raise PipelineError(f"compensation.params: the {c['model']!r} model takes no parameters")
    else:
        c["params"] = {}
    out["compensation"] = c
    out["flow"] = _method_section("flow", d["flow"], FLOW_METHODS, "flow method")
    t = d.get("threshold")
    if t is not None:
        t = _fill("threshold", t, _THRESHOLD_DEFAULTS)
        try:  # the function's own checks, on a 1-pixel field, so errors come now and not mid-run
            threshold_flow(np.zeros((1, 1, 2), np.float32), **t)
        except (TypeError, ValueError) as e:
            raise PipelineError(f"threshold: {e}") from None
    out["threshold"] = t
    for k in ("spatial", "temporal"):
        out[k] = _check_value(k, d.get(k, _DEFAULTS[k]), False)
    out["detection"] = _fill("detection", d.get("detection", {}), _DETECTION_DEFAULTS)
    tr = _mapping("tracking", d.get("tracking", _DEFAULTS["tracking"]))
    for k in tr:
        if k not in ("point", "multi"):
            raise PipelineError(f"tracking.{k}: unknown key; valid: point, multi")
    point = tr.get("point", True)
    if isinstance(point, Mapping):
        point = _fill("tracking.point", point, {"field": "filtered", "kalman": None, "recentre_px": None,
                                                "filter": "flow", "sigma_accel_px": 0.5, "sigma_meas_px": 1.0})
        if point["filter"] not in ("flow", "position"):
            raise PipelineError(f"tracking.point.filter: expected flow or position, got {point['filter']!r}")
        try:
            PointTracker(0.0, 0.0, position_filter={k: point[k] for k in ("sigma_accel_px", "sigma_meas_px")})
        except ValueError as e:
            raise PipelineError(f"tracking.point: {e}") from None
        rc = point["recentre_px"]
        if rc is not None and (isinstance(rc, bool) or not isinstance(rc, (int, float)) or not rc > 0):
            raise PipelineError(f"tracking.point.recentre_px: expected null or a number > 0, got {rc!r}")
        if point["field"] not in ("filtered", "local"):
            raise PipelineError(f"tracking.point.field: expected filtered or local, got {point['field']!r}")
        if point["kalman"] is not None:
            kal = _mapping("tracking.point.kalman", point["kalman"])
            for k in kal:
                if k not in _KALMAN_KEYS:
                    raise PipelineError(f"tracking.point.kalman.{k}: unknown key; valid: {', '.join(_KALMAN_KEYS)}")
            point["kalman"] = {k: _check_value(f"tracking.point.kalman.{k}", kal[k], None if k == "x0" else 0.0)
                               for k in kal}
    elif not isinstance(point, bool):
        raise PipelineError(f"tracking.point: expected true/false or a mapping, got {point!r}")
    multi = tr.get("multi")
    if multi is not None:
        multi = _fill("tracking.multi", multi, _MULTI_DEFAULTS)
        try:
            MultiTargetTracker(**multi)
        except ValueError as e:
            raise PipelineError(f"tracking.multi: {e}") from None
    out["tracking"] = {"point": point, "multi": multi}
    return out


def pipeline_hash(config: Mapping) -> str:
    """Stable 16-hex hash of what a pipeline computes (its resolved dict without name and description)."""
    body = {k: v for k, v in config.items() if k not in ("name", "description")}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


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
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    X, Y = xs + fg[..., 0], ys + fg[..., 1]
    inside = (X >= -1e-3) & (X <= w - 1 + 1e-3) & (Y >= -1e-3) & (Y <= h - 1 + 1e-3)
    return warped, fg, inside


def _compose(M: np.ndarray, w_local: np.ndarray, is_shift: bool) -> np.ndarray:
    """total(x) = M(x + w(x)) - x (for a shift: s + w)."""
    if is_shift:
        out = w_local.astype(np.float32, copy=True)
        out[..., 0] += np.float32(M[0, 2])
        out[..., 1] += np.float32(M[1, 2])
        return out
    h, w = w_local.shape[:2]
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    px, py = xs + w_local[..., 0], ys + w_local[..., 1]
    Z = M[2, 0] * px + M[2, 1] * py + M[2, 2]
    out = np.empty((h, w, 2), dtype=FLOW_DTYPE)
    out[..., 0] = (M[0, 0] * px + M[0, 1] * py + M[0, 2]) / Z - xs
    out[..., 1] = (M[1, 0] * px + M[1, 1] * py + M[1, 2]) / Z - ys
    return out


def _translation(s) -> np.ndarray:
    M = np.eye(3)
    M[0, 2], M[1, 2] = float(s[0]), float(s[1])
    return M


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
        flow: {method: lucas_kanade, params: {window: 15}}    # any name in FLOW_METHODS
        threshold: {direction: -90, tolerance_deg: 45, min_magnitude_px: 0.0, max_magnitude_px: null}  # or null
        spatial: true        # eq. 4.11
        temporal: true       # eq. 4.12
        detection: {min_magnitude_px: 0.5, min_area_px: 20}
        tracking: {point: true | {field: filtered | local, kalman: {x0, p0, q, r}, recentre_px: null | 12.0,
                                  filter: flow | position, sigma_accel_px: 0.5, sigma_meas_px: 1.0},
                   multi: null | {gate_px, birth_hits, death_misses, sigma_accel_px, sigma_meas_px, sigma_vel0_px}}

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
    ``sigma_meas_px``). ``jitter.iterations > 1`` re-measures the global shifts on
    the corrected frames (one more pass over the frames per round).
    """

    config: Mapping[str, Any]

    def __hash__(self) -> int:
        return hash(self.hash)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Pipeline":
        return cls(_validate(d))

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

    def _global_shifts(self, frames, n: int, correction: np.ndarray | None = None):
        gm = self.config["global_motion"]
        fn, params = GLOBAL_MOTION_METHODS[gm["method"]], gm["params"]
        shifts, valid, times = np.zeros((n - 1, 2)), np.zeros(n - 1, bool), np.zeros(n - 1)

        def load(i):
            g = as_gray(frames[i], name=f"frames[{i}]")
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

    # -- run ---------------------------------------------------------------------------------

    def run(self, frames: Sequence, *, seeds: Sequence[tuple] | None = None
            ) -> Iterator[PairEstimate | SequenceEstimate]:
        """Run on ``frames`` (``len`` and ``frames[i]``), yielding a PairEstimate per pair, then a SequenceEstimate.

        Parameters
        ----------
        frames : indexable of (H, W) or (H, W, 3) arrays
            Read on demand; at least two frames.
        seeds : sequence of (vehicle_id, x_px, y_px), optional
            Pixels of frame 0 for the thesis point tracker (``tracking.point``).
        """
        n = len(frames)
        if n < 2:
            raise ValueError(f"frames: expected at least 2 frames, got {n}")
        cfg = self.config
        totals: dict[str, float] = {}

        # pass 1: global shifts of all pairs, jitter over the whole path
        shifts, shifts_valid, gm_ms = self._global_shifts(frames, n)
        t0 = time.perf_counter()
        if cfg["jitter"] is not None:
            j = cfg["jitter"]
            jit = remove_jitter(
                shifts, model=j["model"], window_frames=j["window_frames"], polyorder=j["polyorder"],
                iterations=j["iterations"],
                reestimate=(lambda corr: self._global_shifts(frames, n, corr)[0]) if j["iterations"] > 1 else None)
            cumulative, line, correction, jitter = (jit.cumulative_px, jit.flight_line_px, jit.correction_px,
                                                    jit.jitter_px)
        else:
            cumulative = cumulative_path(shifts)
            line, correction, jitter = cumulative.copy(), np.zeros_like(cumulative), np.zeros_like(cumulative)
        totals["jitter"] = _ms(t0)

        flow_fn, flow_params = FLOW_METHODS[cfg["flow"]["method"]], cfg["flow"]["params"]
        comp = cfg["compensation"]
        thr, det_cfg, track_cfg = cfg["threshold"], cfg["detection"], cfg["tracking"]
        points = []
        point_cfg = track_cfg["point"] if isinstance(track_cfg["point"], Mapping) else {}
        point_field = "flow_local" if point_cfg.get("field") == "local" else "filtered"
        if track_cfg["point"] and seeds:
            kal = point_cfg.get("kalman")
            points = [PointTracker(float(x), float(y), track_id=i, seed_vehicle_id=vid, kalman=kal,
                                   recentre_px=point_cfg.get("recentre_px"),
                                   position_filter={k: point_cfg[k] for k in ("sigma_accel_px", "sigma_meas_px")}
                                   if point_cfg.get("filter") == "position" else None)
                      for i, (vid, x, y) in enumerate(seeds)]
        multi = MultiTargetTracker(**track_cfg["multi"]) if track_cfg["multi"] is not None else None

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
                g1c, fg, inside = _compensate(g1, M)
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
                cleaned = np.where(valid[..., None], w_local, np.float32(0)).astype(np.float32)
            ms["threshold"] = _ms(t0)
            t0 = time.perf_counter()
            if cfg["spatial"]:
                cleaned = spatial_filter(cleaned)
            ms["spatial"] = _ms(t0)
            return {"index": t, "flow_global": fg, "flow_total": total, "flow_local": w_local, "valid": valid,
                    "cleaned": cleaned, "stage_ms": ms}

        def finish(prev: dict | None, cur: dict, nxt: dict | None) -> PairEstimate:
            ms, t = cur["stage_ms"], cur["index"]
            t0 = time.perf_counter()
            if cfg["temporal"]:
                filtered = temporal_filter(prev and prev["cleaned"], cur["cleaned"], nxt and nxt["cleaned"])
            else:
                filtered = cur["cleaned"]
            ms["temporal"] = _ms(t0)
            t0 = time.perf_counter()
            mag = np.hypot(filtered[..., 0], filtered[..., 1])
            mask = cur["valid"] & (mag >= det_cfg["min_magnitude_px"])
            dets = detect_moving_objects(mask, min_area_px=det_cfg["min_area_px"])
            ms["detection"] = _ms(t0)
            t0 = time.perf_counter()
            for p in points:
                p.step(shifts[t], filtered if point_field == "filtered" else cur["flow_local"], cur["valid"])
            if multi is not None:
                multi.step(t, dets, offset_px=cumulative[t])
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
        g0 = as_gray(frames[0], name="frames[0]")
        frame_shape = (int(g0.shape[0]), int(g0.shape[1]))
        for t in range(n - 1):
            g1 = as_gray(frames[t + 1], name=f"frames[{t + 1}]")
            window.append(estimate_pair(t, g0, g1))
            g0 = g1
            if len(window) == 2:
                cur, nxt = window
                yield finish(prev_done, cur, nxt)
                prev_done = {"cleaned": cur["cleaned"]}  # all the next pair's temporal filter needs
                window = [nxt]
                del cur, nxt
        yield finish(prev_done, window[0], None)
        del window, prev_done, g0

        rows = [r for p in points for r in p.rows()] + (multi.rows() if multi is not None else [])
        tracks = pd.DataFrame(rows, columns=list(TRACK_COLUMNS))
        yield SequenceEstimate(shifts_px=shifts, shifts_valid=shifts_valid, cumulative_px=cumulative,
                               flight_line_px=line, correction_px=correction, jitter_px=jitter, tracks=tracks,
                               pipeline=self.name, pipeline_hash=self.hash, frame_shape_px=frame_shape,
                               stage_ms={"global_motion": float(gm_ms.sum()), **totals})


# ---------------------------------------------------------------------------------------------
# built-in pipelines

_THESIS_CLEANUP = {"threshold": None, "spatial": True, "temporal": True}
# Beyond-thesis point trackers re-centre on the region that moves like the point (search half-side, px):
# larger than a vehicle on `nominal` (about 20 x 10 px), smaller than the gap between vehicles. On `nominal`
# (60 frames) it takes pyramidal-lk's mean point error from 2.6 px (max 13) to 1.5 px (max 7.6).
# Their filtered track is a constant-velocity Kalman filter of those positions in the ground frame (the
# multi-target tracker's default noise): on nominal and noisy (60 frames) it changes the mean point error by
# +0.02 and +0.03 px, since what is left there is a bias of the region's centroid (about 1 px), not noise.
_POINT_RECENTRED = {"field": "local", "recentre_px": 12.0, "filter": "position", "sigma_accel_px": 0.5,
                    "sigma_meas_px": 1.0}

# name -> plain dict (what a YAML suite would hold); get_pipeline(name) validates it.
PIPELINES: dict[str, dict] = {
    "thesis-lk": {
        "name": "thesis-lk",
        "description": "Thesis: integer NCC shift, straight flight line, single-level LK 15x15, spatial+temporal filters",
        "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 16, "subpixel": False}},
        "jitter": {"model": "line"}, "compensation": "shift",
        "flow": {"method": "lucas_kanade", "params": {"window": 15}},
        **_THESIS_CLEANUP,
        "tracking": {"point": True, "multi": None},
    },
    "thesis-hs": {
        "name": "thesis-hs",
        "description": "Thesis: integer NCC shift, straight flight line, single-level Horn-Schunck, spatial+temporal filters",
        "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 16, "subpixel": False}},
        "jitter": {"model": "line"}, "compensation": "shift",
        "flow": {"method": "horn_schunck", "params": {"alpha": 15.0, "iterations": 100}},
        **_THESIS_CLEANUP,
        "tracking": {"point": True, "multi": None},
    },
    "pyramidal-lk": {
        "name": "pyramidal-lk",
        "description": "Sub-pixel NCC shift, smooth flight path, coarse-to-fine LK with warping, multi-target tracker",
        "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 16, "subpixel": True}},
        "jitter": {"model": "smooth"}, "compensation": "shift",
        "flow": {"method": "lucas_kanade", "params": {"window": 11, "levels": 4, "iterations": 3}},
        **_THESIS_CLEANUP,
        "tracking": {"point": dict(_POINT_RECENTRED), "multi": {}},
    },
    "pyramidal-hs": {
        "name": "pyramidal-hs",
        "description": "Sub-pixel NCC shift, smooth flight path, coarse-to-fine Horn-Schunck with warping, multi-target tracker",
        "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 16, "subpixel": True}},
        "jitter": {"model": "smooth"}, "compensation": "shift",
        "flow": {"method": "horn_schunck", "params": {"levels": 4}},
        **_THESIS_CLEANUP,
        "tracking": {"point": dict(_POINT_RECENTRED), "multi": {}},
    },
}
for _name, _desc in (("dis", "OpenCV DIS"), ("farneback", "OpenCV Farneback"), ("tvl1", "scikit-image TV-L1"),
                     ("tv_l1", "our TV-L1")):
    PIPELINES[_name] = {
        "name": _name,
        "description": f"Reference: sub-pixel NCC shift compensation, then {_desc} flow; spatial+temporal filters",
        "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 16, "subpixel": True}},
        "jitter": {"model": "smooth"}, "compensation": "shift",
        "flow": {"method": _name, "params": {}},
        **_THESIS_CLEANUP,
        "tracking": {"point": dict(_POINT_RECENTRED), "multi": {}},
    }


def get_pipeline(name: str) -> Pipeline:
    """The built-in pipeline ``name``, validated."""
    if name not in PIPELINES:
        raise KeyError(f"unknown pipeline {name!r}; valid: {', '.join(sorted(PIPELINES))}")
    return Pipeline.from_dict(PIPELINES[name])
