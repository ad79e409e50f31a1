"""The HTML / Markdown report of a run folder: sections, numbers from totals, offline, deterministic."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from reports import write_report
from reports.html import SCENE_SECTIONS

SECTIONS = ["verdict", "lk-vs-hs", "provenance", "headline", "per-scene", "regions", "all-metrics", "difficulty",
            "pictures", "stabilisation", "tracking", "failed"]


def section(html_text: str, sid: str) -> str:
    start = html_text.index(f'<section id="{sid}">')
    return html_text[start:html_text.index("</section>", start)]


def pooled_table(run_dir: Path) -> pd.DataFrame:
    """The fixture's rows read straight from parquet, independently of reports and harness."""
    df = pd.read_parquet(run_dir / "results.parquet")
    return df[df["status"] == "ok"]


@pytest.fixture(scope="module")
def report(fixture_report) -> dict[str, Path]:
    return fixture_report


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
    # frame (total) or valid mask (local), five EPE maps, a colour bar and the no-truth swatch
    assert section(html_text, "pictures").count("<img") == 2 * 2 * ((1 + 5 + 1) + (1 + 5 + 1 + 1))
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
    # track_completeness: three pipelines share the top value (4 of 5 vehicle-frames): a tie, no mark
    tc = ok[ok["metric"] == "track_completeness"].groupby("pipeline")[["sum", "count"]].sum()
    values = 100 * tc["sum"] / tc["count"]
    assert (values == values.max()).sum() == 3
    for pipe in tc.index:
        row = re.search(rf'<th scope="row">{pipe}</th>(.*?)</tr>', section(html_text, "all-metrics")).group(1)
        assert "best" not in re.findall(r'<td class="([^"]*)"', row)[6], pipe


def test_the_best_mark_follows_the_direction_and_skips_ties():
    from reports.tables import Column, best_pipelines

    values = {("a", "m"): 90.0, ("b", "m"): 95.0, ("c", "m"): 80.0}
    assert best_pipelines(values, Column("M", "m", "%", True), ["a", "b", "c"]) == {"b"}
    assert best_pipelines(values, Column("M", "m", "%", False), ["a", "b", "c"]) == {"c"}
    # two pipelines sharing a stage (e.g. the thesis' global motion) tie exactly: no star for either
    tied = {("a", "j"): 0.0, ("b", "j"): 0.0, ("c", "j"): 0.2}
    assert best_pipelines(tied, Column("J", "j", "px", False), ["a", "b", "c"]) == set()


def test_failed_cell_listed_and_escaped(html_text, report):
    failed = section(html_text, "failed")
    assert "rural-noise_sigma=10-s0-hs_thesis" in failed
    assert "Horn-Schunck iteration diverged at pair 2 (&lt;alpha&gt; too small)" in failed
    assert "<alpha>" not in html_text
    assert "rural-noise_sigma=10-s0-hs_thesis" in report["md"].read_text()


def test_no_network_resources(report, html_text):
    assert "http://" not in html_text and "https://" not in html_text
    assert "@import" not in html_text
    assert re.findall(r"url\((?!#)", html_text) == []  # only in-document references (SVG clip paths)
    srcs = re.findall(r'\bsrc="([^"]*)"', html_text)
    folder = report["html"].parent / "report_files"
    for src in srcs:  # pictures: files of the report's folder, by relative path, loaded when scrolled near
        assert re.fullmatch(r"report_files/[0-9a-f]{16}\.(png|webp|svg)", src), src[:40]
        assert (report["html"].parent / src).is_file(), src
    assert html_text.count('loading="lazy"') == len(re.findall(r"<img\b", html_text)) == len(srcs)
    assert sorted(p.name for p in folder.iterdir()) == sorted({s.removeprefix("report_files/") for s in srcs}), \
        "every file is referenced, every reference has its file"
    for href in re.findall(r'\bhref="([^"]*)"', html_text):  # section links, images inside inline SVG
        assert href.startswith(("#", "data:image/png;base64,")), href[:40]
    for svg in folder.glob("*.svg"):  # a figure shown by <img> cannot load another file: all inside it
        text = svg.read_text()
        assert re.findall(r'xlink:href="(?!#|data:image/(png|webp);base64,)', text) == [], svg.name
        assert "@import" not in text and re.findall(r"url\((?!#)", text) == []


def _files(report: dict[str, Path]) -> dict[str, bytes]:
    """The report's picture files by name."""
    return {p.name: p.read_bytes() for p in sorted((report["html"].parent / "report_files").iterdir())}


def test_a_run_without_real_footage_has_neither_real_section(run_dir, html_text):
    """The fixture run is synthetic only (tests/reports/test_real_sections.py has the run with footage)."""
    from reports.model import build_model

    model = build_model(run_dir)
    assert model.real_scenes == [] and model.synthetic_vs_real is None
    assert 'id="real-footage"' not in html_text and 'id="synthetic-vs-real"' not in html_text


def test_a_second_write_by_worker_processes_gives_the_same_bytes(run_dir, report, html_text, tmp_path):
    stale = tmp_path / "report_files" / "0123456789abcdef.png"  # a picture of an earlier report of the folder
    stale.parent.mkdir()
    stale.write_bytes(b"old")
    # two scenes x three scene sections: the blocks are drawn by two spawned processes, in their own order
    again = write_report(run_dir, out_dir=tmp_path, workers=2)
    assert not stale.exists(), "a file the new report does not reference is removed"
    assert again["html"].read_bytes() == report["html"].read_bytes()
    assert again["md"].read_bytes() == report["md"].read_bytes()
    assert _files(again) == _files(report) and len(_files(report)) > 10  # the pictures too
    for sid in ("pictures", "stabilisation", "tracking"):  # both scenes in each, in the run's order
        body = section(html_text, sid)
        assert body.index("<h3>urban") < body.index("<h3>rural")


def test_scene_block_rejects_an_unknown_section(run_dir):
    from reports.html import cell_index, scene_block
    from reports.load import load_run

    data = load_run(run_dir)
    with pytest.raises(ValueError, match="section: expected one of tracking, pictures, stabilisation, real-footage, got 'maps'"):
        scene_block(data, cell_index(data), "maps", "urban")


def _epe(ok: pd.DataFrame, pipeline: str, scene: str | None = None) -> float:
    rows = ok[(ok["metric"] == "epe_mean") & (ok["region"] == "all") & (ok["motion"] == "total")
              & (ok["pipeline"] == pipeline)]
    if scene is not None:
        rows = rows[rows["scene"] == scene]
    return rows["sum"].sum() / rows["count"].sum()


@pytest.fixture(scope="module")
def degraded(run_dir, tmp_path_factory):
    """The fixture run with dis made worse on purpose (every epe total x 1.5), its baseline the original."""
    from harness import gate
    from harness.results import read_results, read_run_json, write_table

    out = tmp_path_factory.mktemp("degraded")
    base = gate.write_baseline(gate.make_baseline(read_results(run_dir), read_run_json(run_dir)), out / "base.json")
    bad = out / "run"
    shutil.copytree(run_dir, bad)
    df = read_results(bad)
    hit = (df["pipeline"] == "dis") & df["metric"].str.startswith("epe")
    df.loc[hit, "sum"] *= 1.5
    df.loc[hit, "value"] *= 1.5
    write_table(df, bad / "results.parquet")
    verdict = gate.write_verdict(gate.compare(bad, gate.read_baseline(base), gate.load_rules(gate.DEFAULT_RULES)),
                                 out / "verdict.json")
    return bad, base, verdict


def test_a_degraded_method_is_marked_worse_by_the_gate_rules(degraded, tmp_path):
    bad, base, _ = degraded
    out = write_report(bad, baseline=base, out_dir=tmp_path)
    verdict = section(out["html"].read_text(), "verdict")
    rows = re.findall(r"<tr><td[^>]*>([^<]*)</td><th scope=\"row\">([^<]*)</th><td[^>]*>([^<]*)</td>.*?"
                      r"<td[^>]*>(worse|better)</td><td[^>]*>([^<]*)</td></tr>", verdict)
    assert rows, "the changed entries are listed"
    assert {r[1] for r in rows} == {"dis"} and {r[3] for r in rows} == {"worse"}
    assert any(r[2] == "epe_mean [all, total]" and r[4] == "abs 0.01" for r in rows)
    assert "entries within tolerance" in verdict
    md = out["md"].read_text()
    assert "## Against the baseline" in md and "| dis | epe_mean [all, total] |" in md and "| better |" not in md


def test_the_gate_verdict_comes_first(degraded, tmp_path):
    bad, _, verdict_path = degraded
    out = write_report(bad, gate_verdict=verdict_path, out_dir=tmp_path)
    text = out["html"].read_text()
    assert text.index('<section id="verdict">') < text.index('<section id="lk-vs-hs">') < text.index(
        '<section id="provenance">')
    head = section(text, "verdict")
    assert "Gate: FAILED" in head and "dis: epe_mean [all, total]: rose by" in head
    assert out["md"].read_text().split("\n## ")[1].startswith("Gate: FAILED")


def test_without_a_gate_verdict_the_report_says_how_to_get_one(html_text):
    assert "aerobench gate RUN --baseline B --json V" in section(html_text, "verdict")


def test_gate_view_of_a_verdict(degraded):
    from harness.gate import read_verdict
    from reports.tables import gate_view

    _, _, path = degraded
    v = gate_view(path)
    assert v == gate_view(read_verdict(path))
    assert v["passed"] is False and v["counts"]["failed"] == len(v["failures"]) > 0
    # the degraded method's errors, and the fixture's failed cell (a failed cell always fails the gate)
    assert all(f.startswith(("urban", "rural")) and (" / dis: epe" in f or " / hs_thesis: cell_failed" in f)
               for f in v["failures"])
    assert sum("cell_failed" in f for f in v["failures"]) == 1


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


@pytest.fixture(scope="module")
def drawn_here(run_dir):
    """The fixture run's data and every scene block drawn in this process (``_draw_blocks`` without a pool)."""
    from reports.load import load_run
    from reports.report import _draw_blocks

    data = load_run(run_dir)
    return data, _draw_blocks(data, None, False, lambda: "numbers")


def test_a_figure_process_that_dies_costs_no_figure(drawn_here, capsys):
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    from reports.report import _draw_blocks

    data, alone = drawn_here
    # a pool whose process exits as it starts: every block it was given is lost with it
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=os._exit,
                             initargs=(3,)) as pool:
        drawn = _draw_blocks(data, pool, False, lambda: "numbers")
    assert drawn == alone and len(drawn[1]) == 2 * len(SCENE_SECTIONS)  # 2 scenes x every section, each drawn here instead
    assert "a report figure process died" in capsys.readouterr().err


def _early(run_dir, pool, cells=None):
    """Blocks handed out before the report is built, as ``aerobench run`` does when its cells are done."""
    from harness.results import cell_table, read_results
    from reports.report import start_figures

    return start_figures(run_dir, cell_table(read_results(run_dir)) if cells is None else cells, pool)


def test_figures_handed_out_before_the_report_give_the_same_bytes(run_dir, report, tmp_path):
    from harness.results import cell_table, read_results
    from reports.html import cell_index
    from reports.load import load_run
    from reports.report import figure_pool

    with figure_pool(run_dir, 2) as pool:
        early = _early(run_dir, pool)
        assert len(early.futures) == 2 * len(SCENE_SECTIONS)  # 2 scenes x every section
        table = read_results(run_dir)  # the table in hand, as the runner has it
        data = load_run(run_dir, table=table)
        assert early.fit(data, cell_index(data))  # the report uses them (does not draw them again)
        drawn = write_report(run_dir, out_dir=tmp_path / "early", table=table, figures=early)
        # blocks drawn for other cells (one cell fewer) are not used: the report draws its own
        other = _early(run_dir, pool, cell_table(table).iloc[1:].reset_index(drop=True))
        assert not other.fit(data, cell_index(data))
        again = write_report(run_dir, out_dir=tmp_path / "other", figures=other)
    for got in (drawn, again):
        assert got["html"].read_bytes() == report["html"].read_bytes()
        assert got["md"].read_bytes() == report["md"].read_bytes()


def test_a_figure_process_that_dies_before_the_report_costs_no_figure(run_dir, report, tmp_path, capsys):
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    # a pool whose process exits as it starts: every block handed out early is lost with it
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=os._exit,
                             initargs=(3,)) as pool:
        early = _early(run_dir, pool)
        drawn = write_report(run_dir, out_dir=tmp_path, figures=early)
    assert drawn["html"].read_bytes() == report["html"].read_bytes()
    assert "a report figure process died" in capsys.readouterr().err


def test_the_page_as_bytes_is_the_page_encoded_even_when_a_table_spans_two_blocks(run_dir, drawn_here):
    from reports.html import render_html, render_html_bytes
    from reports.model import build_model

    data, (_, blocks) = drawn_here
    model = build_model(run_dir, data=data)
    page = render_html(model, blocks)
    assert render_html_bytes(model, blocks) == page.encode("utf-8")
    assert "\u2193" in page and 'data-cards="1"' in page  # not ASCII; tables marked for the narrow layout
    # a table opened in one block and closed in the next is marked as a whole, as on the joined page
    first, second = list(blocks)[:2]
    split = {key: b.html for key, b in blocks.items()}  # blocks as plain HTML are rendered as well
    split[first] += '<table><thead><tr><th>speed</th></tr></thead><tbody><tr><td>'
    split[second] = "7</td></tr></tbody></table>" + split[second]
    page = render_html(model, split)
    assert render_html_bytes(model, split) == page.encode("utf-8")
    assert '<td data-label="speed">7</td>' in page
