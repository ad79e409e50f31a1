"""The sequence folder: write it (``render_sequence``), read it back lazily (``Sequence``).

Layout and columns are the contract of ``docs/architecture.md``. A folder is
complete when its ``MANIFEST.json`` exists: it is written last, and the whole
folder is built under a temporary name next to its destination and renamed
into place, so a crash never leaves a partial folder under the real name.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from scenes.formats import FormatError, atomic_write_bytes, encode_flo, encode_png, read_flo, read_png
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
]

MANIFEST_NAME = "MANIFEST.json"
# files up to this size are hashed whole by the quick check; larger ones by size + sampled blocks
QUICK_FULL_HASH_BYTES = 256 * 1024
_SAMPLE_BYTES = 64 * 1024
# zlib level of the per-frame PNGs: level 1 encodes textured 640x480 frames ~3x faster than 3
PNG_COMPRESSION = 1

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
    """

    def __init__(self, folder: Path):
        self.folder = folder
        self.records: dict[str, dict] = {}

    def write(self, rel: str, data: bytes) -> None:
        path = self.folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as fh:
            fh.write(data)
        self.records[rel] = _file_record(data)

    def write_manifest(self, extra: dict | None = None) -> None:
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
                    timings: dict | None = None) -> Path:
    """Render ``spec`` into the sequence folder ``out_dir`` (see docs/architecture.md).

    Parameters
    ----------
    spec : SceneSpec, or a preset name / YAML path for :func:`load_scene_spec`
    out_dir : path; built under a temporary name next to it, then renamed into place
    progress : callable ``(frames_done, n_frames)``, optional
    overwrite : replace an existing non-empty ``out_dir`` (refused otherwise)
    timings : dict, optional; filled with seconds spent rendering+truth and writing

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
    out_dir = Path(out_dir)
    _prepare_out_dir(out_dir, overwrite)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        _write_into(spec, tmp, progress, timings)
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


def _write_into(spec: SceneSpec, folder: Path, progress: Progress | None, timings: dict | None) -> None:
    from scenes.generate import CAMERA_COLUMNS, TRACK_COLUMNS, SceneGenerator
    from scenes.preview import PreviewCollector
    from scenes.render import gl_info

    n = spec.image.n_frames
    out = _FolderWriter(folder)
    t_gen = t_write = 0.0
    t0 = time.perf_counter()
    gen = SceneGenerator(spec)
    preview = PreviewCollector(n)
    t_gen += time.perf_counter() - t0
    frames = gen.frames()
    for i in range(n):
        t0 = time.perf_counter()
        fo = next(frames)
        t1 = time.perf_counter()
        name = f"{fo.index:06d}"
        out.write(f"frames/{name}.png", encode_png(fo.rgb, compression=PNG_COMPRESSION))
        out.write(f"instances/{name}.png", encode_png(fo.instances, compression=PNG_COMPRESSION))
        if fo.pair is not None:
            pname = f"{fo.pair_index:06d}"
            out.write(f"flow/{pname}.flo", encode_flo(fo.pair.flow))
            out.write(f"flow_camera/{pname}.flo", encode_flo(fo.pair.flow_camera))
            out.write(f"valid/{pname}.png", encode_png(fo.pair.valid.view(np.uint8) * np.uint8(255),
                                                           compression=PNG_COMPRESSION))
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
            "n_buildings": len(gen.world.buildings), "sensor": gen.sensor_meta(), **gl_info()}
    out.write("meta.json", json.dumps(meta, indent=1, sort_keys=True).encode())
    sheet = preview.sheet(tracks)
    if sheet is not None:
        out.write("preview.png", encode_png(sheet))
    out.write_manifest({"spec_hash": spec_hash(spec)})
    t_write += time.perf_counter() - t0
    if timings is not None:
        timings.update({"render_truth_s": t_gen, "write_s": t_write, "n_frames": n})


class Sequence:
    """A sequence folder, read lazily: frames and truth come from disk per index.

    ``len(seq)`` frames; ``seq.frame(i)`` uint8 RGB; ``seq.pair_truth(i)`` the
    :class:`PairTruth` of i -> i+1; ``seq.camera`` / ``seq.tracks`` pandas tables;
    ``seq.meta`` dict; ``seq.spec`` the resolved :class:`SceneSpec`. Also
    indexable (``seq[i]`` is ``seq.frame(i)``), so a pipeline can take it as frames.
    """

    def __init__(self, path: str | os.PathLike, *, verify: bool = False):
        self.path = Path(path)
        if not self.path.is_dir():
            raise FileNotFoundError(f"{self.path}: no such sequence folder")
        self.manifest = verify_manifest(self.path, full=True) if verify else self._manifest_exists()
        self.meta = json.loads((self.path / "meta.json").read_text())
        self._n = int(self.meta["n_frames"])
        self._camera = None
        self._tracks = None
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

    def pair_truth(self, i: int) -> PairTruth:
        """Ground truth of the pair i -> i+1."""
        i = self._index(i, self._n - 1, "pair")
        name = f"{i:06d}"
        valid = read_png(self.path / "valid" / f"{name}.png", expect="gray8") > 127
        return PairTruth(flow=read_flo(self.path / "flow" / f"{name}.flo"),
                         flow_camera=read_flo(self.path / "flow_camera" / f"{name}.flo"),
                         valid=valid, instances=self.instances(i))

    @property
    def camera(self) -> pd.DataFrame:
        if self._camera is None:
            self._camera = pd.read_csv(self.path / "camera.csv")
        return self._camera

    @property
    def tracks(self) -> pd.DataFrame:
        if self._tracks is None:
            self._tracks = pd.read_csv(self.path / "tracks.csv")
        return self._tracks

    @property
    def spec(self) -> SceneSpec:
        if self._spec is None:
            self._spec = load_scene_spec(str(self.path / "scene.yaml"))
        return self._spec

    @property
    def K(self) -> np.ndarray:
        return np.asarray(self.meta["K"], np.float64)

    def __repr__(self) -> str:
        return f"Sequence({str(self.path)!r}, {self._n} frames, {self.meta['width']}x{self.meta['height']})"


def open_sequence(path: str | os.PathLike, *, verify: bool = False) -> Sequence:
    """Open a sequence folder; ``verify=True`` checks every file's sha256 against the manifest."""
    return Sequence(path, verify=verify)


def read_scene_yaml(path: str | os.PathLike) -> dict:
    return yaml.safe_load(Path(path).read_text())
