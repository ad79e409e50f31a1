"""benchmarks/tracker_replay.py: a replay without overrides gives the pipeline's own multi-target figures, an
override reaches the tracker, a key the tracker does not have is refused."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "tracker_replay.py"
_spec = importlib.util.spec_from_file_location("tracker_replay_benchmark", _PATH)
tr = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = tr
_spec.loader.exec_module(tr)


@pytest.fixture(scope="module")
def captured(tmp_path_factory, shared_render_cache):
    from scenes import load_scene_spec
    from scenes.cache import cached_sequence

    spec = load_scene_spec("tiny", {"image.n_frames": 24, "image.width_px": 240, "image.height_px": 180})
    seq_dir = cached_sequence(spec, shared_render_cache)
    out = tmp_path_factory.mktemp("replay") / "tiny.npz"
    assert tr.main(["capture", str(seq_dir), "--pipeline", "dis", "--out", str(out)]) == 0
    return out


def test_a_replay_without_overrides_scores_what_the_pipeline_scored(captured):
    mine, own = tr.replay_one(str(captured), [])
    assert own["mot"]["objects"] > 0 and own["mot"]["predictions"] > 0  # the capture holds tracks to reproduce
    assert mine == own
    with np.load(captured) as z:
        meta = json.loads(str(z["meta"]))
        assert z["img0"].ndim == 2  # the gray frames the tracker holds tracks on
    assert meta["params"]["gate_px"] > 0 and len(meta["steps"]) >= 2


def test_an_override_reaches_the_tracker_and_an_unknown_key_is_refused(captured):
    # no track is ever confirmed: every counted row a miss, nothing predicted
    mine, own = tr.replay_one(str(captured), ["tracking.multi.birth_hits=100000"])
    assert mine["mot"]["predictions"] == 0 and mine["mot"]["misses"] == own["mot"]["objects"] > 0
    with pytest.raises(SystemExit, match="'birth_hit' is not a key of the multi-target tracker"):
        tr.replay_one(str(captured), ["birth_hit=3"])
