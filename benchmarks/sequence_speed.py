"""Wall frames/s and CPU per frame of one whole ``render_sequence`` call, this checkout against a reference.

    python benchmarks/sequence_speed.py \\
        --reference /path/to/other/checkout [--preset nominal] [--frames 60] [--runs 5] \\
        [--cores 0 | --cores 0,1] [--writer-threads N]

Each run is one fresh child process per checkout (its own ``scenes`` package through
``PYTHONPATH``), as one worker of the runner's pool renders one scene: the child pins
itself to ``--cores`` before anything loads (as ``taskset -c`` does: every thread it makes,
writers and llvmpipe's, inherits the mask), holds native pools at one thread
(LP/OMP/OPENBLAS/NUMBA = 1, ``cv2.setNumThreads(1)``), and calls ``render_sequence`` once.
The two checkouts alternate run by run, so both meet the same load of a shared machine;
one untimed call of each first fills the numba caches.

Reported per checkout, medians over the runs:

- ``fps``: frames per wall second from the first frame to the manifest (world building,
  ``setup_s``, excluded: the same for every layout); ``fps call``: of the whole call;
- ``CPU ms/frame``: process CPU (every thread) over the same span, per frame;
- the same split by thread, from ``/proc/self/task`` (read when the setup ends and just
  before the writer pool shuts down; 10 ms ticks): ``main`` (render, truth, Python; the tables,
  preview and manifest at the end), ``writers`` (the encoder threads), ``llvmpipe``
  (rasteriser threads), ``other``;
- per-run ratios this / reference of ``fps`` and of CPU per frame, median.

Measured (issue 13, flat nominal, 60 frames, 5 runs, reference a worktree of 95fabaa, the
2-core machine shared with other jobs at load 7-10, so wall figures are a fraction of an
idle machine's):

- ``--cores 0`` (one core, writers on it): 5.25 frames/s from the first frame (3.33 the whole
  call) against 4.68 (2.98); 82.8 CPU ms a frame (rendering thread 39.7, writers 19.5,
  llvmpipe 22.8) against 97.7 (42.2, 30.5, 22.0); per-run ratios: fps 1.03 (0.89-1.54), CPU
  a frame 0.95 (0.69-1.03).
- ``--cores 0,1`` (writers free to use the other core): 3.16 frames/s (1.83 the call) against
  2.52 (1.54); 85.1 CPU ms a frame (39.0, 21.5, 23.0) against 100.1 (43.2, 32.2, 23.3); ratios
  fps 1.16 (0.93-1.53), CPU a frame 0.85 (0.73-0.96).

The writers' CPU falls by a third (frame PNG ~4 ms instead of ~13, compact flow ~8 instead
of ~18, same load); the rendering thread and llvmpipe, ~62 ms a frame at this load, are
what is left, and they alone exceed the 33 ms a frame of 30 frames/s on one core.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

# what the child runs in a checkout: one render_sequence call, its timings and per-thread CPU
_CHILD = r"""
import json, os, sys, time
cores = {int(c) for c in sys.argv[3].split(",")}
os.sched_setaffinity(0, cores)
for v in ("LP_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[v] = "1"
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import cv2
cv2.setNumThreads(1)
import scenes.sequence as sq
from scenes.spec import load_scene_spec

TICK = os.sysconf("SC_CLK_TCK")


def threads():
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as fh:
                st = fh.read()
        except OSError:
            continue
        comm = st[st.index("(") + 1:st.rindex(")")]
        f = st[st.rindex(")") + 2:].split()
        out[tid] = (comm, (int(f[11]) + int(f[12])) / TICK)
    return out


import threading
import scenes.preview as pv

snap = {}
close = sq._FolderWriter.close
init = pv.PreviewCollector.__init__


def close_and_snap(self):
    # every file written, the writer threads not yet gone
    if "end" not in snap:
        snap["end"] = threads()
        snap["names"] = {str(t.native_id): t.name for t in threading.enumerate()}
    close(self)


def init_and_snap(self, *a, **k):
    # the last step of render_sequence's setup (world, meshes, renderer): frames start here
    init(self, *a, **k)
    snap["start"] = threads()


sq._FolderWriter.close = close_and_snap
pv.PreviewCollector.__init__ = init_and_snap
spec = load_scene_spec(sys.argv[1], {"image.n_frames": int(sys.argv[2])})
kw = {} if sys.argv[5] == "default" else {"writer_threads": int(sys.argv[5])}
timings = {}
t0, c0 = time.perf_counter(), time.process_time()
sq.render_sequence(spec, sys.argv[4], timings=timings, overwrite=True, **kw)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
per = {"main": 0.0, "writers": 0.0, "llvmpipe": 0.0, "other": 0.0}
main_tid = str(os.getpid())
for tid, (comm, t) in snap["end"].items():
    t -= snap["start"].get(tid, (comm, 0.0))[1]
    name = snap["names"].get(tid, comm)
    key = ("main" if tid == main_tid else "writers" if name.startswith("seq-writer")
           else "llvmpipe" if comm.startswith("llvmpipe") else "other")
    per[key] += t
print(json.dumps({"wall": wall, "cpu": cpu, "timings": timings, "threads": per}))
"""


def _child(checkout: str, preset: str, frames: int, cores: str, out: Path, writers: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(checkout))
    res = subprocess.run([sys.executable, "-c", _CHILD, preset, str(frames), cores, str(out), writers], env=env,
                         cwd=tempfile.gettempdir(), capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"{checkout}: the child failed:\n{res.stderr[-3000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def _figures(r: dict, n: int) -> dict:
    t = r["timings"]
    span = t["render_truth_s"] + t["write_s"]
    # process CPU from the first frame on: the call's minus the setup's (world, meshes, renderer)
    cpu = r["cpu"] - t["setup_cpu_s"]
    return {"fps": n / span, "fps_call": n / r["wall"], "cpu_ms": 1000 * cpu / n,
            **{f"{k}_ms": 1000 * v / n for k, v in r["threads"].items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", required=True, help="the other checkout (its scenes/ package)")
    ap.add_argument("--preset", default="nominal")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--cores", default="0", help="CPUs of the child, as taskset -c: '0' one core, '0,1' two")
    ap.add_argument("--writer-threads", default="default", help="writer threads of this checkout (default: its own)")
    args = ap.parse_args()
    if not (Path(args.reference) / "scenes").is_dir():
        ap.error(f"--reference: expected a checkout with a scenes/ package, got {args.reference}")
    here = str(Path(__file__).resolve().parents[1])
    sides = {"this": (here, args.writer_threads), "reference": (args.reference, "default")}
    res: dict[str, list[dict]] = {k: [] for k in sides}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for name, (path, wt) in sides.items():  # fill the numba caches, untimed
            _child(path, args.preset, 2, args.cores, Path(tmp) / name, wt)
        for _ in range(args.runs):
            for name, (path, wt) in sides.items():
                res[name].append(_figures(_child(path, args.preset, args.frames, args.cores, Path(tmp) / name, wt),
                                          args.frames))
    med = {k: {f: statistics.median(r[f] for r in v) for f in v[0]} for k, v in res.items()}
    print(f"preset {args.preset!r}, {args.frames} frames, cores {args.cores}, median of {args.runs} alternating runs; "
          f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f}")
    cols = ["fps", "fps_call", "cpu_ms", "main_ms", "writers_ms", "llvmpipe_ms", "other_ms"]
    print(f"  {'checkout':<10} " + " ".join(f"{c:>11}" for c in cols))
    for k in res:
        print(f"  {k:<10} " + " ".join(f"{med[k][c]:11.2f}" for c in cols))
    fps_r = [a["fps"] / b["fps"] for a, b in zip(res["this"], res["reference"])]
    cpu_r = [a["cpu_ms"] / b["cpu_ms"] for a, b in zip(res["this"], res["reference"])]
    print(f"  this / reference: fps {statistics.median(fps_r):.3f} (per run: {', '.join(f'{r:.2f}' for r in fps_r)}); "
          f"CPU per frame {statistics.median(cpu_r):.3f} (per run: {', '.join(f'{r:.2f}' for r in cpu_r)})")
    per_run = {k: ", ".join(f"{r['fps']:.1f}" for r in v) for k, v in res.items()}
    print(f"  fps per run: this {per_run['this']}; reference {per_run['reference']}")


if __name__ == "__main__":
    main()
