"""The HTML / Markdown report of a run folder: sections, numbers from totals, offline, deterministic."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from reports import write_report

SECTIONS = ["provenance", "verdict", "headline", "per-scene", "regions", "all-metrics", "difficulty",
            "pictures", "stabilisation", "tracking", "failed"]


def section(html_text: str, sid: str) -> str:
    start = html_text.index(f'<section id="{sid}">')
    return html_text[start:html_text.index("</section>", start)]


def pooled_table(run_dir: Path) -> pd.DataFrame:
    """The fixture's rows read straight from parquet, independently of reports and harness."""
    df = pd.read_parquet(run_dir / "results.parquet")
    return df[df["status"] == "ok"]


@pytest.fixture(scope="module")
def report(run_dir, tmp_path_factory) -> dict[str, Path]:
    return write_report(run_dir, out_dir=tmp_path_factory.mktemp("report"))


@pytest.fixture(scope="module")
def html_text(report) -> str:
    return report["html"].read_text(encoding="utf-8")


def test_every_section_present(report, html_text):
    for sid in SECTIONS:
        assert f'<section id="{sid}">' in html_text, sid
    md = report["md"].read_text(encoding="utf-8")
    for heading in ("## Headline", "## Per scene", "## Difficulty", "## Failed cells"):
        assert heading in md
    # pictures per scene, for total and local motion: truth, five methods, wheel; then
    # frame (total) or valid mask (local), five EPE maps and a colour bar
    assert section(html_text, "pictures").count("<img") == 2 * 2 * ((1 + 5 + 1) + (1 + 5 + 1))
    # difficulty curves for both swept parameters, stabilisation and tracking figures drawn
    assert "Against jitter_px" in html_text and "Against noise_sigma" in html_text
    assert section(html_text, "stabilisation").count("<svg") == 4
    assert "\u0394y [px]" in section(html_text, "tracking")


def test_headline_value_is_pooled_from_sums_and_counts(run_dir, html_text):
    ok = pooled_table(run_dir)
    rows = ok[(ok["metric"] == "epe_mean") & (ok["region"] == "all") & (ok["motion"] == "total")
              & (ok["pipeline"] == "lk_pyramid")]
    pooled = rows["sum"].sum() / rows["count"].sum()
    mean_of_means = rows["value"].mean()
    head = section(html_text, "headline")
    assert f"{pooled:.4f}" != f"{mean_of_means:.4f}", "fixture must tell pooling from averaging"
    assert f"{pooled:.4f}" in head
    assert f"{mean_of_means:.4f}" not in head
    # a rate metric: 100 * sum / count over every frame and cell of the pipeline
    out = ok[(ok["metric"] == "outlier_3px") & (ok["pipeline"] == "hs_thesis")]
    assert f"{100 * out['sum'].sum() / out['count'].sum():.3f}" in head


def test_best_value_marked_by_direction(run_dir, html_text):
    ok = pooled_table(run_dir)
    prim = ok[(ok["metric"] == "epe_mean") & (ok["region"] == "all") & (ok["motion"] == "total")]
    g = prim.groupby("pipeline")[["sum", "count"]].sum()
    best = (g["sum"] / g["count"]).idxmin()
    head = section(html_text, "headline")
    # endpoint error is the first metric column: lower is better
    assert f'<th scope="row">{best}</th><td class="num best"' in head
    assert head.count('<td class="num best"') >= 1
    for other in set(g.index) - {best}:
        assert f'<th scope="row">{other}</th><td class="num best"' not in head
    # track_completeness is higher-is-better: the largest pooled value carries the mark
    tc = ok[ok["metric"] == "track_completeness"].groupby("pipeline")[["sum", "count"]].sum()
    top = (100 * tc["sum"] / tc["count"]).idxmax()
    row = re.search(rf'<th scope="row">{top}</th>(.*?)</tr>', section(html_text, "all-metrics")).group(1)
    cells = re.findall(r'<td class="([^"]*)"', row)
    assert "best" in cells[6], "track_completeness (7th column) of the best pipeline is marked"


def test_failed_cell_listed_and_escaped(html_text, report):
    failed = section(html_text, "failed")
    assert "rural-noise_sigma=10-s0-hs_thesis" in failed
    assert "Horn-Schunck iteration diverged at pair 2 (&lt;alpha&gt; too small)" in failed
    assert "<alpha>" not in html_text
    assert "rural-noise_sigma=10-s0-hs_thesis" in report["md"].read_text()


def test_no_network_resources(html_text):
    assert "http://" not in html_text and "https://" not in html_text
    assert "@import" not in html_text
    assert re.findall(r"url\((?!#)", html_text) == []  # only in-document references (SVG clip paths)
    for src in re.findall(r'\bsrc="([^"]*)"', html_text):
        assert src.startswith("data:image/png;base64,"), src[:40]
    for href in re.findall(r'\bhref="([^"]*)"', html_text):  # section links, images inside SVG
        assert href.startswith(("#", "data:image/png;base64,")), href[:40]


def test_two_writes_are_byte_identical(run_dir, report, tmp_path):
    again = write_report(run_dir, out_dir=tmp_path)
    assert again["html"].read_bytes() == report["html"].read_bytes()
    assert again["md"].read_bytes() == report["md"].read_bytes()


@dataclasses.dataclass
class _Gate:
    passed: bool
    failures: list


def _epe(ok: pd.DataFrame, pipeline: str, scene: str | None = None) -> float:
    rows = ok[(ok["metric"] == "epe_mean") & (ok["region"] == "all") & (ok["motion"] == "total")
              & (ok["pipeline"] == pipeline)]
    if scene is not None:
        rows = rows[rows["scene"] == scene]
    return rows["sum"].sum() / rows["count"].sum()


def test_baseline_diff_and_gate_verdict(run_dir, tmp_path):
    """Plain (pipeline, metric) entries match the pooled value; entries keyed like
    harness.results.summarize (as harness.gate writes them) match per key."""
    ok = pooled_table(run_dir)
    dis, lk = _epe(ok, "dis"), _epe(ok, "lk_thesis", "urban[jitter_px=2]")
    keyed = {"pipeline": "lk_thesis", "scene": "urban[jitter_px=2]", "sweep_param": "jitter_px",
             "sweep_value": "2.0", "metric": "epe_mean", "region": "all", "motion": "total", "value": lk * 1.25}
    baseline = {"format": "aerobench-baseline/1", "metrics": [
        {"pipeline": "dis", "metric": "epe_mean", "value": dis / 2},
        keyed,
        dict(keyed, region="vehicles", value=0.0),    # compared and counted, not listed
        dict(keyed, metric="ae_mean", value=1e9),      # headline metric, but no such key: gone
    ]}
    out = write_report(run_dir, baseline=baseline, out_dir=tmp_path,
                       gate_result=_Gate(passed=False, failures=["dis epe_mean +100 % > 5 %"]))
    verdict = section(out["html"].read_text(), "verdict")
    assert "Gate: FAILED" in verdict and "dis epe_mean +100 % &gt; 5 %" in verdict
    assert f"{dis - dis / 2:+.4g} (+100.0 %)" in verdict          # worse: lower is better
    assert f"{lk - lk * 1.25:+.4g} (-20.0 %)" in verdict          # better
    assert verdict.index("+100.0 %") < verdict.index("-20.0 %"), "worse rows come first"
    assert "1 further baseline entries" in verdict and "1 of them are worse" in verdict
    md = out["md"].read_text()
    assert "## Gate: FAILED" in md and "| all scenes | dis | epe_mean |" in md


def test_gate_view_reads_mappings_and_objects():
    from reports.tables import gate_view

    assert gate_view(None) is None
    assert gate_view({"passed": True, "failures": []})["passed"] is True
    assert gate_view({"verdict": "fail"})["passed"] is False

    class Result:  # like harness.gate.GateResult: passed and failures are properties
        notes = ["machine differs from the baseline's"]

        @property
        def passed(self):
            return False

        @property
        def failures(self):
            return [{"metric": "epe_mean", "current": 2.0}]

    v = gate_view(Result())
    assert v["passed"] is False and v["messages"] == ["metric=epe_mean, current=2.0"]
    assert v["notes"] == ["machine differs from the baseline's"]


def test_missing_parts_are_stated_not_fatal(run_dir, tmp_path):
    bare = tmp_path / "run"
    bare.mkdir()
    df = pd.read_parquet(run_dir / "results.parquet")
    df["sweep_param"], df["sweep_value"] = "", ""
    from harness.results import write_table
    write_table(df, bare / "results.parquet")
    shutil.copy(run_dir / "run.json", bare / "run.json")  # its cache dir is elsewhere: no sequences
    text = write_report(bare)["html"].read_text()
    assert "No parameter was swept" in text
    assert "No cell saved estimated flow" in text
    assert "No stabilisation data" in text
    assert "No tracks" in text
    assert 'class="num best"' in section(text, "headline")  # the table itself still stands


def test_stabilisation_legend_names_the_after_row(html_text):
    """The bottom row (fig. 3.2) plots other quantities in the same colours: the legend says so."""
    stab = section(html_text, "stabilisation")
    assert "after: true cumulative + correction" in stab and "after: its refitted line" in stab
    assert "(red)" not in stab  # the flight line is drawn in vermillion/orange
