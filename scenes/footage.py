"""Real footage as a sequence folder: a video or a folder of frames, with whatever annotations exist.

A real clip is decoded once into an ordinary sequence folder (``docs/architecture.md``),
so that the pipelines, the scoring and the report read it as they read a rendered
scene. Its truths are what its annotations give and nothing more; an absent truth is an
absent file, never a file of zeros:

``frames/NNNNNN.png``
    the frames of the range ``[start, stop)`` of the source, resized by ``scale``.
``tracks.csv``
    only with a MOTChallenge-style ground truth (:func:`scenes.formats.read_mot_gt`):
    ``frame, vehicle_id`` (the file's id), ``x_px, y_px`` (the box centre),
    ``bbox_x0_px .. bbox_y1_px`` (inclusive extent, pixel-centre coordinates), ``visible``
    (1: every row written is an annotated, considered object), ``class``,
    ``visible_fraction``. No ``speed_mps`` or ``parked``: the annotation does not say.
``ignore.csv``
    ignored objects and regions of that file (flag 0, distractors, VisDrone's ignored
    regions): ``frame, bbox_x0_px .. bbox_y1_px, class``; never scored, for a metric that
    must not count a detection there as false.
``boxes.csv``
    only with per-frame YOLO labels (``NAME.txt`` beside each frame ``NAME.png``): boxes
    without identities, ``frame, class, x_px, y_px, bbox_x0_px .. bbox_y1_px``. They are
    kept out of tracks.csv on purpose: a sentinel id (-1) there would read as one vehicle
    in every frame to any tracking metric. Detection metrics read
    :attr:`scenes.sequence.Sequence.boxes` (boxes.csv, or the boxes of tracks.csv).
``flow/NNNNNN.flo``, ``valid/NNNNNN.png``
    only for the pairs with a flow file (``flow:`` folder, Middlebury ``.flo`` or KITTI
    16-bit PNG, named by the source index of the pair's first frame); no ``flow_camera``,
    no ``instances``, no ``camera.csv``.
``meta.json``
    ``"source": "real"``, ``"annotations"`` (which of the above exist), size, fps,
    the range, the scale, the source's path and size, :func:`footage_hash`.

Box conversion: a box whose edges are ``[L, R]`` in edge coordinates (the image spans
``[0, W]``; MOTChallenge ``L = bb_left - 1``, ``R = L + bb_width``; YOLO ``L = (cx - w/2) W``)
is scaled to ``[L sx, R sx]`` and written in pixel-centre coordinates (pixel i spans
``[i - 0.5, i + 0.5]``, as every box of a sequence, see :data:`scenes.formats.MOT_ORIGIN_PX`):
``x0 = L sx - 0.5, x1 = R sx - 0.5``, centre ``(x0 + x1) / 2``; the same in y. ``sx = W' / W`` is
the scale the resize really applied (``W' = round(W scale)``).

The cache entry of a clip is keyed by :func:`footage_hash`: the bytes of every file read
(the video, or the frames of the range and their labels, the ground-truth file, the
flow files) and the options. A bad file raises :class:`scenes.formats.FormatError`
naming the file (and the line for text); the entry is built under a temporary name and
renamed into place when complete, so an error leaves nothing behind.

:func:`export_mot_gt`, :func:`export_frames` and :func:`export_video` write a sequence
the other way (a rendered one, to read it back as real footage: the round trip).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from scenes.formats import (
    MOT_LAYOUTS,
    TRUTH_CLASSES,
    FormatError,
    encode_flo,
    encode_png,
    encode_png_fast,
    mot_box,
    read_flo,
    read_kitti_flow,
    read_mot_gt,
    read_mot_labels,
    read_yolo_boxes,
)
from scenes.sequence import MASK_PNG, SEQUENCE_LAYOUT, _csv_bytes, _FolderWriter

__all__ = [
    "FOOTAGE_VERSION",
    "VIDEO_SUFFIXES",
    "FRAME_SUFFIXES",
    "REAL_TRACK_COLUMNS",
    "BOX_COLUMNS",
    "IGNORE_COLUMNS",
    "FootageSpec",
    "footage_hash",
    "footage_key",
    "validate_footage",
    "write_footage",
    "ingest_footage",
    "list_frame_files",
    "natural_key",
    "gt_labels_file",
    "read_gt",
    "clip_frames",
    "export_mot_gt",
    "export_frames",
    "export_video",
]

# version of what ingestion writes; part of the cache key
FOOTAGE_VERSION = 3  # 2: 10-column MOT lines with a class column, labels.txt; 3: boxes in pixel-centre coordinates
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv")
FRAME_SUFFIXES = (".png", ".jpg", ".jpeg")
REAL_TRACK_COLUMNS = ["frame", "vehicle_id", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                      "bbox_y1_px", "visible", "class", "visible_fraction"]
BOX_COLUMNS = ["frame", "class", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]
IGNORE_COLUMNS = ["frame", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px", "class"]
# YOLO class names of other data sets mapped to ours (:data:`scenes.formats.TRUTH_CLASSES`)
_CLASS_ALIASES = {"minibus": "van", "bicycle": "cyclist", "motorcycle": "motorbike", "motor": "motorbike",
                  "person": "pedestrian", "people": "pedestrian"}
_HASH_BLOCK = 1 << 20


@dataclass(frozen=True)
class FootageSpec:
    """A real clip and how to read it (paths absolute; see the module docstring).

    Attributes
    ----------
    name : str
        The scene label (tables, cache entry name).
    source : str
        A video file (``.mp4 .mov .avi .mkv``) or a folder of frames (``.png .jpg``, sorted
        naturally: ``f2`` before ``f10``).
    start, stop : int, int or None
        The source frames ``[start, stop)`` (0-based); ``stop`` None: to the end.
    scale : float
        Resize factor of the frames (and every annotation with them), > 0.
    fps : float or None
        Frame rate; None: the video's own rate (a folder of frames has none: meta says null).
    gt : str or None
        A MOTChallenge-style ground-truth file, read with ``gt_format`` (one of ``mot``,
        ``visdrone``, ``uavdt``).
    yolo : bool or None
        Per-frame YOLO labels beside a folder's frames: True (required: at least one), False
        (not read), None (read when any exists).
    classes : tuple of str or None
        YOLO class names by index; None: ``classes.txt`` in the frames' folder or its parent.
    flow : str or None
        A folder of flow truth for some pairs: ``N.flo`` or KITTI ``N.png`` / ``N_10.png``, N the
        source index of the pair's first frame.
    """

    name: str
    source: str
    start: int = 0
    stop: int | None = None
    scale: float = 1.0
    fps: float | None = None
    gt: str | None = None
    gt_format: str = "mot"
    yolo: bool | None = None
    classes: tuple[str, ...] | None = None
    flow: str | None = None

    @property
    def kind(self) -> str:
        """``"video"`` or ``"frames"``."""
        return "frames" if Path(self.source).is_dir() else "video"

    def options(self) -> dict:
        """The options that change what ingestion writes (paths not included: the bytes are)."""
        d = {k: v for k, v in asdict(self).items() if k not in ("source", "gt", "flow", "name")}
        d["classes"] = list(self.classes) if self.classes is not None else None
        d["kind"] = self.kind
        d["has_gt"], d["has_flow"] = self.gt is not None, self.flow is not None
        return d


def natural_key(name: str) -> tuple:
    """Sort key that orders the numbers in a name by value (``f2`` before ``f10``)."""
    return tuple((0, int(t), "") if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", name) if t)


def list_frame_files(folder: str | os.PathLike) -> list[Path]:
    """The frame images of a folder (``.png .jpg .jpeg``, any case), sorted naturally."""
    folder = Path(folder)
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in FRAME_SUFFIXES]
    return sorted(files, key=lambda p: natural_key(p.name))


def check_footage(spec: FootageSpec) -> None:
    """Refuse options that cannot work, naming the option (before any file is read)."""
    src = Path(spec.source)
    if not src.exists():
        raise FormatError(f"{src}: no such video file or frames folder")
    if src.is_file() and src.suffix.lower() not in VIDEO_SUFFIXES:
        raise FormatError(f"{src}: expected a video ({', '.join(VIDEO_SUFFIXES)}) or a folder of frames, "
                          f"got a {src.suffix or 'suffix-less'} file")
    if not (isinstance(spec.start, int) and spec.start >= 0):
        raise ValueError(f"start: expected an integer >= 0, got {spec.start!r}")
    if spec.stop is not None and not (isinstance(spec.stop, int) and spec.stop >= spec.start + 2):
        raise ValueError(f"stop: expected an integer >= start + 2 (a pair at least), got {spec.stop!r} "
                         f"with start {spec.start}")
    if not (math.isfinite(spec.scale) and spec.scale > 0):
        raise ValueError(f"scale: expected a finite number > 0, got {spec.scale!r}")
    if spec.fps is not None and not (math.isfinite(spec.fps) and spec.fps > 0):
        raise ValueError(f"fps: expected a finite number > 0, got {spec.fps!r}")
    if spec.gt_format not in MOT_LAYOUTS:
        raise ValueError(f"gt_format: expected one of {', '.join(MOT_LAYOUTS)}, got {spec.gt_format!r}")
    if spec.gt is not None and not Path(spec.gt).is_file():
        raise FormatError(f"{spec.gt}: no such ground-truth file")
    if spec.flow is not None and not Path(spec.flow).is_dir():
        raise FormatError(f"{spec.flow}: no such flow folder")
    if spec.yolo and spec.kind != "frames":
        raise ValueError(f"yolo: YOLO labels sit beside the frames of a folder; {src} is a video")


# --------------------------------------------------------------------------- what is read


def _source_frames(spec: FootageSpec) -> list[Path]:
    """The frame files of the range of a frames folder (the whole range must exist)."""
    files = list_frame_files(spec.source)
    stop = len(files) if spec.stop is None else spec.stop
    if stop > len(files):
        raise FormatError(f"{spec.source}: stop {stop}: the folder holds {len(files)} frames")
    if stop - spec.start < 2:
        raise FormatError(f"{spec.source}: {max(stop - spec.start, 0)} frame(s) from start {spec.start}; "
                          f"a sequence needs at least 2")
    return files[spec.start:stop]


def _yolo_files(spec: FootageSpec, frames: list[Path]) -> list[Path | None] | None:
    """The label file of each frame (None where absent), or None when YOLO labels are not read."""
    if spec.kind != "frames" or spec.yolo is False:
        return None
    labels = [f.with_suffix(".txt") if f.with_suffix(".txt").is_file() else None for f in frames]
    if not any(labels):
        if spec.yolo:
            raise FormatError(f"{spec.source}: yolo: no NAME.txt label file beside any frame of the range")
        return None
    return labels


def _classes_file(spec: FootageSpec) -> Path | None:
    for folder in (Path(spec.source), Path(spec.source).parent):
        if (folder / "classes.txt").is_file():
            return folder / "classes.txt"
    return None


def gt_labels_file(spec: FootageSpec) -> Path | None:
    """``labels.txt`` beside a ``mot`` ground truth (CVAT's and Datumaro's MOT export), or None."""
    if spec.gt is None or spec.gt_format != "mot":
        return None
    path = Path(spec.gt).parent / "labels.txt"
    return path if path.is_file() else None


def read_gt(spec: FootageSpec) -> pd.DataFrame:
    """The parsed ground truth of ``spec`` (:func:`scenes.formats.read_mot_gt`), its ``labels.txt`` applied."""
    labels = gt_labels_file(spec)
    return read_mot_gt(spec.gt, layout=spec.gt_format,
                       labels=read_mot_labels(labels) if labels is not None else None)


def clip_frames(spec: FootageSpec) -> int | None:
    """The number of frames of the range, where known before decoding: a folder's files, a video container's
    stated frame count (MP4 states it, Matroska not: None), ``stop - start`` when given."""
    if spec.kind == "frames":
        return len(_source_frames(spec))
    total = _video_header(Path(spec.source))[1]
    if total is None:
        return None if spec.stop is None else spec.stop - spec.start
    return max(min(total, spec.stop if spec.stop is not None else total) - spec.start, 0)


def _check_gt_range(gt: pd.DataFrame, spec: FootageSpec, n: int | None) -> None:
    """Refuse a ground truth with no line in the frames ``[start, start + n)`` (1-based in the file)."""
    lo = spec.start + 1
    hi = spec.start + n if n is not None else (spec.stop if spec.stop is not None else None)
    inside = gt["frame"] >= lo
    if hi is not None:
        inside &= gt["frame"] <= hi
    if not inside.any():
        span = f"{lo}..{hi}" if hi is not None else f"{lo} on"
        raise FormatError(f"{spec.gt}: no annotation in the clip's frames {span} (1-based); the file's frames run "
                          f"{int(gt['frame'].min())}..{int(gt['frame'].max())} (another clip's truth, or a "
                          f"different --frames?)")


_FLOW_NAME = re.compile(r"^(\d+)(?:_10)?$")


def _flow_files(spec: FootageSpec, n_source: int | None) -> dict[int, Path]:
    """Pair index in the sequence -> flow file, for the pairs of the range."""
    if spec.flow is None:
        return {}
    out: dict[int, Path] = {}
    for p in sorted(Path(spec.flow).iterdir(), key=lambda p: natural_key(p.name)):
        m = _FLOW_NAME.match(p.stem)
        if not (p.is_file() and m and p.suffix.lower() in (".flo", ".png")):
            continue
        i = int(m.group(1)) - spec.start
        last = (spec.stop if spec.stop is not None else (n_source or 1 << 60)) - spec.start - 1
        if 0 <= i < last:
            if i in out:
                raise FormatError(f"{p}: a second flow file for pair {i + spec.start} (first: {out[i].name})")
            out[i] = p
    if not out:
        raise FormatError(f"{spec.flow}: no flow file (N.flo, N.png or N_10.png, N a source frame index) "
                          f"for a pair of the range")
    return out


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_HASH_BLOCK), b""):
            h.update(block)
    return h.hexdigest()


def _read_files(spec: FootageSpec) -> list[Path]:
    """Every file ingestion reads, in a fixed order."""
    files: list[Path] = []
    if spec.kind == "frames":
        frames = _source_frames(spec)
        files += frames
        labels = _yolo_files(spec, frames)
        if labels is not None:
            files += [p for p in labels if p is not None]
            cls = _classes_file(spec)
            if cls is not None and spec.classes is None:
                files.append(cls)
    else:
        files.append(Path(spec.source))
    if spec.gt is not None:
        files.append(Path(spec.gt))
        if gt_labels_file(spec) is not None:
            files.append(gt_labels_file(spec))
    files += [p for _, p in sorted(_flow_files(spec, None).items())]
    return files


def footage_hash(spec: FootageSpec) -> str:
    """sha256 (hex) of the bytes of every file read, the options, :data:`FOOTAGE_VERSION` and the layout."""
    check_footage(spec)
    h = hashlib.sha256()
    h.update(json.dumps({"options": spec.options(), "version": FOOTAGE_VERSION, "layout": SEQUENCE_LAYOUT},
                        sort_keys=True).encode())
    for p in _read_files(spec):
        h.update(f"|{p.name}|{_sha256(p)}".encode())
    return h.hexdigest()


def footage_key(spec: FootageSpec, digest: str | None = None) -> str:
    """The cache entry name of a clip: its label and 20 hex digits of :func:`footage_hash`."""
    digest = digest or footage_hash(spec)
    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", spec.name).strip("._")[:40] or "footage"
    return f"real-{label}-{digest[:20]}"


def validate_footage(spec: FootageSpec) -> str:
    """Read what can be read cheaply before a run starts and return :func:`footage_hash`.

    Every annotation file is parsed (each line checked), every flow file read, the video
    opened and its first frame decoded, so that a bad file is refused before anything is
    written (the CLI's exit 2). A video damaged further in is found when it is decoded.
    """
    check_footage(spec)
    if spec.gt is not None:
        _check_gt_range(read_gt(spec), spec, clip_frames(spec))
    if spec.kind == "frames":
        labels = _yolo_files(spec, _source_frames(spec))
        for p in labels or []:
            if p is not None:
                read_yolo_boxes(p)
        if labels is not None:
            _class_names(spec)
    else:
        next(_decode_video(Path(spec.source), 0, 1), None)
    for p in _flow_files(spec, None).values():
        read_flo(p) if p.suffix.lower() == ".flo" else read_kitti_flow(p)
    return footage_hash(spec)


# --------------------------------------------------------------------------- decoding


def _decode_video(path: Path, start: int, stop: int | None) -> Iterator[np.ndarray]:
    """The frames ``[start, stop)`` of a video as (H, W, 3) uint8 RGB (PyAV, else OpenCV)."""
    try:
        import av
    except ImportError:  # OpenCV's FFmpeg build reads the same containers
        av = None
    if av is not None:
        try:
            with av.open(str(path)) as container:
                if not container.streams.video:
                    raise FormatError(f"{path}: no video stream")
                stream = container.streams.video[0]
                for i, frame in enumerate(container.decode(stream)):
                    if i < start:
                        continue
                    if stop is not None and i >= stop:
                        return
                    yield frame.to_ndarray(format="rgb24")
        except av.error.FFmpegError as exc:
            raise FormatError(f"{path}: not a readable video ({exc})") from None
        return
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise FormatError(f"{path}: not a readable video (OpenCV could not open it)")
        i = 0
        while stop is None or i < stop:
            ok, bgr = cap.read()
            if not ok:
                return
            if i >= start:
                yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            i += 1
    finally:
        cap.release()


def _video_header(path: Path) -> tuple[float | None, int | None]:
    """The frame rate and frame count a video's container states (None for what it states not; nothing decoded)."""
    try:
        import av
    except ImportError:
        cap = cv2.VideoCapture(str(path))
        fps, count = cap.get(cv2.CAP_PROP_FPS), cap.get(cv2.CAP_PROP_FRAME_COUNT)
        cap.release()
        return (float(fps) if fps and fps > 0 else None), (int(count) if count and count > 0 else None)
    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                return None, None
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate
            return (float(rate) if rate else None), (int(stream.frames) if stream.frames and stream.frames > 0
                                                      else None)
    except av.error.FFmpegError as exc:
        raise FormatError(f"{path}: not a readable video ({exc})") from None


def _read_image(path: Path) -> np.ndarray:
    data = np.fromfile(path, np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if img is None:
        raise FormatError(f"{path}: not a readable image (truncated or corrupt)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _resize(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    w, h = size
    if (img.shape[1], img.shape[0]) == (w, h):
        return img
    shrink = w < img.shape[1]
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def _scaled_size(w: int, h: int, scale: float) -> tuple[int, int]:
    return max(1, int(round(w * scale))), max(1, int(round(h * scale)))


# --------------------------------------------------------------------------- annotations -> tables


def _edges_to_columns(L, T, R, B, sx: float, sy: float) -> dict:
    """Edge-coordinate boxes ``[L, R] x [T, B]`` of the source -> the scaled centre and box in pixel-centre
    coordinates."""
    x0, x1 = np.asarray(L, float) * sx - 0.5, np.asarray(R, float) * sx - 0.5
    y0, y1 = np.asarray(T, float) * sy - 0.5, np.asarray(B, float) * sy - 0.5
    return {"x_px": (x0 + x1) / 2, "y_px": (y0 + y1) / 2, "bbox_x0_px": x0, "bbox_y0_px": y0,
            "bbox_x1_px": x1, "bbox_y1_px": y1}


def _gt_tables(gt: pd.DataFrame, spec: FootageSpec, n: int, sx: float, sy: float) -> tuple[pd.DataFrame, pd.DataFrame]:
    """tracks.csv and ignore.csv rows of a parsed ground truth, in the range, re-indexed from 0."""
    g = gt.copy()
    g["frame"] = g["frame"] - 1 - spec.start
    g = g[(g["frame"] >= 0) & (g["frame"] < n)]
    L, T = g["left"] - 1.0, g["top"] - 1.0  # the left and top edges, pixels numbered from 0
    cols = _edges_to_columns(L, T, L + g["width"], T + g["height"], sx, sy)
    full = pd.DataFrame({"frame": g["frame"].to_numpy(np.int64), "vehicle_id": g["id"].to_numpy(np.int64),
                         **{k: np.asarray(v) for k, v in cols.items()}, "visible": 1,
                         "class": g["class"].to_numpy(object), "visible_fraction": g["visible_fraction"].to_numpy(float)})
    keep = ~g["ignore"].to_numpy(bool)
    tracks = full[keep].sort_values(["frame", "vehicle_id"], kind="stable").reset_index(drop=True)
    ignore = full[~keep].sort_values(["frame"], kind="stable").reset_index(drop=True)
    return tracks[REAL_TRACK_COLUMNS], ignore[IGNORE_COLUMNS]


def _class_names(spec: FootageSpec) -> list[str] | None:
    if spec.classes is not None:
        names = list(spec.classes)
    else:
        path = _classes_file(spec)
        if path is None:
            return None
        names = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    return [n if n in TRUTH_CLASSES else _CLASS_ALIASES.get(n.lower(), n) for n in names]


def _yolo_table(labels: list, spec: FootageSpec, sizes: list[tuple[int, int]], sx: float,
                sy: float) -> pd.DataFrame:
    names = _class_names(spec)
    rows = []
    for i, (path, (w, h)) in enumerate(zip(labels, sizes)):
        if path is None:
            continue
        b = read_yolo_boxes(path)
        if names is not None and len(b) and b[:, 0].max() >= len(names):
            bad = int(np.flatnonzero(b[:, 0] >= len(names))[0])
            raise FormatError(f"{path}: box {bad + 1}: class {int(b[bad, 0])}, but {len(names)} class names are "
                              f"given ({', '.join(names)})")
        L, R = (b[:, 1] - b[:, 3] / 2) * w, (b[:, 1] + b[:, 3] / 2) * w
        T, B = (b[:, 2] - b[:, 4] / 2) * h, (b[:, 2] + b[:, 4] / 2) * h
        cols = _edges_to_columns(L, T, R, B, sx, sy)
        cls = [names[int(c)] if names is not None else str(int(c)) for c in b[:, 0]]
        rows.append(pd.DataFrame({"frame": i, "class": cls, **cols}))
    if not rows:
        return pd.DataFrame(columns=BOX_COLUMNS)
    return pd.concat(rows, ignore_index=True)[BOX_COLUMNS]


def _flow_truth(path: Path, src_size: tuple[int, int], size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A flow file (``.flo`` or KITTI PNG) at the source size, resampled to ``size``: (flow, valid)."""
    if path.suffix.lower() == ".flo":
        flow = read_flo(path)
        valid = np.isfinite(flow).all(-1)
    else:
        flow, valid = read_kitti_flow(path)
    if (flow.shape[1], flow.shape[0]) != src_size:
        raise FormatError(f"{path}: {flow.shape[1]}x{flow.shape[0]} flow, the frames are {src_size[0]}x{src_size[1]}")
    if size != src_size:
        # nearest neighbour: a sparse truth (KITTI) must not be blended with its unknown pixels
        sx, sy = size[0] / src_size[0], size[1] / src_size[1]
        flow = cv2.resize(flow, size, interpolation=cv2.INTER_NEAREST) * np.float32([sx, sy])
        valid = cv2.resize(valid.view(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
    flow = np.where(valid[..., None], flow, np.nan).astype(np.float32)
    return flow, valid


# --------------------------------------------------------------------------- writing


def write_footage(spec: FootageSpec, folder: str | os.PathLike, *, digest: str | None = None) -> None:
    """Decode ``spec`` into the (empty, temporary) sequence folder ``folder``; see the module docstring.

    Raises
    ------
    FormatError
        a file that cannot be read, naming it (and the line of a text file).
    ValueError
        an option that cannot work, naming it.
    """
    check_footage(spec)
    folder = Path(folder)
    digest = digest or footage_hash(spec)
    # parse every annotation before decoding a frame: a bad line fails fast
    gt = read_gt(spec) if spec.gt is not None else None
    frame_files = _source_frames(spec) if spec.kind == "frames" else None
    labels = _yolo_files(spec, frame_files) if frame_files is not None else None
    if labels is not None:
        for p in labels:
            if p is not None:
                read_yolo_boxes(p)
    fps = spec.fps if spec.fps is not None else (_video_header(Path(spec.source))[0] if spec.kind == "video" else None)

    out = _FolderWriter(folder, threads=2)
    try:
        src_size: tuple[int, int] | None = None
        size: tuple[int, int] | None = None
        sizes: list[tuple[int, int]] = []
        if frame_files is not None:
            images = (_read_image(p) for p in frame_files)
            where = [str(p) for p in frame_files]
        else:
            images = _decode_video(Path(spec.source), spec.start, spec.stop)
            where = None
        n = 0
        for img in images:
            here = where[n] if where is not None else f"{spec.source}: frame {spec.start + n}"
            wh = (img.shape[1], img.shape[0])
            if src_size is None:
                src_size, size = wh, _scaled_size(*wh, spec.scale)
            elif wh != src_size:
                raise FormatError(f"{here}: {wh[0]}x{wh[1]}, the first frame is {src_size[0]}x{src_size[1]}")
            sizes.append(wh)
            out.submit(f"frames/{n:06d}.png", encode_png_fast, np.ascontiguousarray(_resize(img, size)))
            n += 1
        if spec.kind == "video":
            if spec.stop is not None and spec.start + n < spec.stop:
                raise FormatError(f"{spec.source}: stop {spec.stop}: the video has {spec.start + n} frames")
            if n < 2:
                raise FormatError(f"{spec.source}: {n} frame(s) from start {spec.start}; a sequence needs at least 2")
        sx, sy = size[0] / src_size[0], size[1] / src_size[1]
        annotations: dict = {"tracks": None, "ids": False, "boxes": None, "ignore_regions": 0, "flow_pairs": [],
                              "camera": False, "instances": False}
        if gt is not None:
            _check_gt_range(gt, spec, n)
            tracks, ignore = _gt_tables(gt, spec, n, sx, sy)
            out.write("tracks.csv", _csv_bytes(REAL_TRACK_COLUMNS, tracks.to_dict("records")))
            annotations.update(tracks=spec.gt_format, ids=True, ignore_regions=len(ignore))
            if len(ignore):
                out.write("ignore.csv", _csv_bytes(IGNORE_COLUMNS, ignore.to_dict("records")))
        if labels is not None:
            boxes = _yolo_table(labels, spec, sizes, sx, sy)
            out.write("boxes.csv", _csv_bytes(BOX_COLUMNS, boxes.to_dict("records")))
            annotations["boxes"] = "yolo"
        for i, path in sorted(_flow_files(spec, spec.start + n).items()):
            if i >= n - 1:
                continue
            flow, valid = _flow_truth(path, src_size, size)
            out.write(f"flow/{i:06d}.flo", encode_flo(flow))
            out.write(f"valid/{i:06d}.png", encode_png(valid.view(np.uint8) * np.uint8(255), **MASK_PNG))
            annotations["flow_pairs"].append(i)
        meta = {"source": "real", "name": spec.name, "width": size[0], "height": size[1], "n_frames": n,
                "fps": fps, "scale_xy": [sx, sy], "source_path": str(spec.source), "source_kind": spec.kind,
                "source_size": list(src_size), "start": spec.start, "stop": spec.start + n,
                "footage_hash": digest, "footage_version": FOOTAGE_VERSION, "layout": SEQUENCE_LAYOUT,
                "flow_format": "flo", "annotations": annotations, "options": spec.options(),
                "gt_path": spec.gt, "flow_path": spec.flow}
        out.write("meta.json", json.dumps(meta, indent=1, sort_keys=True).encode())
        out.write_manifest({"footage_hash": digest, "layout": SEQUENCE_LAYOUT, "flow_format": "flo",
                            "source": "real"})
    finally:
        out.close()


def ingest_footage(spec: FootageSpec, out_dir: str | os.PathLike) -> Path:
    """Decode ``spec`` into the sequence folder ``out_dir`` (absent or empty); nothing is left on error."""
    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise FileExistsError(f"{out_dir}: exists and is not an empty folder")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        write_footage(spec, tmp)
        if out_dir.exists():
            out_dir.rmdir()
        os.rename(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


# --------------------------------------------------------------------------- export (the round trip)

# our classes -> MOTChallenge class ids (MOT has no van, truck or bus: they are cars there)
_MOT_CLASS_IDS = {"car": 3, "van": 3, "truck": 3, "bus": 3, "motorbike": 5, "cyclist": 4, "pedestrian": 1}


def export_mot_gt(tracks: pd.DataFrame, path: str | os.PathLike, *, counted: np.ndarray | None = None,
                  distractors: np.ndarray | None = None) -> Path:
    """Write a sequence's tracks.csv as a MOTChallenge ``gt.txt`` (9 columns, MOT16/17 layout).

    Which rows, and with which flag: without ``counted`` and ``distractors``, every visible row
    of a road user that is not parked, flag 1. With them (``(N,)`` bool over the rows of
    ``tracks``: what the synthetic path counts and treats as distractors,
    ``harness.metrics.objects``; the CLI's ``export`` passes them), the rows that are counted
    objects or distractors: a counted row and a pedestrian's or cyclist's row (read back as a
    distractor by its class) with flag 1, any other distractor (a vehicle that stands still all
    clip, a row of a vehicle under half visible: what the synthetic path does not count and does
    not hold against a tracker) with flag 0, ignored; rows that are
    neither (a parked car: a track on it is a false positive) are left out. So the real path
    scores the export as the synthetic path scores the sequence, whatever those rules say.

    One line per row written: frame + 1, vehicle_id, the box as :func:`scenes.formats.mot_box`
    writes it (``bb_left = x0 + 1.5``, ``bb_width = x1 - x0``: the inverse of the reader's
    conversion, written with every digit of the float64, so the boxes come back to an ulp or two:
    ``x0 + 1.5`` and the reader's ``- 1.5`` each round),
    the flag, the class id (car 3 for car, van, truck, bus; 5 motorbike; 4 cyclist; 1 pedestrian;
    3 without a class column), visibility (``visible_fraction``, 1 without it). A real reading
    takes the box centre as the vehicle's position, which for a rendered vehicle differs from
    its projected centre ``x_px, y_px`` by up to about a pixel.
    """
    cls_all = tracks["class"].astype(str) if "class" in tracks.columns else pd.Series("car", index=tracks.index)
    if (counted is None) != (distractors is None):
        raise ValueError("counted, distractors: expected both or neither")
    if counted is None:
        keep = tracks["visible"].astype(int).to_numpy() > 0
        if "parked" in tracks.columns:  # a motion benchmark's truth holds the vehicles that move, as the
            keep &= tracks["parked"].astype(int).to_numpy() == 0  # synthetic path counts them: parked ones out
        flag = np.ones(len(tracks), int)
    else:
        counted, distractors = (np.asarray(m, bool).reshape(-1) for m in (counted, distractors))
        if len(counted) != len(tracks) or len(distractors) != len(tracks):
            raise ValueError(f"counted, distractors: expected {len(tracks)} flags each (one per row), got "
                             f"{len(counted)} and {len(distractors)}")
        keep = counted | distractors
        flag = (counted | (distractors & cls_all.isin(["pedestrian", "cyclist"]).to_numpy())).astype(int)
    t = tracks.assign(_flag=flag, _cls=cls_all)[keep].sort_values(["frame", "vehicle_id"], kind="stable")
    vis = t["visible_fraction"] if "visible_fraction" in t.columns else pd.Series(1.0, index=t.index)
    lines = []
    for r, c, v, fl in zip(t.itertuples(index=False), t["_cls"], vis, t["_flag"]):
        box = mot_box(r.bbox_x0_px, r.bbox_y0_px, r.bbox_x1_px, r.bbox_y1_px)
        lines.append(",".join([str(int(r.frame) + 1), str(int(r.vehicle_id)), *(repr(float(b)) for b in box),
                               str(int(fl)), str(_MOT_CLASS_IDS.get(str(c), 3)), repr(float(v))]))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def export_frames(frames, out_dir: str | os.PathLike) -> Path:
    """Write every frame of ``frames`` (an indexable of (H, W, 3) uint8 RGB, e.g. a Sequence) as
    ``out_dir/000001.png ...`` (1-based, as MOTChallenge's ``img1/``): lossless."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for i in range(len(frames)):
        (out_dir / f"{i + 1:06d}.png").write_bytes(encode_png(np.asarray(frames[i])))
    return out_dir


def export_video(frames, path: str | os.PathLike, *, fps: float = 25.0, codec: str | None = None) -> Path:
    """Write ``frames`` (an indexable of (H, W, 3) uint8 RGB) as a lossless video by PyAV.

    ``codec``: ``ffv1`` (RGB as bgr0) or ``libx264rgb`` (H.264 in RGB at crf 0); default by the
    suffix: ffv1 for ``.mkv`` and ``.avi``, libx264rgb for ``.mp4`` and ``.mov``. Either way the
    frames decode back bit for bit (``tests/scenes/test_footage.py``).
    """
    import av
    from fractions import Fraction

    pix = {"ffv1": "bgr0", "libx264rgb": "rgb24"}
    suffix = Path(path).suffix.lower()
    if codec is None:
        codec = "libx264rgb" if suffix in (".mp4", ".mov") else "ffv1"
    if codec not in pix:
        raise ValueError(f"codec: expected one of {', '.join(pix)} (lossless), got {codec!r}")
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"path: expected a {', '.join(VIDEO_SUFFIXES)} file, got {path}")
    path = Path(path)
    first = np.asarray(frames[0])
    with av.open(str(path), "w") as container:
        stream = container.add_stream(codec, rate=Fraction(fps).limit_denominator(1001))
        stream.width, stream.height, stream.pix_fmt = first.shape[1], first.shape[0], pix[codec]
        if codec == "libx264rgb":
            stream.options = {"crf": "0", "preset": "ultrafast"}
        for i in range(len(frames)):
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(frames[i]), format="rgb24")
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path
