"""algorithms.pipeline_spec: the pydantic model of a pipeline dict and the built-in YAML files."""

from __future__ import annotations

import math

import pytest
import yaml

from algorithms import pipeline_spec
from algorithms.pipeline_spec import PipelineError, builtin_pipelines, pipeline_hash, resolve_pipeline

BASE = {"name": "x", "flow": {"method": "lucas_kanade"}}


def test_resolving_fills_every_default_and_widens_integers_where_a_number_is_expected():
    d = resolve_pipeline({**BASE, "flow": {"method": "horn_schunck", "params": {"alpha": 15}}})
    assert list(d) == ["name", "description", "global_motion", "jitter", "compensation", "flow", "threshold",
                       "spatial", "temporal", "detection", "tracking"]
    assert d["flow"]["params"] == {"alpha": 15.0} and isinstance(d["flow"]["params"]["alpha"], float)
    assert d["jitter"] == {"model": "line", "window_frames": 15, "polyorder": 2, "iterations": 1}
    assert d["compensation"] == {"model": "shift", "params": {}}
    assert d["tracking"] == {"point": True, "multi": None}
    assert resolve_pipeline(d) == d  # idempotent
    assert pipeline_hash(d) == pipeline_hash({**d, "name": "y", "description": "other words"})


@pytest.mark.parametrize("change, match", [
    ({"threshold": {"tolerance_deg": math.inf}}, r"threshold.tolerance_deg: expected a finite number"),
    ({"flow": {"method": "horn_schunck", "params": {"tol": [1.0, math.nan]}}}, r"flow.params.tol.*finite"),
    ({"detection": {"min_area_px": 2.5}}, r"detection.min_area_px: expected an integer, got 2.5 \(float\)"),
    ({"tracking": {"point": "yes"}}, r"tracking.point: expected true/false or a mapping, got 'yes'"),
    ({"tracking": {"point": {"recentre_px": True}}}, r"tracking.point.recentre_px: expected null or a number > 0"),
    ({"compensation": {"model": "shift", "params": {"levels": 2}}}, r"compensation.params: the 'shift' model takes"),
    ({"compensation": {"model": "affine", "params": {"levels": 2.0}}}, r"compensation.params.levels: expected an integer"),
    ({"name": "", "flow": 3}, r"name: expected a non-empty string, got ''; flow: expected a mapping, got 3 \(int\)"),
])
def test_bad_values_are_refused_naming_each_field(change, match):
    with pytest.raises(PipelineError, match=match):
        resolve_pipeline({**BASE, **change})


def test_a_source_file_is_named_in_the_error():
    with pytest.raises(PipelineError, match=r"^my.yaml: flw: unknown key"):
        resolve_pipeline({**BASE, "flw": 1}, source="my.yaml")
    with pytest.raises(PipelineError, match=r"^my.yaml: pipeline: expected a mapping, got \[1\] \(list\)"):
        resolve_pipeline([1], source="my.yaml")


def test_each_builtin_is_one_yaml_file_named_like_the_pipeline():
    builtins = builtin_pipelines()
    assert {"thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis", "farneback", "tvl1"} <= set(builtins)
    for name, d in builtins.items():
        assert d["name"] == name and d["description"]


@pytest.mark.parametrize("lk, hs", [("thesis-lk", "thesis-hs"), ("pyramidal-lk", "pyramidal-hs")])
def test_the_lk_and_hs_twins_differ_in_their_flow_alone(lk, hs):
    # the LK vs HS answer compares flows: every other stage (detection, tracker keys) must be the same in both
    builtins = builtin_pipelines()
    a, b = resolve_pipeline(builtins[lk]), resolve_pipeline(builtins[hs])
    assert a["flow"]["method"] == "lucas_kanade" and b["flow"]["method"] == "horn_schunck"
    assert {k for k in a if a[k] != b[k]} == {"name", "description", "flow"}


def test_a_broken_builtin_file_is_refused_naming_the_file(tmp_path, monkeypatch):
    (tmp_path / "bad-one.yaml").write_text(yaml.safe_dump({**BASE, "name": "bad-one", "spatial": "yes"}))
    (tmp_path / "renamed.yaml").write_text(yaml.safe_dump({**BASE, "name": "other"}))
    monkeypatch.setattr(pipeline_spec, "_builtin_texts",
                        lambda: tuple((p.stem, str(p), p.read_text()) for p in sorted(tmp_path.glob("*.yaml"))))
    with pytest.raises(PipelineError, match=r"bad-one.yaml: spatial: expected true/false, got 'yes'"):
        builtin_pipelines()
    (tmp_path / "bad-one.yaml").unlink()
    with pytest.raises(PipelineError, match=r"renamed.yaml: name: expected 'renamed' \(the file's name\), got 'other'"):
        builtin_pipelines()


@pytest.mark.parametrize("section, defaults", [
    ("MultiSpec", "algorithms.tracking:MULTI_DEFAULTS"),
    ("DetectionSpec", "algorithms.detection:DETECTION_DEFAULTS"),
])
def test_a_spec_section_takes_every_key_its_stage_defines(section, defaults):
    """A key added to a stage's defaults is settable from a pipeline file or a suite (merge_hits was not)."""
    import importlib

    module, name = defaults.split(":")
    keys = set(getattr(importlib.import_module(module), name))
    fields = set(getattr(pipeline_spec, section).model_fields)
    assert keys <= fields, f"{section} lacks {sorted(keys - fields)}"


def test_the_tracker_part_joining_keys_are_set_from_a_pipeline_file():
    import copy

    d = copy.deepcopy(builtin_pipelines()["dis"])
    d["tracking"]["multi"] = {**d["tracking"]["multi"], "merge_hits": 0, "end_min_hits": 5}
    spec = resolve_pipeline(d)
    assert spec["tracking"]["multi"]["merge_hits"] == 0 and spec["tracking"]["multi"]["end_min_hits"] == 5
    d["tracking"]["multi"]["merge_hits"] = -1
    with pytest.raises(PipelineError, match="merge_hits"):
        resolve_pipeline(d)
