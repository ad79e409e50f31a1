"""Metric definitions and scoring against ground truth: pure numpy / pandas, no I/O.

Every metric is a :class:`MetricDef` in the plain-dict registry :data:`METRICS`
(name -> unit, direction, weighting, how totals reduce to a value, one-line
description for ``aerobench list``). Scoring functions return *rows*: dicts with
``frame, track_id, metric, region, motion, kind, value, sum, count, unit,
higher_is_better, hist`` (the cell columns of the results table are added by the
runner, see :func:`harness.results.rows_to_frame`).

Every row carries totals from which any aggregate is recomputed: ``sum`` and
``count`` are summed over rows, then reduced by the metric's ``reduce`` rule
(never an average of averages):

==========  ==========================================  ===========================
reduce      value of a row / of an aggregate            sum, count
==========  ==========================================  ===========================
mean        sum / count                                 sum of x, number of items
rms         sqrt(sum / count)                           sum of x**2, number of items
rate        100 * sum / count  (percent)                items over the limit, items
total       sum                                         sum of x, number of items
complement  1 - sum / count  (MOTA)                      errors, number of items
quantile    from the summed EPE histogram (``hist``)    NaN, number of pixels
==========  ==========================================  ===========================

Quantiles (``epe_median``, ``epe_p95``) cannot be summed: their rows carry the
exact per-frame value in ``value`` and the frame's EPE histogram in ``hist``
(fixed bins of :data:`HIST_BIN_PX` = 0.01 px from 0 to :data:`HIST_MAX_PX` = 100 px,
plus one overflow bin, in the compact binary form of :func:`encode_hist`). :func:`aggregate` sums the
histograms and reads the quantile off at the bin centre, so an aggregate
quantile is within half a bin (0.005 px) of the quantile of all pixels pooled,
for quantiles below 100 px (above, it reads 100 px: a floor).

Regions of a flow field (see :func:`region_masks`): ``all`` (every valid
pixel), ``background`` (instance 0), ``vehicles`` (instance > 0), ``interior``
(valid pixels farther than ``boundary_px`` = 3 px, Chebyshev distance, from an
invalid pixel or an instance edge: occlusion boundaries excluded).

Motions: ``total`` scores ``flow_total`` against the ground-truth ``flow``;
``local`` scores ``flow_total - flow_global`` against ``flow - flow_camera``,
so a stabilisation error and a flow error can be told apart.

Public functions
----------------
register_metric, metric_def, describe_metrics         the registry
endpoint_error, angular_error_deg                      per-pixel errors
region_masks, boundary_mask                            pixel regions
epe_histogram, encode_hist, decode_hist, add_hist, hist_quantile   quantile totals
flow_rows, error_rows                                  flow metrics of one field in one mask
score_flow                                             all flow rows of one pair (no PairEstimate needed)
timing_rows                                            rows from ``stage_ms``
prepare_pair_truth, PreparedTruth                     the truth side of score_pair, shared by estimates
score_pair                                             PairEstimate + PairTruth -> rows
shift_rows, jitter_rows, detrend                       global motion and stabilisation
stabilisation_scores, stabilisation_rows               cropping ratio, distortion, stability (Liu 2013)
position_error_px, associate_tracks, track_rows      trajectories, CLEAR-MOT ID switches
MOTCounts, mot_counts, mot_rows                        MOTA, MOTP, IDF1 from summed counts
HOTACounts, hota_counts                                HOTA (Luiten 2021) per alpha, from summed counts
score_sequence                                         SequenceEstimate + camera.csv + tracks.csv -> rows
aggregate                                              rows DataFrame -> aggregates from totals
"""

from __future__ import annotations

import fnmatch
import math
import struct
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from algorithms.flow import check_flow, endpoint_error
from algorithms.jitter import least_squares_line

__all__ = [
    "METRICS", "MetricDef", "register_metric", "metric_def", "describe_metrics", "timing_metric_name",
    "REGIONS", "MOTIONS", "HIST_BIN_PX", "HIST_MAX_PX", "HIST_NBINS",
    "endpoint_error", "angular_error_deg", "boundary_mask", "region_masks",
    "epe_histogram", "encode_hist", "decode_hist", "add_hist", "hist_quantile",
    "flow_rows", "error_rows", "score_flow", "timing_rows", "score_pair", "PreparedTruth", "prepare_pair_truth",
    "shift_rows", "detrend", "jitter_rows", "stabilisation_scores", "stabilisation_rows", "position_error_px", "associate_tracks", "track_rows", "MOTCounts", "mot_counts", "mot_rows",
    "HOTA_ALPHAS", "HOTACounts", "hota_counts",
    "score_sequence",
    "aggregate", "reduce_totals",
]


def _linear_sum_assignment(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`scipy.optimize.linear_sum_assignment`, imported on first use (scipy.optimize takes 0.7 s
    to import, and most processes that import this module never match tracks)."""
    from scipy.optimize import linear_sum_assignment as lsa

    return lsa(cost)


REGIONS = ("all", "background", "vehicles", "interior")
MOTIONS = ("total", "local")
HIST_BIN_PX = 0.01
HIST_MAX_PX = 100.0
HIST_NBINS = int(round(HIST_MAX_PX / HIST_BIN_PX)) + 1  # the last bin is the overflow
REDUCES = ("mean", "rms", "rate", "total", "complement", "quantile")
# stages of algorithms.pipeline that report wall time (others are registered on first use)
STAGES = ("global_motion", "jitter", "compensation", "flow", "compose", "threshold", "spatial", "temporal",
          "detection", "tracking", "total")


@dataclass(frozen=True)
class MetricDef:
    """What a metric means: ``unit``, direction, weighting and how totals reduce to a value."""

    name: str
    unit: str
    higher_is_better: bool
    weighting: str
    description: str
    reduce: str = "mean"
    kind: str = "accuracy"  # "accuracy" | "timing"
    q: float | None = None  # the quantile, for reduce == "quantile"


METRICS: dict[str, MetricDef] = {}


def register_metric(name: str, unit: str, *, higher_is_better: bool, weighting: str, description: str,
                    reduce: str = "mean", kind: str = "accuracy", q: float | None = None) -> MetricDef:
    """Add a metric to :data:`METRICS` (twice with different definitions is an error)."""
    if reduce not in REDUCES:
        raise ValueError(f"metric {name!r}: reduce must be one of {REDUCES}, got {reduce!r}")
    if kind not in ("accuracy", "timing"):
        raise ValueError(f"metric {name!r}: kind must be 'accuracy' or 'timing', got {kind!r}")
    d = MetricDef(name, unit, higher_is_better, weighting, description, reduce, kind, q)
    if name in METRICS and METRICS[name] != d:
        raise ValueError(f"metric {name!r} is registered twice with different definitions")
    METRICS[name] = d
    return d


def timing_metric_name(stage: str) -> str:
    """``time_<stage>_ms``: the wall-time metric of a pipeline stage (registered on first use)."""
    name = f"time_{stage}_ms"
    if name not in METRICS:
        register_metric(name, "ms", higher_is_better=False, kind="timing",
                        weighting="per frame pair, mean over pairs",
                        description=f"wall time of the {stage} stage per frame pair")
    return name


def metric_def(name: str) -> MetricDef:
    """The definition of ``name``; an unknown name raises ``KeyError`` listing the valid ones."""
    try:
        return METRICS[name]
    except KeyError:
        raise KeyError(f"unknown metric {name!r}; valid: {', '.join(sorted(METRICS))}") from None


def describe_metrics(pattern: str = "*") -> pd.DataFrame:
    """A table of the registered metrics matching a glob ``pattern``, for ``aerobench list``."""
    rows = [{"metric": d.name, "unit": d.unit, "better": "higher" if d.higher_is_better else "lower",
             "kind": d.kind, "weighting": d.weighting, "description": d.description}
            for n, d in sorted(METRICS.items()) if fnmatch.fnmatchcase(n, pattern)]
    return pd.DataFrame(rows, columns=["metric", "unit", "better", "kind", "weighting", "description"])


_PIX = "per ground-truth-valid pixel (dense: the method's own valid mask does not exclude any), pooled over frames"
register_metric("epe_mean", "px", higher_is_better=False, weighting=_PIX,
                description="mean endpoint error |w_est - w_true|")
register_metric("epe_rms", "px", higher_is_better=False, weighting=_PIX, reduce="rms",
                description="root mean square endpoint error")
register_metric("epe_median", "px", higher_is_better=False, weighting=_PIX + " (summed 0.01 px histogram)",
                reduce="quantile", q=0.5, description="median endpoint error")
register_metric("epe_p95", "px", higher_is_better=False, weighting=_PIX + " (summed 0.01 px histogram)",
                reduce="quantile", q=0.95, description="95th percentile of the endpoint error")
register_metric("ae_mean", "deg", higher_is_better=False, weighting=_PIX,
                description="mean angular error between (u, v, 1) vectors (Barron 1994, Baker 2011)")
for _t in (1, 3, 5):
    register_metric(f"outlier_{_t}px", "%", higher_is_better=False, weighting=_PIX, reduce="rate",
                    description=f"share of pixels with endpoint error > {_t} px")
register_metric("fl_all", "%", higher_is_better=False, weighting=_PIX, reduce="rate",
                description="KITTI Fl: share of pixels with EPE > 3 px and > 5 % of the true magnitude")
register_metric("coverage", "%", higher_is_better=True, weighting="per ground-truth-valid pixel, pooled",
                reduce="rate", description="share of ground-truth-valid pixels the method marks valid "
                "(the flow errors still score every ground-truth-valid pixel)")
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
_TRK = "per vehicle and frame where visible and tracked, pooled"
register_metric("track_error", "px", higher_is_better=False, weighting=_TRK,
                description="|filtered track position - true vehicle centre|")
register_metric("track_raw_error", "px", higher_is_better=False, weighting=_TRK,
                description="|measured (unfiltered) track position - true vehicle centre|")
register_metric("track_pred_error", "px", higher_is_better=False, weighting=_TRK,
                description="|one-step Kalman prediction for the frame - true vehicle centre|")
register_metric("track_ate_rmse", "px", higher_is_better=False, weighting=_TRK + " (RMS)", reduce="rms",
                description="absolute trajectory error: RMS of filtered position error")
register_metric("track_fde", "px", higher_is_better=False, weighting="per vehicle, mean over vehicles",
                description="final displacement error: filtered position error on the last tracked frame")
register_metric("track_completeness", "%", higher_is_better=True,
                weighting="per vehicle-frame where visible, pooled", reduce="rate",
                description="share of frames where a vehicle is visible and a track is assigned to it")
register_metric("id_switches", "count", higher_is_better=False, weighting="summed over vehicles",
                reduce="total", description="identity switches of the multi-target tracker (CLEAR-MOT)")
_MOT = "per sequence and tracker, from summed counts (never an average of per-sequence scores)"
register_metric("mota", "ratio", higher_is_better=True, weighting=_MOT + "; 1 - (FN + FP + IDSW) / objects",
                reduce="complement", description="CLEAR-MOT accuracy 1 - (misses + false positives + ID switches) "
                "/ visible vehicle-frames (Bernardin 2008), match within the association gate")
register_metric("motp", "px", higher_is_better=False, weighting=_MOT + "; per matched vehicle-frame",
                description="CLEAR-MOT precision: mean distance of matched track-vehicle pairs (Bernardin 2008)")
register_metric("idf1", "ratio", higher_is_better=True, weighting=_MOT + "; 2 IDTP / (objects + predictions)",
                description="identity F1: share of vehicle-frames and track-frames on the best one-to-one "
                "vehicle-track assignment (Ristani 2016)")
register_metric("mot_misses", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT misses (FN): visible vehicle-frames without a track within the gate")
register_metric("mot_false_positives", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT false positives (FP): track-frames matched to no vehicle")
for _s in STAGES:
    timing_metric_name(_s)


# --------------------------------------------------------------------------- per-pixel errors

# endpoint_error (per-pixel EPE) lives in algorithms.flow, its one home; imported above and
# re-exported here for the metric code's readers.


def angular_error_deg(flow_est: np.ndarray, flow_true: np.ndarray) -> np.ndarray:
    """Angular error between the 3-D vectors ``(u, v, 1)`` (Barron et al. 1994), ``(H, W)`` degrees.

    ``AE = arccos((u_e u_t + v_e v_t + 1) / sqrt((u_e^2 + v_e^2 + 1)(u_t^2 + v_t^2 + 1)))``
    """
    e = np.asarray(flow_est, np.float64)
    t = np.asarray(flow_true, np.float64)
    num = e[..., 0] * t[..., 0] + e[..., 1] * t[..., 1] + 1.0
    den = np.sqrt((e[..., 0] ** 2 + e[..., 1] ** 2 + 1.0) * (t[..., 0] ** 2 + t[..., 1] ** 2 + 1.0))
    return np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0)))


def boundary_mask(valid: np.ndarray, instances: np.ndarray | None = None, *, boundary_px: int = 3) -> np.ndarray:
    """Pixels within ``boundary_px`` (Chebyshev distance) of an invalid pixel or an instance edge.

    An instance edge is a pixel whose instance id differs from one of its four
    neighbours (both sides of the edge are edge pixels). Returns ``(H, W)`` bool.
    """
    valid = np.asarray(valid, bool)
    bad = ~valid
    if instances is not None:
        ids = np.asarray(instances)
        if ids.shape != valid.shape:
            raise ValueError(f"instances: expected shape {valid.shape}, got {ids.shape}")
        edge = np.zeros_like(valid)
        dy = ids[1:, :] != ids[:-1, :]
        dx = ids[:, 1:] != ids[:, :-1]
        edge[1:, :] |= dy
        edge[:-1, :] |= dy
        edge[:, 1:] |= dx
        edge[:, :-1] |= dx
        bad = bad | edge
    if boundary_px <= 0:
        return bad
    kernel = np.ones((2 * boundary_px + 1, 2 * boundary_px + 1), np.uint8)
    return cv2.dilate(bad.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)


def region_masks(valid: np.ndarray, instances: np.ndarray | None = None, *, boundary_px: int = 3,
                 regions: Iterable[str] = REGIONS) -> dict[str, np.ndarray]:
    """The scored pixels of each region (see the module docstring), ``name -> (H, W) bool``.

    Without ``instances`` every pixel counts as background.
    """
    valid = np.asarray(valid, bool)
    out: dict[str, np.ndarray] = {}
    for r in regions:
        if r == "all":
            out[r] = valid
        elif r == "background":
            out[r] = valid if instances is None else valid & (np.asarray(instances) == 0)
        elif r == "vehicles":
            out[r] = np.zeros_like(valid) if instances is None else valid & (np.asarray(instances) > 0)
        elif r == "interior":
            out[r] = valid & ~boundary_mask(valid, instances, boundary_px=boundary_px)
        else:
            raise ValueError(f"unknown region {r!r}; valid: {', '.join(REGIONS)}")
    return out


# --------------------------------------------------------------------------- EPE histogram

def epe_histogram(epe: np.ndarray) -> np.ndarray:
    """Counts of ``epe`` in :data:`HIST_NBINS` bins of 0.01 px, the last one for >= 100 px. int64."""
    idx = np.minimum(np.floor(np.asarray(epe, np.float64).ravel() / HIST_BIN_PX), HIST_NBINS - 1)
    return np.bincount(idx.astype(np.int64), minlength=HIST_NBINS).astype(np.int64)


# header of an encoded histogram: format 1, bytes per count (4 or 8), first non-empty bin, bins stored
_HIST_HEADER = struct.Struct("<BBII")
_HIST_FORMAT = 1


def encode_hist(counts: np.ndarray) -> bytes:
    """Compact binary form of a histogram (the results table's ``hist`` column); ``b""`` when empty.

    The counts from the first to the last non-empty bin, little-endian uint32 (uint64 if a
    count needs it), zlib-compressed (level 1), after a 10-byte header (format, bytes per
    count, first bin, number of bins). A 640x480 pair's histogram takes about 0.5 kB, a
    fifth of the ``"bin:count ..."`` text that schema v1 stored, and decodes without parsing.
    """
    counts = np.asarray(counts)
    # first and last non-empty bin by argmax (np.flatnonzero of 10001 bins costs 5 times more)
    nz = counts != 0
    lo = int(nz.argmax()) if nz.size else 0
    if nz.size == 0 or not nz[lo]:
        return b""
    hi = nz.size - int(nz[::-1].argmax())
    part = counts[lo:hi]
    width = 4 if int(part.max()) < 2 ** 32 else 8
    payload = part.astype("<u4" if width == 4 else "<u8").tobytes()
    return _HIST_HEADER.pack(_HIST_FORMAT, width, lo, hi - lo) + zlib.compress(payload, 1)


def decode_hist(data: bytes) -> np.ndarray:
    """Inverse of :func:`encode_hist`: dense ``(HIST_NBINS,)`` int64 counts (``b""`` or None: all zero)."""
    out = np.zeros(HIST_NBINS, np.int64)
    add_hist(out, data)
    return out


def add_hist(total: np.ndarray, data: bytes) -> np.ndarray:
    """Add the histogram encoded in ``data`` (:func:`encode_hist`) into the dense int64 ``total``, in place."""
    if data is None or len(data) == 0:
        return total
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ValueError(f"hist: expected bytes from encode_hist, got {type(data).__name__}")
    try:
        fmt, width, lo, n = _HIST_HEADER.unpack_from(data)
        part = np.frombuffer(zlib.decompress(data[_HIST_HEADER.size:]), "<u4" if width == 4 else "<u8")
    except (struct.error, zlib.error) as exc:
        raise ValueError(f"hist: not an encoded histogram ({exc})") from None
    if fmt != _HIST_FORMAT or width not in (4, 8) or part.size != n or lo + n > HIST_NBINS:
        raise ValueError(f"hist: expected format {_HIST_FORMAT} with bins 0..{HIST_NBINS - 1}, got format {fmt}, "
                         f"{width}-byte counts, bins {lo}..{lo + n - 1} ({part.size} stored)")
    total[lo:lo + n] += part.astype(np.int64)
    return total


def hist_quantile(counts: np.ndarray, q: float) -> float:
    """The ``q`` quantile read at the centre of the bin holding it (within 0.005 px); NaN if empty.

    In the overflow bin it reads :data:`HIST_MAX_PX` (a floor).
    """
    total = int(counts.sum())
    if total == 0:
        return float("nan")
    # the sample of rank ceil(q * n) (1-based), the nearest-rank definition
    rank = max(1, math.ceil(q * total))
    b = int(np.searchsorted(np.cumsum(counts), rank))
    if b >= HIST_NBINS - 1:
        return HIST_MAX_PX
    return (b + 0.5) * HIST_BIN_PX


# --------------------------------------------------------------------------- rows

def _row(metric: str, value: float, total: float, count: float, *, region: str = "all", motion: str = "total",
         frame: int | None = None, track_id: int | None = None, hist: bytes = b"") -> dict:
    d = metric_def(metric)
    return {"frame": frame, "track_id": track_id, "metric": metric, "region": region, "motion": motion,
            "kind": d.kind, "value": float(value), "sum": float(total), "count": float(count),
            "unit": d.unit, "higher_is_better": d.higher_is_better, "hist": hist}


def flow_rows(flow_est: np.ndarray, flow_true: np.ndarray, mask: np.ndarray, *, region: str = "all",
              motion: str = "total", frame: int | None = None) -> list[dict]:
    """The flow metrics of one field over the pixels of ``mask``.

    An empty mask gives rows with ``count`` 0 and NaN values (they add nothing
    to an aggregate). Fl follows KITTI: EPE > 3 px and EPE > 0.05 |w_true|.
    """
    m = np.asarray(mask, bool)
    e = np.asarray(flow_est, np.float64)[m]
    t = np.asarray(flow_true, np.float64)[m]
    return error_rows(np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1]), angular_error_deg(e, t),
                      np.hypot(t[:, 0], t[:, 1]), region=region, motion=motion, frame=frame)


def error_rows(epe: np.ndarray, ae_deg: np.ndarray, true_mag: np.ndarray, *, region: str = "all",
               motion: str = "total", frame: int | None = None) -> list[dict]:
    """The flow metric rows from per-pixel endpoint errors, angular errors and true magnitudes (1-D)."""
    n = int(epe.size)
    if n:
        # nearest-rank quantiles (the sample of rank ceil(q n)), as hist_quantile reads them
        k50, k95 = _rank_index(0.5, n), _rank_index(0.95, n)
        part = np.partition(epe, (k50, k95))
        med, p95 = float(part[k50]), float(part[k95])
    else:
        med = p95 = float("nan")
    over = [int(np.count_nonzero(epe > thr)) for thr in OUTLIER_PX]
    fl = int(np.count_nonzero((epe > 3.0) & (epe > 0.05 * true_mag)))
    return _error_rows_from_totals(n, float(epe.sum()), float(epe @ epe), float(ae_deg.sum()), over, fl, med, p95,
                                   epe_histogram(epe), region=region, motion=motion, frame=frame)


OUTLIER_PX = (1, 3, 5)


def _rank_index(q: float, n: int) -> int:
    """0-based index of the nearest-rank ``q`` quantile of ``n`` sorted samples (rank ceil(q n))."""
    return max(1, math.ceil(q * n)) - 1


def _error_rows_from_totals(n: int, s_epe: float, s_sq: float, s_ae: float, over: list[int], fl: int,
                            med: float, p95: float, hist: np.ndarray, *, region: str, motion: str,
                            frame: int | None) -> list[dict]:
    """The flow metric rows of one region from its totals (one place builds them, whichever path counted)."""
    nan = float("nan")
    kw = {"region": region, "motion": motion, "frame": frame}

    def mean(s: float) -> float:
        return s / n if n else nan

    packed = encode_hist(hist)  # one bytes object shared by both quantile rows
    rows = [
        _row("epe_mean", mean(s_epe), s_epe, n, **kw),
        _row("epe_rms", math.sqrt(s_sq / n) if n else nan, s_sq, n, **kw),
        _row("epe_median", med, nan, n, hist=packed, **kw),
        _row("epe_p95", p95, nan, n, hist=packed, **kw),
        _row("ae_mean", mean(s_ae), s_ae, n, **kw),
    ]
    for thr, k in zip(OUTLIER_PX, over):
        rows.append(_row(f"outlier_{thr}px", 100.0 * mean(k), k, n, **kw))
    # KITTI Fl: EPE > 3 px and EPE > 5 % of |w_true|
    rows.append(_row("fl_all", 100.0 * mean(fl), fl, n, **kw))
    return rows


def _quantile_targets(hist: np.ndarray, qs: tuple[float, ...]):
    """Where the nearest-rank quantiles lie: bin, rank within the bin and size of the bin, each ``(M, R, len(qs))``.

    ``hist`` is ``(M, R, nbins)``; the bin is -1 for an empty histogram.
    """
    from harness._flow_kernels import quantile_targets

    n = hist.sum(axis=-1)
    rank = np.array([[[_rank_index(q, int(c)) if c else -1 for q in qs] for c in row] for row in n], np.int64)
    rank = rank.reshape(hist.shape[:2] + (len(qs),))
    target = np.full(rank.shape, -1, np.int64)
    below, sizes = np.zeros_like(target), np.zeros_like(target)
    quantile_targets(np.ascontiguousarray(hist), rank, target, below, sizes)
    return target, np.where(target >= 0, rank - below, 0), sizes


def _quantiles(e, g, t, tl, bits, bits_l, bins, hist_code, hist, qs: tuple[float, ...]) -> np.ndarray:
    """Exact nearest-rank quantiles ``(2, R, len(qs))`` of each motion's and region's EPE (NaN when empty).

    ``hist_code`` (2, 2**R, nbins) is the histogram of each membership pattern, ``hist``
    (2, R, nbins) of each region (the sum of its patterns').
    """
    from harness._flow_kernels import values_in_bins

    target, rank, _ = _quantile_targets(hist, qs)
    out = np.full(target.shape, np.nan)
    n_m, n_codes, nbins = hist_code.shape
    # the samples of each target bin are collected once per pixel, by membership pattern (a
    # pixel is in several regions; an almost constant error puts most pixels in one bin)
    slot = np.full((n_m, nbins), -1, np.int16)  # a target bin's index among its motion's
    kept = [np.unique(target[m][target[m] >= 0]) for m in range(n_m)]
    sizes = np.zeros((n_m, max(1, max(len(k) for k in kept)), n_codes), np.int64)
    for m, ks in enumerate(kept):
        slot[m, ks] = np.arange(len(ks))
        sizes[m, :len(ks), 1:] = hist_code[m, 1:, ks]  # pattern 0: not scored, not collected
    start = np.zeros(sizes.size, np.int64)
    start[1:] = np.cumsum(sizes.ravel())[:-1]
    start = start.reshape(sizes.shape)
    values = np.empty(int(sizes.sum()), np.float64)
    values_in_bins(e, g, t, tl, bits, bits_l, bins, slot, start, values)
    # the selection, per region and bin, with Python's lists (numpy's scalars cost more than the work here)
    sizes_l, start_l, slot_l = sizes.tolist(), start.tolist(), [dict(zip(ks.tolist(), range(len(ks)))) for ks in kept]
    for m, by_region in enumerate(target.tolist()):
        for r, bins_r in enumerate(by_region):
            for k in dict.fromkeys(k for k in bins_r if k >= 0):  # each bin once, in order
                size, first = sizes_l[m][slot_l[m][k]], start_l[m][slot_l[m][k]]
                parts = [values[first[b]:first[b] + size[b]] for b in range(1, n_codes) if (b >> r) & 1 and size[b]]
                # a pattern's segment serves several regions: partitioned in place only as a copy
                samples = parts[0].copy() if len(parts) == 1 else np.concatenate(parts)
                js = [j for j, kj in enumerate(bins_r) if kj == k]  # the quantiles read from this bin
                samples.partition(rank[m, r, js])
                out[m, r, js] = samples[rank[m, r, js]]
    return out


@dataclass(frozen=True, eq=False)
class PreparedTruth:
    """Everything of a pair's scoring that depends on the ground truth only (:func:`prepare_pair_truth`).

    Shared by every estimate of the same pair (the runner scores several pipelines against
    one truth); its arrays are read-only views.

    Attributes
    ----------
    regions : tuple of str
        The regions scored, in row order.
    boundary_px : int
        The ``interior`` region's margin (:func:`boundary_mask`).
    flow : (H, W, 2) float32
        The true (total) flow, C-contiguous; NaN where unknown.
    flow_local : (H, W, 2) float32
        ``flow - flow_camera`` in float32: the true local motion.
    bits, bits_local : (H, W) uint8
        Bit j set where the pixel is scored in ``regions[j]`` for the total / local motion
        (0: not scored). The same array when the two motions score the same pixels.
    """

    regions: tuple[str, ...]
    boundary_px: int
    flow: np.ndarray
    flow_local: np.ndarray
    bits: np.ndarray
    bits_local: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the pair."""
        return self.bits.shape


def _read_only(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def prepare_pair_truth(truth, *, regions: Iterable[str] = REGIONS, boundary_px: int = 3) -> PreparedTruth:
    """The truth side of :func:`score_pair`, computed once for every estimate of the pair.

    Parameters
    ----------
    truth : PairTruth
        ``flow``, ``flow_camera`` (H, W, 2) float, ``valid`` (H, W) bool, ``instances`` (H, W) int or None.
    regions : iterable of str
        Regions to score (at most 8), from :data:`REGIONS`.
    boundary_px : int
        Margin of the ``interior`` region, px.

    Returns
    -------
    PreparedTruth
        Scored pixels of the total motion: valid and finite in ``flow``; of the local motion:
        valid and finite in ``flow - flow_camera``. Each motion's regions are built from its
        scored pixels (:func:`region_masks`).
    """
    regions = tuple(regions)
    from harness._flow_kernels import truth_local  # numba: on the first scoring, not with the module

    # read-only views: one compiled signature of the kernels whatever the caller's arrays
    t = _read_only(np.ascontiguousarray(check_flow(truth.flow, name="flow_true", allow_nan=True)))
    vt0 = np.asarray(truth.valid, bool)
    if vt0.shape != t.shape[:2]:
        raise ValueError(f"valid_true: expected shape {t.shape[:2]}, got {vt0.shape}")

    # local motion: the camera's field taken out of the truth (float32, as t - np.float32(flow_camera))
    cam = np.asarray(truth.flow_camera, np.float32)
    if cam.shape != t.shape:  # as numpy's t - cam broadcasts it
        cam = np.broadcast_to(cam, t.shape)
    t_local = np.empty_like(t)
    vt, vt_local = np.empty(vt0.shape, bool), np.empty(vt0.shape, bool)
    truth_local(t, _read_only(np.ascontiguousarray(cam)), _read_only(np.ascontiguousarray(vt0)), t_local, vt, vt_local)
    masks = region_masks(vt, truth.instances, boundary_px=boundary_px, regions=regions)
    bits = _region_bits(masks) if regions else np.zeros(vt.shape, np.uint8)
    if np.array_equal(vt, vt_local):  # the regions depend on the scored pixels only
        bits_local = bits
    else:
        masks_local = region_masks(vt_local, truth.instances, boundary_px=boundary_px, regions=regions)
        bits_local = _region_bits(masks_local) if regions else bits
    same = bits_local is bits
    bits = _read_only(np.ascontiguousarray(bits))
    bits_local = bits if same else _read_only(np.ascontiguousarray(bits_local))
    return PreparedTruth(regions=regions, boundary_px=int(boundary_px), flow=_read_only(t),
                         flow_local=_read_only(t_local), bits=bits, bits_local=bits_local)


def _score_motions(e: np.ndarray, g: np.ndarray, truth: PreparedTruth, ve: np.ndarray, *, frame: int | None,
                   motions: tuple[str, ...] = MOTIONS) -> tuple[list[dict], int]:
    """Flow rows of both motions in every region, and the number of non-finite estimate pixels.

    e, g : (H, W, 2) float32 C-contiguous estimate and global field (local estimate = e - g);
    ve : (H, W) bool. ``motions`` names motion 0 (total) and, if two, motion 1 (local); with
    one, the local motion is left unscored. When the count returned is not 0 the rows are
    meaningless: the caller raises.
    """
    from harness._flow_kernels import pair_totals, region_hists  # numba: on the first scoring, not with the module

    names = truth.regions
    h, w = truth.shape
    n_codes = 1 << len(names)
    stats = np.zeros((2, n_codes, 9), np.float64)
    hist_code = np.zeros((2, n_codes, HIST_NBINS), np.int32)
    bins = np.empty((2, h, w), np.uint16)
    bits_l = truth.bits_local if len(motions) > 1 else _read_only(np.zeros_like(truth.bits))
    bad = pair_totals(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, ve, HIST_BIN_PX, HIST_NBINS,
                      stats, hist_code, bins)
    if bad:
        return [], bad
    hist = np.zeros((2, len(names), HIST_NBINS), np.int64)
    region_hists(hist_code, stats[:, :, _N], hist)
    quant = _quantiles(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, bins, hist_code, hist, (0.5, 0.95))
    # region totals: the sum of the patterns it belongs to
    member = (np.arange(n_codes)[None, :] >> np.arange(len(names))[:, None]) & 1  # (R, codes)
    rows: list[dict] = []
    for m, motion in enumerate(motions):
        by_code = stats[m]
        used = np.flatnonzero(by_code[:, _N])
        for j, r in enumerate(names):
            st = np.zeros(9)
            for c in used:
                if member[j, c]:
                    st += by_code[c]
            n = int(st[_N])
            rows += _error_rows_from_totals(n, float(st[_S_EPE]), float(st[_S_SQ]), float(st[_S_AE]),
                                            [int(st[_K1]), int(st[_K3]), int(st[_K5])], int(st[_KFL]),
                                            float(quant[m, j, 0]), float(quant[m, j, 1]), hist[m, j],
                                            region=r, motion=motion, frame=frame)
            k = int(st[_KCOV])
            rows.append(_row("coverage", 100.0 * k / n if n else float("nan"), k, n, region=r, motion=motion,
                             frame=frame))
    return rows, 0


# columns of the pattern totals of harness._flow_kernels.pair_totals
_N, _S_EPE, _S_SQ, _S_AE, _K1, _K3, _K5, _KFL, _KCOV = range(9)


def score_flow(flow_est: np.ndarray, flow_true: np.ndarray, valid_true: np.ndarray, *,
               valid_est: np.ndarray | None = None, instances: np.ndarray | None = None,
               motion: str = "total", frame: int | None = None, regions: Iterable[str] = REGIONS,
               boundary_px: int = 3) -> list[dict]:
    """Flow rows of one field in every region, plus ``coverage``.

    Scored pixels: every pixel valid (and finite) in the truth, whatever the
    method's own ``valid_est`` says, so that a method cannot improve its errors
    by declining hard pixels (Middlebury and KITTI score dense fields the same
    way); ``valid_est`` only feeds ``coverage``. A non-finite estimate is an
    error, not a pixel to skip. Regions are built from the truth's validity and
    instances (:func:`region_masks`).

    All regions are counted in one pass over the pixels (sums, outlier counts,
    EPE histogram); the median and 95th percentile are exact, read among the
    samples of the histogram bin that holds them. The values equal
    :func:`flow_rows` on each region's mask (sums to rounding, ~1e-15 relative;
    counts, quantiles and histograms exactly).
    """
    t = np.ascontiguousarray(check_flow(flow_true, name="flow_true", allow_nan=True))
    e = np.ascontiguousarray(check_flow(flow_est, name="flow_est", shape=t.shape[:2]))
    vt = np.asarray(valid_true, bool)
    if vt.shape != t.shape[:2]:
        raise ValueError(f"valid_true: expected shape {t.shape[:2]}, got {vt.shape}")
    vt = vt & _finite_uv(t)
    ve = _valid_est(valid_est, vt.shape)
    regions = tuple(regions)
    masks = region_masks(vt, instances, boundary_px=boundary_px, regions=regions)
    bits = np.ascontiguousarray(_region_bits(masks)) if regions else np.zeros(vt.shape, np.uint8)
    t, e, bits, ve = _read_only(t), _read_only(e), _read_only(bits), _read_only(ve)
    truth = PreparedTruth(regions=regions, boundary_px=boundary_px, flow=t, flow_local=t, bits=bits, bits_local=bits)
    # one motion: the local one is left unscored (g = e only keeps the pass's finiteness test true)
    rows, _ = _score_motions(e, e, truth, ve, frame=frame, motions=(motion,))
    return rows


def _valid_est(valid, shape: tuple[int, int]) -> np.ndarray:
    """The method's valid mask as C-contiguous (H, W) bool (all True when None)."""
    if valid is None:
        return np.ones(shape, bool)
    ve = np.ascontiguousarray(valid, bool)
    if ve.shape != shape:
        raise ValueError(f"valid_est: expected shape {shape}, got {ve.shape}")
    return ve


def _finite_uv(flow: np.ndarray) -> np.ndarray:
    """(H, W) bool: both components finite (``np.isfinite(flow).all(-1)``, several times faster)."""
    return np.isfinite(flow[..., 0]) & np.isfinite(flow[..., 1])


def _region_bits(masks: Mapping[str, np.ndarray]) -> np.ndarray:
    """(H, W) uint8: bit j set where the pixel is in the j-th region of ``masks`` (at most 8)."""
    if len(masks) > 8:
        raise ValueError(f"regions: at most 8 in one pass, got {len(masks)}")
    bits = None
    for j, m in enumerate(masks.values()):
        b = m.view(np.uint8) << np.uint8(j) if m.dtype == bool else m.astype(np.uint8) << np.uint8(j)
        bits = b if bits is None else bits | b
    return bits


def timing_rows(stage_ms: Mapping[str, float], *, frame: int | None = None) -> list[dict]:
    """One ``time_<stage>_ms`` row per stage (``motion`` "cost"), and ``time_total_ms`` if absent."""
    rows = []
    total = 0.0
    for stage, ms in stage_ms.items():
        ms = float(ms)
        total += ms
        rows.append(_row(timing_metric_name(stage), ms, ms, 1, motion="cost", frame=frame))
    if "total" not in stage_ms and stage_ms:
        rows.append(_row("time_total_ms", total, total, 1, motion="cost", frame=frame))
    return rows


def score_pair(estimate, truth, *, frame: int, regions: Iterable[str] | None = None,
               boundary_px: int | None = None, timings: bool = True, prepared: PreparedTruth | None = None
               ) -> list[dict]:
    """All rows of one frame pair: flow metrics (total and local motion) and stage timings.

    Both motions and every region are scored in one pass over the pixels
    (:mod:`harness._flow_kernels`); the values equal :func:`flow_rows` on each region's
    mask (sums to rounding, ~1e-15 relative, the angular error's arccos being the pass's
    own, within 1 ulp of numpy's; counts, quantiles and histograms exactly). To score
    several estimates of one pair, prepare the truth once::

        prepared = prepare_pair_truth(truth)
        rows = [score_pair(est, truth, frame=f, prepared=prepared) for est in estimates]

    Parameters
    ----------
    estimate : PairEstimate
        Uses ``flow_total``, ``flow_global`` (H, W, 2), ``valid`` (H, W) and ``stage_ms``.
    truth : PairTruth or None
        ``flow``, ``flow_camera`` (H, W, 2), ``valid`` (H, W) bool, ``instances`` (H, W) uint16.
        With ``prepared`` it is only checked for its size (and may be None).
    frame : int
        Index of the first frame of the pair.
    regions : iterable of str, optional
        Regions to score (default :data:`REGIONS`); with ``prepared``, must be its regions if given.
    boundary_px : int, optional
        Margin of the ``interior`` region (default 3); with ``prepared``, must be its margin if given.
    prepared : PreparedTruth, optional
        :func:`prepare_pair_truth` of ``truth``, shared by several estimates of the pair: the
        rows are the same as without it.
    """
    if prepared is None:
        if truth is None:
            raise ValueError("score_pair: expected a PairTruth or prepared=prepare_pair_truth(truth), got neither")
        prepared = prepare_pair_truth(truth, regions=REGIONS if regions is None else regions,
                                      boundary_px=3 if boundary_px is None else boundary_px)
    else:
        if regions is not None and tuple(regions) != prepared.regions:
            raise ValueError(f"regions: expected those of prepared {prepared.regions}, got {tuple(regions)}")
        if boundary_px is not None and boundary_px != prepared.boundary_px:
            raise ValueError(f"boundary_px: expected that of prepared ({prepared.boundary_px}), got {boundary_px}")
        if truth is not None and np.shape(truth.flow)[:2] != prepared.shape:
            raise ValueError(f"truth: expected the size of prepared {prepared.shape}, got {np.shape(truth.flow)[:2]}")
    shape = prepared.shape
    # finiteness of the estimate (total and local) is tested in the pass itself
    e = np.ascontiguousarray(check_flow(estimate.flow_total, name="flow_est", shape=shape, allow_nan=True))
    g = np.asarray(estimate.flow_global, np.float32)
    if g.shape != e.shape:  # as numpy's e - g broadcasts it
        g = np.broadcast_to(g, e.shape)
    # read-only views: one compiled signature of the kernels whatever the caller's arrays
    e, g, ve = _read_only(e), _read_only(np.ascontiguousarray(g)), _read_only(_valid_est(estimate.valid, shape))
    rows, bad = _score_motions(e, g, prepared, ve, frame=frame)
    if bad:  # raise check_flow's message
        check_flow(e, name="flow_est")
        check_flow(e - g, name="flow_est")
    if timings and getattr(estimate, "stage_ms", None):
        rows += timing_rows(estimate.stage_ms, frame=frame)
    return rows


# --------------------------------------------------------------------------- global motion, jitter

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


# --------------------------------------------------------------------------- trajectories

def position_error_px(x_est, y_est, x_true, y_true) -> np.ndarray:
    """Track position error ``|p_est - p_true|`` (Euclidean, px), elementwise, float64; NaN where either is NaN.

    The one definition of a trajectory's error used by every track metric (and
    by reports that show per-frame track errors).
    """
    return np.hypot(np.asarray(x_est, np.float64) - np.asarray(x_true, np.float64),
                    np.asarray(y_est, np.float64) - np.asarray(y_true, np.float64))


_ASSOC_COLUMNS = ["frame", "vehicle_id", "track_id", "dist_px", "switch"]


def _points_by_frame(est: pd.DataFrame, truth: pd.DataFrame):
    """Per frame with a visible vehicle or a finite estimate, ascending: ``(frame, vehicle_ids, P, track_ids, Q)``.

    vehicle_ids (V,) int64 and P (V, 2) ``x_px, y_px`` of the visible rows of ``truth``;
    track_ids (T,) int64 and Q (T, 2) ``x_filt_px, y_filt_px`` of the rows of ``est`` with a
    finite position; each in table order (as ``groupby("frame")`` gives them), from numpy
    arrays taken once (a per-frame DataFrame selection costs ~1 ms each).
    """
    vis = np.asarray(truth["visible"].to_numpy(), bool)
    vf = truth["frame"].to_numpy()[vis]
    vv = truth["vehicle_id"].to_numpy(np.int64)[vis]
    vp = np.stack([truth["x_px"].to_numpy(np.float64)[vis], truth["y_px"].to_numpy(np.float64)[vis]], 1)
    ex, ey = est["x_filt_px"].to_numpy(np.float64), est["y_filt_px"].to_numpy(np.float64)
    ok = np.isfinite(ex) & np.isfinite(ey)
    ef = est["frame"].to_numpy()[ok]
    et = est["track_id"].to_numpy(np.int64)[ok]
    eq = np.stack([ex[ok], ey[ok]], 1)
    ov, oe = np.argsort(vf, kind="stable"), np.argsort(ef, kind="stable")
    vf_s, ef_s = vf[ov], ef[oe]
    for f in np.union1d(vf, ef):
        iv = ov[np.searchsorted(vf_s, f, "left"):np.searchsorted(vf_s, f, "right")]
        ie = oe[np.searchsorted(ef_s, f, "left"):np.searchsorted(ef_s, f, "right")]
        yield f, vv[iv], vp[iv], et[ie], eq[ie]


def _mot_frames(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float):
    """Frame by frame CLEAR-MOT correspondences (Bernardin and Stiefelhagen 2008, sec. 2.1.1).

    Yields ``(frame, vehicle_ids, track_ids, D, match)`` for every frame that has
    a visible vehicle or a finite estimate: ``D`` (V, T) Euclidean distances
    between true centres ``x_px, y_px`` and filtered estimates ``x_filt_px,
    y_filt_px``; ``match`` maps row -> column. A pair farther than ``gate_px``
    never corresponds. A vehicle's last correspondence (of any earlier frame) is
    kept while the same track is present and within the gate; the rest are
    matched by the Hungarian method on distance. ``switch`` flags: the
    vehicle's track differs from its last matched track.
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    last: dict[int, int] = {}   # vehicle -> last matched track ever (Bernardin's M_{t-1}, carried on)
    for f, vids, P, tids, Q in _points_by_frame(est, truth):
        D = position_error_px(P[:, None, 0], P[:, None, 1], Q[None, :, 0], Q[None, :, 1]).reshape(len(P), len(Q))
        match: dict[int, int] = {}
        switch: dict[int, bool] = {}
        for a, vid in enumerate(vids):
            t = last.get(int(vid))
            if t is not None and t in tids:
                b = int(np.flatnonzero(tids == t)[0])
                if D[a, b] <= gate_px and b not in match.values():
                    match[a], switch[a] = b, False
        ra = [a for a in range(len(vids)) if a not in match]
        rb = [b for b in range(len(tids)) if b not in match.values()]
        if ra and rb:
            sub = D[np.ix_(ra, rb)]
            big = 1e6 * (1.0 + float(np.nanmax(sub, initial=0.0)))
            ia, ib = _linear_sum_assignment(np.where(sub <= gate_px, sub, big))
            for x, y in zip(ia, ib):
                if sub[x, y] <= gate_px:
                    a, b = ra[x], rb[y]
                    match[a] = b
                    switch[a] = int(vids[a]) in last and last[int(vids[a])] != int(tids[b])
        for a, b in match.items():
            last[int(vids[a])] = int(tids[b])
        yield f, vids, tids, D, match, switch


def associate_tracks(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0) -> pd.DataFrame:
    """Match estimated tracks to visible vehicles frame by frame (CLEAR-MOT, Bernardin 2008).

    In each frame a vehicle's last correspondence is kept while that track is
    present and within ``gate_px``; the remaining tracks and vehicles are
    matched by the Hungarian method on Euclidean distance, pairs farther than
    ``gate_px`` rejected (the rules of py-motmetrics' ``MOTAccumulator``).
    Positions: estimated ``x_filt_px, y_filt_px`` vs truth ``x_px, y_px``.

    Returns
    -------
    DataFrame with columns frame, vehicle_id, track_id, dist_px, switch (bool:
    the vehicle's track differs from its last matched track).
    """
    out = []
    for f, vids, tids, D, match, switch in _mot_frames(est, truth, gate_px=gate_px):
        for a, b in sorted(match.items()):
            out.append({"frame": int(f), "vehicle_id": int(vids[a]), "track_id": int(tids[b]),
                        "dist_px": float(D[a, b]), "switch": bool(switch[a])})
    return pd.DataFrame(out, columns=_ASSOC_COLUMNS)


@dataclass(frozen=True)
class MOTCounts:
    """Summed CLEAR-MOT and identity counts of one tracker on one sequence (or summed over many).

    objects: visible vehicle-frames (GT); predictions: estimated track-frames;
    matches: corresponding pairs, switches included (py-motmetrics' num_detections); misses (FN), false_positives (FP), switches (IDSW); dist_sum_px: sum
    of the matched distances; idtp, idfn, idfp: identity true positives, false
    negatives, false positives of the best one-to-one vehicle-track assignment
    over the whole sequence (Ristani et al. 2016).
    """

    objects: int
    predictions: int
    matches: int
    misses: int
    false_positives: int
    switches: int
    dist_sum_px: float
    idtp: int
    idfn: int
    idfp: int

    @property
    def mota(self) -> float:
        """MOTA = 1 - (FN + FP + IDSW) / GT (Bernardin 2008, eq. 2); NaN without objects."""
        return 1.0 - (self.misses + self.false_positives + self.switches) / self.objects if self.objects else math.nan

    @property
    def motp_px(self) -> float:
        """MOTP = sum of matched distances / matches (Bernardin 2008, eq. 1), px; NaN without matches."""
        return self.dist_sum_px / self.matches if self.matches else math.nan

    @property
    def idf1(self) -> float:
        """IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN) (Ristani 2016, eq. 7); NaN when both sides are empty."""
        den = 2 * self.idtp + self.idfp + self.idfn
        return 2 * self.idtp / den if den else math.nan


def mot_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0) -> MOTCounts:
    """CLEAR-MOT (Bernardin and Stiefelhagen 2008) and identity (Ristani et al. 2016) counts.

    Parameters
    ----------
    est : DataFrame
        One tracker's rows (``frame, track_id, x_filt_px, y_filt_px``); rows with
        a NaN position are not predictions.
    truth : DataFrame
        tracks.csv (``frame, vehicle_id, x_px, y_px, visible``); visible rows are objects.
    gate_px : float
        A vehicle and a track correspond only within this distance (the
        threshold of both the frame matching and the identity matching).

    The identity assignment pairs each vehicle with at most one track over the
    whole sequence so as to maximise IDTP, the number of frames where the pair
    is present and within the gate (equivalently, to minimise IDFN + IDFP);
    IDFN = objects - IDTP and IDFP = predictions - IDTP.
    """
    objects = predictions = matches = switches = 0
    dist_sum = 0.0
    overlap: dict[tuple[int, int], int] = {}
    for _f, vids, tids, D, match, switch in _mot_frames(est, truth, gate_px=gate_px):
        objects += len(vids)
        predictions += len(tids)
        matches += len(match)
        switches += sum(switch.values())
        dist_sum += float(sum(D[a, b] for a, b in match.items()))
        for a, b in zip(*np.nonzero(D <= gate_px)):
            key = (int(vids[a]), int(tids[b]))
            overlap[key] = overlap.get(key, 0) + 1
    idtp = 0
    if overlap:
        vs = sorted({k[0] for k in overlap})
        ts = sorted({k[1] for k in overlap})
        W = np.zeros((len(vs), len(ts)))
        for (v, t), n in overlap.items():
            W[vs.index(v), ts.index(t)] = n
        ia, ib = _linear_sum_assignment(-W)
        idtp = int(W[ia, ib].sum())
    return MOTCounts(objects=objects, predictions=predictions, matches=matches, misses=objects - matches,
                     false_positives=predictions - matches, switches=switches, dist_sum_px=dist_sum,
                     idtp=idtp, idfn=objects - idtp, idfp=predictions - idtp)


def mot_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0) -> list[dict]:
    """MOTA, MOTP, IDF1 and the FN / FP counts per tracker (``region`` = ``source``), as summable totals.

    One row per metric and tracker, no frame or track id. Each carries the
    counts its aggregate is recomputed from (:class:`MOTCounts`): ``mota`` sum =
    FN + FP + IDSW, count = objects (value 1 - sum / count, reduce
    ``complement``); ``motp`` sum = matched distances, count = matches; ``idf1``
    sum = 2 IDTP, count = objects + predictions; ``mot_misses``,
    ``mot_false_positives`` totals. Summed over cells or seeds these give the
    pooled scores, as py-motmetrics' overall row does.
    """
    rows: list[dict] = []
    if est_tracks is None or est_tracks.empty:
        return rows
    for source, est in est_tracks.groupby("source"):
        c = mot_counts(est, truth_tracks, gate_px=gate_px)
        kw = {"region": str(source), "motion": "track"}
        errors = c.misses + c.false_positives + c.switches
        rows += [
            _row("mota", c.mota, errors, c.objects, **kw),
            _row("motp", c.motp_px, c.dist_sum_px, c.matches, **kw),
            _row("idf1", c.idf1, 2 * c.idtp, c.objects + c.predictions, **kw),
            _row("mot_misses", c.misses, c.misses, c.objects, **kw),
            _row("mot_false_positives", c.false_positives, c.false_positives, c.predictions, **kw),
        ]
    return rows


# HOTA's localisation thresholds alpha = 0.05, 0.10, ..., 0.95 (Luiten et al. 2021, sec. 5)
HOTA_ALPHAS = np.round(np.arange(1, 20) * 0.05, 2)


@dataclass(frozen=True)
class HOTACounts:
    """HOTA totals of one tracker on one sequence, per alpha (Luiten et al. 2021); ``+`` pools sequences.

    Arrays of shape (19,), one entry per alpha in :data:`HOTA_ALPHAS`: ``tp``, ``fn``,
    ``fp`` (detection true positives, misses, false positives at that alpha),
    ``ass_sum`` (sum over the true positives c of the association score
    A(c) = |TPA(c)| / (|TPA(c)| + |FNA(c)| + |FPA(c)|), eq. 9), ``loc_sum`` (sum
    of their similarities). Every score is a ratio of such sums, so pooling
    sequences is adding their counts (TrackEval sums TP, FN, FP and weights AssA
    and LocA by TP, which is the same):

        DetA = TP / (TP + FN + FP)                              (eq. 4)
        AssA = ass_sum / TP                                     (eq. 10)
        HOTA_alpha = sqrt(DetA AssA) = sqrt(ass_sum / (TP + FN + FP))
        HOTA = mean over alpha of HOTA_alpha                    (eq. 12)

    HOTA_alpha is one sum / count pair (reduce ``rms``); HOTA, a mean of 19
    square roots, is not: it needs the 19 pairs.
    """

    tp: np.ndarray
    fn: np.ndarray
    fp: np.ndarray
    ass_sum: np.ndarray
    loc_sum: np.ndarray

    def __add__(self, other: "HOTACounts") -> "HOTACounts":
        return HOTACounts(*(getattr(self, k) + getattr(other, k) for k in ("tp", "fn", "fp", "ass_sum", "loc_sum")))

    def _ratio(self, num: np.ndarray, den: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)

    @property
    def deta(self) -> np.ndarray:
        """DetA per alpha; NaN where there is nothing to detect or predict."""
        return self._ratio(self.tp, self.tp + self.fn + self.fp)

    @property
    def assa(self) -> np.ndarray:
        """AssA per alpha; NaN without true positives."""
        return self._ratio(self.ass_sum, self.tp)

    @property
    def loca(self) -> np.ndarray:
        """LocA per alpha: mean similarity of the true positives; NaN without them."""
        return self._ratio(self.loc_sum, self.tp)

    @property
    def hota_alpha(self) -> np.ndarray:
        """HOTA per alpha, sqrt(DetA AssA) (0 where there are objects but no true positive)."""
        return np.sqrt(self._ratio(self.ass_sum, self.tp + self.fn + self.fp))

    @property
    def hota(self) -> float:
        """HOTA: the mean of HOTA_alpha over the 19 alphas (eq. 12)."""
        return float(np.mean(self.hota_alpha))


def hota_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0) -> HOTACounts:
    """HOTA totals (Luiten et al. 2021) of one tracker's points against the visible vehicles.

    Similarity of a vehicle and a track in a frame: ``S = max(0, 1 - d / gate_px)``
    with d the distance of the true centre ``x_px, y_px`` and the estimate
    ``x_filt_px, y_filt_px`` (HOTA is defined for any similarity in [0, 1]; boxes
    use IoU, points here a distance ramp that reaches 0 at the CLEAR-MOT gate).
    Matching as TrackEval does it: per frame one Hungarian assignment
    maximising ``global_alignment(vehicle, track) * S``, where the global
    alignment score is the pair's soft overlap over the sequence,
    ``sum_t S~ / (n_vehicle + n_track - sum_t S~)`` with ``S~ = S / (row sum +
    column sum - S)`` of the frame's similarity matrix; at each alpha a matched
    pair with ``S >= alpha`` is a true positive. A(c) of a true positive of the
    pair (vehicle, track) is ``n_matched / (n_vehicle + n_track - n_matched)``,
    the counts over the sequence at that alpha.

    Two differences from TrackEval's ``hota.py``, both at edges: the alphas are
    exact (its ``np.arange(0.05, 0.99, 0.05)`` holds 0.30000000000000004 and the
    like, so a similarity equal to such an alpha fails there), and a sequence
    with neither vehicles nor tracks gives NaN, not 0 (as MOTA does here).

    Parameters and row conventions as :func:`mot_counts`. Not yet a results-table
    row: HOTA_alpha is one sum / count pair (``ass_sum``, ``tp + fn + fp``, reduce
    ``rms``), but HOTA itself needs all 19 after pooling.
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    by_frame = list(_points_by_frame(est, truth))
    vids = np.unique(np.concatenate([v for _, v, _, _, _ in by_frame] + [np.zeros(0, np.int64)]))
    tids = np.unique(np.concatenate([t for _, _, _, t, _ in by_frame] + [np.zeros(0, np.int64)]))
    na = len(HOTA_ALPHAS)
    tp, fn, fp = np.zeros(na), np.zeros(na), np.zeros(na)
    loc = np.zeros(na)
    frames = []
    for _f, v, P, t, Q in by_frame:
        a, b = np.searchsorted(vids, v), np.searchsorted(tids, t)
        D = position_error_px(P[:, None, 0], P[:, None, 1], Q[None, :, 0], Q[None, :, 1]).reshape(len(P), len(Q))
        frames.append((a, b, np.maximum(0.0, 1.0 - D / gate_px)))
    # pass 1: global alignment score of every (vehicle, track) pair
    n_v, n_t = np.zeros(len(vids)), np.zeros(len(tids))
    soft = np.zeros((len(vids), len(tids)))
    for a, b, S in frames:
        n_v[a] += 1
        n_t[b] += 1
        den = S.sum(axis=0)[None, :] + S.sum(axis=1)[:, None] - S
        soft[np.ix_(a, b)] += np.where(den > 0, S / np.where(den > 0, den, 1), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        align = soft / (n_v[:, None] + n_t[None, :] - soft)
    # pass 2: per frame one assignment, thresholded at each alpha
    matched = np.zeros((na, len(vids), len(tids)))
    for a, b, S in frames:
        if len(a) == 0 or len(b) == 0:
            fn += len(a)
            fp += len(b)
            continue
        ra, rb = _linear_sum_assignment(-(align[np.ix_(a, b)] * S))
        s = S[ra, rb]
        for k, alpha in enumerate(HOTA_ALPHAS):
            ok = s >= alpha - 1e-10
            tp[k] += ok.sum()
            fn[k] += len(a) - ok.sum()
            fp[k] += len(b) - ok.sum()
            loc[k] += s[ok].sum()
            np.add.at(matched[k], (a[ra[ok]], b[rb[ok]]), 1)
    # sum over true positives of A(c) = sum over pairs of n_matched * n_matched / (n_v + n_t - n_matched)
    union = n_v[None, :, None] + n_t[None, None, :] - matched
    ass = (matched * np.where(union > 0, matched / np.where(union > 0, union, 1), 0.0)).sum(axis=(1, 2))
    return HOTACounts(tp=tp, fn=fn, fp=fp, ass_sum=ass, loc_sum=loc)


def track_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0) -> list[dict]:
    """Trajectory rows per vehicle; ``region`` is the tracker (``source``: "point" or "multi").

    Point-tracker rows map to vehicles by ``seed_vehicle_id``; multi-target rows
    through :func:`associate_tracks`. Errors count the frames where the vehicle
    is visible and a track is assigned; ``x_pred_px`` on frame t is the one-step
    prediction for frame t made from frame t-1. ``track_id`` of a row is the
    vehicle id; per-frame rows (track_error, track_raw_error, track_pred_error)
    carry the frame, per-vehicle rows (ate, fde, completeness, id_switches) not.
    """
    truth = truth_tracks.copy()
    truth["visible"] = truth["visible"].astype(bool)
    vis_n = truth[truth["visible"]].groupby("vehicle_id").size()
    rows: list[dict] = []
    if est_tracks is None or est_tracks.empty:
        return rows
    for source, est in est_tracks.groupby("source"):
        if source == "point":
            m = est.dropna(subset=["seed_vehicle_id"]).copy()
            m["vehicle_id"] = m["seed_vehicle_id"].astype(np.int64)
            m = m[np.isfinite(m["x_filt_px"]) & np.isfinite(m["y_filt_px"])]
            switches = None
        else:
            assoc = associate_tracks(est, truth, gate_px=gate_px)
            m = assoc.merge(est, on=["frame", "track_id"], how="left")
            switches = assoc.groupby("vehicle_id")["switch"].sum()
        m = m.merge(truth[truth["visible"]][["frame", "vehicle_id", "x_px", "y_px"]],
                    on=["frame", "vehicle_id"], suffixes=("_est", "_true"))
        kw = {"region": str(source), "motion": "track"}
        for vid, g in m.sort_values("frame").groupby("vehicle_id"):
            vid = int(vid)
            xt, yt = g["x_px_true"].to_numpy(float), g["y_px_true"].to_numpy(float)
            err = position_error_px(g["x_filt_px"], g["y_filt_px"], xt, yt)
            raw = position_error_px(g["x_px_est"], g["y_px_est"], xt, yt)
            pred = position_error_px(g["x_pred_px"], g["y_pred_px"], xt, yt)
            for f, e1, e2, e3 in zip(g["frame"].to_numpy(), err, raw, pred):
                rows.append(_row("track_error", e1, e1, 1, frame=int(f), track_id=vid, **kw))
                if np.isfinite(e2):
                    rows.append(_row("track_raw_error", e2, e2, 1, frame=int(f), track_id=vid, **kw))
                if np.isfinite(e3):
                    rows.append(_row("track_pred_error", e3, e3, 1, frame=int(f), track_id=vid, **kw))
            sq = float((err ** 2).sum())
            rows.append(_row("track_ate_rmse", math.sqrt(sq / len(err)), sq, len(err), track_id=vid, **kw))
            rows.append(_row("track_fde", err[-1], err[-1], 1, track_id=vid, **kw))
        tracked = m.groupby("vehicle_id")["frame"].nunique()
        for vid, n in vis_n.items():
            k = int(tracked.get(vid, 0))
            rows.append(_row("track_completeness", 100.0 * k / n, k, n, track_id=int(vid), **kw))
            if switches is not None:
                s = int(switches.get(vid, 0))
                rows.append(_row("id_switches", s, s, 1, track_id=int(vid), **kw))
    return rows


def score_sequence(seq_estimate, camera_df: pd.DataFrame, tracks_df: pd.DataFrame | None, *,
                   gate_px: float = 20.0) -> list[dict]:
    """Rows of a whole sequence: global shift errors, residual jitter, trajectories.

    Parameters
    ----------
    seq_estimate : SequenceEstimate
        Uses ``shifts_px`` (N-1, 2), ``jitter_px`` (N, 2) and ``tracks`` (DataFrame or None).
    camera_df, tracks_df : DataFrame or None
        camera.csv and tracks.csv of the sequence; None where the sequence has no such truth
        (real footage): the metrics that need it give no rows.
    """
    rows = []
    if camera_df is not None and getattr(seq_estimate, "shifts_px", None) is not None:
        rows += shift_rows(seq_estimate.shifts_px, camera_df)
    if camera_df is not None and getattr(seq_estimate, "jitter_px", None) is not None:
        rows += jitter_rows(seq_estimate.jitter_px, camera_df)
    shape = getattr(seq_estimate, "frame_shape_px", None)
    if camera_df is not None and getattr(seq_estimate, "correction_px", None) is not None and shape is not None:
        rows += stabilisation_rows(seq_estimate.correction_px, camera_df, shape)
    tracks = getattr(seq_estimate, "tracks", None)
    if tracks is not None and tracks_df is not None and len(tracks):
        rows += track_rows(tracks, tracks_df, gate_px=gate_px)
        rows += mot_rows(tracks, tracks_df, gate_px=gate_px)
    return rows


# --------------------------------------------------------------------------- aggregation

def reduce_totals(metric: str, total: float, count: float, hist: np.ndarray | None = None) -> float:
    """The value of ``metric`` from summed totals (and a summed histogram for quantiles)."""
    d = metric_def(metric) if metric in METRICS else None
    rule = d.reduce if d else "mean"
    if rule == "total":
        return float(total)
    if count == 0 or not np.isfinite(count):
        return float("nan")
    if rule == "mean":
        return float(total / count)
    if rule == "rms":
        return float(math.sqrt(total / count))
    if rule == "rate":
        return float(100.0 * total / count)
    if rule == "complement":
        return float(1.0 - total / count)
    if hist is None:
        return float("nan")
    return hist_quantile(hist, d.q)


def aggregate(rows: pd.DataFrame, by: Iterable[str] = ()) -> pd.DataFrame:
    """Aggregate rows over everything not in ``by`` (+ metric, region, motion), from totals.

    ``sum`` and ``count`` are summed and reduced by each metric's rule; quantile
    metrics sum their ``hist``. Rows whose ``status`` (if present) is not "ok" are
    left out. Returns one row per group with ``by, metric, region, motion, kind,
    value, sum, count, unit, higher_is_better, n_rows`` (and ``hist`` for quantiles).
    """
    keys = list(dict.fromkeys([*by, "metric", "region", "motion"]))
    df = rows
    if "status" in df.columns:
        df = df[df["status"] == "ok"]
    cols = [*keys, "kind", "value", "sum", "count", "unit", "higher_is_better", "n_rows", "hist"]
    if df.empty:
        return pd.DataFrame(columns=cols)
    # the groups of df.groupby(keys, sort=True, dropna=False), walked as slices of one stable sort
    # (a pandas group iteration costs ~2 ms a group: minutes on a suite's results)
    gid = df.groupby(keys, sort=True, dropna=False).ngroup().to_numpy()
    order = np.argsort(gid, kind="stable")  # rows of a group keep their order: the first row is the group's
    bounds = np.flatnonzero(np.diff(gid[order])) + 1
    starts = np.concatenate([[0], bounds])
    ends = np.concatenate([bounds, [len(order)]])
    first = order[starts]
    key_cols = {k: df[k].to_numpy(object)[first] for k in keys}
    sums_all = df["sum"].to_numpy(np.float64)[order]
    counts_all = df["count"].to_numpy(np.float64)[order]
    kind = df["kind"].to_numpy(object)[first]
    unit = df["unit"].to_numpy(object)[first]
    hib = df["higher_is_better"].to_numpy()[first]
    metrics = key_cols["metric"]
    hist_col = df["hist"].to_numpy(object) if "hist" in df.columns else None
    out = []
    for g, (a, b) in enumerate(zip(starts, ends)):
        rec = {k: key_cols[k][g] for k in keys}
        metric = metrics[g]
        sums = sums_all[a:b]
        counts = counts_all[a:b]
        # math.fsum is exactly rounded, so the aggregate does not depend on the order of the rows
        # (which cell finished first); a row with items but no total (NaN) makes the total NaN
        # instead of silently dropping its sum while keeping its count
        total = math.fsum(sums[counts != 0])
        count = math.fsum(counts)
        hist = None
        d = METRICS.get(metric)
        if d is not None and d.reduce == "quantile":
            hist = np.zeros(HIST_NBINS, np.int64)
            for h in ([] if hist_col is None else hist_col[order[a:b]]):
                if isinstance(h, (bytes, bytearray)):
                    add_hist(hist, h)
            total = float("nan")
        rec.update(kind=kind[g], value=reduce_totals(metric, total, count, hist), sum=total,
                   count=count, unit=unit[g], higher_is_better=bool(hib[g]),
                   n_rows=int(b - a), hist=encode_hist(hist) if hist is not None else b"")
        out.append(rec)
    return pd.DataFrame(out, columns=cols)
