"""Metric definitions and scoring, against ground truth or (photometric, ITF) without: numpy / pandas /
OpenCV on arrays, no I/O.

A package split by domain, each formula in one module; this module re-exports every
public name (``from harness.metrics import X`` works for all of them):

=================  ==========================================================
module             what
=================  ==========================================================
``registry``       MetricDef, METRICS, register_metric, the row builder, timing rows
``histogram``      EPE histograms, their binary form, quantiles read from them
``flow``           per-pixel errors, regions, flow rows, PreparedTruth, score_pair
``stabilisation``  shift error, residual jitter, Liu 2013 stabilisation scores
``trajectories``   position error, CLEAR-MOT association, per-vehicle track rows
``mot``            CLEAR-MOT and identity counts (MOTA, MOTP, IDF1), HOTA
``sequence``       score_sequence: every sequence-level row
``aggregate``      reduce_totals, aggregate
``matching``       when an estimate corresponds to a vehicle: IoU, point in box, distance gate
``objects``        which truth rows are counted (vehicles that move) and which are distractors
``detection``      per-frame detection precision and recall against moving vehicles' boxes
``photometric``    truth-free: photometric residual of the total flow, stabilisation ITF
=================  ==========================================================

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
alpha_mean  mean over alphas of summed per-alpha        NaN, visible vehicle-frames
            ratios (``hist``; HOTA, DetA, AssA, LocA)
==========  ==========================================  ===========================

Quantiles (``epe_median``, ``epe_p95``) cannot be summed: their rows carry the
exact per-frame value in ``value`` and the frame's EPE histogram in ``hist``
(fixed bins of :data:`HIST_BIN_PX` = 0.01 px from 0 to :data:`HIST_MAX_PX` = 100 px,
plus one overflow bin whose samples are kept beside it as a sparse histogram of the
same 0.01 px bins, the *tail*, in the compact binary form of :func:`encode_hist`).
:func:`aggregate` sums the histograms and their tails and reads the quantile off at
the bin centre, so an aggregate quantile is within half a bin (0.005 px) of the
quantile of all pixels pooled, above 100 px too (only rows written before tails were
kept, which have an overflow count and no tail, leave a pooled quantile there at
100 px: a floor).

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
overflow_tail, merge_tails, decode_tail               the samples above 100 px, kept for exact quantiles
flow_rows, error_rows                                  flow metrics of one field in one mask
score_flow                                             all flow rows of one pair (no PairEstimate needed)
timing_rows                                            rows from ``stage_ms``
prepare_pair_truth, PreparedTruth                     the truth side of score_pair, shared by estimates
score_pair                                             PairEstimate + PairTruth -> rows
shift_rows, jitter_rows, detrend                       global motion and stabilisation
stabilisation_scores, stabilisation_rows               cropping ratio, distortion, stability (Liu 2013)
position_error_px, associate_tracks, track_rows      trajectories, CLEAR-MOT ID switches
MOTCounts, mot_counts, mot_rows                        MOTA, MOTP, IDF1 from summed counts
HOTACounts, hota_counts, hota_rows, alpha_mean_value  HOTA, DetA, AssA, LocA (Luiten 2021) from per-alpha counts
correspondence, box_iou, box_offset                    when a track or detection matches a vehicle (box-aware)
counted_objects, distractor_table, keep_estimates      counted vehicles, distractors (MOT16, low visibility) and their removal
detection_rows, detection_counts, moving_vehicles      detection precision and recall per pair
prepare_photometric, photometric_rows                  photometric residual of the total flow (no truth)
psnr_shifted, itf_rows                                 stabilisation ITF (no truth)
score_sequence                                         SequenceEstimate + camera.csv + tracks.csv -> rows
aggregate                                              rows DataFrame -> aggregates from totals
"""

from __future__ import annotations

from algorithms.flow import check_flow, endpoint_error  # noqa: F401  (re-exported, as before the split)
from harness.metrics.registry import (  # noqa: F401
    METRICS, REDUCES, STAGES, MetricDef, _row, describe_metrics, metric_def, register_metric, timing_metric_name,
    timing_rows,
)
from harness.metrics.histogram import (  # noqa: F401
    HIST_BIN_PX, HIST_MAX_PX, HIST_NBINS, NO_TAIL, add_hist, decode_hist, decode_tail, encode_hist, epe_histogram,
    hist_quantile, merge_tails, overflow_tail, encode_alpha_totals, decode_alpha_totals,
)
from harness.metrics.flow import (  # noqa: F401
    _KCOV, _KFL, _K1, _K3, _K5, _N, _S_AE, _S_EPE, _S_SQ, MOTIONS, OUTLIER_PX, REGIONS, PreparedTruth,
    _error_rows_from_totals, _finite_uv, _quantile_targets, _quantiles, _rank_index, _read_only, _region_bits,
    _score_motions, _valid_est,
    angular_error_deg, boundary_mask, error_rows, flow_rows, prepare_pair_truth, region_masks, score_flow,
    score_pair,
)
from harness.metrics.stabilisation import (  # noqa: F401
    detrend, jitter_rows, shift_rows, stabilisation_rows, stabilisation_scores,
)
from harness.metrics.matching import _linear_sum_assignment  # noqa: F401
from harness.metrics.objects import (  # noqa: F401
    DISTRACTOR_CLASSES, MIN_VISIBLE_FRACTION, STATIC_SPEED_MPS, VEHICLE_CLASSES, counted_objects, distractor_objects,
    distractor_table, keep_estimates, low_visibility, static_vehicles,
    truth_classes,
)
from harness.metrics.trajectories import (  # noqa: F401
    _mot_frames, _points_by_frame, associate_tracks, position_error_px, track_rows,
)
from harness.metrics.mot import (  # noqa: F401
    HOTA_ALPHAS, HOTACounts, MOTCounts, alpha_mean_value, hota_counts, hota_rows, mot_counts, mot_rows,
)
from harness.metrics.matching import BOX_COLUMNS, IOU_MIN, box_iou, box_offset, correspondence  # noqa: F401
from harness.metrics.detection import MOVING_MIN_MPS, detection_counts, detection_rows, moving_vehicles  # noqa: F401
from harness.metrics.photometric import (  # noqa: F401
    PreparedPhotometric, itf_rows, photometric_rows, prepare_photometric, psnr_shifted,
)
from harness.metrics.sequence import score_sequence  # noqa: F401
from harness.metrics.aggregate import aggregate, reduce_totals  # noqa: F401

__all__ = [
    "METRICS", "MetricDef", "register_metric", "metric_def", "describe_metrics", "timing_metric_name",
    "REGIONS", "MOTIONS", "HIST_BIN_PX", "HIST_MAX_PX", "HIST_NBINS",
    "endpoint_error", "angular_error_deg", "boundary_mask", "region_masks",
    "epe_histogram", "encode_hist", "decode_hist", "add_hist", "hist_quantile",
    "NO_TAIL", "overflow_tail", "merge_tails", "decode_tail",
    "flow_rows", "error_rows", "score_flow", "timing_rows", "score_pair", "PreparedTruth", "prepare_pair_truth",
    "shift_rows", "detrend", "jitter_rows", "stabilisation_scores", "stabilisation_rows", "position_error_px",
    "associate_tracks", "track_rows", "MOTCounts", "mot_counts", "mot_rows",
    "HOTA_ALPHAS", "HOTACounts", "hota_counts", "hota_rows", "alpha_mean_value",
    "encode_alpha_totals", "decode_alpha_totals",
    "BOX_COLUMNS", "IOU_MIN", "box_iou", "box_offset", "correspondence",
    "VEHICLE_CLASSES", "DISTRACTOR_CLASSES", "STATIC_SPEED_MPS", "truth_classes", "counted_objects",
    "distractor_objects", "static_vehicles", "MIN_VISIBLE_FRACTION", "low_visibility",
    "distractor_table", "keep_estimates",
    "detection_rows", "detection_counts", "moving_vehicles",
    "prepare_photometric", "PreparedPhotometric", "photometric_rows", "psnr_shifted", "itf_rows",
    "score_sequence",
    "aggregate", "reduce_totals",
]
