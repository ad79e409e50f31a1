"""benchmarks/pipeline_speed.py: the bit-identity check tells equal estimates from different ones."""

from __future__ import annotations

import importlib.util
import pickle
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from algorithms.detection import Detection

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "pipeline_speed.py"
_spec = importlib.util.spec_from_file_location("pipeline_speed_benchmark", _PATH)
speed = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = speed
_spec.loader.exec_module(speed)


def _estimate(area_m2: float, x0: float = 10.0) -> dict:
    """What a child sends for one pipeline: one pair with one detection, and a sequence without tracks."""
    pair = {k: np.zeros((4, 4)) for k in speed.PAIR_FIELDS}
    pair.update(global_shift_px=np.zeros(2), global_valid=True,
                detections=[Detection(15.0, 12.0, 40, x0, 10.0, 20.0, 14.0, 1.0, 0.0, area_m2)])
    seq = {k: np.zeros((2, 2)) for k in speed.SEQ_FIELDS}
    seq["tracks"] = pd.DataFrame({"frame": [0], "x_px": [1.0]})
    return {"pairs": [pair], "sequence": seq}


def test_equal_detections_without_a_ground_sampling_distance_are_identical():
    # area_m2 is NaN without a GSD; the two children's NaNs arrive as different objects, as they do unpickled apart
    ours, ref = pickle.loads(pickle.dumps(_estimate(np.nan))), pickle.loads(pickle.dumps(_estimate(np.nan)))
    assert speed._compare("dis", ours, ref) == []


def test_a_detection_that_moved_is_a_difference():
    bad = speed._compare("dis", _estimate(np.nan), _estimate(np.nan, x0=11.0))
    assert bad == ["dis pair 0: detections or global_valid differ"]
    assert speed._compare("dis", _estimate(2.0), _estimate(2.5)) == bad
