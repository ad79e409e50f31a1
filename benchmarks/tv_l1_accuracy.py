"""Our TV-L1 (``tv_l1``) beside scikit-image's (``tvl1``) on rendered sequences: EPE and CPU time, one thread.

Render a few short sequences first, then pass their folders:

    for p in nominal thesis fast-vehicles realistic; do
        aerobench render $p --out /tmp/tv/$p --set image.n_frames=6
    done
    python benchmarks/tv_l1_accuracy.py /tmp/tv/nominal /tmp/tv/thesis /tmp/tv/fast-vehicles /tmp/tv/realistic

Each sequence runs through the built-in pipelines ``tvl1`` and ``tv_l1`` (the
same stages, only the flow method differs) and every pair is scored by
``harness.metrics.score_pair`` as the runner scores a cell. Printed: mean EPE
(px, pooled per pixel over the pairs, from summed sums and counts) of the total
and the local motion on background and vehicles, and the CPU seconds of the
whole pipeline per sequence (process time, so a machine busy with other work
inflates it less than wall time), with the ratio.

Measured (6-frame renders of nominal, thesis, fast-vehicles, realistic; tv_l1 / tvl1):
total EPE background 0.052 / 0.067, 0.028 / 0.046, 0.042 / 0.064, 0.210 / 0.212 px;
vehicles 1.27 / 1.73, 0.236 / 0.300, 10.9 / 11.5, 0.246 / 0.406 px; local background
equal within 0.003 px (realistic 0.508 / 0.506); pipeline CPU 1.0-1.1 s / 19-21 s per
sequence (ratio 0.05).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from algorithms.pipeline import PairEstimate, get_pipeline  # noqa: E402
from harness.metrics import score_pair  # noqa: E402
from scenes.sequence import open_sequence  # noqa: E402

PIPELINES = ("tvl1", "tv_l1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="+", help="rendered sequence folders")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    import numpy as np

    from algorithms.tv_l1_flow import tv_l1

    warm = np.random.default_rng(0).uniform(0, 255, (32, 32)).astype(np.float32)
    tv_l1(warm, warm[::-1].copy())  # numba compile (or cache load) outside the timings

    rows = []
    for folder in args.sequences:
        seq = open_sequence(folder)
        scene = Path(folder).name
        frames = [seq.frame(i) for i in range(len(seq))]
        for name in PIPELINES:
            t = time.process_time()
            for est in get_pipeline(name).run(frames):
                if isinstance(est, PairEstimate):
                    for r in score_pair(est, seq.pair_truth(est.index), frame=est.index, timings=False):
                        if r["metric"] == "epe_mean" and r["region"] in ("background", "vehicles"):
                            rows.append({"scene": scene, "pipeline": name, "what": f"{r['motion']} {r['region']}",
                                         "sum": r["sum"], "count": r["count"]})
            rows.append({"scene": scene, "pipeline": name, "what": "cpu s", "sum": time.process_time() - t,
                         "count": 1})
    df = pd.DataFrame(rows).groupby(["scene", "what", "pipeline"], sort=False)[["sum", "count"]].sum()
    table = (df["sum"] / df["count"]).unstack("pipeline")[list(PIPELINES)]
    table["tv_l1 / tvl1"] = table["tv_l1"] / table["tvl1"]
    print("mean EPE px (pooled per pixel) and pipeline CPU s per sequence; one thread")
    print(table.round(3).to_string())


if __name__ == "__main__":
    main()
