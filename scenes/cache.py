"""The render cache: one folder per (resolved spec, generator version, scene code, folder layout), reused when intact.

Real footage (:class:`scenes.footage.FootageSpec`) is decoded into the same cache, its
entry keyed by :func:`scenes.footage.footage_hash` (the bytes of the files read and the
options): every function here takes either kind of spec.

Entries are written with the compact flow format (``flow/NNNNNN.npz``).

An entry is named by a content hash. It is reused only if its manifest
verifies in full (size and sha256 of every file: about 1.8 GB/s here, small
next to rendering, and a sampled hash let an edit inside a large ``.flo`` be
scored as truth); a partial or corrupt entry is removed and rebuilt, never used.
A render killed midway leaves a ``.<key>.partial-<host>-<pid>-*`` folder; the
next call on the same host removes those whose process is gone.
Concurrent renders of the same entry are safe: each renders into its own
temporary folder and renames it into place; if another process got there
first, its entry is kept and ours is discarded.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import socket
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from scenes.footage import FootageSpec, footage_hash, footage_key, write_footage
from scenes.sequence import SEQUENCE_LAYOUT, ManifestError, Progress, _write_into, verify_manifest
from scenes.spec import GENERATOR_VERSION, SceneSpec, load_scene_spec, spec_hash

__all__ = ["CacheResult", "cache_key", "cached_sequence", "cached_sequence_result"]


@dataclass(frozen=True)
class CacheResult:
    """Where the sequence is, and whether this call rendered it (False: reused)."""

    path: Path
    rendered: bool
    key: str


@functools.lru_cache(maxsize=1)
def scene_code_hash() -> str:
    """sha256 of the scene generator's source: every module of the ``scenes`` package but ``footage.py``.

    In the render cache key beside :data:`GENERATOR_VERSION`: an edit to the generator that
    changes what it renders, made without a new version, would otherwise be served the renders
    of the code before it, silently (a branch iterating on the world's look was). The price is
    a render again after any edit of the package, a comment's included; real footage has its own
    key (:func:`scenes.footage.footage_key`), so ``footage.py`` is left out.
    """
    return _source_hash(Path(__file__).resolve().parent)


def _source_hash(root: Path) -> str:
    """sha256 of the names and bytes of the ``*.py`` files under ``root`` but ``footage.py``, in name order."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        if path.name != "footage.py":
            h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def cache_key(spec: SceneSpec | FootageSpec) -> str:
    """Content hash of the resolved spec, the generator version, the generator's code and the folder layout,
    20 hex digits.

    The layout (:data:`scenes.sequence.SEQUENCE_LAYOUT`) is in the key so that an entry
    written in an older layout (``.flo`` flow) is never looked up, let alone misread; the
    code (:func:`scene_code_hash`) so that an edit of the generator is never served an old render.
    """
    if isinstance(spec, FootageSpec):
        return footage_key(spec)
    text = f"{spec_hash(spec)}|{GENERATOR_VERSION}|code-{scene_code_hash()}|layout-{SEQUENCE_LAYOUT}"
    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", spec.name).strip("._")[:40] or "scene"
    return f"{label}-{hashlib.sha256(text.encode()).hexdigest()[:20]}"


_HOST = re.sub(r"[^A-Za-z0-9]+", "_", socket.gethostname())[:32] or "host"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_orphaned_partials(cache_dir: Path) -> None:
    """Remove partial renders of this host whose process has died (a SIGKILLed render)."""
    pattern = re.compile(rf"^\..+\.partial-{re.escape(_HOST)}-(\d+)-")
    for p in cache_dir.glob(".*.partial-*"):
        m = pattern.match(p.name)
        if m and p.is_dir() and not _pid_alive(int(m.group(1))):
            shutil.rmtree(p, ignore_errors=True)


def _discard(path: Path) -> None:
    """Remove a folder by renaming it aside first, so no reader sees it half-deleted."""
    trash = path.with_name(f".{path.name}.trash-{os.getpid()}-{time.monotonic_ns()}")
    try:
        os.rename(path, trash)
    except FileNotFoundError:
        return
    shutil.rmtree(trash, ignore_errors=True)


def cached_sequence_result(spec: SceneSpec | FootageSpec | str | os.PathLike, cache_dir: str | os.PathLike, *,
                           progress: Progress | None = None) -> CacheResult:
    """Return the cached sequence of ``spec``, rendering (or decoding real footage) if absent, partial or corrupt.

    A footage entry whose files cannot be read raises :class:`scenes.formats.FormatError`
    and leaves nothing in the cache.
    """
    if isinstance(spec, FootageSpec):
        digest = footage_hash(spec)
        key = footage_key(spec, digest)

        def write(folder: Path) -> None:
            write_footage(spec, folder, digest=digest)
    else:
        if not isinstance(spec, SceneSpec):
            spec = load_scene_spec(spec)
        key = cache_key(spec)

        def write(folder: Path) -> None:
            _write_into(spec, folder, progress, None)
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    target = cache_dir / key
    _remove_orphaned_partials(cache_dir)
    if target.exists():
        try:
            doc = verify_manifest(target, full=True)
            if doc.get("layout") != SEQUENCE_LAYOUT:
                raise ManifestError(f"{target}: layout {doc.get('layout')!r}, expected {SEQUENCE_LAYOUT}")
            return CacheResult(path=target, rendered=False, key=key)
        except ManifestError:
            _discard(target)
    tmp = Path(tempfile.mkdtemp(prefix=f".{key}.partial-{_HOST}-{os.getpid()}-", dir=cache_dir))
    try:
        write(tmp)
        try:
            os.rename(tmp, target)
        except OSError:
            # another process renamed its complete entry into place first: keep theirs
            shutil.rmtree(tmp, ignore_errors=True)
            verify_manifest(target, full=True)
            return CacheResult(path=target, rendered=False, key=key)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return CacheResult(path=target, rendered=True, key=key)


def cached_sequence(spec: SceneSpec | FootageSpec | str | os.PathLike, cache_dir: str | os.PathLike, *,
                    progress: Progress | None = None) -> Path:
    """Path of the cached sequence of ``spec`` (see :func:`cached_sequence_result`)."""
    return cached_sequence_result(spec, cache_dir, progress=progress).path
