"""``write_report``: ``report.html`` and ``report.md`` of a run folder, from one numbers model.

:func:`reports.model.build_model` computes every number once;
:func:`reports.html.render_html` and :func:`reports.markdown.render_markdown`
render it. The report reads only the run folder (through :mod:`harness.run_folder`,
:mod:`harness.results` and :mod:`harness.cell_artifacts`) and the sequence folders
run.json names. The output is deterministic: the same run folder gives the same bytes.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from reports.html import render_html
from reports.markdown import render_markdown
from reports.model import build_model
from scenes.formats import atomic_write_bytes

__all__ = ["write_report", "build_report"]


def build_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None,
                 rules: str | os.PathLike | None = None) -> tuple[str, str]:
    """The HTML and Markdown text of the report of ``run_dir`` (see :func:`write_report`)."""
    model = build_model(run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules)
    return render_html(model), render_markdown(model)


def write_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None, rules: str | os.PathLike | None = None,
                 out_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` for the run folder ``run_dir``.

    Parameters
    ----------
    run_dir : path
        A run folder (run.json, results.parquet, cells/).
    baseline : path, optional
        A baseline of ``aerobench baseline``; compared with the gate's rules (:func:`harness.gate.compare`).
    gate_verdict : path or dict, optional
        A verdict of ``aerobench gate --json``, shown at the top.
    rules : path, optional
        Gate rules YAML for the baseline comparison (default: the gate's ``gate_rules.yaml``).
    out_dir : path, optional
        Where to write; default ``run_dir``.

    Returns
    -------
    dict
        ``{"html": Path, "md": Path}``.
    """
    html_text, md_text = build_report(run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules)
    out = Path(out_dir) if out_dir is not None else Path(run_dir)
    paths = {"html": out / "report.html", "md": out / "report.md"}
    atomic_write_bytes(paths["html"], html_text.encode("utf-8"))
    atomic_write_bytes(paths["md"], md_text.encode("utf-8"))
    return paths
