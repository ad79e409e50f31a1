"""Shared fixtures of the scene tests: one small rendered sequence per session."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


@pytest.fixture(scope="session")
def tiny_sequence(tmp_path_factory):
    """The ``tiny`` preset rendered once: (spec, folder)."""
    from scenes import load_scene_spec, render_sequence

    spec = load_scene_spec("tiny")
    out = render_sequence(spec, tmp_path_factory.mktemp("tiny") / "seq")
    return spec, out
