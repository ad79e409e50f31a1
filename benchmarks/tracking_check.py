"""Point trackers over whole sequences: per-vehicle position error, open loop beside re-centred.

Not a speed benchmark: the accuracy check too long for the test suite (the tests
run the same trackers on a few frames). Run from the project root:

    python benchmarks/tracking_check.py [--scene nominal] [--pipeline pyramidal-lk] [--set image.fps=30.0 ...]

Renders (or reuses from ``$AEROBENCH_CACHE``, default ``.aerobench-cache``) the
scene, runs the pipeline with its built-in point tracker and with variants of
``tracking.point`` (open loop: flow alone, the thesis's flow filter; flow
predicted and placed by image correlation, thesis 4.1; re-centred with either
filter), seeded on the vehicles visible in frame 0 as the runner seeds them,
and prints per vehicle the mean and largest distance of the raw and the
filtered point to the vehicle's true centre over the frames where it is
visible. Examples (numbers of this commit's measurement are in its message):

    python benchmarks/tracking_check.py --scene thesis --pipeline thesis-lk
    python benchmarks/tracking_check.py --scene nominal --pipeline pyramidal-lk
    python benchmarks/tracking_check.py --scene tiny --pipeline thesis-lk --set seed=1 --set image.fps=30.0
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms.pipeline import PIPELINES, Pipeline  # noqa: E402
from harness.metrics import position_error_px  # noqa: E402
from harness.runner import point_seeds  # noqa: E402
from scenes import load_scene_spec, open_sequence  # noqa: E402
from scenes.cache import cached_sequence  # noqa: E402
from benchmarks._overrides import parse_value as _value  # noqa: E402

VARIANTS = {
    "built-in": None,
    "open loop": {"recentre_px": None, "filter": "flow", "correlation": None},
    "flow + image correlation (thesis 4.1)": {"recentre_px": None, "filter": "flow", "correlation": {}},
    "image correlation, position filter": {"recentre_px": None, "filter": "position", "correlation": {}},
    "re-centred, flow filter": {"recentre_px": 12.0, "filter": "flow", "correlation": None},
    "re-centred, position filter": {"recentre_px": 12.0, "filter": "position", "correlation": None},
}


def point_errors(seq, pipeline: Pipeline) -> pd.DataFrame:
    """Per frame and seeded vehicle: raw and filtered point error (px) where the vehicle is visible."""
    frames = [seq.frame(i) for i in range(len(seq))]
    est = list(pipeline.run(frames, seeds=point_seeds(seq.tracks)))[-1]
    pts = est.tracks[est.tracks["source"] == "point"].astype({"seed_vehicle_id": "int64"})
    truth = seq.tracks[seq.tracks["visible"].astype(bool)].rename(columns={"vehicle_id": "seed_vehicle_id"})
    m = pts.merge(truth, on=["frame", "seed_vehicle_id"], suffixes=("_est", "_true"))
    return pd.DataFrame({"frame": m["frame"], "vehicle": m["seed_vehicle_id"],
                         "raw_px": position_error_px(m["x_px_est"], m["y_px_est"], m["x_px_true"], m["y_px_true"]),
                         "filtered_px": position_error_px(m["x_filt_px"], m["y_filt_px"], m["x_px_true"],
                                                          m["y_px_true"])})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="nominal", help="preset name or YAML path")
    ap.add_argument("--pipeline", default="pyramidal-lk", choices=sorted(PIPELINES))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scene override")
    args = ap.parse_args(argv)
    overrides = dict(kv.split("=", 1) for kv in args.set)
    spec = load_scene_spec(args.scene, {k: _value(v) for k, v in overrides.items()})
    seq = open_sequence(cached_sequence(spec, os.environ.get("AEROBENCH_CACHE", ".aerobench-cache")))
    print(f"scene {args.scene} {overrides or ''}: {len(seq)} frames; pipeline {args.pipeline}")
    for label, point in VARIANTS.items():
        d = copy.deepcopy(PIPELINES[args.pipeline])
        if point is not None:
            base = d["tracking"]["point"] if isinstance(d["tracking"]["point"], dict) else {}
            d["tracking"]["point"] = {**base, **point}
        err = point_errors(seq, Pipeline.from_dict(d))
        per = err.groupby("vehicle")[["raw_px", "filtered_px"]].agg(["mean", "max"]).round(2)
        print(f"\n== {label}: tracking.point = {Pipeline.from_dict(d).config['tracking']['point']}")
        print(per.to_string())
        print(f"all vehicles: raw mean {err['raw_px'].mean():.2f} px (max {err['raw_px'].max():.2f}), "
              f"filtered mean {err['filtered_px'].mean():.2f} px (max {err['filtered_px'].max():.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
