"""Score one cell: run its pipeline on its sequence pair by pair, score each pair at once, then the sequence.

Memory stays bounded by a few frames: the sequence is opened lazily, and every pair's
arrays are dropped as soon as the pair is scored (and its flows written when it is a
picture pair). What a cell is and where its files go is :mod:`harness.tasks`'.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness import cell_artifacts as artifacts

__all__ = ["score_cell", "point_seeds", "warm_up"]


class _Frames:
    """The frames of a sequence as an indexable (``len``, ``[i]``) read lazily from disk."""

    def __init__(self, seq: Any):
        self._seq = seq

    def __len__(self) -> int:
        return len(self._seq)

    def __getitem__(self, i: int) -> np.ndarray:
        if not 0 <= i < len(self._seq):
            raise IndexError(i)
        return self._seq.frame(i)


def point_seeds(tracks: pd.DataFrame) -> list[tuple[int, float, float]]:
    """Seeds for the point tracker: ground-truth centres of the vehicles visible in frame 0."""
    if tracks is None or len(tracks) == 0:
        return []
    first = tracks[(tracks["frame"] == 0) & (tracks["visible"].astype(int) == 1)]
    first = first.sort_values("vehicle_id")
    return [(int(r.vehicle_id), float(r.x_px), float(r.y_px)) for r in first.itertuples()]


def _as_rows(rows: Any) -> list[dict]:
    if rows is None:
        return []
    if isinstance(rows, pd.DataFrame):
        return rows.to_dict("records")
    return [dict(r) for r in rows]


def _renderer_of(meta: Mapping) -> str:
    """One line naming what rendered a sequence (renderer and GL strings of meta.json)."""
    parts = [str(meta.get(k)) for k in ("renderer", "gl_renderer", "gl_version") if meta.get(k)]
    return " | ".join(parts)


# pipeline hashes this process has already run once (see warm_up)
_WARMED: set[str] = set()


def warm_up(pipeline: Any) -> None:
    """Run ``pipeline`` once, untimed, on a small synthetic sequence.

    The first call of a numba kernel compiles it (about 6 s for Horn-Schunck
    without an on-disk cache); without this, that cost lands in the stage
    timings of whichever cell a worker happens to run first, and the report's
    time per frame depends on scheduling. Failures are left to the real run.
    """
    if pipeline.hash in _WARMED:
        return
    _WARMED.add(pipeline.hash)
    import cv2

    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur((rng.random((96, 96)) * 255).astype(np.float32), (0, 0), 1.5)
    frames = [np.ascontiguousarray(texture[k:k + 64, k:k + 64]).astype(np.uint8) for k in range(3)]
    try:
        for _ in pipeline.run(frames, seeds=[(1, 32.0, 32.0)]):
            pass
    except Exception:  # noqa: BLE001 - a warm-up only; the real run reports errors
        pass


def score_cell(payload: Mapping, tmp: Path) -> tuple[list[dict], str]:
    """Run one cell's pipeline on its sequence and score it; artifacts go into ``tmp``.

    Returns the metric rows (filtered to ``payload["metrics"]`` when given) and one line
    naming the renderer of the sequence.
    """
    from algorithms.pipeline import Pipeline, SequenceEstimate
    from harness.metrics import score_pair, score_sequence
    from scenes import open_sequence

    seq = open_sequence(payload["sequence"])
    pipeline = Pipeline.from_dict(payload["pipeline_spec"])
    warm_up(pipeline)
    pictures = set(payload["picture_pairs"])
    rows: list[dict] = []
    seq_est = None
    for est in pipeline.run(_Frames(seq), seeds=point_seeds(seq.tracks)):
        if isinstance(est, SequenceEstimate):  # comes last
            seq_est = est
            continue
        truth = seq.pair_truth(est.index)
        rows += _as_rows(score_pair(est, truth, frame=est.index))
        if est.index in pictures:
            artifacts.write_pair_flows(tmp, est.index, est.flow_total, est.flow_global)
        del est, truth  # the arrays of a pair live no longer than its scoring
    if seq_est is None:
        raise RuntimeError("the pipeline yielded no SequenceEstimate")
    rows += _as_rows(score_sequence(seq_est, seq.camera, seq.tracks))
    artifacts.write_stabilisation(tmp, artifacts.stabilisation_table(seq_est, seq.camera))
    artifacts.write_tracks(tmp, artifacts.tracks_table(seq_est, seq.tracks))
    if payload["metrics"] is not None:
        keep = set(payload["metrics"])
        rows = [r for r in rows if r["metric"] in keep]
    return rows, _renderer_of(seq.meta or {})
