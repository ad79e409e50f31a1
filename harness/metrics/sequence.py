"""The rows of a whole sequence: global motion, stabilisation, trajectories and MOT together."""

from __future__ import annotations

import pandas as pd

from harness.metrics.mot import hota_rows, mot_rows
from harness.metrics.stabilisation import jitter_rows, shift_rows, stabilisation_rows
from harness.metrics.trajectories import track_rows


def score_sequence(seq_estimate, camera_df: pd.DataFrame | None, tracks_df: pd.DataFrame | None, *,
                   gate_px: float = 20.0, ignore_df: pd.DataFrame | None = None) -> list[dict]:
    """Rows of a whole sequence: global shift errors, residual jitter, trajectories.

    Parameters
    ----------
    seq_estimate : SequenceEstimate
        Uses ``shifts_px`` (N-1, 2), ``jitter_px`` (N, 2), ``tracks`` (DataFrame or None) and ``trackers``
        (the trackers that ran: each is scored, with no rows if it output none).
    camera_df, tracks_df : DataFrame or None
        camera.csv and tracks.csv of the sequence; None where the sequence has no such truth
        (real footage): the metrics that need it give no rows.
    ignore_df : DataFrame or None
        ignore.csv of real footage (:attr:`scenes.sequence.Sequence.ignore_regions`): distractor
        regions for the tracking metrics (:mod:`harness.metrics.objects`).
    """
    rows = []
    if camera_df is not None and getattr(seq_estimate, "shifts_px", None) is not None:
        rows += shift_rows(seq_estimate.shifts_px, camera_df)
    if camera_df is not None and getattr(seq_estimate, "jitter_px", None) is not None:
        rows += jitter_rows(seq_estimate.jitter_px, camera_df)
    shape = getattr(seq_estimate, "frame_shape_px", None)
    if camera_df is not None and getattr(seq_estimate, "correction_px", None) is not None and shape is not None:
        rows += stabilisation_rows(seq_estimate.correction_px, camera_df, shape)
    tracks = getattr(seq_estimate, "tracks", None)
    trackers = tuple(getattr(seq_estimate, "trackers", ()))
    if tracks is not None and tracks_df is not None and (len(tracks) or trackers):
        kw = {"gate_px": gate_px, "ignore": ignore_df, "trackers": trackers}
        rows += track_rows(tracks, tracks_df, **kw)
        rows += mot_rows(tracks, tracks_df, **kw)
        rows += hota_rows(tracks, tracks_df, **kw)
    return rows
