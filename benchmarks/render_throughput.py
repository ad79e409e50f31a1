"""Render throughput of the scene generator: frames/s for render alone, render + ground truth, and file writing.

Run single-threaded, as one worker of a process pool would run:

    cd /work/main && LP_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        /work/venv/bin/python benchmarks/render_throughput.py [--preset nominal] [--frames 40] [--runs 3]

(The script sets these variables itself before numpy, cv2 and llvmpipe load,
and calls cv2.setNumThreads(1).) Figures are medians over ``--runs`` runs of
the same sequence on the process's one renderer; the world (texture, meshes)
is built once per run and not counted. CPU-second rates (process time) are
given beside wall-clock rates because a loaded shared machine slows the wall
clock; both are medians.
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
    wall = {k: [] for k in ("render", "truth", "write", "total")}
    cpu = {k: [] for k in ("render", "truth")}
    for _ in range(args.runs):
        gen = SceneGenerator(spec)
        gen.renderer.render(gen.path.R[0], gen.path.C[0], gen.vehicle_matrices(0.0))  # texture upload
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(n):
            gen.renderer.render(gen.path.R[i], gen.path.C[i], gen.vehicle_matrices(float(gen.path.t_s[i])))
        wall["render"].append(n / (time.perf_counter() - t0))
        cpu["render"].append(n / (time.process_time() - c0))

        gen = SceneGenerator(spec)
        gen.renderer.render(gen.path.R[0], gen.path.C[0], gen.vehicle_matrices(0.0))
        t0, c0 = time.perf_counter(), time.process_time()
        for _fo in gen.frames():
            pass
        wall["truth"].append(n / (time.perf_counter() - t0))
        cpu["truth"].append(n / (time.process_time() - c0))

        with tempfile.TemporaryDirectory() as tmp:
            timings: dict = {}
            render_sequence(spec, Path(tmp) / "seq", timings=timings)
            wall["total"].append(n / (timings["render_truth_s"] + timings["write_s"]))
            wall["write"].append(n / timings["write_s"])
    med = {k: statistics.median(v) for k, v in wall.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    print(f"preset {args.preset!r}, {spec.image.width_px}x{spec.image.height_px}, {n} frames, "
          f"light {spec.light.mode}, median of {args.runs} runs, one thread (LP_NUM_THREADS=1, "
          f"OMP/OPENBLAS=1, cv2.setNumThreads(1)); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("                           wall frames/s   frames per CPU-second")
    print(f"  render alone             {med['render']:10.1f}   {med_cpu['render']:10.1f}")
    print(f"  render + ground truth    {med['truth']:10.1f}   {med_cpu['truth']:10.1f}")
    print(f"  file writing alone       {med['write']:10.1f}")
    print(f"  render_sequence total    {med['total']:10.1f}   (world build, truth, files, preview, manifest)")
    print(f"  ground truth costs {med['render'] / med['truth']:.2f}x render alone (wall), "
          f"{med_cpu['render'] / med_cpu['truth']:.2f}x (CPU)")


if __name__ == "__main__":
    main()
