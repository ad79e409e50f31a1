"""Synthetic vs real: rank correlations against scipy, known agreements and reversals, gaps, verdicts."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from harness.results import rows_to_frame
from reports.synthetic_vs_real import comparable_views, compare, kendall_tau_b, spearman, unit_totals, verdict

PIPES = ["p1", "p2", "p3", "p4", "p5"]


def test_rank_correlations_have_their_textbook_values():
    # d = ranks differ by 1 on four items: rho = 1 - 6 * 4 / (5 * 24) = 0.8; 8 concordant, 2 discordant pairs
    x, y = [1, 2, 3, 4, 5], [2, 1, 4, 3, 5]
    assert spearman(x, y) == pytest.approx(0.8, abs=1e-12)
    assert kendall_tau_b(x, y) == pytest.approx(0.6, abs=1e-12)
    assert spearman(x, x[::-1]) == pytest.approx(-1.0, abs=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_rank_correlations_equal_scipys_with_ties(seed):
    rng = np.random.default_rng(seed)
    a = rng.integers(0, 4, size=7).astype(float)  # few values: ties on both sides
    b = rng.integers(0, 4, size=7).astype(float)
    if len(set(a)) == 1 or len(set(b)) == 1:
        a[0], b[0] = 9.0, 9.0
    assert spearman(a, b) == pytest.approx(stats.spearmanr(a, b).statistic, abs=1e-12)
    assert kendall_tau_b(a, b) == pytest.approx(stats.kendalltau(a, b).statistic, abs=1e-12)


def test_the_bootstraps_row_by_row_correlations_are_scipys_and_nan_where_undefined():
    from reports.synthetic_vs_real import _kendall_rows, _spearman_rows

    rng = np.random.default_rng(11)
    a = rng.integers(0, 4, size=(300, 6)).astype(float)  # ties, and some constant rows
    b = rng.integers(0, 4, size=(300, 6)).astype(float)
    b[:20] = rng.random((20, 6))  # no ties
    a[5, 2], b[7, 0] = np.nan, np.inf  # a resample without a value: undefined
    a[9] = 2.0  # a constant side: undefined
    rho, tau = _spearman_rows(a, b), _kendall_rows(a, b)
    for k in range(len(a)):
        defined = np.isfinite(a[k]).all() and np.isfinite(b[k]).all() and len(set(a[k])) > 1 and len(set(b[k])) > 1
        if not defined:
            assert np.isnan(rho[k]) and np.isnan(tau[k]), k
            continue
        assert rho[k] == pytest.approx(stats.spearmanr(a[k], b[k]).statistic, abs=1e-12), k
        assert tau[k] == pytest.approx(stats.kendalltau(a[k], b[k]).statistic, abs=1e-12), k
        assert rho[k] == spearman(a[k], b[k]) and tau[k] == kendall_tau_b(a[k], b[k])  # one formula
    assert np.isnan(rho[[5, 7, 9]]).all()


def test_rank_correlations_refuse_mismatched_vectors_and_say_nan_below_three_items():
    with pytest.raises(ValueError, match=r"spearman: expected two 1-D vectors of one length, got \(3,\) and \(2,\)"):
        spearman([1, 2, 3], [1, 2])
    assert np.isnan(kendall_tau_b([1, 2], [2, 1]))


def _rows(scene: str, pipe: str, mota: float, epe: float, *, n_frames: int, rng) -> list[dict]:
    """One sequence of a pipeline: per-frame epe_mean rows and one mota row (errors / objects)."""
    rows = []
    for f in range(n_frames):
        e = epe + 0.02 * rng.standard_normal()
        rows.append(dict(cell_id=f"{scene}-{pipe}", scene=scene, seed=1, pipeline=pipe, frame=f, metric="epe_mean",
                         region="all", motion="total", kind="accuracy", value=e, sum=e * 1000, count=1000.0,
                         unit="px", higher_is_better=False))
        rows.append(dict(cell_id=f"{scene}-{pipe}", scene=scene, seed=1, pipeline=pipe, frame=f, metric="epe_p95",
                         region="all", motion="total", kind="accuracy", value=e, sum=float("nan"), count=1000.0,
                         unit="px", higher_is_better=False))
    objects = 200.0
    rows.append(dict(cell_id=f"{scene}-{pipe}", scene=scene, seed=1, pipeline=pipe, frame=None, metric="mota",
                     region="multi", motion="track", kind="accuracy", value=mota, sum=(1 - mota) * objects,
                     count=objects, unit="ratio", higher_is_better=True))
    return rows


def _table(real_mota, real_epe, *, seed=3) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    syn_mota = [0.9, 0.8, 0.7, 0.6, 0.5]
    syn_epe = [0.2, 0.4, 0.6, 0.8, 1.0]
    rows = []
    for scene in ("nominal", "city"):
        for p, m, e in zip(PIPES, syn_mota, syn_epe):
            rows += _rows(scene, p, m, e, n_frames=8, rng=rng)
    for p, m, e in zip(PIPES, real_mota, real_epe):
        rows += _rows("clip", p, m, e, n_frames=8, rng=rng)
    return rows_to_frame(rows)


def test_views_are_accuracy_metrics_that_pool_from_totals_not_quantiles():
    views = comparable_views(_table([0.5] * 5, [1.0] * 5))
    assert views == [("epe_mean", "all", "total"), ("mota", "multi", "track")]


def test_a_real_ranking_equal_to_the_synthetic_one_agrees_and_the_harder_clip_is_named():
    # real: same order, every pipeline worse (lower MOTA, higher EPE)
    res = compare(_table([0.6, 0.5, 0.4, 0.3, 0.2], [0.5, 1.0, 1.5, 2.0, 2.5]), ["clip"], pipelines=PIPES)
    assert res.real_scenes == ["clip"] and res.synthetic_scenes == ["nominal", "city"]
    by = {v.label: v for v in res.views}
    assert set(by) == {"epe_mean", "mota (multi)"}
    for v in by.values():
        assert v.spearman == pytest.approx(1.0) and v.kendall == pytest.approx(1.0)
        assert v.spearman_ci[0] > 0.5
        np.testing.assert_array_equal(v.rank_synthetic, [1, 2, 3, 4, 5])
        assert v.gap()["real_worse"].all()
    m = by["mota (multi)"]
    np.testing.assert_allclose(m.synthetic, [0.9, 0.8, 0.7, 0.6, 0.5], atol=1e-12)  # pooled from sums / counts
    np.testing.assert_allclose(m.real, [0.6, 0.5, 0.4, 0.3, 0.2], atol=1e-12)
    assert m.n_units_synthetic == 2 and m.n_units_real == 1  # one unit per sequence for per-sequence rows
    assert by["epe_mean"].n_units_synthetic == 16 and by["epe_mean"].n_units_real == 8
    text = verdict(res)
    assert text.startswith("The synthetic ranking carries over to the real footage on 2 of 2 metrics")
    assert "harder on 2 of 2 metrics" in text


def test_a_reversed_real_ranking_is_called_reversed_and_easier_real_footage_is_not_called_harder():
    res = compare(_table([0.95, 0.96, 0.97, 0.98, 0.99], [0.15, 0.12, 0.1, 0.08, 0.05]), ["clip"], pipelines=PIPES)
    epe = next(v for v in res.views if v.metric == "epe_mean")
    assert epe.spearman == pytest.approx(-1.0) and epe.spearman_ci[1] < 0
    np.testing.assert_array_equal(epe.rank_real, [5, 4, 3, 2, 1])
    text = verdict(res)
    assert "does not clearly carry over" in text or "reversed" in text
    assert "not harder than the synthetic scenes on any metric" in text


def test_the_bootstrap_is_seeded_and_its_interval_holds_the_estimate():
    t = _table([0.6, 0.62, 0.4, 0.45, 0.2], [0.5, 0.55, 1.5, 1.4, 2.5])
    a, b = compare(t, ["clip"], seed=5), compare(t, ["clip"], seed=5)
    for va, vb in zip(a.views, b.views):
        assert va.spearman_ci == vb.spearman_ci and va.kendall_ci == vb.kendall_ci
    epe = next(v for v in a.views if v.metric == "epe_mean")
    assert epe.spearman_ci[0] <= epe.spearman <= epe.spearman_ci[1]


def test_unit_totals_pool_per_unit_and_leave_missing_pipelines_empty():
    t = _table([0.6] * 5, [1.0] * 5)
    sel = t[(t["metric"] == "epe_mean") & (t["scene"] == "clip") & (t["pipeline"] != "p3")]
    sums, counts = unit_totals(sel, PIPES)
    assert sums.shape == (8, 5)
    assert (counts[:, 2] == 0).all() and (counts[:, [0, 1, 3, 4]] == 1000).all()


def test_without_real_scenes_or_enough_pipelines_the_note_says_why():
    t = _table([0.5] * 5, [1.0] * 5)
    assert "no real sequence" in compare(t, []).note
    assert "at least 3 pipelines" in compare(t[t["pipeline"].isin(["p1", "p2"])], ["clip"]).note
    with pytest.raises(ValueError, match="n_boot: expected >= 100, got 10"):
        compare(t, ["clip"], n_boot=10)
