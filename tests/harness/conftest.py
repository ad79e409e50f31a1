"""Fixtures of the harness tests: one render cache for the whole session, small suites."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

# The smallest suite that still goes through every stage: the tiny preset, few frames.
TINY_SUITE = {
    "name": "test-tiny",
    "description": "two pipelines on a short tiny scene",
    "scenes": [{"preset": "tiny", "overrides": {"image.n_frames": 4}}],
    "seeds": [1],
    "pipelines": ["thesis-lk", "dis"],
    "picture_pairs": [0],
}


@pytest.fixture(scope="session")
def render_cache(tmp_path_factory) -> Path:
    """A render cache shared by every harness test, so each scene is rendered once per session."""
    return tmp_path_factory.mktemp("aerobench-cache")


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
