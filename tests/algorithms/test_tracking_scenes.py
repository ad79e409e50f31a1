"""Point trackers on rendered scenes with known vehicle paths, in their domain."""

from __future__ import annotations

import copy
import os

import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _point_errors(preset: str, overrides: dict, pipeline, tmp_path) -> np.ndarray:
    """Per-frame |raw point position - true vehicle centre| (px) of every seeded vehicle while visible.

    ``pipeline``: a built-in name, or a list of pipeline dicts run on the same rendered sequence
    (then a list of error arrays comes back).
    """
    from algorithms.pipeline import Pipeline, get_pipeline
    from harness.metrics import position_error_px
    from harness.cell_scoring import point_seeds
    from scenes import load_scene_spec, open_sequence, render_sequence

    seq = open_sequence(render_sequence(load_scene_spec(preset, overrides), tmp_path / "seq"))
    frames = [seq.frame(i) for i in range(len(seq))]
    truth = seq.tracks[seq.tracks["visible"].astype(bool)].rename(columns={"vehicle_id": "seed_vehicle_id"})
    out = []
    for p in ([get_pipeline(pipeline)] if isinstance(pipeline, str) else [Pipeline.from_dict(d) for d in pipeline]):
        est = list(p.run(frames, seeds=point_seeds(seq.tracks)))[-1]
        pts = est.tracks[est.tracks["source"] == "point"].astype({"seed_vehicle_id": "int64"})
        m = pts.merge(truth, on=["frame", "seed_vehicle_id"], suffixes=("_est", "_true"))
        assert m["seed_vehicle_id"].nunique() >= 2
        out.append(position_error_px(m["x_px_est"], m["y_px_est"], m["x_px_true"], m["y_px_true"]))
    return out[0] if isinstance(pipeline, str) else out


def test_thesis_point_tracker_follows_vehicles_with_sub_pixel_local_motion(tmp_path):
    # tiny at 30 fps: the camera moves 0.7 px/frame and vehicles 0.4-0.8 px/frame over the ground,
    # the small-motion domain of single-level LK and of the thesis's Table 4.1 (0.4-0.7 px/frame)
    err = _point_errors("tiny", {"seed": 1, "image.fps": 30.0, "image.n_frames": 12}, "thesis-lk", tmp_path)
    assert err.mean() < 2.0 and err.max() < 3.0


def test_thesis_point_tracker_follows_sub_pixel_vehicles_on_the_thesis_preset(tmp_path):
    # the thesis's own domain: nadir 25 fps, vehicles of about 17 x 7 px moving 0.35-1 px/frame; flow predicts,
    # image correlation places the pixel (thesis 4.1). The flow alone slides 60-70 % of the way (all 50
    # frames, measured by hand: 4.7 px mean open loop, 0.17 px with the correlation)
    from algorithms.pipeline import PIPELINES

    thesis = [copy.deepcopy(PIPELINES[name]) for name in ("thesis-lk", "thesis-hs")]
    open_loop = copy.deepcopy(thesis[0])
    open_loop["tracking"]["point"]["correlation"] = None
    *errs, err_open = _point_errors("thesis", {"image.n_frames": 12}, thesis + [open_loop], tmp_path)
    for name, err in zip(("thesis-lk", "thesis-hs"), errs):
        assert err.mean() < 0.5 and err.max() < 1.5, name
    assert err_open.max() > 2.0   # what the correlation corrects: single-level LK alone falls behind (4.2 px)


def test_pyramidal_point_tracker_follows_vehicles_on_nominal(tmp_path):
    # nominal: vehicles up to 6.5 px/frame over the ground at 640x480; a few frames keep the test short
    # (all 60 frames, measured by hand: mean 0.35 px with image correlation, 3.2 px re-centred, 2.4 px open loop)
    err = _point_errors("nominal", {"image.n_frames": 8}, "pyramidal-lk", tmp_path)
    assert err.mean() < 3.0
