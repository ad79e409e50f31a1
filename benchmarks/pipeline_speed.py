"""Whole-pipeline CPU time per pair, this tree against a reference tree, and a bit-identity check.

Run from the project root (the reference is a git worktree of the commit to compare with,
e.g. ``git worktree add /tmp/ref 95fabaa``):

    python benchmarks/pipeline_speed.py speed --ref /tmp/ref --seq <rendered sequence dir> \
        [--pipelines thesis-lk,...] [--pairs 20] [--repeats 5]
    python benchmarks/pipeline_speed.py check --ref /tmp/ref --seq <dir> [--pipelines ...] [--pairs 0]

Each tree runs in its own long-lived child process (``PYTHONPATH`` set to the tree), with every
thread pool at one thread, set up by ``harness.executors.limit_threads(1)`` of that tree as the
runner's workers are (OMP/MKL/OpenBLAS/NUMBA env variables, ``cv2.setNumThreads(1)``, and in this
tree the malloc settings of ``keep_freed_memory``). The frames of the first ``--pairs`` pairs are
read into memory once per child, so the timing is :meth:`Pipeline.run` alone (global motion, jitter,
compensation, flow, filters, detection, tracking), in CPU seconds (``time.process_time``).

``--default-malloc`` runs this tree without :func:`harness.executors.keep_freed_memory` (glibc's
default malloc, as the reference), to tell the code changes from the memory setting.

``speed``: per pipeline, after one untimed warm-up run in each child, the two children run the
pipeline alternately (ours, reference, ours, ...) ``--repeats`` times; the table gives the medians
in CPU ms per pair and the ratio reference / ours (above 1: ours is faster). A busy machine slows
both alike.

``check``: each child runs every pipeline once on the same frames and writes every field a
:class:`PairEstimate` carries (``flow_global``, ``flow_total``, ``flow_local``, ``flow_filtered``,
``valid``, ``motion_mask``, the detections and global shifts) and the :class:`SequenceEstimate`'s
paths and tracks; the parent asserts ``np.array_equal`` on each (NaN equal to NaN) and the tracks
table equal cell by cell. Exit status 1 on any difference.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parents[1]
STANDARD = "thesis-lk,thesis-hs,pyramidal-lk,pyramidal-hs,dis,farneback,tv-l1"
PAIR_FIELDS = ("flow_global", "flow_total", "flow_local", "flow_filtered", "valid", "motion_mask")
SEQ_FIELDS = ("shifts_px", "shifts_valid", "cumulative_px", "flight_line_px", "correction_px", "jitter_px")


# ------------------------------------------------------------------------------------------------
# child: a command loop on stdin, one JSON answer per line on stdout


def _child(seq_dir: str, pairs: int) -> None:
    import harness.executors as executors

    if os.environ.get("PIPELINE_SPEED_DEFAULT_MALLOC"):  # --default-malloc: leave glibc's malloc as it is
        executors.keep_freed_memory = lambda: False
    executors.limit_threads(1)  # as the runner's workers start (in both trees)
    from algorithms.pipeline import get_pipeline
    from harness.cell_scoring import point_seeds
    from harness.cell_scoring import warm_up as _warm_up
    from scenes import open_sequence

    seq = open_sequence(seq_dir)
    n = len(seq) if pairs <= 0 else min(len(seq), pairs + 1)
    frames = [seq.frame(i) for i in range(n)]
    seeds = point_seeds(seq.tracks)
    out = sys.stdout
    sys.stdout = sys.stderr  # only the answers go to the parent
    for line in sys.stdin:
        cmd = json.loads(line)
        pipeline = get_pipeline(cmd["pipeline"])
        _warm_up(pipeline)
        if cmd["op"] == "time":
            t0 = time.process_time()
            for _ in pipeline.run(frames, seeds=seeds):
                pass
            answer = {"cpu_s": time.process_time() - t0, "pairs": n - 1}
        elif cmd["op"] == "dump":
            pair_rows = []
            for est in pipeline.run(frames, seeds=seeds):
                if hasattr(est, "flow_total"):
                    pair_rows.append({**{k: getattr(est, k) for k in PAIR_FIELDS},
                                      "detections": est.detections, "global_shift_px": est.global_shift_px,
                                      "global_valid": est.global_valid})
                else:
                    seq_est = {k: getattr(est, k) for k in SEQ_FIELDS}
                    seq_est["tracks"] = est.tracks
            with open(cmd["out"], "wb") as f:
                pickle.dump({"pairs": pair_rows, "sequence": seq_est}, f)
            answer = {"out": cmd["out"]}
        else:
            answer = {"error": f"unknown op {cmd['op']!r}"}
        out.write(json.dumps(answer) + "\n")
        out.flush()


class _Tree:
    """A child process importing the code of ``root``."""

    def __init__(self, root: Path, seq: str, pairs: int, default_malloc: bool = False):
        env = dict(os.environ, PYTHONPATH=str(root))
        if default_malloc:
            env["PIPELINE_SPEED_DEFAULT_MALLOC"] = "1"
        self.root = root
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "_child", seq, str(pairs)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True,
                                     cwd=str(root))

    def ask(self, **cmd) -> dict:
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"the child of {self.root} died (see its stderr above)")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


# ------------------------------------------------------------------------------------------------
# comparisons


def _equal(a, b) -> bool:
    import numpy as np

    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    return bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))


def _compare(name: str, ours: dict, ref: dict) -> list[str]:
    import pandas as pd

    bad = []
    if len(ours["pairs"]) != len(ref["pairs"]):
        return [f"{name}: {len(ours['pairs'])} pairs vs {len(ref['pairs'])}"]
    for t, (po, pr) in enumerate(zip(ours["pairs"], ref["pairs"])):
        for k in PAIR_FIELDS + ("global_shift_px",):
            if not _equal(po[k], pr[k]):
                bad.append(f"{name} pair {t}: {k} differs")
        # as arrays, NaN equal to NaN: a Detection's area_m2 is NaN without a ground sampling distance, and two NaNs
        # unpickled apart compare unequal as tuple fields
        if not _equal(po["detections"], pr["detections"]) or po["global_valid"] != pr["global_valid"]:
            bad.append(f"{name} pair {t}: detections or global_valid differ")
    for k in SEQ_FIELDS:
        if not _equal(ours["sequence"][k], ref["sequence"][k]):
            bad.append(f"{name}: sequence {k} differs")
    to, tr = ours["sequence"]["tracks"], ref["sequence"]["tracks"]
    try:
        pd.testing.assert_frame_equal(to, tr, check_exact=True)
    except AssertionError as e:
        bad.append(f"{name}: tracks differ: {str(e).splitlines()[0]}")
    return bad


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "_child":
        _child(sys.argv[2], int(sys.argv[3]))
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("speed", "check"))
    ap.add_argument("--ref", required=True, help="root of the reference tree (a git worktree)")
    ap.add_argument("--seq", required=True, help="a rendered sequence directory (scenes.open_sequence)")
    ap.add_argument("--pipelines", default=STANDARD)
    ap.add_argument("--pairs", type=int, default=None, help="first pairs only (0: all; default 20 / 0)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--default-malloc", action="store_true",
                    help="this tree without harness.executors.keep_freed_memory (the code changes alone)")
    args = ap.parse_args()
    pairs = args.pairs if args.pairs is not None else (20 if args.mode == "speed" else 0)
    names = [p for p in args.pipelines.split(",") if p]
    ours = _Tree(HERE, args.seq, pairs, default_malloc=args.default_malloc)
    ref = _Tree(Path(args.ref).resolve(), args.seq, pairs)
    try:
        if args.mode == "check":
            problems = []
            with tempfile.TemporaryDirectory(prefix="aerobench-check-") as tmp:
                for name in names:
                    got = {}
                    for label, tree in (("ours", ours), ("ref", ref)):
                        path = str(Path(tmp) / f"{name}-{label}.pkl")
                        tree.ask(op="dump", pipeline=name, out=path)
                        with open(path, "rb") as f:
                            got[label] = pickle.load(f)
                    bad = _compare(name, got["ours"], got["ref"])
                    print(f"{name:14s} {len(got['ours']['pairs'])} pairs: "
                          f"{'identical' if not bad else f'{len(bad)} difference(s)'}", flush=True)
                    for b in bad[:10]:
                        print("   ", b)
                    problems += bad
            return 1 if problems else 0
        print(f"load average {os.getloadavg()[0]:.2f}; CPU ms per pair, medians of {args.repeats} "
              f"interleaved runs of {pairs or 'all'} pairs", flush=True)
        print(f"{'pipeline':14s} {'ours':>9s} {'reference':>10s} {'ref/ours':>9s}")
        for name in names:
            ours.ask(op="time", pipeline=name)  # warm-up: numba compilation, first-touch pages
            ref.ask(op="time", pipeline=name)
            t_o, t_r = [], []
            for _ in range(args.repeats):
                a = ours.ask(op="time", pipeline=name)
                b = ref.ask(op="time", pipeline=name)
                t_o.append(a["cpu_s"] / a["pairs"])
                t_r.append(b["cpu_s"] / b["pairs"])
            mo, mr = statistics.median(t_o), statistics.median(t_r)
            print(f"{name:14s} {mo * 1e3:9.1f} {mr * 1e3:10.1f} {mr / mo:9.2f}", flush=True)
        print(f"load average {os.getloadavg()[0]:.2f}")
    finally:
        ours.close()
        ref.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
