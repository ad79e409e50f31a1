"""Jitter removal (thesis 3.2): cumulative global shifts, a smooth flight path, per-frame corrections.

The per-pair global shifts ``s_t`` (the displacement of the ground's image
content from frame t to t+1) add up to the cumulative path ``c_i`` of the
ground in frame i's image, ``c_0 = 0``. The thesis fits a least-squares
straight line ``l_i`` to that path, per axis (its fig. 3.1: blue = ``c``,
red = ``l``, green = their difference), and displaces every frame by

    correction_i = l_i - c_i

which puts frame i's content on the straight flight line; what is removed,
``jitter_i = c_i - l_i = -correction_i``, is the sway and jitter.

Beyond the thesis, ``model="smooth"`` replaces the line by a Savitzky-Golay
smoothing of the path (a local quadratic fit over ``window_frames`` frames),
which follows a curved or accelerating flight and keeps any quadratic path
exactly. The thesis notes (fig. 3.2) that re-running the correlation on the
corrected sequence and correcting again helps; :func:`remove_jitter` does that
when given ``iterations > 1`` and a ``reestimate`` callable that measures the
residual shifts of the corrected sequence.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from algorithms.registry import register_stage

__all__ = ["JitterResult", "JITTER_MODELS", "cumulative_path", "least_squares_line", "fit_flight_path", "remove_jitter"]

JITTER_MODELS = ("line", "smooth")


@dataclass(frozen=True)
class JitterResult:
    """Result of :func:`remove_jitter`; every array is float64 in pixels, columns (x, y).

    Attributes
    ----------
    shifts_px : (N-1, 2)
        The per-pair global shifts given.
    cumulative_px : (N, 2)
        Path of the ground's image content, ``cumulative_px[0] = 0``.
    flight_line_px : (N, 2)
        The fitted smooth path (a straight line for ``model="line"``).
    correction_px : (N, 2)
        Shift to apply to each frame to put it on the flight path
        (``flight_line_px - cumulative_px``, summed over iterations).
    jitter_px : (N, 2)
        ``-correction_px``: the estimated jitter of each frame.
    model : str
    iterations : int
    """

    shifts_px: np.ndarray
    cumulative_px: np.ndarray
    flight_line_px: np.ndarray
    correction_px: np.ndarray
    jitter_px: np.ndarray
    model: str
    iterations: int


def _check_shifts(shifts: np.ndarray, name: str = "shifts") -> np.ndarray:
    s = np.asarray(shifts)
    if not (np.issubdtype(s.dtype, np.integer) or np.issubdtype(s.dtype, np.floating)):
        raise TypeError(f"{name}: expected (N-1, 2) real shifts in px, got dtype {s.dtype}")
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"{name}: expected (N-1, 2) shifts (dx, dy) in px, got shape {tuple(s.shape)}")
    s = s.astype(np.float64)
    if not np.isfinite(s).all():
        raise ValueError(f"{name}: {int(np.count_nonzero(~np.isfinite(s)))} value(s) are NaN or infinite")
    return s


def cumulative_path(shifts: np.ndarray) -> np.ndarray:
    """Sum per-pair shifts ``(N-1, 2)`` into the path ``(N, 2)`` starting at 0 (float64, px)."""
    s = _check_shifts(shifts)
    return np.vstack([np.zeros((1, 2)), np.cumsum(s, axis=0)])


def least_squares_line(y: np.ndarray, t: np.ndarray | None = None) -> np.ndarray:
    """The least-squares straight line ``l = a t + b`` through ``(t, y)``, per column, evaluated at every t.

    The thesis's flight line (3.2) over the frame index, and the one line fit of
    the project (detrending a true jitter, drawing a fitted path).

    Parameters
    ----------
    y : ndarray, (N,) or (N, K) float
        Samples, e.g. a cumulative path in px; NaN samples are left out of the fit.
    t : ndarray, (N,) float, optional
        Abscissa (e.g. frame numbers); default the index 0..N-1.

    Returns
    -------
    ndarray, same shape as ``y``, float64
        The fitted line at every t; a column with fewer than 2 finite samples is
        NaN (``y`` itself is returned when N < 2).
    """
    y = np.asarray(y, dtype=np.float64)
    n = y.shape[0]
    if n < 2:
        return y.copy()
    t = np.arange(n, dtype=np.float64) if t is None else np.asarray(t, dtype=np.float64)
    if t.shape != (n,):
        raise ValueError(f"t: expected ({n},) abscissae, got shape {t.shape}")
    Y = y.reshape(n, -1)
    A = np.column_stack([t, np.ones(n)])
    out = np.full(Y.shape, np.nan)
    ok = np.isfinite(Y)
    if ok.all():
        coef, *_ = np.linalg.lstsq(A, Y, rcond=None)  # l = a t + b per column
        out = A @ coef
    else:
        for k in range(Y.shape[1]):
            if ok[:, k].sum() >= 2:
                coef, *_ = np.linalg.lstsq(A[ok[:, k]], Y[ok[:, k], k], rcond=None)
                out[:, k] = A @ coef
    return out.reshape(y.shape)


def fit_flight_path(path: np.ndarray, *, model: str = "line", window_frames: int = 15,
                    polyorder: int = 2) -> np.ndarray:
    """Fit a smooth flight path to a cumulative path, per axis.

    Parameters
    ----------
    path : ndarray, (N, 2) float
        Cumulative path in px.
    model : {"line", "smooth"}
        ``"line"``: least-squares straight line over the frame index (thesis 3.2).
        ``"smooth"``: Savitzky-Golay filter, a least-squares polynomial of
        degree ``polyorder`` fitted in a sliding window of ``window_frames``
        frames (its time constant); the ends use the fit of the first/last
        window, so any polynomial path of degree <= ``polyorder`` is kept exactly.
        Sequences shorter than the window use the largest odd window that fits.
    window_frames : int
        Odd window length in frames for ``"smooth"``.
    polyorder : int
        Polynomial degree for ``"smooth"``.

    Returns
    -------
    ndarray, (N, 2) float64
    """
    p = np.asarray(path, dtype=np.float64)
    n = p.shape[0]
    if model not in JITTER_MODELS:
        raise ValueError(f"model: expected one of {', '.join(JITTER_MODELS)}, got {model!r}")
    if n < 3:
        # Two points are their own line; nothing to remove.
        return p.copy()
    if model == "line":
        return least_squares_line(p)  # least squares per axis: l_i = a i + b
    if window_frames < 3 or window_frames % 2 == 0:
        raise ValueError(f"window_frames: expected an odd integer >= 3, got {window_frames}")
    if polyorder < 0:
        raise ValueError(f"polyorder: expected >= 0, got {polyorder}")
    w = min(window_frames, n if n % 2 else n - 1)
    k = min(polyorder, w - 1)
    from scipy.signal import savgol_filter  # here: importing scipy.signal takes a second, most importers never smooth

    return savgol_filter(p, w, k, axis=0, mode="interp")


@register_stage("jitter")
def remove_jitter(shifts: np.ndarray, *, model: str = "line", window_frames: int = 15,
                  polyorder: int = 2, iterations: int = 1,
                  reestimate: Callable[[np.ndarray], np.ndarray] | None = None) -> JitterResult:
    """Estimate jitter from per-pair global shifts and the correction that removes it (thesis 3.2).

    Parameters
    ----------
    shifts : ndarray, (N-1, 2) float
        Global shift ``(dx, dy)`` in px of each pair t -> t+1.
    model : {"line", "smooth"}
        Flight path model, see :func:`fit_flight_path`.
    window_frames, polyorder : int
        Savitzky-Golay window (frames, odd) and degree for ``model="smooth"``.
    iterations : int
        Number of estimate-correct rounds (thesis fig. 3.2). Round k > 1 calls
        ``reestimate(correction_px)``, which must return the ``(N-1, 2)`` shifts
        measured on the sequence with every frame i displaced by
        ``correction_px[i]``; their path's deviation from its own flight path is
        added to the correction. Without ``reestimate`` more rounds would repeat
        the first exactly, so ``iterations > 1`` requires it.

    Returns
    -------
    JitterResult
        ``cumulative_px`` and ``flight_line_px`` describe the first round (the
        measured path); ``correction_px`` sums all rounds; ``jitter_px = -correction_px``.
    """
    if not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"iterations: expected an integer >= 1, got {iterations!r}")
    if iterations > 1 and reestimate is None:
        raise ValueError("iterations > 1 needs reestimate: re-measuring the corrected sequence is what "
                         "a further round adds (with the shifts alone it would repeat round 1)")
    s = _check_shifts(shifts)
    c = cumulative_path(s)
    line = fit_flight_path(c, model=model, window_frames=window_frames, polyorder=polyorder)
    correction = line - c
    for _ in range(iterations - 1):
        s_k = _check_shifts(reestimate(correction.copy()), name="reestimate(...) result")
        if s_k.shape != s.shape:
            raise ValueError(f"reestimate(...) result: expected shape {s.shape}, got {s_k.shape}")
        c_k = cumulative_path(s_k)
        correction = correction + fit_flight_path(c_k, model=model, window_frames=window_frames,
                                                  polyorder=polyorder) - c_k
    return JitterResult(shifts_px=s, cumulative_px=c, flight_line_px=line, correction_px=correction,
                        jitter_px=-correction, model=model, iterations=int(iterations))
