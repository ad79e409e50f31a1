"""Fixtures of the reliability tests: one render cache per session, the CLI's environment."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


@pytest.fixture(scope="session")
def rel_cache(tmp_path_factory) -> Path:
    """A render cache shared by the reliability tests: each tiny scene is rendered once per session."""
    return tmp_path_factory.mktemp("reliability-cache")


@pytest.fixture(scope="session")
def rel_env(rel_cache) -> dict:
    """Environment of an ``aerobench`` subprocess: project and test plugin importable, the shared cache."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(HERE), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["AEROBENCH_CACHE"] = str(rel_cache)
    env["PYOPENGL_PLATFORM"] = "egl"
    env.pop("AEROBENCH_DEBUG", None)
    return env


@pytest.fixture(scope="session")
def reference_run(tmp_path_factory, rel_cache):
    """``rel_support.SUITE`` run uninterrupted on one worker: the numbers every other run must give."""
    from tests.reliability.rel_support import suite

    from harness.runner import run_suite
    from harness.suites import parse_suite

    out = tmp_path_factory.mktemp("reference") / "run"
    result = run_suite(parse_suite(suite()), out, workers=1, cache_dir=rel_cache, progress=False)
    assert result.ok, result.failed_cells
    return result
