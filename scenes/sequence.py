"""The sequence folder: write it (``render_sequence``), read it back lazily (``Sequence``).

Layout and columns are the contract of ``docs/architecture.md``. A folder is
complete when its ``MANIFEST.json`` exists: it is written last, and the whole
folder is built under a temporary name next to its destination and renamed
into place, so a crash never leaves a partial folder under the real name.

Ground-truth flow is stored in one of two formats (``meta.json`` says which):
``"npz"`` (the default: one lossless compact file per pair, ``flow/NNNNNN.npz``
with the total and the camera-induced flow, see :func:`scenes.formats.encode_flow_npz`)
or ``"flo"`` (Middlebury files ``flow/NNNNNN.flo`` and ``flow_camera/NNNNNN.flo``,
for tools that read them; folders written before the compact format have these).
The reader reads both, bit for bit the same arrays.

Files are encoded (PNG, zlib, zstd) and written by a few writer threads while the
next frame renders: our numba encoders (``nogil``), cv2, zlib and zstandard release the GIL. A writer's error is raised
in the rendering thread at its next frame; the manifest is written only after
every file has been written.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import shutil
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from scenes.formats import (
    FormatError,
    atomic_write_bytes,
    encode_flo,
    encode_flow_npz,
    encode_png,
    encode_png_fast,
    read_flo,
    read_flow_npz,
    read_png,
)
from scenes.ground_truth import PairTruth
from scenes.spec import GENERATOR_VERSION, SceneSpec, load_scene_spec, spec_hash, spec_to_yaml

__all__ = [
    "PairTruth",
    "Sequence",
    "open_sequence",
    "render_sequence",
    "write_manifest",
    "verify_manifest",
    "ManifestError",
    "MANIFEST_NAME",
    "FLOW_FORMATS",
    "SEQUENCE_LAYOUT",
    "read_pair_flow",
]

MANIFEST_NAME = "MANIFEST.json"
# files up to this size are hashed whole by the quick check; larger ones by size + sampled blocks
QUICK_FULL_HASH_BYTES = 256 * 1024
_SAMPLE_BYTES = 64 * 1024
# the per-frame PNGs: the Average row predictor on every row and Huffman coding only (no string
# matching: the predictor leaves little for it), by our own encoder (scenes.formats.encode_png_fast):
# the same pixels as libpng + zlib with these settings (level 1, Z_HUFFMAN_ONLY, PNG_FILTER_AVG) and
# files within 0.1 % of theirs (nominal 423 vs 423 KB), at about 0.4x their CPU (benchmarks/io_speed.py).
# Before: libpng's adaptive predictor (26 ms, 382 KB nominal), then Average + run-length matching
# (18.3 ms, 407 KB), then Average + Huffman only through zlib (16.0 ms, 426 KB; one core).
# masks and instance ids: long runs of one value, no row prediction needed (~4x faster, ~2 kB)
MASK_PNG = {"compression": 1, "strategy": "rle", "filters": "none"}
# how ground-truth flow is stored: "npz" (compact, lossless, the default) or "flo" (Middlebury)
FLOW_FORMATS = ("npz", "flo")
# version of the folder layout; part of the render cache key, so a cache entry written in
# another layout is never read as this one (2: compact flow, PNGs with the RLE strategy;
# since then, with the same layout: flow files of codec version 2 (zstd) and PNGs Huffman-coded
# only, then frame PNGs by our own encoder: the same pixels and truth bit for bit, version-1 flow
# files still read)
SEQUENCE_LAYOUT = 2
# threads that encode and write files while the next frame renders
WRITER_THREADS = 2

Progress = Callable[[int, int], None]


class ManifestError(FormatError):
    """A sequence folder is partial, or a file differs from its manifest."""


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _sample_hash(path: Path, size: int) -> str:
    """sha256 of the first, middle and last 64 KiB: cheap, catches truncation and most edits."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for off in sorted({0, max(0, size // 2 - _SAMPLE_BYTES // 2), max(0, size - _SAMPLE_BYTES)}):
            fh.seek(off)
            h.update(fh.read(_SAMPLE_BYTES))
    return h.hexdigest()


def _file_record(data: bytes) -> dict:
    size = len(data)
    h = hashlib.sha256()
    for off in sorted({0, max(0, size // 2 - _SAMPLE_BYTES // 2), max(0, size - _SAMPLE_BYTES)}):
        h.update(data[off:off + _SAMPLE_BYTES])
    return {"size": size, "sha256": hashlib.sha256(data).hexdigest(), "sample_sha256": h.hexdigest()}


class _FolderWriter:
    """Writes the files of a folder that is still under its temporary name, hashing as it goes.

    No per-file rename or fsync: the whole folder is renamed into place once
    complete, and the manifest (recorded from the bytes written) catches any
    file that did not reach the disk intact.

    With ``threads > 0``, :meth:`submit` encodes and writes on a pool of that many
    threads, at most ``max_pending`` jobs queued (the arrays they hold bound memory);
    the first error of a job is raised by the next :meth:`submit` or by :meth:`finish`.
    :meth:`close` (always call it) cancels what has not started and waits for the rest,
    so no thread writes into a folder that is being removed.
    """

    def __init__(self, folder: Path, *, threads: int = 0, max_pending: int | None = None):
        self.folder = folder
        self.records: dict[str, dict] = {}
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="seq-writer") if threads > 0 else None
        self._pending: deque[Future] = deque()
        self._max_pending = max_pending if max_pending is not None else 8 * max(threads, 1)

    def write(self, rel: str, data: bytes) -> None:
        path = self.folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as fh:
            fh.write(data)
        record = _file_record(data)
        with self._lock:
            self.records[rel] = record

    def _encode_write(self, rel: str, encode: Callable[..., bytes], args: tuple, kwargs: dict) -> None:
        self.write(rel, encode(*args, **kwargs))

    def submit(self, rel: str, encode: Callable[..., bytes], *args, **kwargs) -> None:
        """Write ``encode(*args, **kwargs)`` to ``rel``: on a writer thread, or now without threads.

        The arrays in ``args`` must not change afterwards (the job reads them later).
        """
        if self._pool is None:
            self._encode_write(rel, encode, args, kwargs)
            return
        while self._pending and (self._pending[0].done() or len(self._pending) >= self._max_pending):
            self._pending.popleft().result()  # raises the job's error here, in the caller's thread
        self._pending.append(self._pool.submit(self._encode_write, rel, encode, args, kwargs))

    def finish(self) -> None:
        """Wait for every submitted job; raise the first error."""
        while self._pending:
            self._pending.popleft().result()

    def close(self) -> None:
        if self._pool is not None:
            for fut in self._pending:
                fut.cancel()
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            self._pending.clear()

    def write_manifest(self, extra: dict | None = None) -> None:
        self.finish()
        doc = {"generator_version": GENERATOR_VERSION, **(extra or {}), "files": dict(sorted(self.records.items()))}
        atomic_write_bytes(self.folder / MANIFEST_NAME, json.dumps(doc, indent=1, sort_keys=True).encode())


def write_manifest(folder: Path, extra: dict | None = None) -> None:
    """Hash every file under ``folder`` into ``MANIFEST.json`` (written last, atomically)."""
    w = _FolderWriter(folder)
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.name != MANIFEST_NAME:
            w.records[p.relative_to(folder).as_posix()] = _file_record(p.read_bytes())
    w.write_manifest(extra)


def verify_manifest(folder: str | os.PathLike, *, full: bool = True) -> dict:
    """Check ``folder`` against its manifest; return the manifest.

    The default hashes every file whole (sha256 runs at about 1.8 GB/s here,
    little next to rendering): anything that decides whether data is used as
    ground truth must use it. ``full=False`` is a quick look for progress
    displays only: sizes of all files, whole hashes of small files and
    sampled blocks of large ones, so an edit inside a large ``.flo`` can pass.

    Raises
    ------
    ManifestError
        No manifest (a partial folder), a missing, extra-sized or changed file.
    """
    folder = Path(folder)
    mpath = folder / MANIFEST_NAME
    if not mpath.is_file():
        raise ManifestError(f"{folder}: no {MANIFEST_NAME}: the sequence is partial or not a sequence folder")
    try:
        doc = json.loads(mpath.read_text())
        files = doc["files"]
    except (ValueError, KeyError) as err:
        raise ManifestError(f"{mpath}: unreadable manifest ({err})") from None
    for rel, info in files.items():
        p = folder / rel
        if not p.is_file():
            raise ManifestError(f"{p}: listed in {MANIFEST_NAME} but missing")
        size = p.stat().st_size
        if size != info["size"]:
            raise ManifestError(f"{p}: {size} bytes, the manifest says {info['size']} (truncated or edited)")
        if full or size <= QUICK_FULL_HASH_BYTES:
            if _sha256_file(p) != info["sha256"]:
                raise ManifestError(f"{p}: sha256 differs from {MANIFEST_NAME} (edited or corrupt)")
        elif _sample_hash(p, size) != info["sample_sha256"]:
            raise ManifestError(f"{p}: content differs from {MANIFEST_NAME} (edited or corrupt)")
    return doc


def _csv_bytes(columns: list[str], rows: list[dict]) -> bytes:
    import io
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow(["" if r[c] is None or (isinstance(r[c], float) and not np.isfinite(r[c]))
                    else (repr(float(r[c])) if isinstance(r[c], (float, np.floating)) else r[c])
                    for c in columns])
    return buf.getvalue().encode()


def _prepare_out_dir(out_dir: Path, overwrite: bool) -> None:
    if out_dir.exists():
        if not out_dir.is_dir():
            raise FileExistsError(f"{out_dir}: exists and is not a folder")
        if any(out_dir.iterdir()) and not overwrite:
            raise FileExistsError(f"{out_dir}: exists and is not empty; pass overwrite=True to replace it")


def render_sequence(spec: SceneSpec | str | os.PathLike, out_dir: str | os.PathLike, *,
                    progress: Progress | None = None, overwrite: bool = False,
                    timings: dict | None = None, flow_format: str = "npz",
                    writer_threads: int = WRITER_THREADS) -> Path:
    """Render ``spec`` into the sequence folder ``out_dir`` (see docs/architecture.md).

    Parameters
    ----------
    spec : SceneSpec, or a preset name / YAML path for :func:`load_scene_spec`
    out_dir : path; built under a temporary name next to it, then renamed into place
    progress : callable ``(frames_done, n_frames)``, optional
    overwrite : replace an existing non-empty ``out_dir`` (refused otherwise)
    timings : dict, optional; filled with wall seconds of the rendering thread: ``setup_s``
        (world, meshes, renderer), ``render_truth_s`` (frames: render, sensor, truth; from the
        first frame, so the one-time numba load of the truth kernels is in it), ``write_s``
        (handing files to the writers, waiting when they fall behind, the tables, preview and
        manifest after waiting for every file), ``setup_cpu_s`` (process CPU seconds of the setup,
        every thread), and ``n_frames``
    flow_format : {"npz", "flo"}
        ``"npz"`` (default) one lossless compact file per pair; ``"flo"`` Middlebury
        ``flow/*.flo`` and ``flow_camera/*.flo`` (about 10x the bytes), for other tools.
    writer_threads : int
        Threads encoding and writing files while the next frame renders; 0 writes in the
        rendering thread. The bytes written do not depend on it.

    Returns
    -------
    Path of the complete folder.

    Raises
    ------
    FileExistsError
        ``out_dir`` is not empty and ``overwrite`` is False (nothing is written).
    RendererUnavailableError
        No OpenGL renderer (the message names the system packages).
    """
    if not isinstance(spec, SceneSpec):
        spec = load_scene_spec(spec)
    _check_flow_format(flow_format)
    out_dir = Path(out_dir)
    _prepare_out_dir(out_dir, overwrite)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        _write_into(spec, tmp, progress, timings, flow_format=flow_format, writer_threads=writer_threads)
        _move_into_place(tmp, out_dir, overwrite)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def _move_into_place(tmp: Path, out_dir: Path, overwrite: bool) -> None:
    if out_dir.exists() and any(out_dir.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out_dir}: appeared while rendering and is not empty")
        trash = out_dir.with_name(f".{out_dir.name}.old-{os.getpid()}-{time.monotonic_ns()}")
        os.rename(out_dir, trash)
        os.rename(tmp, out_dir)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        if out_dir.exists():
            out_dir.rmdir()
        os.rename(tmp, out_dir)


def _check_flow_format(flow_format: str) -> None:
    if flow_format not in FLOW_FORMATS:
        raise ValueError(f"flow_format: expected one of {', '.join(FLOW_FORMATS)}, got {flow_format!r}")


def _valid_png(valid: np.ndarray) -> bytes:
    return encode_png(valid.view(np.uint8) * np.uint8(255), **MASK_PNG)


def _frame_png(rgb: np.ndarray) -> bytes:
    return encode_png_fast(rgb)


def _write_into(spec: SceneSpec, folder: Path, progress: Progress | None, timings: dict | None, *,
                flow_format: str = "npz", writer_threads: int = WRITER_THREADS) -> None:
    from scenes.generate import CAMERA_COLUMNS, TRACK_COLUMNS, SceneGenerator
    from scenes.preview import PreviewCollector
    from scenes.render import gl_info

    _check_flow_format(flow_format)
    n = spec.image.n_frames
    out = _FolderWriter(folder, threads=writer_threads)
    try:
        t_gen = t_write = 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        gen = SceneGenerator(spec)
        preview = PreviewCollector(n)
        t_setup, c_setup = time.perf_counter() - t0, time.process_time() - c0
        frames = gen.frames()
        for i in range(n):
            t0 = time.perf_counter()
            fo = next(frames)
            t1 = time.perf_counter()
            name = f"{fo.index:06d}"
            out.submit(f"frames/{name}.png", _frame_png, fo.rgb)
            out.submit(f"instances/{name}.png", encode_png, fo.instances, **MASK_PNG)
            if fo.pair is not None:
                pname = f"{fo.pair_index:06d}"
                if flow_format == "npz":
                    out.submit(f"flow/{pname}.npz", encode_flow_npz, fo.pair.flow, fo.pair.flow_camera)
                else:
                    out.submit(f"flow/{pname}.flo", encode_flo, fo.pair.flow)
                    out.submit(f"flow_camera/{pname}.flo", encode_flo, fo.pair.flow_camera)
                out.submit(f"valid/{pname}.png", _valid_png, fo.pair.valid)
            preview.add(fo)
            t_gen += t1 - t0
            t_write += time.perf_counter() - t1
            if progress is not None:
                progress(i + 1, n)
        t0 = time.perf_counter()
        out.write("camera.csv", _csv_bytes(CAMERA_COLUMNS, gen.camera_rows()))
        tracks = gen.track_table()
        out.write("tracks.csv", _csv_bytes(TRACK_COLUMNS, tracks))
        out.write("scene.yaml", spec_to_yaml(spec).encode())
        K = gen.path.K
        meta = {"width": spec.image.width_px, "height": spec.image.height_px, "n_frames": n,
                "fps": spec.image.fps, "K": K.tolist(), "generator_version": GENERATOR_VERSION,
                "spec_hash": spec_hash(spec), "seed": spec.seed, "name": spec.name,
                "gsd_m": spec.gsd_m(), "texel_m": gen.world.texel_m, "n_vehicles": len(gen.vehicles),
                "n_buildings": len(gen.world.buildings), "flow_format": flow_format,
                "layout": SEQUENCE_LAYOUT, "sensor": gen.sensor_meta(), **gl_info()}
        out.write("meta.json", json.dumps(meta, indent=1, sort_keys=True).encode())
        sheet = preview.sheet(tracks, global_shift_px=gen.global_shift_px)
        if sheet is not None:
            out.write("preview.png", encode_png(sheet))
        out.write_manifest({"spec_hash": spec_hash(spec), "layout": SEQUENCE_LAYOUT, "flow_format": flow_format})
        t_write += time.perf_counter() - t0
    finally:
        out.close()
    if timings is not None:
        timings.update({"setup_s": t_setup, "setup_cpu_s": c_setup, "render_truth_s": t_gen, "write_s": t_write,
                        "n_frames": n})


def read_pair_flow(folder: str | os.PathLike, i: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(flow, flow_camera)`` of pair i -> i+1 of a sequence folder, in either flow format.

    Each is ``(H, W, 2)`` float32 px, or None when the folder has no such file
    (for readers such as the report that show what there is). Raises
    :class:`FormatError` for a damaged file.
    """
    folder = Path(folder)
    name = f"{int(i):06d}"
    npz = folder / "flow" / f"{name}.npz"
    if npz.is_file():
        return read_flow_npz(npz)
    flo, cam = folder / "flow" / f"{name}.flo", folder / "flow_camera" / f"{name}.flo"
    return (read_flo(flo) if flo.is_file() else None, read_flo(cam) if cam.is_file() else None)


class Sequence:
    """A sequence folder, read lazily: frames and truth come from disk per index.

    ``len(seq)`` frames; ``seq.frame(i)`` uint8 RGB; ``seq.pair_truth(i)`` the
    :class:`PairTruth` of i -> i+1; ``seq.camera`` / ``seq.tracks`` pandas tables;
    ``seq.meta`` dict; ``seq.spec`` the resolved :class:`SceneSpec`. Also
    indexable (``seq[i]`` is ``seq.frame(i)``), so a pipeline can take it as frames.

    Real footage (``seq.source == "real"``, :mod:`scenes.footage`) has only the truths its
    annotations give: ``pair_truth(i)`` is None for a pair without flow truth (and has
    ``flow_camera`` and ``instances`` None where it exists), ``camera`` and ``spec`` are
    None, ``tracks`` is None without a ground-truth file, ``boxes`` holds boxes without
    identities. ``has_pair_truth``, ``has_camera_truth`` and ``has_track_truth`` say what exists.
    """

    def __init__(self, path: str | os.PathLike, *, verify: bool = False):
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such sequence folder")
        self.manifest = verify_manifest(self.path, full=True) if verify else self._manifest_exists()
        self.meta = json.loads((self.path / "meta.json").read_text())
        self._n = int(self.meta["n_frames"])
        # folders written before the compact format have no "flow_format": theirs is .flo
        self.flow_format = str(self.meta.get("flow_format", "flo"))
        if self.flow_format not in FLOW_FORMATS:
            raise FormatError(f"{self.path / 'meta.json'}: flow_format {self.flow_format!r}, "
                              f"expected one of {', '.join(FLOW_FORMATS)}")
        # "real": decoded footage (scenes.footage) whose absent truths are absent files
        self.source = str(self.meta.get("source", "synthetic"))
        self._camera = None
        self._tracks = None
        self._boxes = None
        self._spec = None

    def _manifest_exists(self) -> dict:
        mpath = self.path / MANIFEST_NAME
        if not mpath.is_file():
            raise ManifestError(f"{self.path}: no {MANIFEST_NAME}: the sequence is partial or not a sequence folder")
        return json.loads(mpath.read_text())

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i: int) -> np.ndarray:
        return self.frame(i)

    def _index(self, i: int, n: int, what: str) -> int:
        if not isinstance(i, (int, np.integer)):
            raise TypeError(f"{what} index: expected an int, got {type(i).__name__}")
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"{what} index {i}: expected 0..{n - 1} in {self.path}")
        return int(i)

    def frame(self, i: int) -> np.ndarray:
        """Frame i, (H, W, 3) uint8 RGB."""
        i = self._index(i, self._n, "frame")
        return read_png(self.path / "frames" / f"{i:06d}.png", expect="rgb8")

    def instances(self, i: int) -> np.ndarray:
        i = self._index(i, self._n, "frame")
        return read_png(self.path / "instances" / f"{i:06d}.png", expect="gray16")

    def has_pair_truth(self, i: int) -> bool:
        """Whether pair i -> i+1 has ground-truth flow (always, for a rendered sequence)."""
        i = self._index(i, self._n - 1, "pair")
        if self.source != "real":
            return True
        return i in set(self.meta.get("annotations", {}).get("flow_pairs", []))

    @property
    def has_camera_truth(self) -> bool:
        """Whether camera.csv (the true global shifts and jitter) exists."""
        return (self.path / "camera.csv").is_file()

    @property
    def has_track_truth(self) -> bool:
        """Whether tracks.csv (vehicles with identities) exists."""
        return (self.path / "tracks.csv").is_file()

    def pair_truth(self, i: int) -> PairTruth | None:
        """Ground truth of the pair i -> i+1; None for a pair of real footage without flow truth."""
        i = self._index(i, self._n - 1, "pair")
        name = f"{i:06d}"
        if self.source == "real":
            if not self.has_pair_truth(i):
                return None
            flow = read_flo(self.path / "flow" / f"{name}.flo")
            valid = read_png(self.path / "valid" / f"{name}.png", expect="gray8") > 127
            return PairTruth(flow=flow, flow_camera=None, valid=valid, instances=None)
        valid = read_png(self.path / "valid" / f"{name}.png", expect="gray8") > 127
        if self.flow_format == "npz":
            flow, flow_camera = read_flow_npz(self.path / "flow" / f"{name}.npz")
        else:
            flow = read_flo(self.path / "flow" / f"{name}.flo")
            flow_camera = read_flo(self.path / "flow_camera" / f"{name}.flo")
        return PairTruth(flow=flow, flow_camera=flow_camera, valid=valid, instances=self.instances(i))

    @property
    def camera(self) -> pd.DataFrame | None:
        """camera.csv; None where it is absent (real footage)."""
        if self._camera is None and (self.source != "real" or self.has_camera_truth):
            self._camera = pd.read_csv(self.path / "camera.csv")
        return self._camera

    @property
    def tracks(self) -> pd.DataFrame | None:
        """tracks.csv; None where it is absent (real footage without a ground-truth file). A folder written
        before the ``class`` and ``visible_fraction`` columns reads as all ``car`` with ``visible_fraction``
        = ``visible``."""
        if self._tracks is None and (self.source != "real" or self.has_track_truth):
            df = pd.read_csv(self.path / "tracks.csv")
            if "class" not in df.columns:
                df["class"] = "car"
            if "visible_fraction" not in df.columns and "visible" in df.columns:
                df["visible_fraction"] = df["visible"].astype(float)
            self._tracks = df
        return self._tracks

    @property
    def boxes(self) -> pd.DataFrame | None:
        """Boxes of the objects to detect, with or without identities: ``frame, class, x_px, y_px,
        bbox_x0_px, bbox_y0_px, bbox_x1_px, bbox_y1_px``.

        boxes.csv where it exists (real footage with YOLO labels), else the visible rows of
        tracks.csv (class ``car`` where it has no class column), else None.
        """
        if self._boxes is None:
            if (self.path / "boxes.csv").is_file():
                self._boxes = pd.read_csv(self.path / "boxes.csv", dtype={"class": str})
            elif self.tracks is not None:
                t = self.tracks[self.tracks["visible"].astype(int) > 0]
                cls = t["class"] if "class" in t.columns else "car"
                self._boxes = t.assign(**{"class": cls})[
                    ["frame", "class", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                     "bbox_y1_px"]].reset_index(drop=True)
        return self._boxes

    @property
    def ignore_regions(self) -> pd.DataFrame | None:
        """ignore.csv of real footage (objects and regions never scored), or None."""
        path = self.path / "ignore.csv"
        return pd.read_csv(path, dtype={"class": str}) if path.is_file() else None

    @property
    def spec(self) -> SceneSpec | None:
        """The resolved scene spec; None for real footage (it has none)."""
        if self._spec is None and (self.path / "scene.yaml").is_file():
            self._spec = load_scene_spec(str(self.path / "scene.yaml"))
        return self._spec

    @property
    def K(self) -> np.ndarray | None:
        """(3, 3) intrinsics; None for real footage (unknown)."""
        return np.asarray(self.meta["K"], np.float64) if "K" in self.meta else None

    def __repr__(self) -> str:
        return f"Sequence({str(self.path)!r}, {self._n} frames, {self.meta['width']}x{self.meta['height']})"


def open_sequence(path: str | os.PathLike, *, verify: bool = False) -> Sequence:
    """Open a sequence folder; ``verify=True`` checks every file's sha256 against the manifest."""
    return Sequence(path, verify=verify)


def read_scene_yaml(path: str | os.PathLike) -> dict:
    return yaml.safe_load(Path(path).read_text())
