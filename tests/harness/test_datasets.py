"""External flow data sets: the real files load with the right shapes and masks, KITTI and Sintel layouts
round trip, bad files are refused, and a zero-flow method scores the mean true magnitude."""

from __future__ import annotations

import numpy as np
import pytest

from harness import datasets as D
from scenes.formats import FormatError, write_flo, write_png
from tests.external_data import EXTERNAL, needs_external


def zero_flow(frame0, frame1):
    """The trivial method: no motion anywhere, every pixel valid."""
    h, w = frame0.shape[:2]
    return np.zeros((h, w, 2), np.float32), np.ones((h, w), bool)


@needs_external
def test_external_pairs_load_with_shapes_and_masks():
    pairs = {p.name: p for p in D.read_middlebury(EXTERNAL)}
    assert set(pairs) == {"middlebury/RubberWhale", "yosemite/yosemite", "synthetic_vision_tp/mysine",
                          "synthetic_vision_tp/square"}
    rw = pairs["middlebury/RubberWhale"]
    assert rw.frame0.shape == (388, 584, 3) and rw.flow.shape == (388, 584, 2)
    assert 0.01 < (~rw.valid).mean() < 0.02          # about 1.6 % unknown (SOURCES.md)
    assert np.isnan(rw.flow[~rw.valid]).all() and np.isfinite(rw.flow[rw.valid]).all()
    yos = pairs["yosemite/yosemite"]
    assert yos.frame0.shape == (252, 316) and yos.flow.shape == (252, 316, 2)
    assert not yos.valid[:57].any()                   # the black sky rows are masked
    placeholder = (yos.flow[..., 0] == 1) & (yos.flow[..., 1] == 0)
    assert not (yos.valid & placeholder).any() and yos.valid[150:].all()
    sq = pairs["synthetic_vision_tp/square"]
    assert sq.valid.all() and sq.flow.shape == (100, 100, 2)


@needs_external
def test_zero_flow_scores_the_mean_true_magnitude():
    df = D.evaluate_flow_dataset(EXTERNAL / "yosemite", format="middlebury", method=zero_flow)
    (pair,) = D.read_middlebury(EXTERNAL / "yosemite")
    epe = df[df["metric"] == "epe_mean"]
    expected = np.hypot(pair.flow[pair.valid][:, 0].astype(np.float64), pair.flow[pair.valid][:, 1]).mean()
    assert epe["value"].item() == pytest.approx(expected, rel=1e-9)
    assert epe["count"].item() == pair.valid.sum()
    assert set(df["region"]) == {"all"} and df["pipeline"].unique().tolist() == ["zero_flow"]
    assert df[df["metric"] == "coverage"]["value"].item() == 100.0


def _kitti_root(tmp_path, rng):
    root = tmp_path / "kitti"
    flows = []
    for i in range(2):
        h, w = 6, 9
        flow = np.round(rng.uniform(-20, 20, size=(h, w, 2)) * 64) / 64
        valid = rng.random((h, w)) > 0.3
        D.write_kitti_flow(root / "flow_occ" / f"{i:06d}_10.png", flow, valid)
        for k in (10, 11):
            write_png(root / "image_2" / f"{i:06d}_{k}.png", rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
        flows.append((flow, valid))
    return root, flows


def test_kitti_fixture_round_trip(tmp_path):
    root, flows = _kitti_root(tmp_path, np.random.default_rng(0))
    pairs = D.read_kitti(root)
    assert [p.name for p in pairs] == ["000000", "000001"]
    for p, (flow, valid) in zip(pairs, flows):
        np.testing.assert_array_equal(p.valid, valid)
        np.testing.assert_array_equal(p.flow[valid], flow[valid].astype(np.float32))
        assert np.isnan(p.flow[~valid]).all() and p.frame0.shape == (6, 9, 3)
    df = D.evaluate_flow_dataset(root, format="kitti", method=zero_flow)
    assert df[df["metric"] == "epe_mean"]["count"].tolist() == [v.sum() for _, v in flows]



def test_a_pooled_p95_above_100_px_is_the_true_one_not_the_overflow_bin(tmp_path):
    # issue 23: eval-flow printed epe_p95 100.0000 on KITTI where the true p95 was 182.3 px
    from harness.metrics import aggregate

    root = tmp_path / "kitti"
    rng = np.random.default_rng(3)
    true = []
    for i in range(2):
        flow = np.round(rng.uniform(60, 260, size=(6, 9, 2)) * 64) / 64
        valid = rng.random((6, 9)) > 0.2
        D.write_kitti_flow(root / "flow_occ" / f"{i:06d}_10.png", flow, valid)
        for k in (10, 11):
            write_png(root / "image_2" / f"{i:06d}_{k}.png", rng.integers(0, 255, (6, 9, 3), dtype=np.uint8))
        f32 = flow[valid].astype(np.float32).astype(np.float64)
        true.append(np.hypot(f32[:, 0], f32[:, 1]))
    pooled = np.sort(np.concatenate(true))
    table = D.evaluate_flow_dataset(root, format="kitti", method=zero_flow)
    summary = aggregate(table, by=["pipeline"]).set_index("metric")["value"]
    for metric, q in (("epe_p95", 0.95), ("epe_median", 0.5)):
        expected = pooled[int(np.ceil(q * pooled.size)) - 1]
        assert expected > 100.0
        assert summary[metric] == pytest.approx(expected, abs=0.005), metric


def test_kitti_decoding_follows_the_devkit(tmp_path):
    img = np.zeros((2, 2, 3), np.uint16)
    img[..., 0] = 2 ** 15 + 64 * 3    # u = 3 px
    img[..., 1] = 2 ** 15 - 32        # v = -0.5 px
    img[0, 0, 2] = 1
    write_png(tmp_path / "f.png", img)
    flow, valid = D.read_kitti_flow(tmp_path / "f.png")
    assert valid.tolist() == [[True, False], [False, False]]
    assert flow[0, 0].tolist() == [3.0, -0.5]


def test_kitti_rejects_an_8_bit_flow_png(tmp_path):
    write_png(tmp_path / "f.png", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(FormatError, match="must be a 16-bit RGB PNG.*expected a rgb16 PNG, got rgb8"):
        D.read_kitti_flow(tmp_path / "f.png")


def test_sintel_layout(tmp_path):
    rng = np.random.default_rng(1)
    for n in (1, 2, 3):
        write_png(tmp_path / "clean" / "alley" / f"frame_{n:04d}.png", rng.integers(0, 255, (5, 7, 3), np.uint8))
    flow = rng.normal(size=(5, 7, 2)).astype(np.float32)
    for n in (1, 2):
        write_flo(tmp_path / "flow" / "alley" / f"frame_{n:04d}.flo", flow)
    invalid = np.zeros((5, 7), np.uint8)
    invalid[0, 0] = 255
    write_png(tmp_path / "invalid" / "alley" / "frame_0001.png", invalid)
    pairs = D.read_sintel(tmp_path)
    assert [p.name for p in pairs] == ["alley/frame_0001", "alley/frame_0002"]
    assert pairs[0].valid.sum() == 34 and pairs[1].valid.all()
    np.testing.assert_array_equal(pairs[1].flow, flow)
    with pytest.raises(FormatError, match="not a Sintel layout"):
        D.read_sintel(tmp_path, pass_="final")


def test_unknown_format_and_empty_folders_are_refused(tmp_path):
    with pytest.raises(KeyError, match="unknown data set format 'vkitti'; valid: middlebury, sintel, kitti"):
        list(D.iter_pairs(tmp_path, format="vkitti"))
    with pytest.raises(FormatError, match="no Middlebury-style pair"):
        D.read_middlebury(tmp_path)
    with pytest.raises(FormatError, match="not a KITTI layout"):
        D.read_kitti(tmp_path)
