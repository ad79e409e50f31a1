"""benchmarks/heldout_rehearsal.py: the scaled pipelines it runs are valid pipelines with the sizes it says."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from algorithms.detection import DETECTION_DEFAULTS
from algorithms.pipeline import Pipeline
from algorithms.tracking import MULTI_DEFAULTS
from harness.suites import expand, parse_suite

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "heldout_rehearsal.py"
_spec = importlib.util.spec_from_file_location("heldout_rehearsal_benchmark", _PATH)
rehearsal = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = rehearsal
_spec.loader.exec_module(rehearsal)


def test_px_parameters_scale_lengths_by_the_factor_and_areas_by_its_square(tmp_path):
    spec = rehearsal.scaled_spec(2.0)
    det, multi = spec["detection"], spec["tracking"]["multi"]
    assert det["min_area_px"] == 4 * DETECTION_DEFAULTS["min_area_px"]
    assert det["merge_gap_px"] == 2 * DETECTION_DEFAULTS["merge_gap_px"]
    assert det["close_px"] == 2 * DETECTION_DEFAULTS["close_px"] and isinstance(det["close_px"], int)
    assert multi["gate_px"] == 2 * MULTI_DEFAULTS["gate_px"]
    assert "min_magnitude_px" not in det
    moving = rehearsal.scaled_spec(2.0, motion=True)["detection"]
    assert moving["min_magnitude_px"] == 2 * DETECTION_DEFAULTS["min_magnitude_px"]
    # every key it scales exists, and a suite's inline pipeline over a built-in one takes them
    assert set(det) <= set(DETECTION_DEFAULTS) and set(multi) <= set(MULTI_DEFAULTS)
    (tmp_path / "f").mkdir()
    import cv2
    import numpy as np

    for k in range(3):
        cv2.imwrite(str(tmp_path / "f" / f"{k}.png"), np.full((64, 96), 40 * k, np.uint8))
    suite = parse_suite({"name": "s", "scenes": [{"real": str(tmp_path / "f")}], "seeds": [0],
                         "pipelines": [{"name": "dis-px2", "base": "dis", "spec": spec}]})
    (cell,) = expand(suite)
    p = Pipeline.from_dict(cell.pipeline_spec)
    assert p.config["detection"]["min_area_px"] == det["min_area_px"]
    assert p.config["tracking"]["multi"]["gate_px"] == multi["gate_px"]
    assert p.config["flow"]["method"] == "dis"  # the base's flow kept
