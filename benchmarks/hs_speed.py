"""Horn-Schunck iteration (``hs_iterate``) against the version of a reference tree: the same bits, and the CPU-time ratio.

    python benchmarks/hs_speed.py --ref REF_TREE [--shape 479,639] [--iterations 100] [--repeats 7]

The reference ``algorithms/horn_schunck_flow.py`` is loaded from ``--ref`` under another module name
(its registration decorator dropped). Identity: both iterate the same random Ex, Ey, Et (and the
derivatives of a smooth random texture shifted by a sub-pixel amount) from the same start, at many
shapes (1xN, Nx1, 2x2, odd sizes, 640x480) and sweep counts 1..17 and 100, with and without a
tolerance, and the fields and sweep counts are compared with ``np.array_equal``. Speed: ``hs_iterate``
at ``--shape`` (the cube grid of a 640x480 frame) with ``--iterations`` sweeps, ours and the reference
alternately ``--repeats`` times (CPU time of this process, one thread), medians and the median of the
per-call ratios reference / ours (above 1: ours is faster); also ``_hs_sweep`` alone.

Measured (issue 13; reference 95a9436, machine loaded by other work, load average 2.7-3.5 on 2 cores):
1086 of 1086 cases equal; hs_iterate 640x480 x 100 sweeps 30.4 -> 25.9 ms, ratio 1.18 (1.16 in an
earlier run); one sweep 1.16-1.19. What did not help, measured with the same bits: temporal blocking
(2-16 sweeps per pass over row chunks of 8-128 rows, in the two ping-pong arrays): 0.92-1.01, and a
sweep on arrays that fit in L2 is no faster per point than at 640x480 (about 1 ns per point either way,
load-port bound: 22 loads for 21 float operations per point), so the sweep is not memory bound; two
rows per loop iteration (12 instead of 16 loads of u per pair of points) does not vectorise (LLVM:
"too many memory checks needed"), and forced with noalias it spilled and was slower.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _earlier  # noqa: E402  (benchmarks/, the script's folder)

import algorithms.horn_schunck_flow as hs  # noqa: E402


def load_earlier(tree: str):
    """``tree/algorithms/horn_schunck_flow.py`` as a module named ``hs_earlier``."""
    return _earlier.load_earlier(tree, "algorithms/horn_schunck_flow.py", "hs_earlier")


def _random_terms(rng, shape):
    Ex, Ey, Et = (rng.normal(0, 8, shape).astype(np.float32) for _ in range(3))
    return Ex, Ey, Et


def _texture_terms(rng, shape):
    """Derivatives of a smooth random texture and its copy shifted by (0.4, -0.7) px (Fourier shift)."""
    h, w = shape[0] + 1, shape[1] + 1
    f = rng.normal(0, 1, (h, w))
    ky = np.fft.fftfreq(h)[:, None]
    kx = np.fft.fftfreq(w)[None, :]
    F = np.fft.fft2(f) * np.exp(-(kx**2 + ky**2) / (2 * 0.05**2))
    f0 = np.real(np.fft.ifft2(F))
    f1 = np.real(np.fft.ifft2(F * np.exp(-2j * np.pi * (kx * 0.4 + ky * -0.7))))
    s = 100 / max(f0.std(), 1e-3)  # tiny shapes keep only the mean: a flat texture
    return hs.hs_derivatives((f0 * s + 128).astype(np.float32), (f1 * s + 128).astype(np.float32))


def check(old, rng) -> list[str]:
    """Every shape x sweep count x tolerance: ours and the reference give equal fields and counts."""
    bad = []
    shapes = [(1, 1), (1, 2), (2, 1), (1, 17), (17, 1), (2, 2), (3, 3), (2, 5), (5, 2), (7, 13), (31, 33),
              (64, 64), (59, 81), (120, 160), (239, 319)]
    cases = [(s, n, tol, kind) for s in shapes for n in (*range(1, 18), 100) for tol in (0.0, 1e-3)
             for kind in ("random", "texture")]
    cases += [((479, 639), n, tol, "texture") for n in (1, 7, 100) for tol in (0.0, 1e-4)]
    for shape, n, tol, kind in cases:
        Ex, Ey, Et = (_random_terms if kind == "random" else _texture_terms)(rng, shape)
        u0 = rng.normal(0, 1, shape).astype(np.float32)
        v0 = rng.normal(0, 1, shape).astype(np.float32)
        ua, va, ub, vb = u0.copy(), v0.copy(), u0.copy(), v0.copy()
        da = hs.hs_iterate(Ex, Ey, Et, ua, va, 15.0, n, tol)
        db = old.hs_iterate(Ex, Ey, Et, ub, vb, 15.0, n, tol)
        if da != db or not np.array_equal(ua, ub) or not np.array_equal(va, vb):
            bad.append(f"{shape} {kind} iterations {n} tol {tol}: sweeps {da} vs {db}, "
                       f"max |du| {np.abs(ua - ub).max():.3g}, |dv| {np.abs(va - vb).max():.3g}")
    print(f"identity: {len(cases) - len(bad)} of {len(cases)} cases equal", flush=True)
    return bad


def _cpu(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def speed(old, rng, shape, iterations, repeats) -> None:
    Ex, Ey, Et = _texture_terms(rng, shape)
    u = np.zeros(shape, np.float32)
    v = np.zeros(shape, np.float32)

    def ours():
        hs.hs_iterate(Ex, Ey, Et, u.copy(), v.copy(), 15.0, iterations, 0.0)

    def ref():
        old.hs_iterate(Ex, Ey, Et, u.copy(), v.copy(), 15.0, iterations, 0.0)

    inv_den = np.empty(shape, np.float32)
    out_u, out_v = np.empty(shape, np.float32), np.empty(shape, np.float32)

    def sweep(mod):
        def run():
            for _ in range(iterations):
                mod._hs_sweep(u, v, Ex, Ey, Et, inv_den, out_u, out_v)
        return run

    runs = {"reference": ref, "ours": ours, "reference _hs_sweep": sweep(old), "ours _hs_sweep": sweep(hs)}
    for fn in runs.values():  # compile and warm up
        fn()
    times = {name: [] for name in runs}
    for _ in range(repeats):
        for name, fn in runs.items():
            times[name].append(_cpu(fn))
    ref_t = {name: times["reference _hs_sweep" if "sweep" in name else "reference"] for name in times}
    print(f"hs_iterate {shape[0]}x{shape[1]}, {iterations} sweeps, {repeats} interleaved runs, "
          f"load {os.getloadavg()[0]:.2f}")
    print(f"{'':24s} {'median ms':>10s} {'ns/px/sweep':>12s} {'ratio ref/this':>15s}")
    for name, ts in times.items():
        med = statistics.median(ts)
        ratio = statistics.median(r / t for r, t in zip(ref_t[name], ts))
        print(f"{name:24s} {1e3 * med:10.1f} {1e9 * med / (iterations * shape[0] * shape[1]):12.3f} "
              f"{ratio:15.2f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref", required=True, help="root of the reference tree")
    ap.add_argument("--shape", default="479,639", help="h,w of the cube grid (frame size minus one)")
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--no-check", action="store_true", help="skip the identity check")
    args = ap.parse_args()
    old = load_earlier(args.ref)
    rng = np.random.default_rng(0)
    bad = [] if args.no_check else check(old, rng)
    for b in bad[:20]:
        print("   ", b)
    shape = tuple(int(x) for x in args.shape.split(","))
    speed(old, rng, shape, args.iterations, args.repeats)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
