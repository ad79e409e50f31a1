"""Readers for external optical-flow data sets with ground truth, and their evaluation.

Three layouts, each read into :class:`FlowPair` (frames as stored, ground-truth
flow in our layout with NaN where unknown, and a ``valid`` mask):

* ``middlebury``: any folder under ``root`` holding one ``.flo`` file and two
  PNG frames whose names end in consecutive numbers with the same prefix
  (``frame10.png, frame11.png, flow10.flo``; ``yos9.png, yos10.png,
  correct_yos.flo``; ...). The pair is found by the files present. Yosemite
  (a folder or frame prefix starting with ``yos``) has its sky masked: the
  black pixels of the first frame connected to the top edge in their column,
  and pixels whose ground truth is the placeholder (1, 0) exactly (the
  horizon's anti-aliased pixels carry it too); black pixels on the ground stay.
* ``sintel``: ``root/<pass>/<scene>/frame_NNNN.png`` with
  ``root/flow/<scene>/frame_NNNN.flo`` (``pass`` "clean" or "final");
  ``root/invalid/<scene>/frame_NNNN.png`` (non-zero = invalid) is used when present.
* ``kitti``: ``root/image_2/NNNNNN_10.png, NNNNNN_11.png`` and
  ``root/flow_occ/NNNNNN_10.png`` (or ``flow_noc``): a 16-bit RGB PNG whose
  channels are u, v, valid; ``u = (R - 2**15) / 64`` px, valid where B > 0.
  A PNG of another bit depth is refused.

Public functions
----------------
FlowPair                                      name, frame0, frame1, flow (H, W, 2), valid (H, W)
read_middlebury(root), read_sintel(root, *, pass_="clean"), read_kitti(root, *, occ=True)
read_kitti_flow(path), write_kitti_flow(path, flow, valid)
FORMATS                                       format name -> reader
iter_pairs(root, *, format)                   the pairs of a data set
evaluate_flow_dataset(root, *, format, method, params=None) -> DataFrame of results-schema rows
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from algorithms.registry import get_flow_method
from harness.metrics import score_flow
from harness.results import rows_to_frame
from scenes.formats import (KITTI_OFFSET, KITTI_SCALE, FormatError, read_flo, read_kitti_flow, read_png,
                            write_kitti_flow)

__all__ = ["FlowPair", "FORMATS", "read_middlebury", "read_sintel", "read_kitti", "read_kitti_flow",
           "write_kitti_flow", "iter_pairs", "evaluate_flow_dataset", "KITTI_SCALE", "KITTI_OFFSET"]


@dataclass
class FlowPair:
    """One frame pair with ground truth: frames as stored, ``flow`` (H, W, 2) float32 (NaN unknown),
    ``valid`` (H, W) bool (known, and not masked)."""

    name: str
    frame0: np.ndarray
    frame1: np.ndarray
    flow: np.ndarray
    valid: np.ndarray


def _check_pair(p: FlowPair, where: str) -> FlowPair:
    h, w = p.flow.shape[:2]
    for label, f in (("frame0", p.frame0), ("frame1", p.frame1)):
        if f.shape[:2] != (h, w):
            raise FormatError(f"{where}: {label} is {f.shape[:2]}, the ground-truth flow {(h, w)}")
    return p


# --------------------------------------------------------------------------- Middlebury

_NUMBERED = re.compile(r"^(.*?)(\d+)\.png$", re.IGNORECASE)


def _middlebury_folder(folder: Path) -> FlowPair | None:
    flos = sorted(folder.glob("*.flo"))
    if len(flos) != 1:
        return None
    frames: dict[tuple[str, int], Path] = {}
    for p in folder.glob("*.png"):
        m = _NUMBERED.match(p.name)
        if m:
            frames[(m.group(1), int(m.group(2)))] = p
    pairs = sorted(k for k in frames if (k[0], k[1] + 1) in frames)
    if len(pairs) != 1:
        if pairs:
            raise FormatError(f"{folder}: {len(pairs)} candidate frame pairs next to {flos[0].name}: "
                              f"{[frames[k].name for k in pairs]}; expected exactly one")
        return None
    prefix, n = pairs[0]
    frame0, frame1 = read_png(frames[(prefix, n)]), read_png(frames[(prefix, n + 1)])
    flow = read_flo(flos[0])
    valid = np.isfinite(flow).all(-1)
    if folder.name.lower().startswith("yos") or prefix.lower().startswith("yos"):
        black = (frame0 == 0) if frame0.ndim == 2 else (frame0 == 0).all(-1)
        sky = np.cumprod(black, axis=0).astype(bool)  # black pixels connected to the top edge in their column
        placeholder = (flow[..., 0] == 1.0) & (flow[..., 1] == 0.0)
        valid &= ~(sky | placeholder)
    return _check_pair(FlowPair(folder.name, frame0, frame1, flow, valid), str(folder))


def read_middlebury(root: str | os.PathLike) -> list[FlowPair]:
    """Every Middlebury-style pair under ``root`` (recursively), sorted by relative folder path."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such data set folder")
    out = []
    for folder in sorted({p.parent for p in root.rglob("*.flo")}):
        pair = _middlebury_folder(folder)
        if pair is not None:
            pair.name = folder.relative_to(root).as_posix() if folder != root else folder.name
            out.append(pair)
    if not out:
        raise FormatError(f"{root}: no Middlebury-style pair (two numbered PNG frames and one .flo per folder)")
    return out


# --------------------------------------------------------------------------- Sintel

def read_sintel(root: str | os.PathLike, *, pass_: str = "clean") -> list[FlowPair]:
    """Every pair of a Sintel training layout for ``pass_`` ("clean" or "final")."""
    root = Path(root)
    if pass_ not in ("clean", "final"):
        raise ValueError(f"pass_: expected 'clean' or 'final', got {pass_!r}")
    if not (root / pass_).is_dir() or not (root / "flow").is_dir():
        raise FormatError(f"{root}: not a Sintel layout: expected folders {pass_}/ and flow/")
    out = []
    for flo in sorted((root / "flow").glob("*/*.flo")):
        scene, stem = flo.parent.name, flo.stem
        m = re.match(r"^frame_(\d+)$", stem)
        if not m:
            continue
        n = int(m.group(1))
        width = len(m.group(1))
        f0 = root / pass_ / scene / f"frame_{n:0{width}d}.png"
        f1 = root / pass_ / scene / f"frame_{n + 1:0{width}d}.png"
        if not (f0.is_file() and f1.is_file()):
            raise FormatError(f"{flo}: frames {f0.name} and {f1.name} expected in {f0.parent}")
        flow = read_flo(flo)
        valid = np.isfinite(flow).all(-1)
        inv = root / "invalid" / scene / f"{stem}.png"
        if inv.is_file():
            mask = read_png(inv)
            valid &= (mask == 0) if mask.ndim == 2 else (mask == 0).all(-1)
        out.append(_check_pair(FlowPair(f"{scene}/{stem}", read_png(f0), read_png(f1), flow, valid), str(flo)))
    if not out:
        raise FormatError(f"{root}: no flow/<scene>/frame_NNNN.flo files")
    return out


# --------------------------------------------------------------------------- KITTI

def read_kitti(root: str | os.PathLike, *, occ: bool = True) -> list[FlowPair]:
    """Every pair of a KITTI training layout (``flow_occ`` if ``occ`` else ``flow_noc``)."""
    root = Path(root)
    gt_dir = root / ("flow_occ" if occ else "flow_noc")
    if not (root / "image_2").is_dir() or not gt_dir.is_dir():
        raise FormatError(f"{root}: not a KITTI layout: expected folders image_2/ and {gt_dir.name}/")
    out = []
    for gt in sorted(gt_dir.glob("*_10.png")):
        stem = gt.name[: -len("_10.png")]
        f0, f1 = root / "image_2" / f"{stem}_10.png", root / "image_2" / f"{stem}_11.png"
        if not (f0.is_file() and f1.is_file()):
            raise FormatError(f"{gt}: frames {f0.name} and {f1.name} expected in {f0.parent}")
        flow, valid = read_kitti_flow(gt)
        out.append(_check_pair(FlowPair(stem, read_png(f0), read_png(f1), flow, valid), str(gt)))
    if not out:
        raise FormatError(f"{gt_dir}: no NNNNNN_10.png flow files")
    return out


FORMATS: dict[str, Callable[..., list[FlowPair]]] = {
    "middlebury": read_middlebury, "sintel": read_sintel, "kitti": read_kitti,
}


def iter_pairs(root: str | os.PathLike, *, format: str) -> Iterator[FlowPair]:
    """The pairs of the data set at ``root`` in ``format`` (one of :data:`FORMATS`)."""
    try:
        reader = FORMATS[format]
    except KeyError:
        raise KeyError(f"unknown data set format {format!r}; valid: {', '.join(FORMATS)}") from None
    yield from reader(root)


def evaluate_flow_dataset(root: str | os.PathLike, *, format: str, method: str | Callable,
                          params: Mapping | None = None) -> pd.DataFrame:
    """Run a flow method on every pair of a data set and score it (region "all", motion "total").

    Returns a results-schema table (:func:`harness.results.rows_to_frame`):
    ``scene`` = ``"<format>:<pair name>"``, ``pipeline`` = the method name,
    ``frame`` 0, one row per metric (``coverage`` included); ``method`` is a
    name of ``algorithms.registry.FLOW_METHODS`` or a callable of the same
    signature ``(frame0, frame1, **params) -> (flow, valid)``, so
    ``summarize`` / ``aggregate`` work on it as on synthetic results.
    """
    if isinstance(method, str):
        import algorithms.pipeline  # noqa: F401  (its imports fill the flow method registry)

        fn = get_flow_method(method)
    else:
        fn = method
    name = method if isinstance(method, str) else getattr(method, "__name__", "method")
    params = dict(params or {})
    parts = []
    for pair in iter_pairs(root, format=format):
        flow, valid = fn(pair.frame0, pair.frame1, **params)
        rows = score_flow(flow, pair.flow, pair.valid, valid_est=valid, regions=("all",), motion="total", frame=0)
        parts.append(rows_to_frame(rows, cell_id=f"{format}:{pair.name}:{name}", scene=f"{format}:{pair.name}",
                                   pipeline=name))
    return pd.concat(parts, ignore_index=True)
