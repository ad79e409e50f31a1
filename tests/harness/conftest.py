"""Fixtures of the harness tests: one render cache for the whole session, small suites."""

from __future__ import annotations

import os
from pathlib import Path

import copy

import pytest
import yaml
from tests.harness.harness_testdata import HERE, RESUME_SUITE, ROOT

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


@pytest.fixture(scope="session")
def render_cache(shared_render_cache) -> Path:
    """A render cache shared by every harness test, so each scene is rendered once per session."""
    return shared_render_cache


@pytest.fixture
def write_suite(tmp_path):
    """Write a suite (dict or YAML text) to a file in ``tmp_path`` and return its path."""

    def write(data, name: str = "suite.yaml") -> Path:
        path = tmp_path / name
        path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
        return path

    return write


@pytest.fixture
def cli_env(render_cache) -> dict:
    """Environment of an ``aerobench`` subprocess: the project importable, the shared cache, EGL."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(HERE), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["AEROBENCH_CACHE"] = str(render_cache)
    env["PYOPENGL_PLATFORM"] = "egl"
    return env


@pytest.fixture(scope="session")
def reference_run(tmp_path_factory, render_cache):
    """RESUME_SUITE run uninterrupted on one worker: the numbers every other run must reproduce."""
    from harness.runner import run_suite
    from harness.suites import parse_suite

    out = tmp_path_factory.mktemp("runs") / "reference"
    result = run_suite(parse_suite(copy.deepcopy(RESUME_SUITE)), out, workers=1, cache_dir=render_cache,
                       progress=False)
    assert result.ok, result.failed_cells
    return result
