"""File formats: .flo and PNG round trips, and what a damaged file does."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from scenes.formats import FormatError, read_flo, read_png, write_flo, write_png
from tests.external_data import EXTERNAL, needs_external


def test_flo_round_trip_keeps_values_and_unknowns(tmp_path):
    rng = np.random.default_rng(0)
    flow = rng.normal(size=(7, 9, 2)).astype(np.float32)
    flow[2, 3] = np.nan
    write_flo(tmp_path / "a.flo", flow)
    back = read_flo(tmp_path / "a.flo")
    assert back.shape == (7, 9, 2) and back.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(back), np.isnan(flow))
    np.testing.assert_array_equal(back[~np.isnan(back)], flow[~np.isnan(flow)])
    assert not list(tmp_path.glob("*.tmp")), "temporary file left behind"


def test_flo_layout_is_u_then_v_row_major(tmp_path):
    flow = np.zeros((2, 3, 2), np.float32)
    flow[0, 1] = (5.0, -7.0)
    write_flo(tmp_path / "b.flo", flow)
    raw = (tmp_path / "b.flo").read_bytes()
    values = np.frombuffer(raw, "<f4", offset=12)
    assert np.frombuffer(raw, "<i4", 2, 4).tolist() == [3, 2]  # width, height
    assert values[2:4].tolist() == [5.0, -7.0]


@needs_external
def test_middlebury_file_reads_with_its_unknown_pixels():
    flow = read_flo(EXTERNAL / "middlebury" / "RubberWhale" / "flow10.flo")
    assert flow.shape == (388, 584, 2)
    unknown = np.isnan(flow[..., 0]).mean()
    assert 0.01 < unknown < 0.02  # SOURCES.md: about 1.6 % unknown


def test_bad_flo_files_are_named_in_the_error(tmp_path):
    write_flo(tmp_path / "ok.flo", np.zeros((4, 4, 2), np.float32))
    raw = (tmp_path / "ok.flo").read_bytes()
    (tmp_path / "tag.flo").write_bytes(b"XXXX" + raw[4:])
    with pytest.raises(FormatError, match=r"tag.flo: not a .flo file: tag"):
        read_flo(tmp_path / "tag.flo")
    (tmp_path / "short.flo").write_bytes(raw[:-8])
    with pytest.raises(FormatError, match=r"short.flo: 132 bytes, expected 140 for a 4x4"):
        read_flo(tmp_path / "short.flo")
    with pytest.raises(ValueError, match=r"expected \(H, W, 2\)"):
        write_flo(tmp_path / "x.flo", np.zeros((4, 4)))


def test_png_round_trips_rgb8_and_gray16(tmp_path):
    rgb = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    ids = np.array([[0, 1], [65535, 7]], np.uint16)
    write_png(tmp_path / "rgb.png", rgb)
    write_png(tmp_path / "ids.png", ids)
    np.testing.assert_array_equal(read_png(tmp_path / "rgb.png", expect="rgb8"), rgb)
    np.testing.assert_array_equal(read_png(tmp_path / "ids.png", expect="gray16"), ids)
    with pytest.raises(FormatError, match="expected a gray16 PNG, got rgb8"):
        read_png(tmp_path / "rgb.png", expect="gray16")


def test_truncated_png_is_an_error_not_an_image(tmp_path):
    write_png(tmp_path / "f.png", np.full((32, 32, 3), 9, np.uint8))
    data = (tmp_path / "f.png").read_bytes()
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match="t.png: not a readable PNG"):
        read_png(tmp_path / "t.png")


def test_written_files_get_the_ordinary_mode_not_mkstemps_0600(tmp_path):
    import os
    import stat

    write_png(tmp_path / "m.png", np.zeros((4, 4), np.uint8))
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE((tmp_path / "m.png").stat().st_mode) == 0o666 & ~mask


def _bits(a):
    return np.ascontiguousarray(a, np.float32).view(np.uint32)


def _smooth_pair(h=48, w=64):
    """A homography-like camera flow and a total flow with one moving box on top, float32."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    den = 1.0 + 1e-4 * xs - 2e-4 * ys
    cam = np.stack([(3.25 + 0.01 * xs + 0.002 * ys) / den - xs * (1 - 1 / den),
                    (-1.5 + 0.004 * xs - 0.01 * ys) / den - ys * (1 - 1 / den)], -1).astype(np.float32)
    flow = cam.copy()
    flow[10:20, 30:44] += np.float32([2.5, -0.75])
    return flow, cam


def test_compact_flow_round_trip_is_bit_exact_with_nan_inf_and_negative_zero():
    from scenes.formats import decode_flow_npz, encode_flow_npz

    rng = np.random.default_rng(1)
    flow = rng.normal(scale=20, size=(9, 11, 2)).astype(np.float32)  # no smoothness to exploit
    cam = rng.normal(size=(9, 11, 2)).astype(np.float32)
    flow[2, 3] = np.nan
    cam[4, 5, 1] = np.inf
    cam[0, 0] = -0.0
    flow[8, 10] = cam[8, 10]
    back_flow, back_cam = decode_flow_npz(encode_flow_npz(flow, cam))
    assert back_flow.shape == (9, 11, 2) and back_flow.dtype == np.float32 and back_cam.dtype == np.float32
    np.testing.assert_array_equal(_bits(back_flow), _bits(flow))
    np.testing.assert_array_equal(_bits(back_cam), _bits(cam))


def test_compact_flow_is_deterministic_small_and_a_plain_npz(tmp_path):
    from scenes.formats import FLOW_NPZ_CODEC, encode_flo, encode_flow_npz, read_flow_npz

    flow, cam = _smooth_pair(120, 160)
    data = encode_flow_npz(flow, cam)
    assert encode_flow_npz(flow, cam) == data  # no timestamp or other noise in the zip
    # smooth fields: well under a quarter of the two .flo files they replace
    assert len(data) < 0.25 * (len(encode_flo(flow)) + len(encode_flo(cam)))
    (tmp_path / "f.npz").write_bytes(data)
    with np.load(tmp_path / "f.npz") as z:  # any numpy opens it
        assert sorted(z.files) == ["codec", "flow_camera_rowdelta_zstd", "flow_camera_shape", "flow_xor_bits",
                                   "flow_xor_index"]
        assert z["codec"].item() == FLOW_NPZ_CODEC
        assert z["flow_camera_shape"].tolist() == [120, 160]
        assert z["flow_xor_index"].size == 10 * 14 * 2  # the moving box's pixels, both components
    back_flow, back_cam = read_flow_npz(tmp_path / "f.npz")
    np.testing.assert_array_equal(_bits(back_flow), _bits(flow))
    np.testing.assert_array_equal(_bits(back_cam), _bits(cam))


def test_compact_flow_of_the_first_version_still_reads_bit_for_bit():
    # data/flow_npz_v1.npz was written by the version-1 encoder (commit 4a7bb3b) from these fields
    from scenes.formats import FLOW_NPZ_CODEC_V1, decode_flow_npz, encode_flow_npz, read_flow_npz

    flow, cam = _smooth_pair(24, 32)
    flow[1, 2] = np.nan
    cam[3, 4, 1] = np.inf
    cam[0, 0] = -0.0
    path = Path(__file__).parent / "data" / "flow_npz_v1.npz"
    with np.load(path) as z:
        assert z["codec"].item() == FLOW_NPZ_CODEC_V1
    back_flow, back_cam = read_flow_npz(path)
    np.testing.assert_array_equal(_bits(back_flow), _bits(flow))
    np.testing.assert_array_equal(_bits(back_cam), _bits(cam))
    # and the version-1 writer, kept for this, still writes those very bytes
    assert encode_flow_npz(flow, cam, codec=FLOW_NPZ_CODEC_V1) == path.read_bytes()
    back_flow, back_cam = decode_flow_npz(encode_flow_npz(flow, cam))
    np.testing.assert_array_equal(_bits(back_flow), _bits(flow))
    np.testing.assert_array_equal(_bits(back_cam), _bits(cam))


def test_compact_flow_with_a_damaged_zstd_frame_is_named_in_the_error(tmp_path):
    import io
    import zipfile

    from scenes.formats import encode_flow_npz, read_flow_npz

    flow, cam = _smooth_pair()
    members = {}
    with zipfile.ZipFile(io.BytesIO(encode_flow_npz(flow, cam))) as zf:
        for info in zf.infolist():
            members[info.filename] = zf.read(info)
    frame = np.load(io.BytesIO(members["flow_camera_rowdelta_zstd.npy"]))
    with zipfile.ZipFile(tmp_path / "bad.npz", "w") as zf:
        for name, data in members.items():
            if name == "flow_camera_rowdelta_zstd.npy":  # the frame without its last 8 bytes
                buf = io.BytesIO()
                np.save(buf, frame[:-8])
                data = buf.getvalue()
            zf.writestr(name, data)
    with pytest.raises(FormatError, match=r"bad.npz: not a readable compact flow file \(ZstdError"):
        read_flow_npz(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match=r"codec: expected one of aerobench-flow-npz-1, aerobench-flow-npz-2, "
                                         r"got 'lz4'"):
        encode_flow_npz(flow, cam, codec="lz4")


def test_bad_compact_flow_files_are_named_in_the_error(tmp_path):
    from scenes.formats import encode_flow_npz, read_flow_npz

    flow, cam = _smooth_pair()
    data = encode_flow_npz(flow, cam)
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match=r"cut.npz: not a readable compact flow file"):
        read_flow_npz(tmp_path / "cut.npz")
    np.savez(tmp_path / "other.npz", flow=flow)
    with pytest.raises(FormatError, match=r"other.npz: not a compact flow file: codec None"):
        read_flow_npz(tmp_path / "other.npz")
    with pytest.raises(ValueError, match=r"flow: expected shape \(48, 64, 2\) \(as flow_camera\), got \(48, 63, 2\)"):
        encode_flow_npz(flow[:, :63], cam)
    with pytest.raises(ValueError, match=r"flow_camera: expected \(H, W, 2\) float32, got \(48, 64, 2\) float64"):
        encode_flow_npz(flow, cam.astype(np.float64))


def test_png_strategy_changes_bytes_not_pixels():
    from scenes.formats import encode_png

    rng = np.random.default_rng(2)
    img = np.clip(rng.normal(120, 30, (40, 50, 3)), 0, 255).astype(np.uint8)
    rle = encode_png(img, compression=1, strategy="rle")
    assert rle != encode_png(img, compression=1)
    np.testing.assert_array_equal(cv2.cvtColor(cv2.imdecode(np.frombuffer(rle, np.uint8), cv2.IMREAD_UNCHANGED),
                                               cv2.COLOR_BGR2RGB), img)
    ids = np.zeros((40, 50), np.uint16)
    ids[10:20, 5:30] = 3
    for kw in ({"strategy": "rle", "filters": "none"}, {"filters": "none"}):
        data = encode_png(ids, compression=1, **kw)
        np.testing.assert_array_equal(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), ids)
    with pytest.raises(ValueError, match=r"strategy: expected one of default, rle, filtered, huffman, got 'lz4'"):
        encode_png(img, strategy="lz4")
    for filters in ("sub", "up", "avg", "paeth"):  # one row predictor for every row: other bytes, same pixels
        data = encode_png(img, compression=1, strategy="rle", filters=filters)
        assert data != rle
        np.testing.assert_array_equal(cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED),
                                                   cv2.COLOR_BGR2RGB), img)
    with pytest.raises(ValueError, match=r"filters: expected one of adaptive, none, sub, up, avg, paeth, got 'lzw'"):
        encode_png(img, filters="lzw")
