"""Our TV-L1 against an earlier version of itself: the same bits, and the CPU-time ratio, on rendered pairs.

    git worktree add /tmp/tv-ref 95fabaa      # the version to compare with
    python benchmarks/tv_l1_identical.py /tmp/tv-ref CACHE/*-*/ [--params '{}'] [--repeats 3]

The earlier ``algorithms/tv_l1_flow.py`` is loaded from the given tree under
another module name (its registration decorator dropped; its other imports come
from this tree: frame checks, ``target_inside``). For one pair (frames 2 and 3)
of each sequence folder, both run with the same ``--params`` and the flows and
valid masks are compared with ``np.array_equal``; then each pair is timed
ours / earlier alternately ``--repeats`` times (CPU time of this process, one
thread: NUMBA/OMP env variables and ``cv2.setNumThreads(1)``), and the medians
and the median of the per-call ratios are printed. ``--new-params`` times ours
with other parameters (the equality check is then skipped).

Measured (issue 13; reference 95fabaa, 9 sequences, one of each standard preset, 640x480 and 160x120,
machine loaded by other work, load average 2-7 on 2 cores): equal on every pair, also with bicubic
sampling, epsilon 0.01, sigma_px 0.5 and 3 scales without median, and on Middlebury RubberWhale
(584x388) and Yosemite (316x252); median of per-pair CPU ratios new / old 0.83, 0.83, 0.90
(three runs of 27 calls; medians 145 -> 119, 124.6 -> 113.3 ms).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _earlier  # noqa: E402  (benchmarks/, the script's folder)

from algorithms.tv_l1_flow import tv_l1  # noqa: E402
from scenes.sequence import open_sequence  # noqa: E402


def load_earlier(tree: str):
    """The ``tv_l1`` of ``tree/algorithms/tv_l1_flow.py``, as a module named ``tv_l1_earlier``."""
    return _earlier.load_earlier(tree, "algorithms/tv_l1_flow.py", "tv_l1_earlier").tv_l1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tree", help="a checkout of the earlier version")
    parser.add_argument("sequences", nargs="+", help="rendered sequence folders")
    parser.add_argument("--params", default="{}", help="tv_l1 keyword arguments, JSON")
    parser.add_argument("--new-params", default=None, help="other arguments for ours when timing (JSON)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    earlier = load_earlier(args.tree)
    params = json.loads(args.params)
    new_params = params if args.new_params is None else json.loads(args.new_params)

    pairs = []
    for folder in args.sequences:
        seq = open_sequence(folder)
        pairs.append((Path(folder).name, seq.frame(2), seq.frame(3)))
    all_equal = True
    for name, f0, f1 in pairs:
        old_flow, old_valid = earlier(f0, f1, **params)
        flow, valid = tv_l1(f0, f1, **params)
        if args.new_params is None:
            eq = np.array_equal(old_flow, flow) and np.array_equal(old_valid, valid)
            all_equal &= eq
            print(f"{name} {f0.shape[1]}x{f0.shape[0]}: "
                  + ("equal" if eq else f"DIFFERENT, max |d| {np.abs(old_flow - flow).max():.3g} px"))
    if args.new_params is None:
        print("flows and valid masks equal on every pair:", "yes" if all_equal else "NO")
    t_old, t_new = [], []
    for _ in range(args.repeats):
        for _name, f0, f1 in pairs:
            t = time.process_time()
            earlier(f0, f1, **params)
            t_old.append(time.process_time() - t)
            t = time.process_time()
            tv_l1(f0, f1, **new_params)
            t_new.append(time.process_time() - t)
    t_old, t_new = np.array(t_old), np.array(t_new)
    print(f"CPU ms per call, median of {len(t_old)}: earlier {np.median(t_old) * 1e3:.1f}, "
          f"ours {np.median(t_new) * 1e3:.1f}; median of per-call ratios ours / earlier "
          f"{np.median(t_new / t_old):.3f}; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
