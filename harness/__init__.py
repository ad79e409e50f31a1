"""aerobench harness: suites, the runner and executors, metrics, results, gate, the CLI.

The driving API is importable from here lazily (``from harness import run_suite``),
so that importing ``harness.results`` (as reports do) does not import the runner.
"""

from __future__ import annotations

_LAZY = {
    "run_suite": "harness.runner",
    "RunResult": "harness.runner",
    "RunFolderError": "harness.runner",
    "load_suite": "harness.suites",
    "parse_suite": "harness.suites",
    "expand": "harness.suites",
    "SuiteError": "harness.suites",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'harness' has no attribute {name!r}")
