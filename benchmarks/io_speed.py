"""Sequence files: bytes on disk and render_sequence speed, the compact layout against the .flo one.

    PYOPENGL_PLATFORM=egl python benchmarks/io_speed.py [--presets nominal noisy] [--frames 60] [--runs 3]

For each preset, side by side in one process (so machine load hits both alike):

- ``flo``: the layout before issue 10: ``.flo`` flow and camera flow, PNG frames with
  zlib's default strategy and libpng's adaptive row filters, every file encoded and
  written in the rendering thread;
- ``npz``: today's defaults: compact lossless flow (``flow/NNNNNN.npz``), PNG with
  Huffman coding only and the Average row filter (our encoder, ``encode_png_fast``), files encoded by
  :data:`scenes.sequence.WRITER_THREADS` writer threads.

Reported per layout: MB of the whole folder (``frames/``, flow, masks, tables, preview,
manifest), frames per wall-clock second and per CPU second (process time: all threads)
of the whole ``render_sequence`` (world build, render, truth, files, preview, manifest),
medians over ``--runs`` runs alternating the two layouts. Native thread pools are held
at one thread (LP/OMP/OPENBLAS/NUMBA = 1, ``cv2.setNumThreads(1)``), as in one worker
of the runner's process pool; the writer threads are Python threads on top.
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

import scenes.sequence as sequence  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402


def folder_bytes(folder: Path) -> dict[str, int]:
    """Bytes per top-level entry of a folder (sub-folders summed)."""
    out: dict[str, int] = {}
    for p in folder.rglob("*"):
        if p.is_file():
            top = p.relative_to(folder).parts[0]
            out[top] = out.get(top, 0) + p.stat().st_size
    return out


def render_once(spec, layout: str, tmp: Path) -> tuple[float, float, dict[str, int]]:
    """(wall s, CPU s, bytes per entry) of one render_sequence in ``layout`` ("flo" or "npz")."""
    saved = sequence._frame_png
    if layout == "flo":
        sequence._frame_png = lambda rgb: sequence.encode_png(rgb, compression=1)  # zlib default, adaptive rows
        kw = {"flow_format": "flo", "writer_threads": 0}
    else:
        kw = {"flow_format": "npz", "writer_threads": sequence.WRITER_THREADS}
    out = tmp / f"seq-{layout}"
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        sequence.render_sequence(spec, out, overwrite=True, **kw)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        sequence._frame_png = saved
    return wall, cpu, folder_bytes(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", nargs="+", default=["nominal", "noisy"])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    print(f"{args.frames} frames, median of {args.runs} runs, native threads 1, writer threads "
          f"{sequence.WRITER_THREADS} (npz); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{'preset':10s} {'layout':6s} {'MB':>7s} {'frames':>7s} {'flow':>7s}   {'frames/s wall':>13s} "
          f"{'frames/CPU-s':>12s}")
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for preset in args.presets:
            spec = load_scene_spec(preset, {"image.n_frames": args.frames})
            n = spec.image.n_frames
            wall: dict[str, list[float]] = {"flo": [], "npz": []}
            cpu: dict[str, list[float]] = {"flo": [], "npz": []}
            sizes: dict[str, dict[str, int]] = {}
            for _ in range(args.runs):
                for layout in ("flo", "npz"):
                    w, c, b = render_once(spec, layout, tmp)
                    wall[layout].append(n / w)
                    cpu[layout].append(n / c)
                    sizes[layout] = b
            for layout in ("flo", "npz"):
                b = sizes[layout]
                flow = b.get("flow", 0) + b.get("flow_camera", 0)
                print(f"{preset:10s} {layout:6s} {sum(b.values()) / 1e6:7.1f} {b.get('frames', 0) / 1e6:7.1f} "
                      f"{flow / 1e6:7.1f}   {statistics.median(wall[layout]):13.1f} "
                      f"{statistics.median(cpu[layout]):12.1f}")
            print(f"{preset:10s} npz/flo: bytes {sum(sizes['npz'].values()) / sum(sizes['flo'].values()):.3f}, "
                  f"wall speed {statistics.median(wall['npz']) / statistics.median(wall['flo']):.2f}x")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
