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


def test_a_scaled_pipeline_fixes_px_scale_and_a_suite_takes_it(tmp_path):
    spec = rehearsal.scaled_spec(2.0)
    assert spec == {"detection": {"px_scale": 2.0}}
    # a suite's inline pipeline over a built-in one takes it
    (tmp_path / "f").mkdir()
    import cv2
    import numpy as np

    for k in range(3):
        cv2.imwrite(str(tmp_path / "f" / f"{k}.png"), np.full((64, 96), 40 * k, np.uint8))
    suite = parse_suite({"name": "s", "scenes": [{"real": str(tmp_path / "f")}], "seeds": [0],
                         "pipelines": [{"name": "dis-px2", "base": "dis", "spec": spec}]})
    (cell,) = expand(suite)
    p = Pipeline.from_dict(cell.pipeline_spec)
    assert p.config["detection"]["px_scale"] == 2.0
    assert p.config["detection"]["min_area_px"] == DETECTION_DEFAULTS["min_area_px"]   # scaled when it runs
    assert p.config["tracking"]["multi"]["gate_px"] == MULTI_DEFAULTS["gate_px"]
    assert p.config["flow"]["method"] == "dis"  # the base's flow kept


def test_over_worlds_summarises_each_pipeline_over_the_seeds_and_ranks_by_median():
    import pandas as pd

    rows = [("dis", 1, 0.30), ("dis", 2, 0.60), ("dis", 3, 0.40),
            ("tv-l1", 1, 0.50), ("tv-l1", 2, 0.20), ("tv-l1", 3, 0.25)]
    table = pd.DataFrame([{"scene": "city-wide", "scale": 1.0, "pipeline": p, "tracker": "multi", "seed": s,
                           "mota": m} for p, s, m in rows])
    out = rehearsal.over_worlds(table).set_index("pipeline")
    assert out.loc["dis", "worlds"] == 3
    assert out.loc["dis", "mota_median"] == 0.40 and out.loc["dis", "mota_min"] == 0.30
    assert out.loc["tv-l1", "mota_max"] == 0.50
    # tv-l1 wins one world of three and scores higher than dis on it; by median it ranks second
    assert (out.loc["dis", "rank"], out.loc["tv-l1", "rank"]) == (1, 2)
