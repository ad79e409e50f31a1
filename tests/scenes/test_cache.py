"""scenes.cache: content-addressed renders, reused when complete, rendered again when partial or corrupt."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from scenes import cache_key, cached_sequence_result, load_scene_spec
from scenes.cache import _HOST


def _spec(**overrides):
    return load_scene_spec("tiny", {"image.n_frames": 2, **overrides})


def test_the_key_follows_the_content_and_names_the_scene():
    a, b = cache_key(_spec()), cache_key(_spec(seed=99))
    assert a != b and a == cache_key(_spec())
    assert a.startswith("tiny-") and len(a.split("-")[-1]) == 20
    weird = load_scene_spec(_spec().model_dump(mode="json") | {"name": "../my scene/?"})
    assert "/" not in cache_key(weird) and cache_key(weird).startswith("my_scene")


@pytest.mark.gl
def test_a_render_is_reused_and_a_corrupt_one_rendered_again(tmp_path):
    spec = _spec()
    first = cached_sequence_result(spec, tmp_path)
    assert first.rendered and first.path == tmp_path / cache_key(spec)
    again = cached_sequence_result(spec, tmp_path)
    assert not again.rendered and again.path == first.path
    frame = first.path / "frames" / "000001.png"
    frame.write_bytes(frame.read_bytes()[:-10])  # a truncated file: the manifest's hash no longer matches
    healed = cached_sequence_result(spec, tmp_path)
    assert healed.rendered and healed.path == first.path
    assert sorted(p.name for p in tmp_path.iterdir()) == [first.path.name]  # nothing aside is left behind


@pytest.mark.gl
def test_the_partial_render_of_a_dead_process_is_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)  # that process has exited
    orphan = tmp_path / f".tiny-x.partial-{_HOST}-{pid}-abc"
    orphan.mkdir()
    mine = tmp_path / f".tiny-y.partial-{_HOST}-{os.getpid()}-abc"  # a live process's render: left alone
    mine.mkdir()
    cached_sequence_result(_spec(), tmp_path)
    assert not orphan.exists() and mine.exists()


def test_the_key_follows_the_generator_code_but_not_the_footage_reader(tmp_path, monkeypatch):
    import shutil

    from scenes import cache

    pkg = tmp_path / "scenes"
    shutil.copytree(os.path.dirname(cache.__file__), pkg, ignore=shutil.ignore_patterns("__pycache__", "presets"))
    before = cache._source_hash(pkg)
    (pkg / "footage.py").write_text((pkg / "footage.py").read_text() + "\n# a reader's edit\n")
    assert cache._source_hash(pkg) == before  # real footage has its own key
    (pkg / "world.py").write_text((pkg / "world.py").read_text() + "\n# an edit of the generator\n")
    assert cache._source_hash(pkg) != before
    key = cache_key(_spec())
    monkeypatch.setattr(cache, "scene_code_hash", lambda: "0" * 64)
    assert cache_key(_spec()) != key and cache_key(_spec()).startswith("tiny-")
