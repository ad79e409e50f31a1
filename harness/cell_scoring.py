"""Score cells: run their pipelines on their sequence pair by pair, score each pair at once, then the sequence.

:func:`score_cells` runs the cells of one sequence together, in lock-step: the
pipelines share the decoded frames, pass 1 and compensation
(:class:`algorithms.shared_work.SharedWork`), and each pair's ground truth is read
once for all of them. :func:`score_cell` is one cell alone. Memory stays bounded: the
sequence is opened lazily, gray frames are kept up to a byte budget, and every pair's
arrays are dropped as soon as the pair is scored (and its flows written when it is a
picture pair). What a cell is and where its files go is :mod:`harness.tasks`'.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness import cell_artifacts as artifacts

__all__ = ["score_cell", "score_cells", "CellOutcome", "point_seeds", "warm_up"]


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


def point_seeds(tracks: pd.DataFrame | None) -> list[tuple[int, float, float]]:
    """Seeds for the point tracker: ground-truth centres of the counted vehicles visible in frame 0.

    Counted: :func:`harness.metrics.objects.counted_objects` (vehicles that move; no parked
    car, pedestrian or cyclist), the objects the track metrics score.

    None (real footage without identities: no tracks.csv) gives no seed, so no point tracking.
    """
    if tracks is None or len(tracks) == 0:
        return []
    from harness.metrics.objects import counted_objects

    first = tracks[(tracks["frame"] == 0).to_numpy() & counted_objects(tracks)]
    first = first.sort_values("vehicle_id")
    return [(int(r.vehicle_id), float(r.x_px), float(r.y_px)) for r in first.itertuples()]


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
    naming the renderer of the sequence. Raises what the cell raised.
    """
    (outcome,) = score_cells([payload], [tmp])
    if outcome.error is not None:
        raise outcome.error
    return outcome.rows, outcome.renderer


@dataclass
class CellOutcome:
    """What :func:`score_cells` gives per cell: its rows, or the exception that stopped it."""

    rows: list[dict]
    renderer: str  # one line naming the renderer of the sequence
    error: BaseException | None
    seconds: float  # wall time spent on this cell (its pipeline, scoring, files; shared work where it fell)


class _CellRun:
    """One cell of :func:`score_cells`: its pipeline's estimates as they come, its rows, its time."""

    def __init__(self, payload: Mapping, tmp: Path, frames: Any, seeds: list, shared: Any,
                 gsd_m_per_px: float | None = None):
        from algorithms.pipeline import Pipeline

        self.payload, self.tmp = payload, tmp
        self.rows: list[dict] = []
        self.seq_est = None
        self.error: BaseException | None = None
        self.pictures = set(payload["picture_pairs"])
        self.seconds = 0.0
        self.pairs_done = 0
        pipeline = Pipeline.from_dict(payload["pipeline_spec"])
        warm_up(pipeline)
        self.estimates = pipeline.run(frames, seeds=seeds, shared=shared, gsd_m_per_px=gsd_m_per_px)


def score_cells(payloads: list[Mapping], tmps: list[Path], *,
                progress: Callable[[int, int], None] | None = None) -> list[CellOutcome]:
    """Run the cells of one sequence in lock-step and score them; artifacts go into their ``tmps``.

    Every payload names the same ``sequence``. The pipelines share one
    :class:`algorithms.shared_work.SharedWork` (frames decoded once, pass-1 shifts and
    compensated frames computed once per distinct setting) and each pair's ground truth
    is read and prepared once (:func:`harness.metrics.prepare_pair_truth`) and scored
    against every pipeline's estimate of it; so are the truth-free photometric
    residual's reference check (:func:`harness.metrics.photometric.prepare_photometric`)
    and the pair's ground-truth boxes for detection precision and recall. After the
    pipelines finish, the stabilised video's ITF is computed per cell, the frames read
    once for all. A pipeline's rows are the rows it gives alone. A cell that raises stops alone (its outcome carries the
    exception), the others go on. Returns one :class:`CellOutcome` per payload, in order.

    ``progress(done, total)``, if given, is called after every pair scored: pairs done over all the
    cells, of ``(frames - 1) x cells`` (a cell that stops early counts its pairs as done).
    """
    from algorithms.pipeline import SequenceEstimate
    from algorithms.shared_work import SharedWork
    from harness.metrics import prepare_pair_truth, score_pair
    from harness.metrics.detection import detection_rows
    from harness.metrics.photometric import photometric_rows, prepare_photometric
    from scenes import open_sequence

    if len(payloads) != len(tmps) or not payloads:
        raise ValueError(f"score_cells: expected as many folders as payloads (>= 1), got {len(tmps)} "
                         f"for {len(payloads)}")
    paths = {str(p["sequence"]) for p in payloads}
    if len(paths) != 1:
        raise ValueError(f"score_cells: expected the cells of one sequence, got {sorted(paths)}")
    seq = open_sequence(paths.pop())
    frames = _Frames(seq)
    shared = SharedWork(frames)
    seeds = point_seeds(seq.tracks)
    # the ground sampling distance, where the sequence knows it: detections get an area in m^2
    gsd = seq.meta.get("gsd_m")
    gsd = float(gsd) if isinstance(gsd, (int, float)) and gsd > 0 else None
    runs: list[_CellRun | BaseException] = []
    for payload, tmp in zip(payloads, tmps):
        t0 = time.perf_counter()
        try:
            runs.append(_CellRun(payload, tmp, frames, seeds, shared, gsd))
            runs[-1].seconds += time.perf_counter() - t0
        except Exception as exc:  # an invalid pipeline fails its cell only
            runs.append(exc)
    live = [r for r in runs if isinstance(r, _CellRun)]
    n_pairs = len(frames) - 1
    pairs_total, pairs_done = n_pairs * len(runs), n_pairs * (len(runs) - len(live))
    truth_of: dict[int, Any] = {}  # the truth of the pair being scored (lock-step: one pair at a time)
    boxes_of = _truth_by_frame(_detection_truth(seq))
    while live:
        for run in list(live):
            t0 = time.perf_counter()
            try:
                est = next(run.estimates, None)
                if est is None:
                    live.remove(run)
                    pairs_done += n_pairs - run.pairs_done  # none left to come
                    run.pairs_done = n_pairs
                elif isinstance(est, SequenceEstimate):  # comes last
                    run.seq_est = est
                else:
                    if est.index not in truth_of:
                        truth_of.clear()
                        truth = seq.pair_truth(est.index)
                        photo = prepare_photometric(shared.gray(est.index), shared.gray(est.index + 1))
                        truth_of[est.index] = (truth, _prepare(truth, prepare_pair_truth), photo)
                        del truth, photo
                    truth, prepared, photo = truth_of[est.index]
                    run.rows += _pair_rows(est, truth, prepared, score_pair)  # fresh dicts: no copy
                    run.rows += photometric_rows(est.flow_total, photo, frame=est.index)
                    if boxes_of is not None:
                        run.rows += detection_rows(est.detections, boxes_of(est.index), frame=est.index)
                    del truth, prepared, photo
                    if est.index in run.pictures:
                        artifacts.write_pair_flows(run.tmp, est.index, est.flow_total, est.flow_global)
                    run.pairs_done += 1
                    pairs_done += 1
                    if progress is not None:
                        progress(pairs_done, pairs_total)
                del est  # the arrays of a pair live no longer than its scoring
            except Exception as exc:
                run.error = exc
                live.remove(run)
                pairs_done += n_pairs - run.pairs_done
                run.pairs_done = n_pairs
            run.seconds += time.perf_counter() - t0
    truth_of.clear()
    _score_itf([r for r in runs if isinstance(r, _CellRun) and r.error is None and r.seq_est is not None], shared)
    renderer = _renderer_of(seq.meta or {})
    out: list[CellOutcome] = []
    for run in runs:
        if isinstance(run, BaseException):
            out.append(CellOutcome([], renderer, run, 0.0))
            continue
        try:
            if run.error is not None:
                raise run.error
            out.append(CellOutcome(_finish(run, seq), renderer, None, run.seconds))
        except Exception as exc:
            out.append(CellOutcome([], renderer, exc, run.seconds))
    return out


def _prepare(truth: Any, prepare_pair_truth: Any) -> Any:
    """The prepared truth of a pair with full truth; None for a pair of real footage (partial or no truth)."""
    if truth is None or truth.flow_camera is None:
        return None
    return prepare_pair_truth(truth)


def _pair_rows(est: Any, truth: Any, prepared: Any, score_pair: Any) -> list[dict]:
    """A pair's rows: every flow metric with full truth; with only the total flow of real footage,
    the total motion over its known pixels (no local motion, no regions: no camera flow, no
    instances); without truth, the stage timings alone (no flow row: never a zero)."""
    from harness.metrics import score_flow, timing_rows

    if prepared is not None:
        return score_pair(est, truth, frame=est.index, prepared=prepared)
    rows = []
    if truth is not None:
        rows += score_flow(est.flow_total, truth.flow, truth.valid, valid_est=est.valid, motion="total",
                           frame=est.index, regions=("all",))
    if getattr(est, "stage_ms", None):
        rows += timing_rows(est.stage_ms, frame=est.index)
    return rows


def _detection_truth(seq) -> pd.DataFrame | None:
    """The boxes detections are scored against: tracks.csv, else boxes without identities (boxes.csv of
    real footage with YOLO labels: every labelled vehicle, visible where labelled), else None."""
    if seq.tracks is not None:
        return seq.tracks
    boxes = getattr(seq, "boxes", None)
    if boxes is None or len(boxes) == 0:
        return None
    return boxes if "visible" in boxes.columns else boxes.assign(visible=1)


def _truth_by_frame(tracks: pd.DataFrame | None):
    """``frame -> tracks.csv rows of that frame`` (empty rows for a frame without any); None without tracks."""
    if tracks is None or len(tracks) == 0:
        return None
    groups = {int(f): g for f, g in tracks.groupby("frame", sort=False)}
    empty = tracks.iloc[:0]
    return lambda f: groups.get(int(f), empty)


def _score_itf(runs: list[_CellRun], shared: Any) -> None:
    """``stab_itf`` rows of each finished cell: consecutive stabilised frames compared, each pair's gray
    frames read once for every cell (:func:`harness.metrics.photometric.psnr_shifted`)."""
    from harness.metrics.photometric import itf_rows, psnr_shifted

    todo = []
    for run in runs:
        c = getattr(run.seq_est, "correction_px", None)
        c = None if c is None else np.asarray(c, np.float64).reshape(-1, 2)
        if c is not None and len(c) == len(shared) and np.isfinite(c).all():
            todo.append((run, c, []))
    if not todo:
        return
    for i in range(len(shared) - 1):
        t0 = time.perf_counter()
        g0, g1 = shared.gray(i), shared.gray(i + 1)
        share = (time.perf_counter() - t0) / len(todo)
        for run, c, psnr in todo:
            t1 = time.perf_counter()
            try:
                psnr.append(psnr_shifted(g0, g1, c[i + 1] - c[i]))
            except Exception as exc:  # fails its cell only
                run.error = run.error or exc
            run.seconds += share + time.perf_counter() - t1
    for run, _, psnr in todo:
        if run.error is None:
            run.rows += itf_rows(psnr)


def _finish(run: _CellRun, seq: Any) -> list[dict]:
    """The sequence rows and files of a cell whose pipeline ran to the end; its rows, filtered."""
    from harness.metrics import score_sequence

    t0 = time.perf_counter()
    if run.seq_est is None:
        raise RuntimeError("the pipeline yielded no SequenceEstimate")
    # real footage: camera.csv and tracks.csv may be absent (None): their metrics give no rows
    rows = run.rows + score_sequence(run.seq_est, seq.camera, seq.tracks,  # fresh dicts: no copy
                                     ignore_df=getattr(seq, "ignore_regions", None))
    artifacts.write_stabilisation(run.tmp, artifacts.stabilisation_table(run.seq_est, seq.camera))
    artifacts.write_tracks(run.tmp, artifacts.tracks_table(run.seq_est, seq.tracks))
    artifacts.write_mot_tracks(run.tmp, getattr(run.seq_est, "tracks", None))
    if run.payload["metrics"] is not None:
        keep = set(run.payload["metrics"])
        rows = [r for r in rows if r["metric"] in keep]
    run.seconds += time.perf_counter() - t0
    return rows
