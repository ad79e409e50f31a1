"""Speed of the flow and global-motion methods at 512x512 on one thread, beside their references.

Run from the project root:

    python benchmarks/flow_speed.py [--repeats 7]

Every time is the median of ``--repeats`` runs after one warm-up call (numba
compile time is measured separately and reported). Threads are pinned to one:
OMP/MKL/OpenBLAS/NUMBA env variables are set before the imports and
``cv2.setNumThreads(1)``. Targets (ratios measured in the same run):
HS 100 sweeps >= 50x faster than pyoptflow; dense single-level LK <= 5 ms;
coarse-to-fine LK >= 20x faster than scikit-image ilk at no worse EPE;
NCC global motion over +/-16 px <= 5 ms.
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
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from algorithms.global_motion import ncc_global_motion  # noqa: E402
from algorithms.horn_schunck import horn_schunck  # noqa: E402
from algorithms.lucas_kanade import lucas_kanade  # noqa: E402
from algorithms.reference import dis, ilk  # noqa: E402


def textured_pair(rng: np.random.Generator, size: int, shift_px: tuple[float, float]) -> tuple[np.ndarray, ...]:
    """A smooth periodic random texture and its exact sub-pixel Fourier shift, uint8-range float32."""
    noise = rng.normal(size=(size, size))
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.fftfreq(size)[None, :]
    spectrum = np.fft.fft2(noise) * np.exp(-(fx**2 + fy**2) / (2 * 0.06**2))
    dx, dy = shift_px
    shifted = spectrum * np.exp(-2j * np.pi * (fx * dx + fy * dy))
    f0, f1 = np.fft.ifft2(spectrum).real, np.fft.ifft2(shifted).real
    lo, hi = f0.min(), f0.max()
    return [((f - lo) / (hi - lo) * 200 + 25).astype(np.float32) for f in (f0, f1)]


def median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000.0 * float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--size", type=int, default=512)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    import numba
    numba.set_num_threads(1)
    import pyoptflow

    truth = (2.3, -1.7)
    f0, f1 = textured_pair(np.random.default_rng(0), args.size, truth)
    inner = (slice(32, -32), slice(32, -32))

    def epe(flow: np.ndarray) -> float:
        return float(np.hypot(flow[..., 0] - truth[0], flow[..., 1] - truth[1])[inner].mean())

    t = time.perf_counter()
    horn_schunck(f0[:16, :16], f1[:16, :16], iterations=1)
    compile_ms = 1000.0 * (time.perf_counter() - t)

    rows = []  # (name, ms, reference name, reference ms, epe, reference epe, target)

    def run(fn):
        fn()  # warm-up
        return median_ms(fn, args.repeats)

    hs_ms = run(lambda: horn_schunck(f0, f1, iterations=100))
    po_ms = median_ms(lambda: pyoptflow.HornSchunck(f0, f1, alpha=15.0, Niter=100), max(3, args.repeats // 2))
    rows.append(("horn_schunck 100 sweeps", hs_ms, "pyoptflow 100", po_ms, None, None, "ratio >= 50"))

    lk_ms = run(lambda: lucas_kanade(f0, f1))
    rows.append(("lucas_kanade single level", lk_ms, "", None, None, None, "<= 5 ms"))

    c2f = {"levels": 4, "iterations": 3}
    lk2_ms = run(lambda: lucas_kanade(f0, f1, **c2f))
    ilk_ms = median_ms(lambda: ilk(f0, f1), max(3, args.repeats // 2))
    rows.append(("lucas_kanade levels 4 x 3", lk2_ms, "skimage ilk", ilk_ms,
                 epe(lucas_kanade(f0, f1, **c2f)[0]), epe(ilk(f0, f1)[0]), "ratio >= 20, EPE <= ilk"))

    hs2_ms = run(lambda: horn_schunck(f0, f1, levels=4))
    dis_ms = run(lambda: dis(f0, f1))
    rows.append(("horn_schunck levels 4", hs2_ms, "cv2 DIS medium", dis_ms,
                 epe(horn_schunck(f0, f1, levels=4)[0]), epe(dis(f0, f1)[0]), "(information)"))

    ncc_ms = run(lambda: ncc_global_motion(f0, f1, max_shift=16))
    rows.append(("ncc_global_motion +/-16", ncc_ms, "", None, None, None, "<= 5 ms"))

    print(f"{args.size}x{args.size}, 1 thread, median of {args.repeats}; synthetic shift {truth} px; "
          f"numba compile (first call, cache may hit) {compile_ms:.0f} ms")
    print(f"{'method':28s} {'ms':>8s}  {'reference':16s} {'ref ms':>8s} {'ratio':>7s} {'EPE px':>7s} "
          f"{'ref EPE':>7s}  target")
    for name, ms, ref, ref_ms, e, ref_e, target in rows:
        ratio = f"{ref_ms / ms:7.1f}" if ref_ms else f"{'':7s}"
        ref_ms_s = f"{ref_ms:8.1f}" if ref_ms else f"{'':8s}"
        e_s = f"{e:7.3f}" if e is not None else f"{'':7s}"
        re_s = f"{ref_e:7.3f}" if ref_e is not None else f"{'':7s}"
        print(f"{name:28s} {ms:8.1f}  {ref:16s} {ref_ms_s} {ratio} {e_s} {re_s}  {target}")


if __name__ == "__main__":
    main()
