"""Our TV-L1 (``tv-l1`` pipeline) on rendered sequences: beside scikit-image's, or beside other settings.

Two modes. Without ``--setting``, the built-in pipelines ``tvl1`` (scikit-image)
and ``tv-l1`` (ours; the same stages, only the flow method differs) run on each
sequence. With ``--setting NAME=JSON`` (twice or more), ``tv-l1`` runs once per
setting, its flow ``params`` replaced by the JSON dict (``{}``: ``tv_l1``'s
defaults), and the first setting is the reference the others are compared to.

    python benchmarks/tv_l1_accuracy.py CACHE/*-* --pairs 8 \\
        --setting old='{"n_warps": 5, "n_iter": 15}' --setting new='{"n_warps": 3, "n_iter": 10}'

Every pair is scored by ``harness.metrics.score_pair`` as the runner scores a
cell. Printed per preset (the sequence folder's name up to its hash) and over
all: mean EPE (px, pooled per pixel over the pairs, from summed sums and
counts) of the total and the local motion on every region (all, background,
vehicles, interior), and, per setting after the first, its difference to the
first with the noise of that difference: ``2 SE``, twice the standard error of
the paired per-pair differences of the pair means (a pair's EPE minus the same
pair's EPE under the reference; pairs without pixels of the region skipped).
A difference above ``2 SE`` is flagged ``WORSE``. Then the pipeline CPU seconds
per pair (process time, one thread, so a machine busy with other work inflates
it less than wall time; the whole pipeline, not the flow alone: see
``benchmarks/flow_speed.py`` for that). ``--csv`` writes the per-pair rows.

Measured, mode 1 (6-frame renders of nominal, thesis, fast-vehicles, realistic; tv_l1 / tvl1):
total EPE background 0.052 / 0.067, 0.028 / 0.046, 0.042 / 0.064, 0.210 / 0.212 px;
vehicles 1.27 / 1.73, 0.236 / 0.300, 10.9 / 11.5, 0.246 / 0.406 px; local background
equal within 0.003 px (realistic 0.508 / 0.506); pipeline CPU 1.0-1.1 s / 19-21 s per
sequence (ratio 0.05). That was scikit-image at its default ``attachment`` 15. At tv_l1's
data weight (38.25, the ``tvl1`` pipeline since 2026-11-29; renders of that day's generator):
background 0.057 / 0.094, 0.030 / 0.075, 0.053 / 0.108, 0.126 / 0.163 px; vehicles
0.896 / 0.752, 0.246 / 0.305, 9.68 / 8.70, 0.128 / 0.163 px (scikit-image's is now the
better on nominal's and fast-vehicles' vehicles, ours on every background); pipeline CPU
0.229 / 2.33 s per pair (ratio 0.10).

Mode 2, the pipeline's lighter setting (issue 13): see ``benchmarks/tv_l1_setting.md``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from algorithms.pipeline import PIPELINES, PairEstimate, Pipeline, get_pipeline  # noqa: E402
from harness.metrics import score_pair  # noqa: E402
from scenes.sequence import open_sequence  # noqa: E402


def _setting(text: str) -> tuple[str, Pipeline]:
    name, sep, params = text.partition("=")
    if not sep:
        raise SystemExit(f"--setting: expected NAME=JSON, got {text!r}")
    d = json.loads(json.dumps(PIPELINES["tv-l1"]))
    d["flow"]["params"] = json.loads(params)
    return name, Pipeline.from_dict(d)


def _preset(folder: str) -> str:
    # <preset>-<20 hex digits> as the render cache names them; any other folder name as it is
    return re.sub(r"-[0-9a-f]{20}$", "", Path(folder).name)


def _run(pipelines: dict[str, Pipeline], folders: list[str], n_pairs: int | None) -> pd.DataFrame:
    rows = []
    for folder in folders:
        seq = open_sequence(folder)
        n = len(seq) if n_pairs is None else min(len(seq), n_pairs + 1)
        frames = [seq.frame(i) for i in range(n)]
        truths = [seq.pair_truth(i) for i in range(n - 1)]
        base = {"preset": _preset(folder), "sequence": Path(folder).name}
        for name, pipe in pipelines.items():
            t = time.process_time()
            for est in pipe.run(frames):
                if isinstance(est, PairEstimate):
                    for r in score_pair(est, truths[est.index], frame=est.index, timings=False):
                        if r["metric"] == "epe_mean":
                            rows.append({**base, "setting": name, "pair": est.index, "motion": r["motion"],
                                         "region": r["region"], "sum": r["sum"], "count": r["count"]})
            rows.append({**base, "setting": name, "pair": -1, "motion": "cpu", "region": "s per pair",
                         "sum": time.process_time() - t, "count": n - 1})
            print(f"{base['sequence']} {name}: {time.process_time() - t:.1f} CPU s", file=sys.stderr, flush=True)
    return pd.DataFrame(rows)


def compare(df: pd.DataFrame, ref: str) -> pd.DataFrame:
    """Pooled mean EPE per (preset, motion, region, setting), and each setting's difference to ``ref`` with 2 SE."""
    epe = df[df["motion"] != "cpu"]
    out = []
    for preset, g in list(epe.groupby("preset", sort=False)) + [("ALL", epe)]:
        for (motion, region), h in g.groupby(["motion", "region"], sort=False):
            s = h.groupby("setting", sort=False)[["sum", "count"]].sum()
            pooled = s["sum"] / s["count"].where(s["count"] > 0)
            per_pair = h[h["count"] > 0].assign(e=lambda x: x["sum"] / x["count"]).pivot_table(
                index=["sequence", "pair"], columns="setting", values="e")
            row = {"preset": preset, "motion": motion, "region": region, "pairs": len(per_pair)}
            for name in s.index:
                row[name] = pooled[name]
                if name != ref:
                    d = (per_pair[name] - per_pair[ref]).dropna()
                    se2 = 2 * d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else np.nan
                    row[f"{name}-{ref}"] = pooled[name] - pooled[ref]
                    row[f"2SE {name}"] = se2
                    row[f"flag {name}"] = "WORSE" if pooled[name] - pooled[ref] > se2 else ""
            out.append(row)
    return pd.DataFrame(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="+", help="rendered sequence folders")
    parser.add_argument("--setting", action="append", default=[], metavar="NAME=JSON",
                        help="tv_l1 params of the tv-l1 pipeline (repeat; the first is the reference)")
    parser.add_argument("--pairs", type=int, default=None, help="first N pairs of each sequence (default: all)")
    parser.add_argument("--csv", help="write the per-pair rows here")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    if args.setting:
        pipelines = dict(_setting(s) for s in args.setting)
    else:
        pipelines = {"tvl1": get_pipeline("tvl1"), "tv-l1": get_pipeline("tv-l1")}
    first = open_sequence(args.sequences[0])
    for pipe in pipelines.values():  # every stage's numba compile (or cache load) outside the timings
        list(pipe.run([first.frame(0), first.frame(1)]))
    df = _run(pipelines, args.sequences, args.pairs)
    if args.csv:
        df.to_csv(args.csv, index=False)
    names = list(pipelines)
    table = compare(df, names[0])
    cpu = df[df["motion"] == "cpu"].groupby("setting", sort=False)[["sum", "count"]].sum()
    pd.set_option("display.width", 250)
    print("mean EPE px (pooled per pixel); differences to", names[0], "with 2 SE of the paired per-pair differences")
    print(table.round(4).to_string(index=False))
    print("pipeline CPU s per pair (one thread):",
          ", ".join(f"{k} {v:.3f}" for k, v in (cpu["sum"] / cpu["count"]).items()))


if __name__ == "__main__":
    main()
