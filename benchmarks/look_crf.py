"""Which x264 CRF gives `realistic` the bit rate of real drone video: bits per pixel, PSNR and fine detail kept.

    PYOPENGL_PLATFORM=egl python benchmarks/look_crf.py [--frames 16] [--crf 14 16 18 20 23]

Renders the first frames of ``realistic`` without compression (every other sensor effect on: its
noise is much of what the encoder spends bits on), then codes them as the scene generator does
(``scenes.sensor.Compressor``: x264 veryfast, zero latency, no B-frames, one key frame a second)
at each CRF. Prints bits per pixel, Mbit/s at the preset's size and rate, PSNR, and "fine detail
kept": the standard deviation of the gray frame minus its 1 px Gaussian blur, decoded over
original (what a waxy look loses). A drone's own recording spends about 0.4-0.6 bit/px
(4K at 30 fps and 100-130 Mbit/s; 1080p at 30 fps and 40-60 Mbit/s is more).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scenes.generate import SceneGenerator  # noqa: E402
from scenes.sensor import Compressor  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402


class _Counting:
    """The encoder, counting the bytes of the packets it gives."""

    def __init__(self, enc):
        self.enc, self.nbytes = enc, 0

    def encode(self, frame):
        packets = list(self.enc.encode(frame))
        self.nbytes += sum(p.size for p in packets)
        return packets


def fine_detail(rgb: np.ndarray) -> float:
    g = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)
    return float((g - cv2.GaussianBlur(g, (0, 0), 1.0)).std())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=16)
    ap.add_argument("--crf", type=int, nargs="+", default=[14, 16, 18, 20, 23])
    args = ap.parse_args()
    spec = load_scene_spec("realistic", {"image.n_frames": args.frames, "sensor.compression.codec": "none"})
    img, comp = spec.image, spec.sensor.compression
    t = time.perf_counter()
    frames = [f.rgb for f in SceneGenerator(spec).frames()]
    print(f"rendered {len(frames)} frames in {time.perf_counter() - t:.1f} s")
    base = np.mean([fine_detail(f) for f in frames])
    for crf in args.crf:
        # the generator's own coder, with its packets counted
        c = Compressor("h264", width_px=img.width_px, height_px=img.height_px, fps=img.fps, h264_crf=crf,
                       h264_gop=comp.h264_gop)
        c._enc = _Counting(c._enc)
        outs = [c(f) for f in frames]
        nbytes = c._enc.nbytes
        bpp = nbytes * 8 / (img.width_px * img.height_px * len(frames))
        print(f"crf {crf}: {bpp:.3f} bit/px, {bpp * img.width_px * img.height_px * img.fps / 1e6:.2f} Mbit/s "
              f"at {img.width_px}x{img.height_px}x{img.fps:g}, PSNR "
              f"{np.mean([cv2.PSNR(a, b) for a, b in zip(frames, outs)]):.1f} dB, fine detail kept "
              f"{np.mean([fine_detail(o) for o in outs]) / base:.2f}")


if __name__ == "__main__":
    main()
