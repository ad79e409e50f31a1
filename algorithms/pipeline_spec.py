"""The pipeline description: a pydantic model, the built-in pipelines (YAML package data) and the hash.

A pipeline is described by a plain dict, as YAML holds it (the schema is in the
:class:`~algorithms.pipeline.Pipeline` docstring). :func:`resolve_pipeline` validates it
with :class:`PipelineSpec` (extra keys forbidden, NaN and infinities refused, no
silent type coercion except an integer where a number is expected) and returns the
resolved dict, defaults filled; :func:`pipeline_hash` hashes what it computes. Method
sections (``global_motion``, ``flow``) name a stage of :mod:`algorithms.registry` and
their ``params`` are checked against that function's keyword parameters, so a method a
plugin registers is validated like a built-in one.

The built-in pipelines are the files ``algorithms/pipelines/<name>.yaml`` (package
data), loaded once by :func:`builtin_pipelines`; an error there names the file.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import math
from collections.abc import Callable, Mapping
from functools import cache
from importlib import resources
from typing import Annotated, Any, ClassVar, Union

import numpy as np
import yaml
from pydantic import (BaseModel, ConfigDict, Discriminator, Field, StrictBool, StrictInt, StrictStr,
                      Tag, ValidationError, field_validator, model_validator)
from pydantic_core import PydanticCustomError

import algorithms.horn_schunck_flow  # noqa: F401  (each built-in stage module registers its stages on import)
import algorithms.lucas_kanade_flow  # noqa: F401
import algorithms.reference  # noqa: F401
import algorithms.tv_l1_flow  # noqa: F401
from algorithms.filters import threshold_flow
from algorithms.global_motion import affine_global_motion
from algorithms.jitter import JITTER_MODELS
from algorithms.registry import STAGES
from algorithms.detection import DETECTION_DEFAULTS, detect_vehicles
from algorithms.long_baseline import LONG_BASELINE_DEFAULTS, check_long_baseline
from algorithms.sequence_size import SEQUENCE_SIZE_DEFAULTS, check_sequence_size
from algorithms.tracking import MULTI_DEFAULTS, MultiTargetTracker, PointTracker

__all__ = ["PipelineError", "PipelineSpec", "COMPENSATION_MODELS", "resolve_pipeline", "pipeline_hash",
           "builtin_pipelines", "BUILTIN_DIR"]

COMPENSATION_MODELS = ("none", "shift", "affine", "homography")
BUILTIN_DIR = "pipelines"  # inside the algorithms package: <name>.yaml per built-in pipeline


class PipelineError(ValueError):
    """A pipeline description is invalid; the message names the field (and the file, for a built-in)."""


# ---------------------------------------------------------------------------------------------
# errors: one line per problem, "dotted.field: what was expected, what came"


def _fail(msg: str, **ctx: Any) -> PydanticCustomError:
    """An error whose message is ours; ``at`` (dotted, optional) is appended to the field's location."""
    return PydanticCustomError("pipeline", msg.replace("{", "{{").replace("}", "}}"), ctx)


def _checked_by(check: Callable[[], Any]) -> Any:
    """``check()``'s result; its ``ValueError`` ("key: message", the stage's own check) as a pipeline error at that
    key, so that each stage's keys and ranges have one home, the stage, and errors come at load, not mid-run."""
    try:
        return check()
    except ValueError as e:
        at, _, msg = str(e).partition(": ")
        raise _fail(msg, at=at) from None


def _got(v: Any) -> str:
    return f"{v!r} ({type(v).__name__})"


_MESSAGES = {
    "bool_type": "expected true/false, got {got}",
    "int_type": "expected an integer, got {got}",
    "float_type": "expected a number, got {got}",
    "string_type": "expected a string, got {got}",
    "finite_number": "expected a finite number, got {input}",
    "missing": "missing (required)",
    "model_type": "expected a mapping, got {got}",
    "model_attributes_type": "expected a mapping, got {got}",
    "dict_type": "expected a mapping, got {got}",
}


_UNION_TAGS = ("true/false", "mapping")  # members of a union, not fields


def _error_lines(err: ValidationError) -> list[str]:
    lines = []
    for e in err.errors(include_url=False):
        loc = [str(p) for p in e["loc"] if p not in _UNION_TAGS]
        ctx = e.get("ctx") or {}
        if ctx.get("at"):
            loc.append(ctx["at"])
        if e["type"] == "pipeline":
            msg = e["msg"]
        elif e["type"] in _MESSAGES:
            msg = _MESSAGES[e["type"]].format(got=_got(e.get("input")), input=e.get("input"))
        else:
            msg = e["msg"]
        lines.append(f"{'.'.join(loc) or 'pipeline'}: {msg}")
    # a value of a union type fails once per member: say each line once
    return list(dict.fromkeys(lines))


# ---------------------------------------------------------------------------------------------
# the model


class _Section(BaseModel):
    """Strict: no unknown keys (the error lists the valid ones), no NaN, no coercion but int -> float."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, validate_default=False)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, v: Any) -> Any:
        if isinstance(v, Mapping):
            for k in v:
                if k not in cls.model_fields:
                    raise _fail(f"unknown key; valid: {', '.join(cls.model_fields)}{cls._hint()}", at=str(k))
        return v

    @classmethod
    def _hint(cls) -> str:
        return ""


def _finite(where: str, v: Any) -> Any:
    """A value of a parameter whose default is None: any JSON-like value, numbers finite, lists checked inside."""
    if isinstance(v, float) and not math.isfinite(v):
        raise _fail(f"expected a finite number, got {v}", at=where)
    if isinstance(v, (list, tuple)):
        return [_finite(f"{where}[{i}]" if where else f"[{i}]", x) for i, x in enumerate(v)]
    return v


def _check_param(name: str, v: Any, default: Any) -> Any:
    """``v`` checked against the type of the function's default (None default: any finite value)."""
    if default is None or default is inspect.Parameter.empty:
        return _finite(name, v)
    if isinstance(v, float) and not math.isfinite(v):
        raise _fail(f"expected a finite number, got {v}", at=name)
    if isinstance(default, bool):
        if not isinstance(v, bool):
            raise _fail(f"expected true/false, got {_got(v)}", at=name)
    elif isinstance(default, int):
        if isinstance(v, bool) or not isinstance(v, int):
            raise _fail(f"expected an integer, got {_got(v)}", at=name)
    elif isinstance(default, float):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise _fail(f"expected a number, got {_got(v)}", at=name)
        v = float(v)
    elif isinstance(default, str):
        if not isinstance(v, str):
            raise _fail(f"expected a string, got {_got(v)}", at=name)
    return v


def check_params(fn: Callable, params: Mapping, *, skip: tuple[str, ...] = ()) -> dict:
    """``params`` checked against the keyword parameters of ``fn`` after its two frames (given order kept)."""
    sig = list(inspect.signature(fn).parameters.values())[2:]
    accepted = {p.name: p.default for p in sig if p.name not in skip
                and p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)}
    out = {}
    for k, v in params.items():
        if k not in accepted:
            raise _fail(f"unknown parameter of {fn.__name__}; valid: {', '.join(accepted)}", at=f"params.{k}")
        out[k] = _check_param(f"params.{k}", v, accepted[k])
    return out


class _MethodSection(_Section):
    """``{method: <name registered as a stage of KIND>, params: {...}}``."""

    KIND: ClassVar[str]
    WHAT: ClassVar[str]

    method: str
    params: dict[str, Any] = Field(default_factory=dict)

    @classmethod
    def _hint(cls) -> str:
        return f" (method parameters go under {cls.KIND}.params)"

    @model_validator(mode="before")
    @classmethod
    def _method_known(cls, v: Any) -> Any:
        if isinstance(v, Mapping):
            table = STAGES.get(cls.KIND, {})
            valid = ", ".join(sorted(table)) or "(none registered)"
            if "method" not in v:
                raise _fail(f"missing; valid: {valid}", at="method")
            name = v["method"]
            if not isinstance(name, str) or name not in table:
                raise _fail(f"unknown {cls.WHAT} {name!r}; valid: {valid}", at="method")
        return v

    @model_validator(mode="after")
    def _params_fit(self) -> _MethodSection:
        self.params = check_params(STAGES[self.KIND][self.method], self.params)
        return self


class GlobalMotionSpec(_MethodSection):
    KIND = "global_motion"
    WHAT = "global motion method"


class FlowSpec(_MethodSection):
    KIND = "flow"
    WHAT = "flow method"


class JitterSpec(_Section):
    model: StrictStr = "line"
    window_frames: StrictInt = 15
    polyorder: StrictInt = 2
    iterations: StrictInt = 1

    @model_validator(mode="after")
    def _ranges(self) -> JitterSpec:
        if self.model not in JITTER_MODELS:
            raise _fail(f"expected one of {', '.join(JITTER_MODELS)}, got {self.model!r}", at="model")
        if self.iterations < 1:
            raise _fail(f"expected >= 1, got {self.iterations}", at="iterations")
        if self.window_frames < 3 or self.window_frames % 2 == 0:
            raise _fail(f"expected an odd integer >= 3, got {self.window_frames}", at="window_frames")
        return self


class CompensationSpec(_Section):
    """``none | shift | affine | homography``, or ``{model, params}`` (params: of affine_global_motion)."""

    model: Any = None
    params: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="before")
    @classmethod
    def _from_name(cls, v: Any) -> Any:
        return {"model": v} if isinstance(v, str) else v

    @model_validator(mode="after")
    def _model_and_params(self) -> CompensationSpec:
        if self.model not in COMPENSATION_MODELS:
            raise _fail(f"expected one of {', '.join(COMPENSATION_MODELS)}, got {self.model!r}", at="model")
        if self.model in ("affine", "homography"):
            self.params = check_params(affine_global_motion, self.params, skip=("model",))
        elif self.params:
            raise _fail(f"the {self.model!r} model takes no parameters", at="params")
        return self


class ThresholdSpec(_Section):
    direction: Any = None
    tolerance_deg: float = 45.0
    min_magnitude_px: float = 0.0
    max_magnitude_px: Any = None

    @field_validator("direction", "max_magnitude_px")
    @classmethod
    def _any_finite(cls, v: Any) -> Any:
        return _finite("", v)

    @model_validator(mode="after")
    def _function_accepts(self) -> ThresholdSpec:
        try:  # the function's own checks, on a 1-pixel field, so errors come now and not mid-run
            threshold_flow(np.zeros((1, 1, 2), np.float32), **_dump(self))
        except (TypeError, ValueError) as e:
            raise _fail(str(e)) from None
        return self


class LongBaselineSpec(_Section):
    """The keys of :data:`algorithms.long_baseline.LONG_BASELINE_DEFAULTS` (defaults and meaning there)."""

    frames: StrictInt = LONG_BASELINE_DEFAULTS["frames"]
    slow_frames: StrictInt = LONG_BASELINE_DEFAULTS["slow_frames"]
    min_displacement_px: float = LONG_BASELINE_DEFAULTS["min_displacement_px"]
    max_speed_px: float = LONG_BASELINE_DEFAULTS["max_speed_px"]
    ground_model: StrictStr = LONG_BASELINE_DEFAULTS["ground_model"]
    replace_rel: float = LONG_BASELINE_DEFAULTS["replace_rel"]
    min_box_px: StrictInt = LONG_BASELINE_DEFAULTS["min_box_px"]
    parallax_max_ratio: float = LONG_BASELINE_DEFAULTS["parallax_max_ratio"]
    mid_check: StrictBool = LONG_BASELINE_DEFAULTS["mid_check"]
    reregister_px: float = LONG_BASELINE_DEFAULTS["reregister_px"]
    parallax_trend: float = LONG_BASELINE_DEFAULTS["parallax_trend"]
    parallax_trend_frames: StrictInt = LONG_BASELINE_DEFAULTS["parallax_trend_frames"]
    parallax_trend_snr: float = LONG_BASELINE_DEFAULTS["parallax_trend_snr"]
    flow_params: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _checked(self) -> LongBaselineSpec:
        _checked_by(lambda: check_long_baseline(_dump(self)))
        return self


class SequenceSizeSpec(_Section):
    """The keys of :data:`algorithms.sequence_size.SEQUENCE_SIZE_DEFAULTS` (defaults and meaning there)."""

    small_rel: float = SEQUENCE_SIZE_DEFAULTS["small_rel"]
    slow_rel: float = SEQUENCE_SIZE_DEFAULTS["slow_rel"]
    large_rel: float = SEQUENCE_SIZE_DEFAULTS["large_rel"]
    min_history: StrictInt = SEQUENCE_SIZE_DEFAULTS["min_history"]
    history: StrictInt = SEQUENCE_SIZE_DEFAULTS["history"]
    vehicle_m2: Any = SEQUENCE_SIZE_DEFAULTS["vehicle_m2"]

    @model_validator(mode="after")
    def _checked(self) -> SequenceSizeSpec:
        _checked_by(lambda: check_sequence_size(_dump(self)))
        return self


class DetectionSpec(_Section):
    """The keys of :data:`algorithms.detection.DETECTION_DEFAULTS` (defaults and meaning there), checked by it."""

    field: StrictStr = "local"
    px_scale: Any = "auto"
    min_magnitude_px: float = DETECTION_DEFAULTS["min_magnitude_px"]
    open_px: StrictInt = DETECTION_DEFAULTS["open_px"]
    close_px: StrictInt = DETECTION_DEFAULTS["close_px"]
    min_area_px: StrictInt = DETECTION_DEFAULTS["min_area_px"]
    max_area_px: Any = DETECTION_DEFAULTS["max_area_px"]
    split_px: float = DETECTION_DEFAULTS["split_px"]
    split_rel: float = DETECTION_DEFAULTS["split_rel"]
    merge_gap_px: float = DETECTION_DEFAULTS["merge_gap_px"]
    merge_px: float = DETECTION_DEFAULTS["merge_px"]
    merge_rel: float = DETECTION_DEFAULTS["merge_rel"]
    parallax_max_ratio: float = DETECTION_DEFAULTS["parallax_max_ratio"]
    parallax_perp_px: float = DETECTION_DEFAULTS["parallax_perp_px"]
    parallax_perp_rel: float = DETECTION_DEFAULTS["parallax_perp_rel"]
    parallax_lengthwise_rel: float = DETECTION_DEFAULTS["parallax_lengthwise_rel"]
    parallax_min_fraction: float = DETECTION_DEFAULTS["parallax_min_fraction"]
    parallax_angle_deg: float = DETECTION_DEFAULTS["parallax_angle_deg"]
    parallax_speed_rel: float = DETECTION_DEFAULTS["parallax_speed_rel"]
    min_explained: float = DETECTION_DEFAULTS["min_explained"]
    min_area_m2: Any = DETECTION_DEFAULTS["min_area_m2"]
    max_area_m2: Any = DETECTION_DEFAULTS["max_area_m2"]
    core_rel: float = DETECTION_DEFAULTS["core_rel"]
    ground_model: StrictStr = DETECTION_DEFAULTS["ground_model"]
    noise_k: float = DETECTION_DEFAULTS["noise_k"]
    border_px: StrictInt = DETECTION_DEFAULTS["border_px"]
    refine_px: StrictInt = DETECTION_DEFAULTS["refine_px"]
    nms_iou: float = DETECTION_DEFAULTS["nms_iou"]
    nms_inside: float = DETECTION_DEFAULTS["nms_inside"]
    box_from_frames: StrictBool = DETECTION_DEFAULTS["box_from_frames"]
    box_join: float = DETECTION_DEFAULTS["box_join"]
    box_three_frames: StrictBool = DETECTION_DEFAULTS["box_three_frames"]
    box_reach_px: StrictInt = DETECTION_DEFAULTS["box_reach_px"]
    box_reach_join: float = DETECTION_DEFAULTS["box_reach_join"]
    box_reach_parts: StrictBool = DETECTION_DEFAULTS["box_reach_parts"]
    box_reach_road_k: float = DETECTION_DEFAULTS["box_reach_road_k"]
    change_noise_k: float = DETECTION_DEFAULTS["change_noise_k"]
    change_enough: float = DETECTION_DEFAULTS["change_enough"]
    box_margin_rel: float = DETECTION_DEFAULTS["box_margin_rel"]
    box_split_rel: float = DETECTION_DEFAULTS["box_split_rel"]
    leftover_rel: float = DETECTION_DEFAULTS["leftover_rel"]
    max_area_halo_rel: float = DETECTION_DEFAULTS["max_area_halo_rel"]
    min_box_m2: Any = DETECTION_DEFAULTS["min_box_m2"]
    gap_split_width_px: StrictInt = DETECTION_DEFAULTS["gap_split_width_px"]
    gap_split_length_px: StrictInt = DETECTION_DEFAULTS["gap_split_length_px"]
    gap_split_road_k: float = DETECTION_DEFAULTS["gap_split_road_k"]
    gap_split_valley: float = DETECTION_DEFAULTS["gap_split_valley"]
    gap_split_moved: StrictBool = DETECTION_DEFAULTS["gap_split_moved"]
    shadow_trim_rel: float = DETECTION_DEFAULTS["shadow_trim_rel"]
    shadow_ratio_lo: float = DETECTION_DEFAULTS["shadow_ratio_lo"]
    shadow_ratio_hi: float = DETECTION_DEFAULTS["shadow_ratio_hi"]
    shadow_vote: float = DETECTION_DEFAULTS["shadow_vote"]
    shadow_min_votes: StrictInt = DETECTION_DEFAULTS["shadow_min_votes"]
    refine_wide_px: StrictInt = DETECTION_DEFAULTS["refine_wide_px"]
    shadow_scope: StrictStr = DETECTION_DEFAULTS["shadow_scope"]
    shadow_clip_min_votes: StrictInt = DETECTION_DEFAULTS["shadow_clip_min_votes"]
    shadow_lead_px: StrictInt = DETECTION_DEFAULTS["shadow_lead_px"]
    shadow_diagonal_deg: float = DETECTION_DEFAULTS["shadow_diagonal_deg"]
    lane_fill_rel: float = DETECTION_DEFAULTS["lane_fill_rel"]
    lane_fill_line: float = DETECTION_DEFAULTS["lane_fill_line"]
    lane_fill_road_k: float = DETECTION_DEFAULTS["lane_fill_road_k"]
    gsd_m_per_px: Any = None
    long_baseline: LongBaselineSpec = Field(default_factory=LongBaselineSpec)
    sequence_size: SequenceSizeSpec = Field(default_factory=SequenceSizeSpec)

    @model_validator(mode="after")
    def _detector_accepts(self) -> DetectionSpec:
        d = _dump(self)
        d.pop("long_baseline")
        d.pop("sequence_size")
        gsd = d.pop("gsd_m_per_px")
        if d.pop("field") not in ("local", "filtered"):
            raise _fail(f"expected local or filtered, got {self.field!r}", at="field")
        ps = d.pop("px_scale")
        if ps not in ("auto", "frame") and (isinstance(ps, bool) or not isinstance(ps, (int, float))
                                            or not math.isfinite(ps) or not ps > 0):
            raise _fail(f"expected auto, frame or a finite number > 0, got {ps!r}", at="px_scale")
        if gsd is not None and (isinstance(gsd, bool) or not isinstance(gsd, (int, float))
                                or not math.isfinite(gsd) or not gsd > 0):
            raise _fail(f"expected null or a finite number > 0, got {gsd!r}", at="gsd_m_per_px")
        # the detector's own checks, on a 1-pixel field
        _checked_by(lambda: detect_vehicles(np.zeros((1, 1, 2), np.float32), np.zeros((1, 1), bool), **d))
        return self


# the scalar Kalman filter of the thesis point tracker (eqs. 4.6-4.10): the keys a pipeline may give, and the
# type each takes (x0: any finite value); only the given ones are kept (the filter's own defaults apply)
_KALMAN_TYPES = {"x0": None, "p0": 0.0, "q": 0.0, "r": 0.0}


class PointSpec(_Section):
    field: StrictStr = "filtered"
    kalman: dict[str, Any] | None = None
    recentre_px: Any = None
    filter: StrictStr = "flow"
    sigma_accel_px: float = 0.5
    sigma_meas_px: float = 1.0
    correlation: dict[str, Any] | None = None

    @field_validator("kalman", mode="before")
    @classmethod
    def _kalman(cls, v: Any) -> Any:
        if v is None:
            return v
        if not isinstance(v, Mapping):
            raise _fail(f"expected a mapping, got {_got(v)}")
        for k in v:
            if k not in _KALMAN_TYPES:
                raise _fail(f"unknown key; valid: {', '.join(_KALMAN_TYPES)}", at=str(k))
        return {k: _check_param(k, v[k], _KALMAN_TYPES[k]) for k in v}

    @field_validator("recentre_px", mode="before")
    @classmethod
    def _radius(cls, v: Any) -> Any:
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
            raise _fail(f"expected null or a number > 0, got {v!r}")
        return _finite("", v)

    @model_validator(mode="after")
    def _values(self) -> PointSpec:
        if self.filter not in ("flow", "position"):
            raise _fail(f"expected flow or position, got {self.filter!r}", at="filter")
        try:
            PointTracker(0.0, 0.0, position_filter={"sigma_accel_px": self.sigma_accel_px,
                                                    "sigma_meas_px": self.sigma_meas_px})
        except ValueError as e:
            raise _fail(str(e)) from None
        if self.field not in ("filtered", "local"):
            raise _fail(f"expected filtered or local, got {self.field!r}", at="field")
        if self.correlation is not None:
            # the tracker fills CORRELATION_DEFAULTS and checks them: one home for its keys and their ranges
            self.correlation = _checked_by(lambda: PointTracker(0.0, 0.0, correlation=self.correlation).correlation)
        return self


class MultiSpec(_Section):
    """The keys of :data:`algorithms.tracking.MULTI_DEFAULTS` (defaults and meaning there), checked by the tracker."""

    gate_px: float = MULTI_DEFAULTS["gate_px"]
    min_iou: float = MULTI_DEFAULTS["min_iou"]
    birth_hits: StrictInt = MULTI_DEFAULTS["birth_hits"]
    birth_gap: StrictInt = MULTI_DEFAULTS["birth_gap"]
    min_travel_px: float = MULTI_DEFAULTS["min_travel_px"]
    min_travel_rel: float = MULTI_DEFAULTS["min_travel_rel"]
    travel_lengthwise_rel: float = MULTI_DEFAULTS["travel_lengthwise_rel"]
    min_trend_f: float = MULTI_DEFAULTS["min_trend_f"]
    partial_rel: float = MULTI_DEFAULTS["partial_rel"]
    partial_abreast: StrictBool = MULTI_DEFAULTS["partial_abreast"]
    partial_steady_frames: StrictInt = MULTI_DEFAULTS["partial_steady_frames"]
    abreast_shared: StrictBool = MULTI_DEFAULTS["abreast_shared"]
    death_misses: StrictInt = MULTI_DEFAULTS["death_misses"]
    coast_gate_growth: float = MULTI_DEFAULTS["coast_gate_growth"]
    report_coasting: StrictBool = MULTI_DEFAULTS["report_coasting"]
    fill_gaps: StrictBool = MULTI_DEFAULTS["fill_gaps"]
    fill_min_ncc: float = MULTI_DEFAULTS["fill_min_ncc"]
    min_area_rel: float = MULTI_DEFAULTS["min_area_rel"]
    use_velocity: StrictBool = MULTI_DEFAULTS["use_velocity"]
    hold_min_ncc: float = MULTI_DEFAULTS["hold_min_ncc"]
    hold_search_px: float = MULTI_DEFAULTS["hold_search_px"]
    hold_min_travel_rel: float = MULTI_DEFAULTS["hold_min_travel_rel"]
    hold_same_frames: StrictInt = MULTI_DEFAULTS["hold_same_frames"]
    back_min_travel_rel: float = MULTI_DEFAULTS["back_min_travel_rel"]
    back_track_size: StrictBool = MULTI_DEFAULTS["back_track_size"]
    back_stop_inside: float = MULTI_DEFAULTS["back_stop_inside"]
    hold_frames: StrictInt = MULTI_DEFAULTS["hold_frames"]
    hold_history: StrictInt = MULTI_DEFAULTS["hold_history"]
    steady_flow_rel: float = MULTI_DEFAULTS["steady_flow_rel"]
    end_min_hits: StrictInt = MULTI_DEFAULTS["end_min_hits"]
    steady_min_hits: StrictInt = MULTI_DEFAULTS["steady_min_hits"]
    merge_hits: StrictInt = MULTI_DEFAULTS["merge_hits"]
    merge_inside: float = MULTI_DEFAULTS["merge_inside"]
    merge_covered: StrictBool = MULTI_DEFAULTS["merge_covered"]
    merge_whole_spares: StrictBool = MULTI_DEFAULTS["merge_whole_spares"]
    merge_rigid_rel: float = MULTI_DEFAULTS["merge_rigid_rel"]
    merge_union_rel: float = MULTI_DEFAULTS["merge_union_rel"]
    merge_bridge_grey: float = MULTI_DEFAULTS["merge_bridge_grey"]
    smooth_size_frames: StrictInt = MULTI_DEFAULTS["smooth_size_frames"]
    part_inside: float = MULTI_DEFAULTS["part_inside"]
    sigma_accel_px: float = MULTI_DEFAULTS["sigma_accel_px"]
    sigma_size_accel_px: float = MULTI_DEFAULTS["sigma_size_accel_px"]
    sigma_meas_px: float = MULTI_DEFAULTS["sigma_meas_px"]
    sigma_vel_meas_px: float = MULTI_DEFAULTS["sigma_vel_meas_px"]
    sigma_vel0_px: float = MULTI_DEFAULTS["sigma_vel0_px"]

    @model_validator(mode="after")
    def _tracker_accepts(self) -> MultiSpec:
        _checked_by(lambda: MultiTargetTracker(**_dump(self)))
        return self


class TrackingSpec(_Section):
    point: Annotated[Union[Annotated[StrictBool, Tag("true/false")], Annotated[PointSpec, Tag("mapping")]],
                     Discriminator(lambda v: "true/false" if isinstance(v, bool) else "mapping")] = True
    multi: MultiSpec | None = None

    @field_validator("point", mode="before")
    @classmethod
    def _bool_or_mapping(cls, v: Any) -> Any:
        if not isinstance(v, (bool, Mapping)):
            raise _fail(f"expected true/false or a mapping, got {v!r}")
        return v


class PipelineSpec(_Section):
    """A pipeline description (the stages in the order they run); :func:`resolve_pipeline` dumps it."""

    name: StrictStr
    description: StrictStr = ""
    global_motion: GlobalMotionSpec = Field(
        default_factory=lambda: GlobalMotionSpec(method="ncc_global_motion"))
    jitter: JitterSpec | None = Field(default_factory=JitterSpec)
    compensation: CompensationSpec = Field(default_factory=lambda: CompensationSpec(model="shift"))
    flow: FlowSpec
    threshold: ThresholdSpec | None = None
    spatial: StrictBool = False
    temporal: StrictBool = False
    detection: DetectionSpec = Field(default_factory=DetectionSpec)
    tracking: TrackingSpec = Field(default_factory=TrackingSpec)

    @field_validator("name")
    @classmethod
    def _non_empty(cls, v: str) -> str:
        if not v:
            raise _fail(f"expected a non-empty string, got {v!r}")
        return v

    @model_validator(mode="after")
    def _long_flow_params_fit(self) -> PipelineSpec:
        # the long pair's flow parameters are the flow method's: checked against it, at their own key
        extra = self.detection.long_baseline.flow_params
        if extra:
            try:
                self.detection.long_baseline.flow_params = check_params(STAGES["flow"][self.flow.method], extra)
            except PydanticCustomError as e:
                raise _fail(e.message(), at="detection.long_baseline.flow_" + str(e.context.get("at", "params"))) \
                    from None
        return self


def _dump(model: BaseModel) -> dict:
    """A section as the resolved dict holds it: every field (defaults filled) in the model's order."""
    out = {}
    for k in type(model).model_fields:
        v = getattr(model, k)
        if isinstance(v, BaseModel):
            v = _dump(v)
        elif isinstance(v, (dict, list)):
            v = json.loads(json.dumps(v))  # a fresh copy
        out[k] = v
    return out


# ---------------------------------------------------------------------------------------------
# entry points


def resolve_pipeline(d: Any, *, source: str | None = None) -> dict:
    """Validate a pipeline dict and return it resolved (defaults filled, ints widened to floats where a
    number is expected). Raises :class:`PipelineError` naming the field, and ``source`` (a file) when given."""
    prefix = f"{source}: " if source else ""
    if not isinstance(d, Mapping):
        raise PipelineError(f"{prefix}pipeline: expected a mapping, got {_got(d)}")
    try:
        spec = PipelineSpec.model_validate(dict(d))
    except ValidationError as e:
        raise PipelineError(prefix + "; ".join(_error_lines(e))) from None
    return _dump(spec)


def pipeline_hash(config: Mapping) -> str:
    """Stable 16-hex hash of what a pipeline computes (its resolved dict without name and description)."""
    body = {k: v for k, v in config.items() if k not in ("name", "description")}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@cache
def _builtin_texts() -> tuple[tuple[str, str, str], ...]:
    folder = resources.files("algorithms") / BUILTIN_DIR
    return tuple(sorted((f.name.removesuffix(".yaml"), str(f), f.read_text())
                        for f in folder.iterdir() if f.name.endswith(".yaml")))


def builtin_pipelines() -> dict[str, dict]:
    """The built-in pipelines, name -> the plain dict of its YAML file (as a suite would hold it), checked.

    Each file ``algorithms/pipelines/<name>.yaml`` holds one pipeline whose ``name`` is the
    file's stem; a file that does not validate raises :class:`PipelineError` naming it.
    """
    out = {}
    for stem, path, text in _builtin_texts():
        try:
            d = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise PipelineError(f"{path}: not valid YAML: {e}") from None
        resolve_pipeline(d, source=path)
        if d["name"] != stem:
            raise PipelineError(f"{path}: name: expected {stem!r} (the file's name), got {d['name']!r}")
        out[stem] = d
    return out
