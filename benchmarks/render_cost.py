"""The render cost of a preset against ``nominal``: ``aerobench render`` wall and CPU time, side by side.

    python benchmarks/render_cost.py [--scene realistic] [--against nominal] [--runs 3] \\
        [--reference /path/to/other/checkout] [--quiet-renders]

Each run renders ``--against`` and then ``--scene`` with ``aerobench render`` in a child process
(this checkout's, or with ``--reference`` the other checkout's ``harness.cli`` through its
``PYTHONPATH``), into a fresh temporary folder: the whole command, from import to the manifest.
CPU time is the child's user + system time (every thread: the writers, llvmpipe's). The runs
alternate, so both meet the same load; figures are medians over ``--runs`` and the ratio is the
median of the per-run ratios (issue 22's target: ``realistic`` at most 4x ``nominal``).

Measured (issue 22, 2-core machine shared with other jobs, load 6.6 -> 18; ``--runs 3 --reference
<main at 4a1276c>``, 60 frames each): nominal 29.0 s wall, 6.0 s CPU; realistic 58.6 s, 19.5 s
(3.40x wall, 3.26x CPU per run, median); main's realistic 335 s, 77.4 s (16.4x wall, 12.9x CPU).
What made the difference: flat light with painted shadows in the preset (the sun's shader with
shadow maps rasterised about 10x slower per pixel on llvmpipe), bands of 96 rows instead of 24
(6 bands x 3 sub-frames = 18 renders a frame instead of 66), vehicles outside a band not drawn,
one shadow map a frame under sun light, and the shot noise's Gaussian draw.

Then (``--runs 5 --reference <main at 9b84010>``, load 10): nominal 10.8 s wall, 6.2 s CPU;
realistic 36.9 s, 20.9 s (3.00x wall, 3.42x CPU), with twice the buildings and four times the
parked cars of main's, whose realistic took 35.9 s, 25.6 s (3.74x, 4.14x) in the same run: the
banded truth's per-pixel pass only for road users whose box reaches the band, batched
projections, and colour-only read-back for motion-blur sub-frames (``docs/realism.md``).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def render_once(checkout: Path, scene: str) -> tuple[float, float]:
    """(wall s, CPU s) of ``aerobench render SCENE`` run from ``checkout`` in a child process."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "harness.cli", "render", scene, "--out", str(Path(tmp) / "seq")],
                             env=env, cwd=tmp, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise SystemExit(f"{checkout}: aerobench render {scene} failed:\n{out.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="realistic")
    ap.add_argument("--against", default="nominal")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--reference", default=None, help="another checkout, whose --scene runs once after each run")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error(f"--runs: expected at least 1, got {args.runs}")
    rows: dict[str, list[tuple[float, float]]] = {args.against: [], args.scene: [], "reference": []}
    load = os.getloadavg()[0]
    for _ in range(args.runs):
        rows[args.against].append(render_once(HERE, args.against))
        rows[args.scene].append(render_once(HERE, args.scene))
        if args.reference is not None:
            rows["reference"].append(render_once(Path(args.reference), args.scene))
    print(f"aerobench render, median of {args.runs} alternating runs, load average {load:.1f} -> "
          f"{os.getloadavg()[0]:.1f}, {os.cpu_count()} cores")
    print(f"  {'scene':<24} {'wall s':>8} {'CPU s':>8} {'x wall':>7} {'x CPU':>7}   per run (wall / CPU)")
    base = rows[args.against]
    for name, runs in rows.items():
        if not runs:
            continue
        label = f"{args.scene} ({args.reference})" if name == "reference" else name
        xw = statistics.median(r[0] / b[0] for r, b in zip(runs, base))
        xc = statistics.median(r[1] / b[1] for r, b in zip(runs, base))
        per = ", ".join(f"{w:.1f}/{c:.1f}" for w, c in runs)
        print(f"  {label:<24} {statistics.median(r[0] for r in runs):8.1f} {statistics.median(r[1] for r in runs):8.1f} "
              f"{xw:7.2f} {xc:7.2f}   {per}")


if __name__ == "__main__":
    main()
