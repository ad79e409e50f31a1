"""Our own encoders of the sequence files: frame PNGs (filter + Huffman-only deflate) and the flow kernels."""

from __future__ import annotations

import zlib
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
import pytest

from scenes import _codec_kernels as K
from scenes.formats import _byte_planes, decode_flow_npz, encode_flow_npz, encode_png, encode_png_fast


def _decode(data: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert img is not None, "cv2 (libpng + zlib) cannot read the file"
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB) if img.ndim == 3 else img


def _images(rng):
    yield "noise", rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)  # incompressible: stored blocks
    yield "constant", np.full((20, 30, 3), 7, np.uint8)  # one literal after the first row
    yield "skewed", np.minimum(rng.geometric(0.45, (64, 64, 3)), 255).astype(np.uint8)  # deep Huffman tree
    yield "gradient", (np.arange(90 * 70 * 3) % 256).astype(np.uint8).reshape(90, 70, 3)
    yield "one pixel", np.array([[[1, 2, 3]]], np.uint8)
    yield "gray", rng.integers(0, 4, (33, 17), dtype=np.uint8)
    yield "gray pixel", np.array([[200]], np.uint8)


@pytest.mark.parametrize("block", [1, 100, 32768, 65535])
def test_fast_png_gives_back_every_pixel_through_libpng(block):
    rng = np.random.default_rng(3)
    for name, img in _images(rng):
        got = _decode(encode_png_fast(img, block=block))
        assert got.dtype == np.uint8 and np.array_equal(got, img), f"{name}, block {block}"


def test_fast_png_is_a_plain_png_with_one_zlib_stream_of_average_filtered_rows():
    img = np.random.default_rng(1).integers(0, 256, (12, 9, 3), dtype=np.uint8)
    data = encode_png_fast(img, block=50)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR" and data.endswith(b"IEND\xaeB`\x82")
    n = int.from_bytes(data[33:37], "big")
    assert data[37:41] == b"IDAT"
    assert zlib.crc32(data[37:41 + n]) == int.from_bytes(data[41 + n:45 + n], "big")
    rows = np.frombuffer(zlib.decompress(data[41:41 + n]), np.uint8).reshape(12, 1 + 9 * 3)
    assert (rows[:, 0] == 3).all()  # filter type 3, Average, on every row
    # Filt(x) = Orig(x) - floor((Orig(a) + Orig(b)) / 2) mod 256 (PNG spec 9.3)
    a = img.reshape(12, -1).astype(np.int32)
    left = np.zeros_like(a)
    left[:, 3:] = a[:, :-3]
    up = np.zeros_like(a)
    up[1:] = a[:-1]
    assert np.array_equal(rows[:, 1:], ((a - (left + up) // 2) % 256).astype(np.uint8))


def test_fast_png_has_the_pixels_and_about_the_size_of_zlibs_huffman_only_png():
    # a textured image like a frame: smooth shading plus a little noise
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:240, 0:320]
    base = 128 + 60 * np.sin(x / 9.0)[..., None] * np.cos(y / 13.0)[..., None] * np.array([1.0, 0.8, 0.6])
    img = np.clip(base + rng.normal(0, 6, (240, 320, 3)), 0, 255).astype(np.uint8)
    ours = encode_png_fast(img)
    theirs = encode_png(img, compression=1, strategy="huffman", filters="avg")
    assert np.array_equal(_decode(ours), _decode(theirs))
    assert 0.97 < len(ours) / len(theirs) < 1.03
    assert len(ours) < img.nbytes  # Huffman coding gained something on it


def test_code_lengths_are_limited_complete_and_follow_the_counts():
    fib = [1, 1]
    while len(fib) < 40:
        fib.append(fib[-1] + fib[-2])
    freq = np.zeros(257, np.int64)
    freq[:40] = fib  # unlimited, Huffman would give this 39 levels
    for max_bits in (15, 7):
        lengths = K._code_lengths(freq, max_bits)
        used = lengths[lengths > 0]
        assert used.max() <= max_bits and used.size == 40
        assert np.sum(2.0 ** -used) == 1.0  # Kraft: complete, as inflate wants
    one = np.zeros(19, np.int64)
    one[5] = 9
    lengths = K._code_lengths(one, 7)
    assert lengths[5] == 1 and np.count_nonzero(lengths) == 2  # a second symbol completes the code


def test_fast_png_rejects_what_it_cannot_write():
    with pytest.raises(ValueError, match="expected uint8, got uint16"):
        encode_png_fast(np.zeros((4, 4), np.uint16))
    with pytest.raises(ValueError, match=r"expected \(H, W\) or \(H, W, 3\), got \(4, 4, 4\)"):
        encode_png_fast(np.zeros((4, 4, 4), np.uint8))
    with pytest.raises(ValueError, match="block: expected 1..65535"):
        encode_png_fast(np.zeros((4, 4), np.uint8), block=70000)
    with pytest.raises(ValueError, match="at least 1x1"):
        encode_png_fast(np.zeros((0, 4, 3), np.uint8))


def test_encoders_give_the_same_bytes_from_several_threads():
    rng = np.random.default_rng(5)
    imgs = [np.minimum(rng.geometric(0.1, (48, 64, 3)), 255).astype(np.uint8) for _ in range(6)]
    flows = [rng.normal(0, 3, (48, 64, 2)).astype(np.float32) for _ in range(6)]
    alone = [(encode_png_fast(i), encode_flow_npz(f, f)) for i, f in zip(imgs, flows)]
    with ThreadPoolExecutor(3) as pool:
        threaded = list(pool.map(lambda a: (encode_png_fast(a[0]), encode_flow_npz(a[1], a[1])), zip(imgs, flows)))
    assert threaded == alone


def test_flow_kernels_equal_the_numpy_chain_they_replace():
    rng = np.random.default_rng(11)
    fc = rng.normal(0, 5, (31, 47, 2)).astype(np.float32)
    fc[3, 4, 0], fc[5, 6, 1], fc[7, 0, 0] = np.nan, -np.inf, -0.0
    f = fc.copy()
    f[10:14, 20:25] += 1.5
    f[0, 0, 1] = np.nan
    bits_c, bits = fc.view(np.uint32), f.view(np.uint32)
    # before: copy, subtract (wrapping modulo 2**32), byte planes by a transpose; XOR, nonzero
    delta = bits_c.copy()
    np.subtract(bits_c[:, 1:], bits_c[:, :-1], out=delta[:, 1:])
    planes = np.empty((4, 2, 31, 47), np.uint8)
    K.flow_rowdelta_planes(bits_c, planes)
    assert np.array_equal(planes, _byte_planes(delta))
    xor = (bits ^ bits_c).ravel()
    index, got = K.flow_xor(bits.reshape(-1), bits_c.reshape(-1))
    assert np.array_equal(index, np.flatnonzero(xor)) and np.array_equal(got, xor[np.flatnonzero(xor)])
    back, back_c = decode_flow_npz(encode_flow_npz(f, fc))
    assert np.array_equal(back.view(np.uint32), bits) and np.array_equal(back_c.view(np.uint32), bits_c)
