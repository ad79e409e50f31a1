"""reports.tables: the numbers of the report's tables, pooled per pipeline, best marked only when unique."""

from __future__ import annotations

import math

import pytest

from reports.load import load_run
from reports.tables import (Column, best_pipelines, format_value, gate_view, headline_columns, metric_table,
                            region_table, sweep_curves)
from tests.reports.conftest import FAILED, PIPELINES, QUALITY


@pytest.mark.parametrize("v, text", [(0.12345, "0.1235"), (-0.5, "-0.5000"), (1.23456, "1.235"),
                                     (99.9994, "99.999"), (123.456, "123.5"), (math.nan, "n/a"),
                                     (None, "n/a")])
def test_format_value_keeps_about_four_significant_digits(v, text):
    assert format_value(v) == text


def test_best_is_the_one_best_finite_value_and_nobody_on_a_tie():
    lower = Column("Endpoint error", "epe_mean", "px", False)
    higher = Column("Completeness", "track_completeness", "%", True)
    vals = {("a", "epe_mean"): 1.0, ("b", "epe_mean"): 0.5, ("c", "epe_mean"): math.nan,
            ("a", "track_completeness"): 80.0, ("b", "track_completeness"): 80.0}
    assert best_pipelines(vals, lower, ["a", "b", "c"]) == {"b"}
    assert best_pipelines(vals, higher, ["a", "b"]) == set()  # a shared value earns no mark
    assert best_pipelines(vals, lower, ["a", "c"]) == set()  # one finite value is no comparison


def test_the_headline_table_marks_the_best_pipeline_and_counts_failed_cells(run_dir):
    data = load_run(run_dir)
    cols = headline_columns(data)
    assert [c.label for c in cols] == ["Endpoint error", "Angular error", "Outlier rate", "Stabilisation residual",
                                       "Trajectory error", "Time per frame"]
    assert cols[0].unit == "px" and cols[0].arrow == "\u2193"
    table = metric_table(data, data.ok, cols)
    assert table.pipelines == PIPELINES
    assert table.best["epe_mean"] == {min(QUALITY, key=QUALITY.get)}  # the fixture's best quality factor
    # six scene variants per pipeline; one cell of FAILED's pipeline failed
    assert table.cells[FAILED[2]] == "5 / 6" and table.cells["dis"] == "6 / 6"
    assert all(table.counts[(p, "epe_mean")] > 0 for p in PIPELINES)


def test_region_table_puts_total_before_local_and_all_first(run_dir):
    data = load_run(run_dir)
    wide = region_table(data, "epe_mean")
    assert list(wide.index) == PIPELINES
    assert list(wide.columns) == ["all / total", "vehicles / total", "all / local"]
    assert region_table(data, "no_such_metric").empty


def test_sweep_curves_pool_each_swept_value(run_dir):
    curves = sweep_curves(load_run(run_dir))
    assert set(curves) == {"jitter_px", "noise_sigma"}
    epe = curves["jitter_px"][curves["jitter_px"]["metric"] == "epe_mean"]
    assert sorted(epe["sweep_value"].unique()) == [0.0, 2.0, 4.0]
    assert set(epe["pipeline"]) == set(PIPELINES)


def test_gate_view_lists_the_failed_checks_only():
    verdict = {"passed": False, "suite": "smoke", "counts": {"fail": 1, "pass": 1}, "notes": ["timings skipped"],
               "checks": [{"status": "fail", "scene": "tiny", "sweep_param": "", "sweep_value": "", "pipeline": "dis",
                           "metric": "epe_mean", "region": "all", "motion": "total", "reason": "+0.2 px > abs 0.01"},
                          {"status": "pass", "scene": "tiny", "pipeline": "dis", "metric": "ae_mean",
                           "region": "all", "motion": "total", "reason": ""}]}
    view = gate_view(verdict)
    assert view["passed"] is False and view["suite"] == "smoke" and view["notes"] == ["timings skipped"]
    assert view["failures"] == ["tiny / dis: epe_mean [all, total]: +0.2 px > abs 0.01"]
