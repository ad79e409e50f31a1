"""benchmarks/_overrides.py: --set reaches into a pipeline's sections and names a key that is no section."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location("overrides_benchmark",
                                               Path(__file__).resolve().parents[2] / "benchmarks" / "_overrides.py")
_overrides = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_overrides)
pipeline_with = _overrides.pipeline_with


def test_a_section_key_is_set_and_a_value_given_as_a_section_is_refused_naming_it():
    p = pipeline_with("dis", ["tracking.multi.gate_px=15", "compensation=affine"])
    assert p.config["tracking"]["multi"]["gate_px"] == 15
    assert p.config["compensation"]["model"] == "affine"
    with pytest.raises(ValueError, match=r"--set compensation.model=affine: compensation is 'shift' in dis, not a "
                                         r"section; set it whole \(compensation=\.\.\.\)"):
        pipeline_with("dis", ["compensation.model=affine"])
