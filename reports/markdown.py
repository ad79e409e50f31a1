"""report.md: the report's numbers as Markdown, rendered from a :class:`reports.model.ReportModel`.

The same numbers and verdicts as report.html (both writers read one model);
figures are in report.html only.
"""

from __future__ import annotations

import math

import numpy as np

from reports.lkhs import LEVEL, N_BOOT
from reports.model import LOCAL_VS_TOTAL, ReportModel
from reports.synthetic_vs_real import verdict as svr_verdict
from reports.tables import MetricTable, format_value

__all__ = ["render_markdown"]


def _md(x) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def _metric_table_md(t: MetricTable) -> str:
    if not t.pipelines:
        return "_No results for these metrics._\n"
    head = ["Pipeline"] + [f"{c.label} [{c.unit}] {c.arrow}" if c.unit else f"{c.label} {c.arrow}"
                           for c in t.columns] + ["Cells ok/total"]
    lines = ["| " + " | ".join(_md(h) for h in head) + " |", "|" + "---|" * len(head)]
    for p in t.pipelines:
        vals = []
        for c in t.columns:
            s = format_value(t.values.get((p, c.metric), math.nan))
            vals.append(f"**{s}**" if p in t.best.get(c.metric, set()) else s)
        lines.append("| " + " | ".join([_md(p), *vals, t.cells[p]]) + " |")
    return "\n".join(lines) + "\n"


def _gate_md(model: ReportModel) -> list[str]:
    gate = model.gate
    if gate is None:
        return ["## Gate", "", "_No gate verdict was given (`aerobench gate RUN --baseline B --json V`, then "
                "`aerobench report RUN --gate V`)._", ""]
    n = gate["counts"]
    word = "PASSED" if gate["passed"] else "FAILED"
    md = [f"## Gate: {word}", "", f"{n['checked']} checked, {n['passed']} passed, {n['failed']} failed, "
          f"{n['skipped']} skipped.", ""]
    md += [f"- {_md(m)}" for m in gate["failures"]]
    md += [f"_{_md(x)}_" for x in gate["notes"]] + [""]
    return md


def _baseline_md(model: ReportModel) -> list[str]:
    diffs = model.baseline
    if diffs is None:
        return []
    md = ["## Against the baseline", ""]
    if model.baseline_note:
        md += [f"_{_md(model.baseline_note)}_", ""]
    if len(diffs):
        md += ["| Where | Pipeline | Metric | Current | Baseline | Diff | Change | Gate rule |",
               "|---|---|---|---|---|---|---|---|"]
        for r in diffs.itertuples(index=False):
            d = "\u2013" if not np.isfinite(r.diff) else f"{r.diff:+.4g}" + (
                f" ({r.diff_pct:+.1f} %)" if np.isfinite(r.diff_pct) else "")
            md.append(f"| {_md(r.where)} | {_md(r.pipeline)} | {_md(r.metric)} [{r.region}, {r.motion}] | "
                      f"{format_value(r.current)} | {format_value(r.baseline)} | {d} | {r.change} | {_md(r.rule)} |")
        md.append("")
    return md


def _na(v: float) -> str:
    return format_value(v) if np.isfinite(v) else "n/a"


def _diff_md(c) -> list[str]:
    if c.n_units == 0 or not np.isfinite(c.diff):
        return ["n/a", "n/a", "n/a"]
    d = f"{c.diff:+.3f}"
    return [f"**{d}** ({c.better} better)" if c.better else d, f"{c.lo:+.3f} to {c.hi:+.3f}",
            f"{c.n_lk_better} / {c.n_units}"]


def _lkhs_md(model: ReportModel) -> list[str]:
    md = ["## LK vs HS", ""]
    if not model.lkhs:
        return md + [f"_{_md(model.lkhs_note)}_", ""]
    md += [f"Flow: paired by frame pair (same scene, seed and frame): difference LK \u2212 HS of the pooled "
           f"endpoint error with a {LEVEL:.0%} percentile-bootstrap interval over the frame pairs ({N_BOOT} "
           "resamples, seeded). Negative: LK has the lower error. Trajectories: paired by sequence (scene, seed), "
           "values pooled from the summed counts; n/a where a side has no such rows. An interval containing 0 is "
           "no clear difference; a bold difference names the better side.", ""]
    for pair in model.lkhs:
        md += [f"### {_md(pair.lk)} vs {_md(pair.hs)}", ""]
        unit = pair.comparisons[0].unit if pair.comparisons else "px"
        if pair.comparisons:
            md += [f"| Region | Motion | LK [{unit}] | HS [{unit}] | LK \u2212 HS | {LEVEL:.0%} CI | LK lower / pairs |",
                   "|---|---|---|---|---|---|---|"]
            for c in pair.comparisons:
                md.append("| " + " | ".join([c.region, c.motion, _na(c.lk_value), _na(c.hs_value), *_diff_md(c)])
                          + " |")
            md.append("")
        if pair.tracking:
            md += [f"| Metric | Tracker | LK | HS | LK \u2212 HS | {LEVEL:.0%} CI | LK better / sequences |",
                   "|---|---|---|---|---|---|---|"]
            for c in pair.tracking:
                unit_t = f" [{c.unit}]" if c.unit and c.unit != "ratio" else ""
                arrow = "\u2191" if c.higher_is_better else "\u2193"
                md.append("| " + " | ".join([f"{c.metric}{unit_t} {arrow}", c.region, _na(c.lk_value),
                                             _na(c.hs_value), *_diff_md(c)]) + " |")
            md.append("")
        md += [f"- {_md(c.sentence)}" for c in [*pair.comparisons, *pair.tracking]] + [""]
        per = pair.by_scene_seed
        if len(per):
            cols = [c for c in per.columns if c not in ("scene", "seed")]
            md += [f"LK \u2212 HS [{unit}] per scene and seed:", "",
                   "| Scene, seed | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
            md += [f"| {_md(r['scene'])}, seed {r['seed']} | "
                   + " | ".join(f"{r[c]:+.3f}" if np.isfinite(r[c]) else "\u2013" for c in cols) + " |"
                   for r in per.to_dict("records")]
            md.append("")
    md += [LOCAL_VS_TOTAL, ""]
    return md


def _regions_md(model: ReportModel) -> list[str]:
    md = ["## By region and motion", ""]
    for c in model.columns:
        wide = model.regions.get(c.metric)
        if wide is None:
            continue
        md += [f"{c.label} [{c.unit}] {c.arrow}:", "", "| Pipeline | " + " | ".join(map(_md, wide.columns)) + " |",
               "|---|" + "---|" * wide.shape[1]]
        md += [f"| {_md(p)} | " + " | ".join(format_value(float(v)) for v in row) + " |" for p, row in wide.iterrows()]
        md.append("")
    return md if len(md) > 2 else md + ["_The table has no region or motion breakdown._", ""]


def _ci(ci) -> str:
    return "n/a" if not all(map(math.isfinite, ci)) else f"[{ci[0]:+.2f}, {ci[1]:+.2f}]"


def _real_md(model: ReportModel) -> list[str]:
    """Real footage (each real scene's metrics) and Synthetic vs real (rank agreement, gaps, verdict)."""
    if not model.real_scenes:
        return []
    md = ["## Real footage", "", "n/a: the metric's ground truth is absent for that sequence (never scored as 0). "
          "Frames with the boxes and tracks: see report.html.", ""]
    for scene in model.real_scenes:
        md += [f"### {_md(scene)}", "", _metric_table_md(model.real_tables[scene])]
    md += ["## Synthetic vs real", ""]
    svr = model.synthetic_vs_real
    if svr is None or not svr.views:
        return md + [f"_{_md(svr.note if svr is not None else 'Nothing to compare.')}_", ""]
    md += [f"**{_md(svr_verdict(svr))}**", "",
           f"Synthetic: {_md(', '.join(svr.synthetic_scenes))}. Real: {_md(', '.join(svr.real_scenes))}. "
           "Rank 1 = best; intervals are 95 % bootstrap intervals over each side's units.", ""]
    pipes = svr.views[0].pipelines
    md += ["| Metric | Spearman | Kendall | " + " | ".join(_md(p) for p in pipes) + " |",
           "|" + "---|" * (3 + len(pipes))]
    for v in svr.views:
        ranks = " | ".join(f"{int(a)} / {int(b)}" for a, b in zip(v.rank_synthetic, v.rank_real))
        md.append(f"| {_md(v.label)} | {v.spearman:+.2f} {_ci(v.spearman_ci)} | {v.kendall:+.2f} "
                  f"{_ci(v.kendall_ci)} | {ranks} |")
    md += ["", "The gap, synthetic \u2192 real (* where real is worse):", "",
           "| Metric | " + " | ".join(_md(p) for p in pipes) + " |", "|" + "---|" * (1 + len(pipes))]
    for v in svr.views:
        g = v.gap()
        md.append(f"| {_md(v.label)} | " + " | ".join(
            f"{format_value(a)} \u2192 {format_value(b)}{' *' if w else ''}"
            for a, b, w in zip(g["synthetic"], g["real"], g["real_worse"])) + " |")
    return md + [""]


def render_markdown(model: ReportModel) -> str:
    """The Markdown report of ``model``."""
    data = model.data
    md = [f"# {_md(model.title)}", ""]
    if model.summary:
        md += ["**" + " \u00b7 ".join(_md(x) for x in model.summary) + "**", ""]
    quiet = model.gate is None and model.baseline is None  # nothing to judge: the hint goes to the end
    md += ([] if quiet else _gate_md(model) + _baseline_md(model)) + _lkhs_md(model) + _real_md(model)
    md += ["## What was run", ""] + [f"- **{_md(k)}**: {_md(v)}" for k, v in model.provenance] + [""]
    md += ["## Headline", "", "Pooled over every scene, sweep value and seed; best value in bold when one pipeline "
           "alone holds it; \u2193 lower is better, \u2191 higher is better. Flow errors over all pixels (the "
           "background dominates them; LK vs HS above splits them).", "", _metric_table_md(model.headline)]
    md += ["## Per scene", ""]
    for s, t in model.per_scene.items():
        md += [f"### {_md(s)}", "", _metric_table_md(t)]
    md += _regions_md(model)
    md += ["## All metrics", "", _metric_table_md(model.all_metrics)]
    if model.curves and model.columns:
        md += ["## Difficulty", ""]
        c = model.columns[0]
        for param, agg in model.curves.items():
            sub = agg[agg["metric"] == c.metric]
            if sub.empty:
                continue
            xs = sorted(sub["sweep_value"].dropna().unique())
            md += [f"{c.label} [{c.unit}] {c.arrow} against {_md(param)}:", "",
                   "| Pipeline | " + " | ".join(f"{x:g}" for x in xs) + " |", "|---|" + "---|" * len(xs)]
            for p in data.pipelines:
                vals = {float(r.sweep_value): r.value for r in sub[sub["pipeline"] == p].itertuples()}
                if vals:
                    md.append(f"| {_md(p)} | " + " | ".join(format_value(vals.get(x, math.nan)) for x in xs) + " |")
            md.append("")
    else:
        md += ["## Difficulty", "", "_No parameter was swept in this run._", ""]
    md += ["## Failed cells", ""]
    if data.failed.empty:
        md += ["No cell failed.", ""]
    else:
        md += [f"- `{_md(r.cell_id)}` ({_md(r.pipeline)}): {_md(r.error)}" for r in data.failed.itertuples()] + [""]
    if quiet:
        md += _gate_md(model)
    md += ["Figures (difficulty curves, flow pictures, stabilisation, tracking): see report.html.", ""]
    return "\n".join(md)
