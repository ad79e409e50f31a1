"""Speed of the flow and global-motion methods at 512x512 on one thread, beside their references.

Run from the project root:

    python benchmarks/flow_speed.py [--repeats 15] [--cpu 1]

Each method and its reference are timed in the same process, interleaved
(ours, reference, ours, reference, ...) after one warm-up call each, and the
medians are compared, so a machine that is busy with other work slows both
alike. Each row runs in a fresh process, so no row inherits another's heap.
Threads are pinned to one: OMP/MKL/OpenBLAS/NUMBA env variables are set before
the imports, ``cv2.setNumThreads(1)``, and the process is bound to one CPU
(``--cpu``); the load average is printed before and after.

Targets (ratios measured in the same run):
HS 100 sweeps >= 50x faster than pyoptflow; dense single-level LK <= 5 ms
(reference: the same LK written with numpy and cv2.boxFilter, about 3 ms on a
quiet machine); coarse-to-fine LK >= 20x faster than scikit-image ilk at no
worse EPE; NCC global motion over +/-16 px <= 5 ms (reference: matchTemplate
with the whole central part as template, about 3 ms on a quiet machine); our TV-L1
(``tv_l1``) >= 10x faster than scikit-image's ``optical_flow_tvl1`` (``tvl1``) at no
worse EPE.

Endpoint errors (mean, px) are reported on three pairs: an exact sub-pixel
Fourier shift of a smooth texture (512x512, inner part, 32 px from the edges),
Middlebury RubberWhale and Yosemite (sky masked), the latter two from
``shared/external`` beside the clone (or ``AEROBENCH_EXTERNAL``), as the tests read them.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from algorithms.global_motion import ncc_global_motion  # noqa: E402
from algorithms.horn_schunck_flow import horn_schunck  # noqa: E402
from algorithms.lucas_kanade_flow import lucas_kanade  # noqa: E402
from algorithms.reference import dis, ilk, tvl1  # noqa: E402
from algorithms.tv_l1_flow import tv_l1  # noqa: E402
from scenes.formats import read_flo  # noqa: E402

EXTERNAL = Path(os.environ.get("AEROBENCH_EXTERNAL") or Path(__file__).resolve().parents[2] / "shared" / "external")
TRUTH_PX = (2.3, -1.7)
C2F_LK = {"levels": 4, "iterations": 3}
C2F_HS = {"levels": 4}


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


def lk_box_reference(f0: np.ndarray, f1: np.ndarray, window: int = 15) -> np.ndarray:
    """Reference anchor: the thesis's dense LK written plainly with numpy and cv2.boxFilter."""
    mean = 0.5 * (f0 + f1)
    Ix = cv2.Sobel(mean, cv2.CV_32F, 1, 0, ksize=3, scale=0.125, borderType=cv2.BORDER_REPLICATE)
    Iy = cv2.Sobel(mean, cv2.CV_32F, 0, 1, ksize=3, scale=0.125, borderType=cv2.BORDER_REPLICATE)
    It = f1 - f0

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, cv2.CV_32F, (window, window), borderType=cv2.BORDER_REPLICATE)

    Sxx, Sxy, Syy, Sxt, Syt = box(Ix * Ix), box(Ix * Iy), box(Iy * Iy), box(Ix * It), box(Iy * It)
    det = Sxx * Syy - Sxy * Sxy
    valid = 0.5 * (Sxx + Syy) - np.sqrt((0.5 * (Sxx - Syy)) ** 2 + Sxy * Sxy) >= 1e-3
    inv_det = np.divide(1.0, det, out=np.zeros_like(det), where=valid)
    return np.dstack([(Sxy * Syt - Syy * Sxt) * inv_det, (Sxy * Sxt - Sxx * Syt) * inv_det])


def ncc_full_reference(f0: np.ndarray, f1: np.ndarray, s: int = 16) -> tuple[int, int]:
    """Reference anchor: NCC over +/- s px with the whole central part of frame t as template."""
    h, w = f0.shape
    r = cv2.matchTemplate(f1, f0[s:h - s, s:w - s], cv2.TM_CCOEFF_NORMED)
    iy, ix = np.unravel_index(int(np.argmax(r)), r.shape)
    return ix - s, iy - s


def interleaved_ms(fns: list[Callable[[], object]], repeats: int) -> list[tuple[float, float]]:
    """(median, best) wall time in ms of each function, called in turn ``repeats`` times after a warm-up."""
    for fn in fns:
        fn()
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return [(1000.0 * float(np.median(t)), 1000.0 * float(np.min(t))) for t in times]


def load_external(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Frames (uint8 gray), ground truth and the mask of known pixels, or None when missing."""
    if name == "RubberWhale":
        d = EXTERNAL / "middlebury" / "RubberWhale"
        p0, p1, pf = d / "frame10.png", d / "frame11.png", d / "flow10.flo"
    else:
        d = EXTERNAL / "yosemite" / "yosemite"
        p0, p1, pf = d / "yos9.png", d / "yos10.png", d / "correct_yos.flo"
    if not (p0.exists() and p1.exists() and pf.exists()):
        return None
    g0 = cv2.imread(str(p0), cv2.IMREAD_GRAYSCALE)
    g1 = cv2.imread(str(p1), cv2.IMREAD_GRAYSCALE)
    gt = read_flo(pf)
    known = np.isfinite(gt).all(axis=-1)
    if name == "Yosemite":
        known &= g0 > 0  # the black sky's ground truth is a placeholder
    return g0, g1, gt, known


# row name -> (reference name, target text, check(ours median ms, reference median ms) or None)
ROWS = {
    "horn_schunck 100 sweeps": ("pyoptflow 100", "ratio >= 50", lambda ms, ref: ref / ms >= 50),
    "lucas_kanade single level": ("numpy+boxFilter", "<= 5 ms", lambda ms, ref: ms <= 5.0),
    "lucas_kanade levels 4 x 3": ("skimage ilk", "ratio >= 20", lambda ms, ref: ref / ms >= 20),
    "horn_schunck levels 4": ("cv2 DIS medium", "(information)", None),
    "ncc_global_motion +/-16": ("whole template", "<= 5 ms", lambda ms, ref: ms <= 5.0),
    "tv_l1": ("skimage tvl1", "ratio >= 10", lambda ms, ref: ref / ms >= 10),
}


def time_row(name: str, size: int, repeats: int) -> list[tuple[float, float]]:
    """Interleaved (median, best) ms of one row's method and its reference."""
    import pyoptflow

    f0, f1 = textured_pair(np.random.default_rng(0), size, TRUTH_PX)
    pair = {
        "horn_schunck 100 sweeps": (lambda: horn_schunck(f0, f1, iterations=100),
                                    lambda: pyoptflow.HornSchunck(f0, f1, alpha=15.0, Niter=100)),
        "lucas_kanade single level": (lambda: lucas_kanade(f0, f1), lambda: lk_box_reference(f0, f1)),
        "lucas_kanade levels 4 x 3": (lambda: lucas_kanade(f0, f1, **C2F_LK), lambda: ilk(f0, f1)),
        "horn_schunck levels 4": (lambda: horn_schunck(f0, f1, **C2F_HS), lambda: dis(f0, f1)),
        "ncc_global_motion +/-16": (lambda: ncc_global_motion(f0, f1, max_shift=16),
                                    lambda: ncc_full_reference(f0, f1)),
        "tv_l1": (lambda: tv_l1(f0, f1), lambda: tvl1(f0, f1)),
    }[name]
    return interleaved_ms(list(pair), repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--cpu", type=int, default=None,
                        help="CPU to bind to (default: the highest-numbered one available)")
    parser.add_argument("--row", choices=sorted(ROWS), help=argparse.SUPPRESS)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    import numba
    numba.set_num_threads(1)

    cpus = sorted(os.sched_getaffinity(0))
    cpu = args.cpu if args.cpu is not None else cpus[-1]
    os.sched_setaffinity(0, {cpu})
    if args.row:
        print(json.dumps(time_row(args.row, args.size, args.repeats)))
        return
    load_before = os.getloadavg()

    f0, f1 = textured_pair(np.random.default_rng(0), args.size, TRUTH_PX)
    inner = (slice(32, -32), slice(32, -32))

    def synthetic_epe(flow: np.ndarray) -> float:
        return float(np.hypot(flow[..., 0] - TRUTH_PX[0], flow[..., 1] - TRUTH_PX[1])[inner].mean())

    t = time.perf_counter()
    horn_schunck(f0[:16, :16], f1[:16, :16], iterations=1)
    lucas_kanade(f0[:16, :16], f1[:16, :16], **C2F_LK)
    tv_l1(f0[:16, :16], f1[:16, :16])
    compile_ms = 1000.0 * (time.perf_counter() - t)

    rows = []  # (name, (ms, best ms), reference name, (ref ms, ref best ms), target text, met)
    for name, (ref, target, check) in ROWS.items():
        # a fresh process per row: the previous rows' heap (pyoptflow's, above all) would make
        # glibc return pages to the system and later calls page-fault, skewing whichever row follows
        out = subprocess.run([sys.executable, __file__, "--row", name, "--repeats", str(args.repeats),
                              "--size", str(args.size), "--cpu", str(cpu)],
                             capture_output=True, text=True, check=True)
        ours_ms, ref_ms = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append((name, ours_ms, ref, ref_ms, target, None if check is None else check(ours_ms[0], ref_ms[0])))

    # endpoint errors: ours beside the reference on the same pairs
    pairs = {"synthetic": (f0, f1, None, None)}
    for name in ("RubberWhale", "Yosemite"):
        loaded = load_external(name)
        if loaded is not None:
            pairs[name] = loaded

    def epe(method: Callable, pair: tuple) -> float:
        a, b, gt, known = pair
        flow = method(a, b)[0]
        if gt is None:
            return synthetic_epe(flow)
        return float(np.hypot(*(flow - gt)[known].T).mean())

    methods = {
        "lucas_kanade levels 4 x 3": lambda a, b: lucas_kanade(a, b, **C2F_LK),
        "skimage ilk": ilk,
        "horn_schunck levels 4": lambda a, b: horn_schunck(a, b, **C2F_HS),
        "cv2 DIS medium": dis,
        "tv_l1": tv_l1,
        "skimage tvl1": tvl1,
    }
    errors = {m: {p: epe(fn, pair) for p, pair in pairs.items()} for m, fn in methods.items()}
    lk_no_worse = all(errors["lucas_kanade levels 4 x 3"][p] <= errors["skimage ilk"][p] for p in pairs)

    print(f"{args.size}x{args.size}, 1 thread on CPU {cpu}, median of {args.repeats} interleaved runs, "
          f"one process per row; "
          f"numba compile (first calls, cache may hit) {compile_ms:.0f} ms")
    print(f"load average before {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}, "
          f"after {os.getloadavg()[0]:.2f} (2 cores: above ~1 the timings are inflated)")
    print("median ms (best of the runs in brackets); ratio = reference / ours, of the medians")
    print(f"{'method':28s} {'ms':>16s}  {'reference':16s} {'ref ms':>18s} {'ratio':>7s}  {'target':12s} met")
    for name, (ms, best), ref, (ref_ms, ref_best), target, met in rows:
        met_s = "" if met is None else ("yes" if met else "NO")
        print(f"{name:28s} {ms:7.1f} ({best:6.1f})  {ref:16s} {ref_ms:8.1f} ({ref_best:7.1f}) {ref_ms / ms:7.1f}  "
              f"{target:12s} {met_s}")
    print()
    print(f"mean endpoint error, px (synthetic: exact shift {TRUTH_PX} px)")
    print(f"{'method':28s}" + "".join(f" {p:>12s}" for p in pairs))
    for m, per_pair in errors.items():
        print(f"{m:28s}" + "".join(f" {per_pair[p]:12.4f}" for p in pairs))
    print(f"lucas_kanade levels 4 x 3 EPE <= ilk on every pair: {'yes' if lk_no_worse else 'NO'}")
    tv_no_worse = all(errors["tv_l1"][p] <= errors["skimage tvl1"][p] for p in pairs)
    print(f"tv_l1 EPE <= skimage tvl1 on every pair: {'yes' if tv_no_worse else 'NO'}")


if __name__ == "__main__":
    main()
