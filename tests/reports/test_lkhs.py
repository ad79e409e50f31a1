"""LK vs HS: twins found by flow method, paired bootstrap intervals with known answers, verdict sentences."""

from __future__ import annotations

import copy
import re

import numpy as np
import pandas as pd
import pytest

from algorithms.pipeline import PIPELINES
from harness.results import rows_to_frame
from reports.lkhs import bootstrap_difference, compare_pair, pair_pipelines, paired_units

N_SCENES, N_SEEDS, N_FRAMES = 2, 3, 6


def _table(lk_minus_hs_px: float, *, noise_px: float = 0.05, seed: int = 7) -> pd.DataFrame:
    """Paired epe_mean rows: per frame pair HS = 1 px + scene/frame spread, LK = HS + the given shift + noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for scene in range(N_SCENES):
        for s in range(N_SEEDS):
            for f in range(N_FRAMES):
                n = 400 + 37 * f + 11 * s  # pixel counts differ per pair, equal on both sides
                hs = 1.0 + 0.5 * scene + 0.3 * rng.random()  # scenes differ much more than the methods
                lk = hs + lk_minus_hs_px + noise_px * rng.standard_normal()
                for pipe, epe in (("mine-a", lk), ("mine-b", hs)):
                    rows.append(dict(cell_id=f"{scene}-{s}-{pipe}", scene=f"scene{scene}", seed=s, pipeline=pipe,
                                     frame=f, metric="epe_mean", region="vehicles", motion="total",
                                     kind="accuracy", value=epe, sum=epe * n, count=float(n), unit="px",
                                     higher_is_better=False))
    return rows_to_frame(rows)


def test_twins_are_found_by_flow_method_not_by_name():
    specs = {"a": copy.deepcopy(PIPELINES["pyramidal-hs"]), "b": copy.deepcopy(PIPELINES["thesis-lk"]),
             "c": copy.deepcopy(PIPELINES["dis"]), "d": copy.deepcopy(PIPELINES["thesis-hs"]),
             "e": copy.deepcopy(PIPELINES["pyramidal-lk"])}
    assert pair_pipelines(specs) == [("b", "d"), ("e", "a")]
    # an LK pipeline whose other stages differ from every HS pipeline has no twin
    specs["b"]["global_motion"]["params"]["max_shift"] = 8
    assert pair_pipelines(specs) == [("e", "a")]


@pytest.mark.parametrize("shift_px, word", [(-0.2, "LK"), (0.2, "HS"), (0.0, None)])
def test_known_differences_give_the_right_interval_and_verdict(shift_px, word):
    (c,) = compare_pair(_table(shift_px), "mine-a", "mine-b", regions=("vehicles",), motions=("total",))
    assert c.n_units == N_SCENES * N_SEEDS * N_FRAMES
    assert c.diff == pytest.approx(shift_px, abs=0.03)
    assert c.lo <= c.diff <= c.hi
    if word is None:
        assert c.lo < 0 < c.hi
        assert "no clear difference between mine-a and mine-b" in c.sentence
        assert "contains 0" in c.sentence
    else:
        assert (c.hi < 0) if word == "LK" else (c.lo > 0)
        assert re.match(rf"vehicles pixels, total motion: {word} \(mine-[ab]\) is better, its error 0\.[12]\d\d px "
                        rf"lower", c.sentence), c.sentence
        assert c.n_lk_lower == (c.n_units if word == "LK" else 0)


def test_the_difference_is_of_pooled_per_pixel_means_and_the_interval_is_seeded():
    t = _table(0.1)
    u = paired_units(t, "mine-a", "mine-b", region="vehicles", motion="total")
    pooled = u["sum_lk"].sum() / u["count_lk"].sum() - u["sum_hs"].sum() / u["count_hs"].sum()
    d1 = bootstrap_difference(u["sum_lk"], u["count_lk"], u["sum_hs"], u["count_hs"], rng=np.random.default_rng(3))
    d2 = bootstrap_difference(u["sum_lk"], u["count_lk"], u["sum_hs"], u["count_hs"], rng=np.random.default_rng(3))
    assert d1 == d2 and d1[0] == pytest.approx(pooled)
    mean_of_means = (u["sum_lk"] / u["count_lk"] - u["sum_hs"] / u["count_hs"]).mean()
    assert abs(pooled - mean_of_means) > 1e-6, "the fixture's counts differ: pooling is not averaging"


def test_bad_input_is_refused_with_what_was_expected():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"expected four \(n,\) arrays of one length, got shapes"):
        bootstrap_difference(np.ones(3), np.ones(3), np.ones(2), np.ones(3), rng=rng)
    with pytest.raises(ValueError, match=r"level: expected a probability in \(0, 1\), got 95"):
        bootstrap_difference(np.ones(3), np.ones(3), np.ones(3), np.ones(3), rng=rng, level=95)
    assert all(np.isnan(bootstrap_difference([], [], [], [], rng=rng)))


def test_a_failed_cell_leaves_its_frames_unpaired():
    t = _table(0.1)
    t.loc[t["cell_id"] == "0-0-mine-b", "status"] = "failed"
    u = paired_units(t, "mine-a", "mine-b", region="vehicles", motion="total")
    assert len(u) == (N_SCENES * N_SEEDS - 1) * N_FRAMES


def test_the_difference_per_scene_and_seed_pools_that_scene_and_seed_only():
    from reports.lkhs import by_scene_seed

    t = _table(0.1)
    per = by_scene_seed(t, "mine-a", "mine-b", regions=("vehicles",), motions=("total",))
    assert len(per) == N_SCENES * N_SEEDS and list(per.columns) == ["scene", "seed", "vehicles / total"]
    rows = t[(t["scene"] == "scene1") & (t["seed"] == 2)]
    a, b = rows[rows["pipeline"] == "mine-a"], rows[rows["pipeline"] == "mine-b"]
    want = a["sum"].sum() / a["count"].sum() - b["sum"].sum() / b["count"].sum()
    got = per[(per["scene"] == "scene1") & (per["seed"] == 2)]["vehicles / total"].item()
    assert got == pytest.approx(want)


def _mot_table(*, hs_has_multi: bool = True, seed: int = 11) -> pd.DataFrame:
    """MOTA rows per sequence and tracker: LK's multi-target tracker makes about 10 % errors, HS's 30 %."""
    rng = np.random.default_rng(seed)
    rows = []
    for scene in range(N_SCENES):
        for s in range(N_SEEDS):
            objects = 80 + 40 * scene + 7 * s  # sequences differ in size: pooling is not averaging
            for pipe, rate in (("mine-a", 0.1), ("mine-b", 0.3)):
                if pipe == "mine-b" and not hs_has_multi:
                    continue
                errors = round(objects * (rate + 0.05 * rng.random()))
                rows.append(dict(cell_id=f"{scene}-{s}-{pipe}", scene=f"scene{scene}", seed=s, pipeline=pipe,
                                 frame=None, metric="mota", region="multi", motion="track", kind="accuracy",
                                 value=1 - errors / objects, sum=float(errors), count=float(objects), unit="ratio",
                                 higher_is_better=True))
    return rows_to_frame(rows)


def test_tracking_rows_pair_whole_sequences_and_pool_mota_from_summed_counts():
    from reports.lkhs import compare_tracking

    t = _mot_table()
    got = {(c.region, c.metric): c for c in compare_tracking(t, "mine-a", "mine-b")}
    assert set(got) == {("multi", m) for m in ("mota", "idf1", "hota", "track_error")}
    c = got[("multi", "mota")]
    a, b = t[t["pipeline"] == "mine-a"], t[t["pipeline"] == "mine-b"]
    pooled_a, pooled_b = 1 - a["sum"].sum() / a["count"].sum(), 1 - b["sum"].sum() / b["count"].sum()
    assert c.lk_value == pytest.approx(pooled_a) and c.hs_value == pytest.approx(pooled_b)
    assert abs(pooled_a - a["value"].mean()) > 1e-4, "the fixture's sequences differ in size"
    assert c.n_units == N_SCENES * N_SEEDS
    assert c.diff == pytest.approx(pooled_a - pooled_b) and 0 < c.lo <= c.diff <= c.hi
    assert c.higher_is_better and c.better == "LK" and c.n_lk_better == c.n_units
    assert re.match(r"mota, multi tracker: LK \(mine-a\) is better, its mota 0\.2\d\d higher than HS \(mine-b\) "
                    r"\(95 % CI \+0\.\d{3} to \+0\.\d{3}; LK better on 6 of 6 sequences\)\.", c.sentence), c.sentence
    # seeded: the same rows give the same interval
    again = {(x.region, x.metric): x for x in compare_tracking(t, "mine-a", "mine-b")}[("multi", "mota")]
    assert (again.lo, again.hi) == (c.lo, c.hi)
    # metrics the rows lack on both sides: no unit, no number, never a zero
    for m in ("idf1", "hota", "track_error"):
        assert got[("multi", m)].n_units == 0 and np.isnan(got[("multi", m)].lk_value)
        assert got[("multi", m)].sentence == f"{m}, multi tracker: n/a (mine-a and mine-b without it)."


def test_a_tracker_one_side_lacks_is_not_applicable_not_zero():
    from reports.lkhs import compare_tracking

    (c, *_) = compare_tracking(_mot_table(hs_has_multi=False), "mine-a", "mine-b", metrics=("mota",))
    assert (c.region, c.metric, c.n_units, c.better) == ("multi", "mota", 0, None)
    assert np.isfinite(c.lk_value) and np.isnan(c.hs_value) and np.isnan(c.diff)
    assert c.sentence == "mota, multi tracker: n/a (mine-b without it)."


def test_a_reduction_rule_turns_each_sides_totals_into_its_value():
    rng = np.random.default_rng(0)
    s_a, c_a, s_b, c_b = np.array([1.0, 3.0]), np.array([10.0, 10.0]), np.array([2.0, 2.0]), np.array([10.0, 10.0])
    d, _, _ = bootstrap_difference(s_a, c_a, s_b, c_b, rng=rng, reduce="complement")
    assert d == pytest.approx((1 - 4 / 20) - (1 - 4 / 20))
    d, _, _ = bootstrap_difference(s_a, c_a, s_b, c_b, rng=rng, reduce="rms")
    assert d == pytest.approx(np.sqrt(4 / 20) - np.sqrt(4 / 20))
    d, _, _ = bootstrap_difference(np.array([5.0]), np.array([10.0]), np.array([2.0]), np.array([10.0]), rng=rng,
                                   reduce="rate")
    assert d == pytest.approx(30.0)
    with pytest.raises(ValueError, match=r"reduce: expected one of mean, complement, rate, rms, got 'median'"):
        bootstrap_difference(s_a, c_a, s_b, c_b, rng=rng, reduce="median")
