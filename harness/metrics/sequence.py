"""The rows of a whole sequence: global motion, stabilisation, trajectories and MOT together."""

from __future__ import annotations

import pandas as pd

from harness.metrics.mot import hota_rows, mot_rows
from harness.metrics.stabilisation import jitter_rows, shift_rows, stabilisation_rows
from harness.metrics.trajectories import track_rows


def score_sequence(seq_estimate, camera_df: pd.DataFrame | None, tracks_df: pd.DataFrame | None, *,
                   gate_px: float = 20.0) -> list[dict]:
    """Rows of a whole sequence: global shift errors, residual jitter, trajectories.

    Parameters
    ----------
    seq_estimate : SequenceEstimate
        Uses ``shifts_px`` (N-1, 2), ``jitter_px`` (N, 2) and ``tracks`` (DataFrame or None).
    camera_df, tracks_df : DataFrame or None
        camera.csv and tracks.csv of the sequence; None where the sequence has no such truth
        (real footage): the metrics that need it give no rows.
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
    if tracks is not None and tracks_df is not None and len(tracks):
        rows += track_rows(tracks, tracks_df, gate_px=gate_px)
        rows += mot_rows(tracks, tracks_df, gate_px=gate_px)
        rows += hota_rows(tracks, tracks_df, gate_px=gate_px)
    return rows
