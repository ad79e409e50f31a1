"""aerobench reports: a self-contained HTML report and a Markdown summary of a run folder.

``write_report(run_dir, *, baseline=None, gate_result=None, out_dir=None)`` writes
``report.html`` and ``report.md`` and returns their paths.
"""

from reports.report import build_report, write_report

__all__ = ["write_report", "build_report"]
