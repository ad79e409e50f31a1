"""Render throughput of the scene generator: one row per sensor effect, against flat nominal in the same run.

Run single-threaded, as one worker of a process pool would run:

    python benchmarks/render_throughput.py \\
        [--preset nominal] [--frames 20] [--runs 3] [--only flat,blur,...] \\
        [--reference /path/to/other/checkout] [--one-core]

(The script sets LP_NUM_THREADS, OMP_NUM_THREADS, ... to 1 itself before numpy, cv2
and llvmpipe load, and calls cv2.setNumThreads(1).) Each row streams
``SceneGenerator(spec).frames()`` of the preset with one sensor effect switched on:
render, sensor and ground truth, no file writing. The world (texture, meshes) is
built, and the truth kernels loaded (numba, once per process), before the clock
starts. Figures are frames per CPU-second (process time: a loaded shared machine
slows the wall clock, not the CPU time) and wall frames/s, medians over ``--runs``
runs; the runs of all rows are interleaved, so every row meets the same load, and
the ratio to the flat row is the median of the per-run ratios.

Rows after the effects (flat nominal):

- ``render``: the render alone (``SceneRenderer.render``: draw, resolve, read-back);
  ``x flat`` is then render alone / (render + truth). The line under the table gives
  (render + truth) / render alone (issue 13: at least 0.8) per run and median, as the CPU
  time of the renders inside the flat stream over the whole stream (the same frames at the
  same moment), and from the two rows.
- ``files``: the whole ``render_sequence`` (frames, truth, PNG / compact flow encoding by
  the writer threads, preview, manifest), frames per wall second of the rendering thread
  from the first frame to the manifest (world building excluded: ``setup_s``), and frames
  per CPU-second of the whole process (every thread: the encoders' cost).
- with ``--reference DIR``: flat render + truth and render alone of the checkout in DIR
  (its ``scenes`` package, run in a child process with ``PYTHONPATH=DIR``), interleaved
  with this checkout's, and the per-run ratios this / reference, median.

``--one-core`` pins the process (and its threads: writers, llvmpipe) to one CPU, so
that ``files`` measures render_sequence on one core.

Measured (issue 13, 2-core machine shared with other jobs, load 4-5):
``--frames 20 --runs 5 --only flat --reference <worktree of ec6d630>``: flat nominal
(render + truth) / render alone 0.855 (runs 0.846-0.864); this / ec6d630 render + truth
1.040 (runs 0.974-1.129), render alone 0.883 (measured again at load 1-4 after the uniform-location
cache was reverted: it made frames depend on what the process rendered before; with it, 1.137). ``--frames 60 --runs 3 --only flat
--one-core``: render alone 36.6 frames/CPU-s, render + truth 29.0, whole render_sequence
11.6 frames/CPU-s and 7.6 frames/s wall: file encoding (PNG frame ~16 ms, compact flow
~24 ms, masks ~2.5 ms a frame) costs more than render + truth, so on one core the
sequence runs at about 0.32x the render alone. Then compact flow codec 2 (zstd byte
planes, ~11 ms a pair) and Huffman-only frame PNGs (~14-16 ms), 3 runs of ``--frames 60
--runs 1 --only flat --one-core`` alternating with a checkout of 4a7bb3b: whole
render_sequence 13.5 frames/CPU-s and 12.9 frames/s wall (runs 13.2-15.4) against 11.2
and 11.1 (runs 10.7-12.4), 1.25x (per-run ratios 1.17-1.26); still about 0.4x the render
alone: PNG deflate (~14 ms) and render + truth (~35 ms) are most of a frame's CPU.
Then our own PNG encoder and the flow kernels (scenes/_codec_kernels.py): the whole
render_sequence call against a reference checkout, per thread, is measured by
benchmarks/sequence_speed.py (its docstring has the figures).
"""

from __future__ import annotations

import os

for _var in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scenes.generate import SceneGenerator  # noqa: E402
from scenes.sequence import render_sequence  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402

# name -> (overrides, what the row shows)
EFFECTS: dict[str, tuple[dict, str]] = {
    "flat": ({}, "flat nominal, no sensor effect"),
    "blur": ({"sensor.motion_blur.exposure_s": 0.02, "sensor.motion_blur.subframes": 5},
             "motion blur, 5 sub-frame renders"),
    "rolling": ({"sensor.rolling_shutter.line_delay_s": 3e-5, "sensor.rolling_shutter.band_rows": 16},
                "rolling shutter, bands of 16 rows"),
    "lens": ({"sensor.lens.k1": -0.1, "sensor.lens.k2": 0.01}, "lens distortion k1 -0.1, k2 0.01"),
    "optics": ({"sensor.lens.blur_sigma_px": 0.7}, "optics blur 0.7 px"),
    "haze": ({"sensor.haze.extinction_per_km": 2.0}, "haze 2 per km"),
    "noise": ({"sensor.noise.gaussian_std": 2.0, "sensor.noise.full_well_e": 4000.0}, "shot + read noise"),
    "jpeg": ({"sensor.compression.codec": "jpeg", "sensor.compression.jpeg_quality": 75}, "JPEG quality 75"),
    "h264": ({"sensor.compression.codec": "h264", "sensor.compression.h264_crf": 23}, "H.264 crf 23 (libx264)"),
    "realistic": (None, "the realistic preset's sensor (all of the above)"),
}


def _spec(preset: str, frames: int, name: str):
    overrides, _ = EFFECTS[name]
    if overrides is None:  # the realistic preset's sensor section on this preset's scene
        sensor = load_scene_spec("realistic").sensor.model_dump()
        base = load_scene_spec(preset, {"image.n_frames": frames})
        return load_scene_spec({**base.model_dump(mode="json"), "sensor": sensor})
    return load_scene_spec(preset, {"image.n_frames": frames, **overrides})


def _warm(gen) -> None:
    """Texture upload and (pinhole specs) the truth kernels' first call, before any clock starts."""
    Ms = gen.vehicle_matrices(0.0)
    _, depth = gen.renderer.render(gen.path.R[0], gen.path.C[0], Ms)
    if depth.shape == (gen.truth.h, gen.truth.w):
        s = gen.truth.surface(depth, gen.path.R[0], gen.path.C[0], Ms)
        gen.truth.pair(s, s)


def _stream(spec) -> tuple[float, float, float]:
    """(wall s, CPU s, CPU s in the renders) of generating every frame with its truth; world built before the clock.

    The renders inside the stream are timed too, so that the truth's share is measured on the
    same frames at the same moment as the whole (a loaded machine drifts between runs).
    """
    gen = SceneGenerator(spec)
    _warm(gen)
    render, spent = gen.renderer.render, [0.0]

    def timed(*args, **kwargs):
        c = time.process_time()
        out = render(*args, **kwargs)
        spent[0] += time.process_time() - c
        return out

    gen.renderer.render = timed
    t0, c0 = time.perf_counter(), time.process_time()
    for _fo in gen.frames():
        pass
    return time.perf_counter() - t0, time.process_time() - c0, spent[0]


# what the child process of --reference runs in the other checkout (its own scenes package)
_CHILD = """
import json, os, sys, time
for v in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[v] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import cv2
cv2.setNumThreads(1)
from scenes.generate import SceneGenerator
from scenes.spec import load_scene_spec
n = int(sys.argv[2])
gen = SceneGenerator(load_scene_spec(sys.argv[1], {"image.n_frames": n}))
Ms = gen.vehicle_matrices(0.0)
_, depth = gen.renderer.render(gen.path.R[0], gen.path.C[0], Ms)
s = gen.truth.surface(depth, gen.path.R[0], gen.path.C[0], Ms)
gen.truth.pair(s, s)
c0 = time.process_time()
for _fo in gen.frames():
    pass
rt = n / (time.process_time() - c0)
c0 = time.process_time()
for i in range(n):
    gen.renderer.render(gen.path.R[i], gen.path.C[i], gen.vehicle_matrices(float(gen.path.t_s[i])))
print(json.dumps({"render_truth": rt, "render": n / (time.process_time() - c0)}))
"""


def _child(checkout: str, preset: str, frames: int) -> dict:
    """Flat render + truth and render alone (frames per CPU-second) of ``checkout``, in a child process."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    out = subprocess.run([sys.executable, "-c", _CHILD, preset, str(frames)], env=env, cwd=tempfile.gettempdir(),
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{checkout}: the child failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--only", default=",".join(EFFECTS), help=f"comma-separated rows of: {', '.join(EFFECTS)}")
    ap.add_argument("--reference", default=None, help="another checkout whose flat nominal runs beside this one's")
    ap.add_argument("--one-core", action="store_true", help="pin the process and its threads to one CPU")
    args = ap.parse_args()
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = sorted(set(names) - set(EFFECTS))
    if unknown:
        ap.error(f"--only: unknown rows {unknown}; valid: {', '.join(EFFECTS)}")
    if args.reference is not None and not (Path(args.reference) / "scenes").is_dir():
        ap.error(f"--reference: expected a checkout with a scenes/ package, got {args.reference}")
    if "flat" not in names:
        names.insert(0, "flat")
    if args.one_core:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    cv2.setNumThreads(1)
    specs = {n: _spec(args.preset, args.frames, n) for n in names}
    n = args.frames
    cpu = {k: [] for k in names}
    wall = {k: [] for k in names}
    ratio = {k: [] for k in names}
    files_wall, files_cpu, render_cpu, truth_share, in_stream = [], [], [], [], []
    ref_rt, ref_r, vs_ref_rt, vs_ref_r, own_rt = [], [], [], [], []
    load_before = os.getloadavg()[0]
    for _ in range(args.runs):
        for name in names:
            w, c, r = _stream(specs[name])
            wall[name].append(n / w)
            cpu[name].append(n / c)
            if name == "flat":
                in_stream.append(r / c)
        for name in names:
            ratio[name].append(cpu[name][-1] / cpu["flat"][-1])
        gen = SceneGenerator(specs["flat"])
        _warm(gen)
        c0 = time.process_time()
        for i in range(n):
            gen.renderer.render(gen.path.R[i], gen.path.C[i], gen.vehicle_matrices(float(gen.path.t_s[i])))
        render_cpu.append(n / (time.process_time() - c0))
        truth_share.append(cpu["flat"][-1] / render_cpu[-1])
        with tempfile.TemporaryDirectory() as tmp:
            timings: dict = {}
            c0 = time.process_time()
            render_sequence(specs["flat"], Path(tmp) / "seq", timings=timings)
            files_cpu.append(n / (time.process_time() - c0 - timings["setup_cpu_s"]))
            files_wall.append(n / (timings["render_truth_s"] + timings["write_s"]))
        if args.reference is not None:
            ref = _child(args.reference, args.preset, n)
            own = _child(str(Path(__file__).resolve().parents[1]), args.preset, n)
            ref_rt.append(ref["render_truth"])
            ref_r.append(ref["render"])
            own_rt.append(own["render_truth"])
            vs_ref_rt.append(own["render_truth"] / ref["render_truth"])
            vs_ref_r.append(own["render"] / ref["render"])
    flat = specs["flat"]
    cores = f"pinned to CPU {min(os.sched_getaffinity(0))}" if args.one_core else f"{os.cpu_count()} cores"
    print(f"preset {args.preset!r}, {flat.image.width_px}x{flat.image.height_px}, {n} frames, "
          f"light {flat.light.mode}, median of {args.runs} interleaved runs, one thread (LP_NUM_THREADS=1, OMP/OPENBLAS=1, "
          f"cv2.setNumThreads(1)); load average {load_before:.1f} -> {os.getloadavg()[0]:.1f}, {cores}")
    print(f"  {'row':<11} {'frames/CPU-s':>12} {'wall frames/s':>14} {'x flat':>7}   what")
    for name in names:
        print(f"  {name:<11} {statistics.median(cpu[name]):12.2f} {statistics.median(wall[name]):14.2f} "
              f"{statistics.median(ratio[name]):7.3f}   {EFFECTS[name][1]} (render + sensor + truth)")
    print(f"  {'render':<11} {statistics.median(render_cpu):12.2f} {'':>14} "
          f"{statistics.median(render_cpu) / statistics.median(cpu['flat']):7.3f}   flat nominal, render alone")
    print(f"  {'files':<11} {statistics.median(files_cpu):12.2f} {statistics.median(files_wall):14.2f} {'':>7}   "
          "flat nominal, whole render_sequence (truth, PNG / compact flow by the writer threads, preview, "
          "manifest; CPU: every thread)")
    print(f"  flat: (render + truth) / render alone = {statistics.median(in_stream):.3f}, timing the renders inside "
          f"the stream (per run: {', '.join(f'{r:.3f}' for r in in_stream)}); "
          f"from the rows flat / render: {statistics.median(truth_share):.3f}")
    if args.reference is not None:
        print(f"  reference {args.reference}: flat render + truth {statistics.median(ref_rt):.2f} frames/CPU-s, "
              f"render alone {statistics.median(ref_r):.2f}; this checkout {statistics.median(own_rt):.2f} "
              f"in the same child runs")
        print(f"  this / reference: render + truth {statistics.median(vs_ref_rt):.3f} "
              f"(per run: {', '.join(f'{r:.3f}' for r in vs_ref_rt)}), render alone {statistics.median(vs_ref_r):.3f}")


if __name__ == "__main__":
    main()
