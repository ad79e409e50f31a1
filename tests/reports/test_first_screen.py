"""The report's first screen (issue 23, item 12) and the trajectory rows of LK vs HS (issue 21)."""

from __future__ import annotations

import math
import re

import pytest

from reports import write_report
from reports.lkhs import Comparison


def section(html_text: str, sid: str) -> str:
    start = html_text.index(f'<section id="{sid}">')
    return html_text[start:html_text.index("</section>", start)]


def _text(fragment: str) -> str:
    return re.sub(r"<[^>]+>", "", fragment)


# fixture_report (conftest): the session's report of run_dir, the one test_report reads; not written again here


@pytest.fixture(scope="module")
def model(run_dir):
    from reports.model import build_model

    return build_model(run_dir)


def test_the_page_opens_with_a_one_line_verdict_then_lk_vs_hs(fixture_report, model):
    page = fixture_report["html"].read_text()
    body = page[page.index("<main>"):]
    head = body[:body.index("<nav>")]
    line = _text(re.search(r'<p class="summary">(.*?)</p>', head).group(1))
    c = model.lkhs[0].comparisons[0]
    assert (c.lk, c.hs, c.region, c.motion) == ("lk_thesis", "hs_thesis", "all", "total")
    # the fixture's LK has the lower error everywhere
    assert c.better == "LK"
    assert line.startswith(f"LK vs HS: LK better by {abs(c.diff):.3f} px EPE (95 % CI {c.lo:+.3f} to {c.hi:+.3f}; "
                           "lk_thesis vs hs_thesis, all pixels)"), line
    assert " \u00b7 best: dis (EPE " in line and line.endswith(" \u00b7 gate: not run")
    # no gate, no baseline: nothing about them and no grey prose before the LK vs HS table
    top = body[:body.index('<table class="lkhs"')]
    for text in ("No gate verdict", "No baseline", 'class="missing"', '<p class="note"'):
        assert text not in top, text
    assert body.index('<section id="lk-vs-hs">') < body.index('<section id="provenance">')
    assert body.index('<section id="failed">') < body.index('<section id="verdict">'), "the hint comes last"
    md = fixture_report["md"].read_text()
    assert md.split("\n")[2] == "**" + line.replace("|", "\\|") + "**"
    assert md.index("## LK vs HS") < md.index("## Gate")


def test_with_a_gate_verdict_the_line_says_it_and_the_verdict_comes_first(run_dir, tmp_path):
    from harness import gate
    from harness.results import read_results, read_run_json

    base = gate.write_baseline(gate.make_baseline(read_results(run_dir), read_run_json(run_dir)), tmp_path / "b.json")
    verdict = gate.compare(run_dir, gate.read_baseline(base), gate.load_rules(gate.DEFAULT_RULES))
    path = gate.write_verdict(verdict, tmp_path / "verdict.json")
    out = write_report(run_dir, gate_verdict=path, baseline=base, out_dir=tmp_path / "report")
    page = out["html"].read_text()
    line = _text(re.search(r'<p class="summary">(.*?)</p>', page).group(1))
    n = gate.read_verdict(path)["counts"]
    assert n["failed"] >= 1, "fixture: its failed cell fails the gate"
    assert line.endswith(f" \u00b7 gate: FAILED ({n['failed']} of {n['checked']} checks) \u00b7 baseline: 0 worse, "
                         "0 better"), line
    assert page.index('<section id="verdict">') < page.index('<section id="lk-vs-hs">')


def test_the_hint_keeps_each_command_whole(fixture_report):
    from reports.html import stylesheet

    hint = section(fixture_report["html"].read_text(), "verdict")
    assert "<code>aerobench gate RUN --baseline B --json V</code>" in hint
    assert "<code>aerobench report RUN --baseline B --gate V</code>" in hint
    rule = re.search(r"(?m)^code \{([^}]*)\}", stylesheet())
    assert rule and "white-space: nowrap" in rule.group(1), "an option never breaks at its hyphens"


def _cmp(diff, lo, hi, *, hib=False, n=5) -> Comparison:
    return Comparison(lk="a", hs="b", metric="mota" if hib else "epe_mean", unit="", region="all",
                      motion="track" if hib else "total", n_units=n, n_lk_lower=0, lk_value=1.0, hs_value=1.0,
                      diff=diff, lo=lo, hi=hi, higher_is_better=hib)


@pytest.mark.parametrize("c, cls", [
    (_cmp(-0.3, -0.4, -0.2), "lk-better"),            # LK's error lower
    (_cmp(+0.3, +0.2, +0.4), "hs-better"),            # HS's error lower
    (_cmp(+0.1, -0.1, +0.2), ""),                     # the interval contains 0
    (_cmp(+0.2, +0.1, +0.3, hib=True), "lk-better"),  # LK's MOTA higher
    (_cmp(-0.2, -0.3, -0.1, hib=True), "hs-better"),
])
def test_the_difference_is_shaded_by_the_better_side_never_as_best(c, cls):
    from reports.html import _diff_cells

    first = re.match(r'<td class="num( [a-z-]+)?">', _diff_cells(c))
    assert (first.group(1) or "").strip() == cls


def test_a_comparison_without_units_shows_na(fixture_report):
    from reports.html import _diff_cells

    assert _diff_cells(_cmp(math.nan, math.nan, math.nan, n=0)).count(">n/a<") == 3
    lkhs = section(fixture_report["html"].read_text(), "lk-vs-hs")
    assert " best" not in "".join(re.findall(r'<td class="[^"]*"', lkhs)), "green means best elsewhere"
    assert '<span class="swatch lk-better"></span> LK better' in lkhs and "HS better" in lkhs
    # the fixture has point-tracker rows (track_error, track_completeness) but no MOTA, IDF1 or HOTA
    rows = re.findall(r'<tr><th scope="row"[^>]*>(\w+)[^<]*</th><td[^>]*>point</td>(.*?)</tr>', lkhs)
    by_metric = {m: re.findall(r">([^<]*)</td>", cells) for m, cells in rows}
    assert set(by_metric) >= {"mota", "idf1", "hota", "track_error"}
    assert by_metric["mota"] == ["n/a"] * 5 and by_metric["hota"] == ["n/a"] * 5
    assert "n/a" not in by_metric["track_error"]


def test_lk_vs_hs_tracking_rows_of_a_real_run(tiny_run, tmp_path):
    from harness.results import read_table

    out = write_report(tiny_run, out_dir=tmp_path)
    lkhs = section(out["html"].read_text(), "lk-vs-hs")
    pair = lkhs[lkhs.index("<h3>lk-multi vs hs-multi</h3>"):]
    table = read_table(tiny_run / "results.parquet")
    for tracker in ("point", "multi"):
        row = re.search(rf'<tr><th scope="row"[^>]*>mota \u2191</th><td[^>]*>{tracker}</td>(.*?)</tr>', pair)
        assert row, tracker
        cells = re.findall(r">([^<]*)</td>", row.group(1))
        for k, pipe in ((0, "lk-multi"), (1, "hs-multi")):
            r = table[(table["pipeline"] == pipe) & (table["metric"] == "mota") & (table["region"] == tracker)]
            assert cells[k] == f"{1 - r['sum'].sum() / r['count'].sum():.4f}"[:len(cells[k])], (tracker, pipe)
        assert cells[4].endswith(" / 1"), "one sequence: tiny, seed 1"
    hota = re.search(r'<tr><th scope="row"[^>]*>hota \u2191</th><td[^>]*>multi</td>(.*?)</tr>', pair)
    if "hota" not in set(table["metric"]):
        assert re.findall(r">([^<]*)</td>", hota.group(1)) == ["n/a"] * 5
    # the thesis twins' trajectory rows are those of the trackers their pipelines run
    from harness.run_folder import read_run

    has_multi = (read_run(tiny_run).pipelines["thesis-lk"].get("tracking") or {}).get("multi") is not None
    thesis = lkhs[lkhs.index("<h3>thesis-lk vs thesis-hs</h3>"):lkhs.index("<h3>lk-multi vs hs-multi</h3>")]
    assert "<td data-label=\"Tracker\">point</td>" in thesis and (">multi</td>" in thesis) == has_multi
