"""File formats: .flo and PNG round trips, and what a damaged file does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenes.formats import FormatError, read_flo, read_png, write_flo, write_png

EXTERNAL = Path(__file__).resolve().parents[2].parent / "shared" / "external"


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


@pytest.mark.skipif(not EXTERNAL.is_dir(), reason="shared/external not beside the checkout")
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
