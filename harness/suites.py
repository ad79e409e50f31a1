"""Benchmark suites: a validated YAML description of scenes x seeds x pipelines, and its cells.

A suite names scenes (a preset, fixed overrides and an optional sweep: a grid over
any scene parameter by dotted key), the seeds each scene is rendered with, the
pipelines to run (names from ``algorithms.pipeline.PIPELINES`` or inline dicts) and
the metrics to score (names from ``harness.metrics``). :func:`expand` turns it into
cells, one per (scene variant, seed, pipeline), each with a stable ``cell_id``
derived from the hash of everything that determines its results.

Example::

    name: sweep-jitter
    scenes:
      - preset: jitter
        sweep: {camera.jitter.roll_std_deg: [0.0, 0.3, 0.6]}
    seeds: [1, 2]
    pipelines:
      - thesis-lk
      - {name: hs-alpha-5, base: thesis-hs, spec: {flow: {params: {alpha: 5.0}}}}
    metrics: [epe_mean, shift_error]

(``tests/harness/test_suites.py`` parses and expands this example.)

A scene may instead be real footage (:class:`RealEntry`): a video file or a folder of
frames, with a frame range, a scale, a frame rate and optional annotations; relative
paths are taken from the suite file's folder::

    scenes:
      - real: clips/flight3.mp4
        label: flight3
        start: 100
        frames: 60            # or stop: 160 (exclusive); default: to the end
        scale: 0.5
        fps: 30               # default: the video's own rate
        gt: clips/flight3/gt/gt.txt
        gt_format: mot        # or visdrone, uavdt
      - real: kit_ais/MOS74-93 # frames folder; NAME.txt YOLO labels beside each frame are read
        label: MOS74

A real scene is decoded once into the render cache (:mod:`scenes.footage`) and runs once,
with seed 0, whatever ``seeds`` says (it has nothing random to vary).

``imports:`` names
modules to import first, e.g. one that registers your own flow method; modules in the
working folder are importable (:func:`import_modules`).

Errors raise :class:`SuiteError` naming the file and the field
(``suite.yaml: scenes[0].sweep: an empty sweep ...``); YAML syntax errors give the line.
"""

from __future__ import annotations

import copy
import itertools
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import (BaseModel, ConfigDict, Discriminator, Field, Tag, ValidationError, field_validator,
                      model_validator)

__all__ = [
    "SuiteError",
    "SceneEntry",
    "RealEntry",
    "InlinePipeline",
    "Suite",
    "SceneVariant",
    "Cell",
    "builtin_suites",
    "describe_suites",
    "load_suite",
    "parse_suite",
    "expand",
    "pipeline_names",
    "metric_names",
    "import_modules",
]

# A scene override or pipeline parameter as YAML gives it (checked finite below; the scene
# spec and the pipeline validate the rest with messages naming their fields).
Value = Any


class SuiteError(ValueError):
    """A suite file or dict is not a valid suite; the message names the file and the field."""


def _check_finite(value: Any, where: str = "") -> None:
    """Refuse NaN and infinity anywhere in ``value`` (YAML's .nan / .inf), naming the key."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{where or 'value'}: {value!r} is not a finite number")
    if isinstance(value, Mapping):
        for k, v in value.items():
            _check_finite(v, f"{where}.{k}" if where else str(k))
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_finite(v, f"{where}[{i}]")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True, strict=False)


class SceneEntry(_Model):
    """One scene line of a suite: a preset, fixed overrides, and an optional sweep grid."""

    preset: str = Field(min_length=1, description="scene preset name or path to a scene YAML")
    label: str | None = Field(None, description="name in tables; default: the preset name")
    overrides: dict[str, Value] = Field(default_factory=dict, description="dotted key -> value")
    sweep: dict[str, list[Value]] | None = Field(
        None, description="dotted key -> values; the cells cover the cartesian grid"
    )

    @field_validator("overrides")
    @classmethod
    def _finite_overrides(cls, v: dict) -> dict:
        _check_finite(v)
        return v

    @field_validator("sweep")
    @classmethod
    def _non_empty_sweep(cls, v: dict | None) -> dict | None:
        if v is None:
            return v
        if not v:
            raise ValueError("an empty sweep: give at least one dotted key with values, or leave sweep out")
        for key, values in v.items():
            if not values:
                raise ValueError(f"an empty sweep: {key!r} has no values")
            if len({repr(x) for x in values}) != len(values):
                raise ValueError(f"sweep {key!r} repeats a value: {values}")
        _check_finite(v)
        return v


class RealEntry(_Model):
    """One real clip of a suite: a video or a folder of frames, its range, scale and annotations.

    Paths are absolute once loaded (:func:`load_suite` resolves them from the suite file's folder).
    """

    real: str = Field(min_length=1, description="a video (.mp4 .mov .avi .mkv) or a folder of frames (.png .jpg)")
    label: str | None = Field(None, description="name in tables; default: the file or folder name")
    start: int = Field(0, ge=0, description="first source frame (0-based)")
    stop: int | None = Field(None, description="source frame to stop before (exclusive); default: the end")
    frames: int | None = Field(None, ge=2, description="number of frames from start (instead of stop)")
    scale: float = Field(1.0, gt=0, description="resize factor of frames and annotations")
    fps: float | None = Field(None, gt=0, description="frame rate; default: the video's own")
    gt: str | None = Field(None, description="MOTChallenge-style ground truth (gt.txt)")
    gt_format: Literal["mot", "visdrone", "uavdt"] = Field("mot", description="the column layout of gt")
    yolo: bool | None = Field(None, description="YOLO labels beside the frames: true, false, or read if present")
    classes: list[str] | None = Field(None, description="YOLO class names; default: classes.txt beside the frames")
    flow: str | None = Field(None, description="folder of flow truth for some pairs (.flo or KITTI .png)")

    @model_validator(mode="after")
    def _range(self) -> "RealEntry":
        if self.stop is not None and self.frames is not None:
            raise ValueError("give stop or frames, not both")
        if self.stop is not None and self.stop < self.start + 2:
            raise ValueError(f"stop: expected >= start + 2 (a pair at least), got {self.stop} with start {self.start}")
        return self

    def footage_spec(self) -> Any:
        """The :class:`scenes.footage.FootageSpec` of this entry."""
        from scenes.footage import FootageSpec

        stop = self.stop if self.frames is None else self.start + self.frames
        return FootageSpec(name=self.label or Path(self.real).stem, source=self.real, start=self.start, stop=stop,
                           scale=self.scale, fps=self.fps, gt=self.gt, gt_format=self.gt_format, yolo=self.yolo,
                           classes=tuple(self.classes) if self.classes is not None else None, flow=self.flow)


# A scene entry: a preset (rendered) or real footage, told apart by the key "real".
SceneLine = Annotated[
    Union[Annotated[SceneEntry, Tag("preset-scene")], Annotated[RealEntry, Tag("real-scene")]],
    Discriminator(lambda v: "real-scene" if (isinstance(v, RealEntry) or (isinstance(v, Mapping) and "real" in v))
                  else "preset-scene"),
]


class InlinePipeline(_Model):
    """A pipeline written in the suite: a name, an optional built-in base and the dict on top."""

    name: str = Field(min_length=1)
    base: str | None = Field(None, description="a name from algorithms.pipeline.PIPELINES to start from")
    spec: dict[str, Value] = Field(
        default_factory=dict, description="Pipeline.from_dict dict, deep-merged over the base"
    )

    @field_validator("spec")
    @classmethod
    def _finite_spec(cls, v: dict) -> dict:
        _check_finite(v)
        return v


# A pipeline entry: a built-in name, or an inline mapping (the tag keeps errors to one branch).
PipelineEntry = Annotated[
    Union[Annotated[str, Tag("pipeline-name")], Annotated[InlinePipeline, Tag("inline-pipeline")]],
    Discriminator(lambda v: "pipeline-name" if isinstance(v, str) else "inline-pipeline"),
]


class Suite(_Model):
    """A validated suite (see the module docstring for the YAML form)."""

    name: str = Field(min_length=1)
    description: str = ""
    scenes: list[SceneLine] = Field(min_length=1)
    seeds: list[int] = Field(min_length=1)
    pipelines: list[PipelineEntry] = Field(min_length=1)
    metrics: list[str] | None = Field(None, description="metric names; default: every metric")
    picture_pairs: list[int] = Field(
        default_factory=lambda: [0], description="pair indices whose estimated total flow is saved"
    )
    imports: list[str] = Field(
        default_factory=list,
        description="modules every worker imports first (plugins that register flow methods or stages)",
    )

    @field_validator("seeds")
    @classmethod
    def _distinct_seeds(cls, v: list[int]) -> list[int]:
        if len(set(v)) != len(v):
            raise ValueError(f"seeds repeat: {v}")
        if any(s < 0 for s in v):
            raise ValueError(f"seeds must be >= 0, got {v}")
        return v

    @field_validator("picture_pairs")
    @classmethod
    def _non_negative(cls, v: list[int]) -> list[int]:
        if any(i < 0 for i in v):
            raise ValueError(f"picture_pairs must be >= 0, got {v}")
        return sorted(set(v))


# --------------------------------------------------------------------------- registries


def pipeline_names() -> dict[str, dict]:
    """The built-in pipelines, ``algorithms.pipeline.PIPELINES`` (name -> plain dict, from ``algorithms/pipelines/``)."""
    from algorithms.pipeline import PIPELINES

    return PIPELINES


def metric_names() -> list[str]:
    """Names of every metric ``harness.metrics`` defines."""
    from harness import metrics

    # timing metrics are registered on first use; their names are known from the stages
    timing = [metrics.timing_metric_name(s) for s in metrics.STAGES]
    return sorted(set(metrics.METRICS) | set(timing))


def _pipeline_dict(entry: Mapping) -> dict:
    """A built-in pipeline as a fresh plain dict (to merge a suite's changes into)."""
    return copy.deepcopy(dict(entry))


def _deep_merge(base: dict, top: Mapping) -> dict:
    """``top`` over ``base``, mapping by mapping; a section naming another ``method`` replaces the base's
    (its parameters belong to the old method)."""
    out = copy.deepcopy(base)
    for k, v in top.items():
        old = out.get(k)
        same_method = not (isinstance(v, Mapping) and isinstance(old, Mapping) and "method" in v
                           and v["method"] != old.get("method"))
        if isinstance(v, Mapping) and isinstance(old, Mapping) and same_method:
            out[k] = _deep_merge(dict(out[k]), v)
        else:
            out[k] = copy.deepcopy(v)
    return out


# --------------------------------------------------------------------------- loading


class _UniqueKeyLoader(yaml.SafeLoader):
    """A SafeLoader that refuses a key given twice in one mapping (PyYAML keeps the last)."""


def _construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: set = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} appears twice", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _builtin_dir() -> Path:
    return Path(str(resources.files("harness") / "suites"))


def builtin_suites() -> dict[str, Path]:
    """Built-in suite name -> YAML path."""
    return {p.stem: p for p in sorted(_builtin_dir().glob("*.yaml"))}


def describe_suites() -> dict[str, str]:
    """Built-in suite name -> its one-line description, for ``aerobench list``."""
    out = {}
    for name, path in builtin_suites().items():
        try:
            out[name] = load_suite(path).description.strip().splitlines()[0]
        except (SuiteError, IndexError):
            out[name] = "(invalid or undescribed)"
    return out


def _field_path(loc: tuple) -> str:
    s = ""
    for part in loc:
        if isinstance(part, int):
            s += f"[{part}]"
        elif part in ("pipeline-name", "inline-pipeline", "function-after", "preset-scene", "real-scene"):
            # pydantic names union branches in the location; they mean nothing to a user
            continue
        else:
            s += f".{part}" if s else str(part)
    return s or "(top level)"


def _format_validation(err: ValidationError, source: str) -> str:
    lines = []
    for e in err.errors():
        msg = e["msg"].removeprefix("Value error, ")
        lines.append(f"{source}: {_field_path(tuple(e['loc']))}: {msg}")
    # one clear line first; union branches repeat the same field, keep distinct messages
    return "; ".join(dict.fromkeys(lines))


def _resolve_real_paths(data: Any, base_dir: Path) -> Any:
    """A copy of ``data`` whose real scenes' relative paths (``real``, ``gt``, ``flow``) start at ``base_dir``."""
    if not (isinstance(data, Mapping) and isinstance(data.get("scenes"), list)):
        return data
    scenes = []
    for entry in data["scenes"]:
        if isinstance(entry, Mapping) and "real" in entry:
            entry = dict(entry)
            for key in ("real", "gt", "flow"):
                if isinstance(entry.get(key), str) and entry[key] and not Path(entry[key]).is_absolute():
                    entry[key] = os.path.normpath(base_dir / entry[key])
        scenes.append(entry)
    return {**data, "scenes": scenes}


def parse_suite(data: Any, *, source: str = "<suite>", base_dir: str | os.PathLike | None = None) -> Suite:
    """Validate a suite given as a dict; check pipeline and metric names against the registries.

    ``base_dir``: the folder relative paths of real scenes start from (default: the working folder).

    Raises
    ------
    SuiteError
        naming ``source`` and the field.
    """
    if not isinstance(data, Mapping):
        raise SuiteError(f"{source}: expected a mapping at the top level, got {type(data).__name__}")
    data = _resolve_real_paths(data, Path(base_dir) if base_dir is not None else Path.cwd())
    try:
        suite = Suite.model_validate(dict(data))
    except ValidationError as exc:
        raise SuiteError(_format_validation(exc, source)) from None
    _check_names(suite, source)
    return suite


def _check_names(suite: Suite, source: str) -> None:
    builtins = pipeline_names()
    seen: set[str] = set()
    for i, p in enumerate(suite.pipelines):
        name = p if isinstance(p, str) else p.name
        base = p if isinstance(p, str) else p.base
        if base is not None and base not in builtins:
            where = f"pipelines[{i}]" + ("" if isinstance(p, str) else ".base")
            raise SuiteError(
                f"{source}: {where}: unknown pipeline {base!r}; valid: {', '.join(sorted(builtins))}"
            )
        if name in seen:
            raise SuiteError(f"{source}: pipelines[{i}]: the name {name!r} is used twice")
        seen.add(name)
    if suite.metrics is not None:
        valid = metric_names()
        for i, m in enumerate(suite.metrics):
            if m not in valid:
                raise SuiteError(f"{source}: metrics[{i}]: unknown metric {m!r}; valid: {', '.join(valid)}")
    from scenes import list_presets

    presets = set(list_presets())
    for i, s in enumerate(suite.scenes):
        if isinstance(s, RealEntry):
            continue
        looks_like_path = s.preset.endswith((".yaml", ".yml")) or os.sep in s.preset
        if not looks_like_path and s.preset not in presets:
            raise SuiteError(
                f"{source}: scenes[{i}].preset: unknown preset {s.preset!r}; valid: {', '.join(sorted(presets))}"
            )


def load_suite(name_or_path: str | os.PathLike) -> Suite:
    """A built-in suite by name, or a suite YAML file by path, validated.

    Raises
    ------
    SuiteError
        the file is missing, is not YAML (with the line), or is not a valid suite.
    """
    builtins = builtin_suites()
    text_name = str(name_or_path)
    if text_name in builtins and not Path(text_name).exists():
        path = builtins[text_name]
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise SuiteError(
                f"{text_name}: no such suite file, and not a built-in suite ({', '.join(builtins)})"
            )
    try:
        data = yaml.load(path.read_text(), Loader=_UniqueKeyLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        raise SuiteError(f"{path}: YAML syntax error at {line}{exc.problem or exc}") from None
    except yaml.YAMLError as exc:
        raise SuiteError(f"{path}: not valid YAML: {exc}") from None
    return parse_suite(data, source=str(path), base_dir=path.resolve().parent)


# --------------------------------------------------------------------------- expansion


@dataclass(frozen=True)
class SceneVariant:
    """One rendered scene: a preset with its overrides (sweep values included) and a seed."""

    label: str
    preset: str
    seed: int
    overrides: dict
    sweep_param: str
    sweep_value: Any
    spec: Any = field(compare=False, repr=False)  # the resolved scene spec (scenes' object)
    scene_hash: str = ""


@dataclass(frozen=True)
class Cell:
    """One unit of work: a scene variant x a pipeline, identified by its config hash."""

    cell_id: str
    config_hash: str
    variant: SceneVariant
    pipeline: str
    pipeline_spec: dict = field(repr=False)
    pipeline_hash: str
    metrics: tuple[str, ...] | None
    picture_pairs: tuple[int, ...]

    def identity(self) -> dict:
        """Everything that determines this cell's results, as plain data (what the hash covers)."""
        return {
            "scene_hash": self.variant.scene_hash,
            "pipeline_hash": self.pipeline_hash,
            "metrics": list(self.metrics) if self.metrics is not None else None,
            "picture_pairs": list(self.picture_pairs),
        }


def import_modules(names: list[str] | tuple[str, ...], *, source: str = "<suite>") -> None:
    """Import each module of a suite's ``imports:`` (plugins that register flow methods or stages).

    The working folder is searched too (after everything else, so a local file never shadows an
    installed package): ``aerobench`` is a console script, whose ``sys.path`` does not hold it.

    Raises
    ------
    SuiteError
        a module cannot be imported (naming it, its position and the folders searched).
    """
    import importlib
    import sys

    cwd = os.getcwd()
    if cwd not in sys.path:
        sys.path.append(cwd)
    for i, module in enumerate(names):
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise SuiteError(f"{source}: imports[{i}]: cannot import {module!r} (searched the installed packages "
                             f"and the working folder {cwd}): {exc}") from None


def _format_value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _resolve_pipelines(suite: Suite, source: str) -> list[tuple[str, dict]]:
    from algorithms.pipeline import Pipeline

    import_modules(suite.imports, source=source)
    builtins = pipeline_names()
    out = []
    for i, p in enumerate(suite.pipelines):
        if isinstance(p, str):
            name, spec = p, _pipeline_dict(builtins[p])
        else:
            base = _pipeline_dict(builtins[p.base]) if p.base else {}
            name, spec = p.name, _deep_merge(base, p.spec)
            spec["name"] = name
        try:
            Pipeline.from_dict(spec)
        except (ValueError, TypeError, KeyError) as exc:
            raise SuiteError(f"{source}: pipelines[{i}] ({name}): {exc}") from None
        out.append((name, spec))
    return out


def _variants(suite: Suite, source: str) -> list[SceneVariant]:
    from scenes import load_scene_spec
    from scenes.spec import spec_hash

    out = []
    for i, s in enumerate(suite.scenes):
        if isinstance(s, RealEntry):
            out.append(_real_variant(s, i, source))
            continue
        base_label = s.label or Path(s.preset).stem
        grid = [()]
        keys: list[str] = []
        if s.sweep:
            keys = list(s.sweep)
            grid = list(itertools.product(*(s.sweep[k] for k in keys)))
        for values in grid:
            overrides = dict(s.overrides)
            overrides.update(zip(keys, values))
            label = base_label
            if keys:
                label += "[" + ",".join(f"{k}={_format_value(v)}" for k, v in zip(keys, values)) + "]"
            sweep_param = ",".join(keys)
            sweep_value = values[0] if len(values) == 1 else (",".join(map(_format_value, values)) or None)
            for seed in suite.seeds:
                try:
                    spec = load_scene_spec(s.preset, overrides={**overrides, "seed": seed})
                except (ValueError, TypeError, KeyError, FileNotFoundError) as exc:
                    raise SuiteError(f"{source}: scenes[{i}] ({label}): {exc}") from None
                out.append(
                    SceneVariant(
                        label=label,
                        preset=s.preset,
                        seed=seed,
                        overrides=overrides,
                        sweep_param=sweep_param,
                        sweep_value=sweep_value,
                        spec=spec,
                        scene_hash=spec_hash(spec),
                    )
                )
    return out


def _real_variant(entry: RealEntry, i: int, source: str) -> SceneVariant:
    """The one variant of a real clip: seed 0, its scene hash the hash of the files' bytes and the options."""
    from scenes.footage import validate_footage
    from scenes.formats import FormatError

    spec = entry.footage_spec()
    try:
        digest = validate_footage(spec)
    except (FormatError, ValueError, OSError) as exc:
        raise SuiteError(f"{source}: scenes[{i}] ({spec.name}): {exc}") from None
    return SceneVariant(label=spec.name, preset=f"real:{entry.real}", seed=0, overrides={}, sweep_param="",
                        sweep_value=None, spec=spec, scene_hash=digest)


def expand(suite: Suite, *, source: str | None = None) -> list[Cell]:
    """The suite's cells, (scene variant, seed, pipeline), in a stable order.

    ``cell_id`` is the first 16 hex digits of the hash of the cell's identity
    (resolved scene spec, pipeline dict, metrics, picture pairs): the same cell in
    another suite or another run has the same id, so results and caches line up.
    """
    from harness.provenance import config_hash

    source = source or suite.name
    pipelines = _resolve_pipelines(suite, source)
    metrics = tuple(suite.metrics) if suite.metrics is not None else None
    cells = []
    seen: dict[str, str] = {}
    for variant in _variants(suite, source):
        for name, spec in pipelines:
            p_hash = config_hash(spec)
            cell = Cell(
                cell_id="",
                config_hash="",
                variant=variant,
                pipeline=name,
                pipeline_spec=spec,
                pipeline_hash=p_hash,
                metrics=metrics,
                picture_pairs=tuple(suite.picture_pairs),
            )
            h = config_hash({**cell.identity(), "pipeline": name, "scene": variant.label, "seed": variant.seed})
            cell_id = h[:16]
            where = f"{variant.label} seed {variant.seed} x {name}"
            if cell_id in seen:
                raise SuiteError(f"{source}: the cell {where} repeats {seen[cell_id]}")
            seen[cell_id] = where
            cells.append(
                Cell(cell_id, h, variant, name, spec, p_hash, metrics, tuple(suite.picture_pairs))
            )
    return cells
