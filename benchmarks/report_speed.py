"""How long the report of a run folder takes: this tree against a reference tree, alternately.

The report is written serially by the driver after every cell has finished, so its time is a
tail no number of workers shortens. This measures ``reports.write_report`` on one run folder
with this tree's ``reports`` and with a reference tree's (e.g. a git worktree of the commit
before a change), each in a fresh child process (``PYTHONPATH`` set to the tree), alternately,
``--repeats`` times each, writing into copies of ``report.html`` / ``report.md`` in a scratch
folder (the run folder is only read). Reported per tree: median CPU seconds of the child
(user + system, ``RUSAGE_CHILDREN``) and median wall seconds, and their ratio; then whether
the two report.md are byte-identical and how many ``<img>`` / ``<svg>`` the two HTML have.
CPU is the figure to trust on a loaded machine; wall moves with the load.

    python benchmarks/report_speed.py RUN_DIR --reference REF_TREE [--repeats 3]

Measured (run folder of the ``standard`` suite, 189 cells, 2 cores shared with 5 other jobs,
load average 7-9; reference 4a49991, this tree the ``reportspeed`` branch):

    tree   CPU s (median)  wall s (median)
    new              84.6             91.5   reportspeed f0716f0
    ref             152.2            169.8   4a49991
    ratio new/ref: CPU 0.556, wall 0.539   (2 runs each, alternated)
    report.md byte-identical: True
    report.html: 143.6 MB (ref 144.2 MB); the 646 pictures pixel-identical; outside the 9 tracking
    figures the HTML is byte-identical apart from the PNG bytes (checked separately)

Where the remaining ~85 CPU-s go (profile of the new tree): matplotlib figures about half (the 9
tracking figures ~1.9 CPU-s each, was ~2.9; stabilisation, jitter, error and sweep figures
unchanged), ``algorithms.flow.flow_to_color`` ~0.12 CPU-s per 640x480 picture x 273 (~33 s),
PNG encoding ~0.01-0.02 s per picture, reading results.parquet ~5 s, tables ~5 s.
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

_CHILD = ("import sys, reports.report as r; "
          "r.write_report(sys.argv[1], out_dir=sys.argv[2])")


def _run_once(tree: Path, run_dir: Path, out_dir: Path) -> tuple[float, float]:
    """(CPU s, wall s) of one report written by ``tree``'s code in a child process."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", _CHILD, str(run_dir), str(out_dir)], env=env, check=True, cwd=tree)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("run_dir", type=Path, help="a run folder (run.json, results.parquet, cells/); only read")
    ap.add_argument("--reference", type=Path, required=True, help="the reference source tree")
    ap.add_argument("--tree", type=Path, default=Path(__file__).resolve().parent.parent,
                    help="the tree under test (default: this file's)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    if not (args.run_dir / "results.parquet").is_file():
        print(f"{args.run_dir}: expected a run folder with results.parquet", file=sys.stderr)
        return 2
    if args.repeats < 1:
        print(f"--repeats: expected >= 1, got {args.repeats}", file=sys.stderr)
        return 2
    trees = {"new": args.tree.resolve(), "ref": args.reference.resolve()}
    with tempfile.TemporaryDirectory(prefix="report_speed_") as tmp:
        outs = {k: Path(tmp) / k for k in trees}
        for o in outs.values():
            o.mkdir()
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in trees}
        for i in range(args.repeats):
            for k in (("ref", "new") if i % 2 else ("new", "ref")):
                cpu, wall = _run_once(trees[k], args.run_dir, outs[k])
                times[k].append((cpu, wall))
                print(f"run {i + 1} {k}: CPU {cpu:.1f} s, wall {wall:.1f} s", flush=True)
        med = {k: (statistics.median(c for c, _ in v), statistics.median(w for _, w in v)) for k, v in times.items()}
        print(f"\n{'tree':<5} {'CPU s (median)':>15} {'wall s (median)':>16}")
        for k in trees:
            print(f"{k:<5} {med[k][0]:>15.1f} {med[k][1]:>16.1f}   {trees[k]}")
        print(f"ratio new/ref: CPU {med['new'][0] / med['ref'][0]:.3f}, wall {med['new'][1] / med['ref'][1]:.3f}")
        md = {k: (outs[k] / "report.md").read_bytes() for k in trees}
        html = {k: (outs[k] / "report.html").read_text("utf-8") for k in trees}
        print(f"report.md byte-identical: {md['new'] == md['ref']}")
        for k in trees:
            print(f"report.html {k}: {len(html[k].encode()) / 1e6:.1f} MB, {html[k].count('<img')} <img>, "
                  f"{html[k].count('<svg')} <svg>")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
