"""The regression gate: pass, fail with numbers, errors that are never a pass, directions, timings, JUnit."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from harness import gate as G
from harness import metrics as M
from harness import results as R

META = {"suite": "ci", "config_hash": "cfg", "provenance": {"machine": "box-A", "git_commit": "abc"}}


def _results(epe=0.50, coverage=90.0, time_ms=10.0, machine="box-A", extra=False):
    rows = [
        {"metric": "epe_mean", "frame": 0, "region": "all", "motion": "total", "kind": "accuracy",
         "value": epe, "sum": epe * 100, "count": 100, "unit": "px", "higher_is_better": False},
        {"metric": "coverage", "frame": 0, "region": "all", "motion": "total", "kind": "accuracy",
         "value": coverage, "sum": coverage, "count": 100, "unit": "%", "higher_is_better": True},
        {"metric": "time_flow_ms", "frame": 0, "region": "all", "motion": "cost", "kind": "timing",
         "value": time_ms, "sum": time_ms, "count": 1, "unit": "ms", "higher_is_better": False},
    ]
    if extra:
        rows.append({**rows[0], "metric": "epe_rms"})
    return R.rows_to_frame(rows, cell_id="c", scene="tiny", pipeline="thesis-lk", machine=machine)


@pytest.fixture
def baseline():
    return G.make_baseline(_results(), META)


def test_identical_results_pass(baseline):
    r = G.compare(_results(), baseline, suite="ci")
    assert r.passed and r.exit_code == 0
    assert len(r.checks) == 3 and not r.skipped


def test_worse_accuracy_fails_with_its_numbers(baseline):
    r = G.compare(_results(epe=0.53), baseline, G.rules_from_mapping({"epe_mean": "abs 0.02"}), suite="ci")
    assert not r.passed and r.exit_code == 1
    (f,) = r.failures
    assert f.key["metric"] == "epe_mean" and f.baseline == pytest.approx(0.5) and f.current == pytest.approx(0.53)
    assert "rose by 0.03 px, allowed 0.02 px" in f.reason
    md = G.to_markdown(r)
    assert "FAIL" in md and "| 0.5 | 0.53 | +0.03 |" in md
    assert G.compare(_results(epe=0.515), baseline, G.rules_from_mapping({"epe_mean": "abs 0.02"})).passed


def test_improvements_never_fail(baseline):
    r = G.compare(_results(epe=0.1, coverage=99.0, time_ms=1.0), baseline, suite="ci")
    assert r.passed
    r = G.compare(_results(coverage=89.0), baseline, suite="ci")  # higher is better: a drop fails
    assert [c.key["metric"] for c in r.failures] == ["coverage"]
    assert "fell by 1" in r.failures[0].reason


def test_timings_relative_and_only_on_the_same_machine(baseline):
    slow = _results(time_ms=13.0)
    r = G.compare(slow, baseline, G.rules_from_mapping({"time_*": "rel 25%"}))
    assert [c.key["metric"] for c in r.failures] == ["time_flow_ms"]
    assert G.compare(_results(time_ms=12.0), baseline, G.rules_from_mapping({"time_*": "rel 25%"})).passed
    elsewhere = G.compare(_results(time_ms=100.0, machine="box-B"), baseline)
    assert elsewhere.passed
    assert [c.key["metric"] for c in elsewhere.skipped] == ["time_flow_ms"]
    assert any("timings skipped" in n and "box-B" in n for n in elsewhere.notes)


def test_missing_baseline_is_an_error_not_a_pass(tmp_path):
    with pytest.raises(G.GateError, match="no baseline file"):
        G.read_baseline(tmp_path / "none.json")
    (tmp_path / "x.json").write_text('{"metrics": []}')
    with pytest.raises(G.GateError, match="not an aerobench baseline"):
        G.read_baseline(tmp_path / "x.json")


def test_baseline_of_another_suite_is_an_error(baseline):
    with pytest.raises(G.GateError, match="baseline is for suite 'ci', the results are of suite 'nightly'"):
        G.compare(_results(), baseline, suite="nightly")


def test_metric_on_one_side_only_is_an_error(baseline):
    with pytest.raises(G.GateError, match="1 in the results but not in the baseline: .*epe_rms"):
        G.compare(_results(extra=True), baseline)
    fewer = _results()
    fewer = fewer[fewer["metric"] != "coverage"]
    with pytest.raises(G.GateError, match="1 in the baseline but not in the results: .*coverage"):
        G.compare(fewer, baseline)


def test_a_failed_cell_is_named_in_the_error(baseline):
    failed = R.rows_to_frame([{"metric": "cell_failed", "value": float("nan"), "sum": float("nan"), "count": 0}],
                             cell_id="c", scene="tiny", pipeline="thesis-lk", status="failed",
                             error="RuntimeError: boom")
    with pytest.raises(G.GateError, match="1 cell\\(s\\) failed: tiny/thesis-lk: RuntimeError: boom"):
        G.compare(failed, baseline)


def test_rules_are_parsed_statements(tmp_path):
    p = tmp_path / "rules.yaml"
    p.write_text("rules:\n  epe_mean: abs 0.02\n  'time_*': rel 10%\n  track_fde: 'off'\n")
    rules = G.load_rules(p)
    assert rules["epe_mean"] == G.Rule("abs", 0.02, "abs 0.02")
    assert rules["time_*"].mode == "rel" and rules["time_*"].tolerance == pytest.approx(0.10)
    assert rules["track_fde"].mode == "off"
    p.write_text("rules:\n  epe_maen: abs 0.02\n")
    with pytest.raises(G.GateError, match="rule 'epe_maen' names no metric"):
        G.load_rules(p)
    with pytest.raises(G.GateError, match="expected 'abs <number>'"):
        G.parse_rule("abs lots")
    with pytest.raises(G.GateError, match="a percentage is relative"):
        G.parse_rule("abs 5%")
    assert G.load_rules() == {}


def test_a_rule_off_skips_the_metric(baseline):
    r = G.compare(_results(epe=9.0), baseline, G.rules_from_mapping({"epe_*": "off"}))
    assert r.passed and [c.key["metric"] for c in r.skipped] == ["epe_mean"]


def test_junit_xml_parses_with_one_testcase_per_check(baseline):
    r = G.compare(_results(epe=0.9, machine="box-B"), baseline)
    root = ET.fromstring(G.to_junit_xml(r))
    assert root.tag == "testsuite" and root.get("tests") == "3" and root.get("failures") == "1"
    cases = root.findall("testcase")
    assert len(cases) == 3 and {c.get("classname") for c in cases} == {"tiny.thesis-lk"}
    failed = [c for c in cases if c.find("failure") is not None]
    assert len(failed) == 1 and "baseline 0.5 px, current 0.9 px" in failed[0].find("failure").text
    assert sum(c.find("skipped") is not None for c in cases) == 1


def test_run_folder_and_baseline_file_round_trip(tmp_path, baseline):
    run = tmp_path / "run"
    R.write_table(_results(), run / R.RESULTS_FILE)
    R.write_run_json(run, META)
    path = G.baseline_from_run(run, tmp_path / "base.json")
    assert G.read_baseline(path)["metrics"] == baseline["metrics"]
    assert G.compare(run, path).passed
    other = dict(META, suite="nightly")
    R.write_run_json(run, other)
    with pytest.raises(G.GateError, match="suite"):
        G.compare(run, path)
    with pytest.raises(TypeError, match="baseline_from_run"):
        G.make_baseline(_results(), tmp_path / "x.json")


def test_make_baseline_needs_a_suite_name():
    with pytest.raises(G.GateError, match="no suite name"):
        G.make_baseline(_results(), {"config_hash": "x"})
    from_summary = G.make_baseline(R.summarize(_results()), META)["metrics"]
    assert from_summary == G.make_baseline(_results(), META)["metrics"]


def _quantile_results(bin_index: int):
    """An epe_median row whose 100 pixels all fall in one 0.01 px bin (aggregate: the bin centre)."""
    row = {"metric": "epe_median", "frame": 0, "region": "all", "motion": "total", "kind": "accuracy",
           "value": (bin_index + 0.5) * 0.01, "sum": float("nan"), "count": 100, "unit": "px",
           "higher_is_better": False, "hist": M.encode_hist(np.bincount([bin_index], [100], minlength=M.HIST_NBINS))}
    return R.rows_to_frame([row], cell_id="c", scene="tiny", pipeline="thesis-lk", machine="box-A")


def test_a_move_of_exactly_the_tolerance_passes_despite_float_rounding():
    # bin centres 0.075 -> 0.085: one 0.01 px bin, 0.010000000000000009 in binary
    assert 0.085 - 0.075 > 0.01
    rules = G.rules_from_mapping({"epe_median": "abs 0.01"})
    base = G.make_baseline(_quantile_results(7), META)
    assert G.compare(_quantile_results(8), base, rules, suite="ci").passed
    r = G.compare(_quantile_results(9), base, rules, suite="ci")  # two bins: a regression
    assert [c.key["metric"] for c in r.failures] == ["epe_median"]


def test_a_failure_names_its_rule_once(baseline):
    r = G.compare(_results(epe=0.60), baseline, G.rules_from_mapping({"epe_mean": "abs 0.05"}), suite="ci")
    (f,) = r.failures
    assert "(abs 0.05)" in f.reason and "abs abs" not in f.reason
    assert "| abs 0.05 |" in G.to_markdown(r) and "abs abs" not in G.to_markdown(r)
    r = G.compare(_results(epe=0.60), baseline, G.rules_from_mapping({"epe_mean": "rel 10%"}), suite="ci")
    assert "(rel 10%)" in r.failures[0].reason
    assert "(abs 0.0001 (default))" in G.compare(_results(epe=0.60), baseline, suite="ci").failures[0].reason


def test_the_verdict_file_round_trips_and_marks_each_change(baseline, tmp_path):
    rules = G.rules_from_mapping({"epe_mean": "abs 0.02", "coverage": "abs 0.5"})
    # epe worse beyond its tolerance, coverage better beyond its tolerance, timing within
    r = G.compare(_results(epe=0.60, coverage=95.0, time_ms=10.5), baseline, rules, suite="ci")
    path = G.write_verdict(r, tmp_path / "verdict.json")
    v = G.read_verdict(path)
    assert v["format"] == G.VERDICT_FORMAT and v["passed"] is False and v["exit_code"] == 1
    assert v["counts"] == {"checked": 3, "passed": 2, "failed": 1, "skipped": 0}
    change = {c["metric"]: c["change"] for c in v["checks"]}
    assert change == {"epe_mean": "worse", "coverage": "better", "time_flow_ms": "within tolerance"}
    assert next(c for c in v["checks"] if c["metric"] == "epe_mean")["rule"] == "abs 0.02"
    (tmp_path / "other.json").write_text('{"format": "aerobench-baseline/1"}')
    with pytest.raises(G.GateError, match="not an aerobench gate verdict: format 'aerobench-baseline/1'"):
        G.read_verdict(tmp_path / "other.json")
    with pytest.raises(G.GateError, match="no gate verdict file"):
        G.read_verdict(tmp_path / "missing.json")
