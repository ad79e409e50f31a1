"""Scoring speed per frame pair: the one-pass ``score_pair`` against the per-region scoring it replaced.

    cd /work/wt/iospeed && PYTHONPATH=. PYOPENGL_PLATFORM=egl \\
        /work/main/.venv/bin/python benchmarks/score_speed.py [--preset nominal] [--runs 15]

The pair is real: frames 0 -> 1 of ``--preset`` rendered with its exact ground truth
(flow, camera flow, valid mask, instances); the "estimate" is the true flow plus
heavy-tailed noise (Student t, 2 degrees of freedom, 0.5 px scale: errors from
hundredths of a pixel to past the histogram's 100 px edge) and a constant global
field. Both implementations score the same pair alternately, after one untimed call
each (numba's compiled kernels load from its cache); the figures are medians over
``--runs`` calls, wall-clock and CPU (process) time, with one native thread (``cv2.setNumThreads(1)``, numba and BLAS at
1). The reference is ``reference_score_pair`` of ``tests/harness/test_score_fused.py``
(the scoring as it was before the fused pass), where the test that the two agree lives.
"""

from __future__ import annotations

import os

for _var in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "harness"))

from harness.metrics import score_pair  # noqa: E402
from scenes.generate import SceneGenerator  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402
from test_score_fused import reference_score_pair  # noqa: E402


def real_pair(preset: str):
    """(estimate, truth) of frames 0 -> 1 of ``preset``."""
    spec = load_scene_spec(preset, {"image.n_frames": 2})
    frames = SceneGenerator(spec).frames()
    next(frames)
    truth = next(frames).pair
    rng = np.random.default_rng(0)
    noise = rng.standard_t(2, size=truth.flow.shape).astype(np.float32) * np.float32(0.5)
    glob = np.broadcast_to(np.nanmedian(truth.flow_camera.reshape(-1, 2), axis=0).astype(np.float32),
                           truth.flow.shape).copy()
    estimate = SimpleNamespace(flow_total=truth.flow + noise, flow_global=glob,
                               valid=rng.random(truth.valid.shape) > 0.1, stage_ms={})
    return estimate, truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    estimate, truth = real_pair(args.preset)
    h = truth.valid.shape[0]
    score_pair(estimate, truth, frame=0)
    reference_score_pair(estimate, truth, frame=0)
    wall: dict[str, list[float]] = {"new": [], "old": []}
    cpu: dict[str, list[float]] = {"new": [], "old": []}
    for _ in range(args.runs):
        for name, fn in (("new", score_pair), ("old", reference_score_pair)):
            t0, c0 = time.perf_counter(), time.process_time()
            fn(estimate, truth, frame=0)
            wall[name].append(1e3 * (time.perf_counter() - t0))
            cpu[name].append(1e3 * (time.process_time() - c0))
    w = {k: statistics.median(v) for k, v in wall.items()}
    c = {k: statistics.median(v) for k, v in cpu.items()}
    print(f"score_pair on a {truth.valid.shape[1]}x{h} {args.preset!r} pair (4 regions x 2 motions), median of "
          f"{args.runs} runs, one native thread; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("                         wall ms    CPU ms")
    print(f"  per-region reference  {w['old']:8.1f}  {c['old']:8.1f}")
    print(f"  one pass (package)    {w['new']:8.1f}  {c['new']:8.1f}")
    print(f"  new / old             {w['new'] / w['old']:8.3f}  {c['new'] / c['old']:8.3f}")

if __name__ == "__main__":
    main()
