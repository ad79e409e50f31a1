"""aerobench algorithms: pure estimation code on arrays (imports nothing else of the project).

The public API is re-exported here and loaded lazily (PEP 562), so that
``import algorithms.flow`` (what ``scenes`` needs) does not pull in numba,
scikit-image or the pipeline:

* flow convention: ``as_gray``, ``check_frame_pair``, ``check_flow``, ``warp_backward``,
  ``flow_to_color``, ``color_wheel_image`` (``algorithms.flow``)
* the stage registry: ``STAGES`` (kind -> name -> function; ``FLOW_METHODS`` is ``STAGES["flow"]``),
  ``register_flow``, ``register_stage``, ``get_flow_method``, ``get_stage``, ``flow_cost`` (``algorithms.registry``)
* flow methods ``flow, valid = f(frame0, frame1, **params)``: ``lucas_kanade``,
  ``horn_schunck`` (in ``lucas_kanade_flow`` / ``horn_schunck_flow``: a module named like
  its function would shadow the function on the package), ``tv_l1`` (our TV-L1, in
  ``tv_l1_flow``), ``farneback``, ``dis``, ``tvl1`` (scikit-image's), ``ilk``
* global motion: ``ncc_global_motion``, ``affine_global_motion``, ``global_flow``
* jitter removal: ``remove_jitter``; clean-up: ``threshold_flow``, ``zero_outside``,
  ``spatial_filter``, ``temporal_filter``; Kalman: ``scalar_kalman``, ``THESIS_KALMAN``,
  ``ConstantVelocityKalman``, ``kalman_cv_filter``; tracking: ``detect_moving_objects``,
  ``PointTracker``, ``MultiTargetTracker``, the point's image correlation ``ncc_refine``,
  ``point_template``, ``CorrelationMatch``, ``CORRELATION_DEFAULTS``
* the pipeline: ``Pipeline``, ``PIPELINES``, ``get_pipeline``, ``PairEstimate``, ``SequenceEstimate``;
  its description: ``PipelineSpec``, ``resolve_pipeline`` (``algorithms.pipeline_spec``; the built-ins are
  ``algorithms/pipelines/*.yaml``)
"""

from __future__ import annotations

import importlib

# public name -> the module that defines it
_EXPORTS: dict[str, str] = {}
for _module, _names in {
    "algorithms.flow": ("FLOW_DTYPE", "as_gray", "check_frame_pair", "check_flow", "warp_backward",
                        "flow_to_color", "color_wheel_image"),
    "algorithms.registry": ("FLOW_METHODS", "STAGES", "register_flow", "register_stage", "get_flow_method",
                            "get_stage", "flow_cost", "describe"),
    "algorithms.lucas_kanade_flow": ("lucas_kanade",),
    "algorithms.horn_schunck_flow": ("horn_schunck",),
    "algorithms.reference": ("farneback", "dis", "tvl1", "ilk"),
    "algorithms.tv_l1_flow": ("tv_l1",),
    "algorithms.global_motion": ("GlobalMotion", "GlobalModel", "ncc_global_motion", "affine_global_motion",
                                 "global_flow"),
    "algorithms.jitter": ("JitterResult", "cumulative_path", "fit_flight_path", "remove_jitter"),
    "algorithms.filters": ("threshold_flow", "zero_outside", "spatial_filter", "temporal_filter"),
    "algorithms.kalman": ("THESIS_KALMAN", "scalar_kalman", "ConstantVelocityKalman", "CVFilterResult",
                          "kalman_cv_filter", "BoxKalman"),
    "algorithms.detection": ("Detection", "DETECTION_DEFAULTS", "detect_vehicles", "ground_residual"),
    "algorithms.tracking": ("TRACK_COLUMNS", "MULTI_DEFAULTS", "detect_moving_objects", "PointTracker",
                            "MultiTargetTracker",
                            "ncc_refine", "point_template", "CorrelationMatch", "CORRELATION_DEFAULTS"),
    "algorithms.pipeline": ("Pipeline", "PipelineError", "PairEstimate", "SequenceEstimate", "PIPELINES",
                            "get_pipeline", "pipeline_hash"),
    "algorithms.pipeline_spec": ("PipelineSpec", "resolve_pipeline"),
}.items():
    for _name in _names:
        _EXPORTS[_name] = _module
del _module, _names, _name

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'algorithms' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # cache: later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
