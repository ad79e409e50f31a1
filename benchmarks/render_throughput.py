"""Render throughput of the scene generator: frames/s for render alone, render + ground truth, and file writing.

Run single-threaded, as one worker of a process pool would run:

    cd /work/main && LP_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        /work/venv/bin/python benchmarks/render_throughput.py [--preset nominal] [--frames 40] [--runs 3]

(The script sets these variables itself before numpy, cv2 and llvmpipe load,
and calls cv2.setNumThreads(1).) Figures are medians over ``--runs`` runs of
the same sequence on the process's one renderer; the world (texture, meshes)
is built once per run and not counted.
"""

from __future__ import annotations

import os

for _var in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scenes.generate import SceneGenerator  # noqa: E402
from scenes.sequence import render_sequence  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    spec = load_scene_spec(args.preset, {"image.n_frames": args.frames})
    n = spec.image.n_frames
    render_fps, gt_fps, seq_fps, write_fps = [], [], [], []
    for _ in range(args.runs):
        gen = SceneGenerator(spec)
        gen.renderer.render(gen.path.R[0], gen.path.C[0], gen.vehicle_matrices(0.0))  # texture upload
        t0 = time.perf_counter()
        for i in range(n):
            gen.renderer.render(gen.path.R[i], gen.path.C[i], gen.vehicle_matrices(float(gen.path.t_s[i])))
        render_fps.append(n / (time.perf_counter() - t0))

        gen = SceneGenerator(spec)
        gen.renderer.render(gen.path.R[0], gen.path.C[0], gen.vehicle_matrices(0.0))
        t0 = time.perf_counter()
        for _fo in gen.frames():
            pass
        gt_fps.append(n / (time.perf_counter() - t0))

        with tempfile.TemporaryDirectory() as tmp:
            timings: dict = {}
            render_sequence(spec, Path(tmp) / "seq", timings=timings)
            seq_fps.append(n / (timings["render_truth_s"] + timings["write_s"]))
            write_fps.append(n / timings["write_s"])
    print(f"preset {args.preset!r}, {spec.image.width_px}x{spec.image.height_px}, {n} frames, "
          f"lighting {spec.photometry.lighting}, {args.runs} runs, one thread (LP_NUM_THREADS=1, "
          "OMP/OPENBLAS=1, cv2.setNumThreads(1))")
    print(f"  render alone            {statistics.median(render_fps):7.1f} frames/s")
    print(f"  render + ground truth   {statistics.median(gt_fps):7.1f} frames/s")
    print(f"  file writing alone      {statistics.median(write_fps):7.1f} frames/s")
    print(f"  render_sequence total   {statistics.median(seq_fps):7.1f} frames/s (incl. world build, files, manifest)")
    print(f"  ground-truth overhead   {statistics.median(render_fps) / statistics.median(gt_fps):7.2f}x render alone")


if __name__ == "__main__":
    main()
