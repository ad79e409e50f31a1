"""aerobench reports: a self-contained HTML report and a Markdown summary of a run folder.

``write_report(run_dir, *, baseline=None, gate_verdict=None, rules=None, out_dir=None)`` writes
``report.html`` and ``report.md`` and returns their paths. Modules: ``model`` (every number,
computed once), ``lkhs`` (LK vs HS paired statistics), ``html`` and ``markdown`` (the writers),
``tables``, ``plots``, ``pictures``, ``load`` (reads through the harness readers), ``report.css``.
"""

from reports.report import build_report, write_report

__all__ = ["write_report", "build_report"]
