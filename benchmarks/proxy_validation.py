"""Does the photometric residual rank flow methods as the endpoint error does? (issue 20)

Not a speed benchmark: an accuracy check of a truth-free proxy, too long for the test
suite. Run from the project root:

    python benchmarks/proxy_validation.py [--scenes tiny nominal] [--seeds 1 2] [--frames 6]
                                          [--pipelines dis farneback ...] [--out DIR]

Runs a small suite (the scenes at ``--frames`` frames, the pipelines, the seeds) through
:func:`harness.runner.run_suite` into ``--out`` (default a temporary folder; the render
cache is ``$AEROBENCH_CACHE``), then per rendered sequence (scene x seed) and pooled over
all of them ranks the pipelines twice: by ``epe_mean`` (total motion, every valid pixel,
the truth) and by ``photo_residual`` (the photometric residual of the total flow over the
pixels that pass the reference forward-backward check, no truth). It prints both values
per pipeline and the rank correlations between the two orders: Spearman's rho (Pearson's
correlation of the ranks, ties at their mean rank) and Kendall's tau-b (concordant minus
discordant pairs over the tie-corrected number of pairs), both written here on numpy. A
correlation near 1 means the proxy orders methods as EPE does where truth exists, the
argument for trusting it on real footage where it does not.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from harness.metrics import aggregate  # noqa: E402
from harness.runner import run_suite  # noqa: E402
from harness.suites import parse_suite  # noqa: E402
from reports.synthetic_vs_real import kendall_tau_b, spearman  # noqa: E402  (one home of the rank correlations)

DEFAULT_PIPELINES = ["thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis", "farneback", "tv-l1"]


def suite_dict(scenes: list[str], seeds: list[int], frames: int, pipelines: list[str]) -> dict:
    return {"name": "proxy-validation", "seeds": seeds, "pipelines": pipelines, "picture_pairs": [],
            "scenes": [{"preset": s, "overrides": {"image.n_frames": frames}} for s in scenes]}


def compare(table: pd.DataFrame) -> pd.DataFrame:
    """Per (scene, seed) and pooled: each pipeline's EPE and photometric residual, from summed totals."""
    keep = table[((table["metric"] == "epe_mean") & (table["motion"] == "total") & (table["region"] == "all"))
                 | (table["metric"] == "photo_residual")]
    per = aggregate(keep, by=["scene", "seed", "pipeline"])
    pooled = aggregate(keep, by=["pipeline"]).assign(scene="pooled", seed=-1)
    both = pd.concat([per, pooled], ignore_index=True)
    return both.pivot_table(index=["scene", "seed", "pipeline"], columns="metric", values="value").reset_index()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["tiny", "nominal"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--pipelines", nargs="+", default=DEFAULT_PIPELINES)
    ap.add_argument("--out", default=None, help="run folder (default: a temporary one)")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args(argv)
    suite = parse_suite(suite_dict(args.scenes, args.seeds, args.frames, args.pipelines))
    with tempfile.TemporaryDirectory(prefix="proxy-") as tmp:
        out = Path(args.out) if args.out else Path(tmp) / "run"
        result = run_suite(suite, out, workers=args.workers, progress=False)
        table = result.table
    values = compare(table)
    pd.set_option("display.width", 160)
    print(values.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    print()
    print(f"{'sequence':<24} {'n':>3} {'spearman':>9} {'kendall':>9}")
    for (scene, seed), g in values.groupby(["scene", "seed"], sort=False):
        g = g.dropna(subset=["epe_mean", "photo_residual"])
        name = scene if seed < 0 else f"{scene} seed {seed}"
        print(f"{name:<24} {len(g):>3} {spearman(g['epe_mean'], g['photo_residual']):>9.3f} "
              f"{kendall_tau_b(g['epe_mean'], g['photo_residual']):>9.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
