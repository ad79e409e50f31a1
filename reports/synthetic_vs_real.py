"""Synthetic vs real: does a ranking of pipelines on the synthetic scenes say something about real footage?

A benchmark is worth what its ranking predicts. For every metric that the synthetic
scenes and the real sequences of one run both have, this module ranks the pipelines
on each side (by the metric's pooled value: sums and counts summed over the side's
units, then reduced by the metric's own rule, never an average of averages), and
measures how well the two rankings agree:

- Spearman's rho: Pearson's correlation of the ranks (ties get their mean rank);
- Kendall's tau-b: (concordant - discordant) / sqrt((n0 - n1)(n0 - n2)), with n0 = n(n-1)/2
  pairs and n1, n2 the pairs tied on each side (Kendall 1945).

Each correlation gets a 95 % percentile-bootstrap interval: the units of each side
(a frame pair ``(scene, seed, frame)`` where the rows are per frame, else a sequence
``(scene, seed)``) are resampled with replacement, the same resample for every pipeline
(the pipelines ran on the same units), :data:`N_BOOT` times with ``numpy.random.default_rng(seed)``,
so the same results give the same interval. The gap table puts the same metric on
synthetic and on real side by side (how much harder the real footage is), and
:func:`verdict` says both in one sentence.

Public functions
----------------
ranks(x), spearman(a, b) -> float, kendall_tau_b(a, b) -> float   ranks (ties: mean rank), rank correlations
unit_totals(rows, pipelines) -> (sums, counts)             (units, pipelines) totals of one side
compare(table, real_scenes, *, pipelines, metrics, seed, n_boot) -> SyntheticVsReal
verdict(result) -> str
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from harness.metrics import METRICS, reduce_totals

__all__ = ["N_BOOT", "LEVEL", "MetricAgreement", "SyntheticVsReal", "ranks", "spearman", "kendall_tau_b", "unit_totals",
           "comparable_views", "compare", "verdict"]

N_BOOT = 2000
LEVEL = 0.95
# the reductions that work on summed (sum, count) totals alone (quantiles need histograms)
_TOTAL_RULES = {"mean", "rms", "rate", "complement", "total"}


def ranks(x: Sequence[float]) -> np.ndarray:
    """1-based ranks of the 1-D ``x`` (ascending), ties given the mean of the ranks they span."""
    return _ranks_rows(np.asarray(x, np.float64)[None])[0]


def _ranks_rows(x: np.ndarray) -> np.ndarray:
    """:func:`ranks` of each row of the 2-D ``x``: a value below ``less`` others and equal to ``equal``
    (itself included) spans ranks ``less + 1 .. less + equal``, whose mean is ``less + (equal + 1) / 2``.
    Quadratic in the row length: rows here are a run's pipelines."""
    less = (x[:, None, :] < x[:, :, None]).sum(axis=2)
    equal = (x[:, None, :] == x[:, :, None]).sum(axis=2)
    return less + 0.5 * (equal + 1)


def _pair(name: str, a, b) -> tuple[np.ndarray, np.ndarray] | None:
    """``a, b`` as float64 vectors of one length (ValueError otherwise); None where a correlation is
    undefined: fewer than 3 items or a value that is not finite."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"{name}: expected two 1-D vectors of one length, got {a.shape} and {b.shape}")
    if len(a) < 3 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return None
    return a, b


def spearman(a: Sequence[float], b: Sequence[float]) -> float:
    """Spearman's rho of two score vectors of the same items (NaN with fewer than 3 items or a constant side)."""
    ab = _pair("spearman", a, b)
    return float("nan") if ab is None else float(_spearman_rows(ab[0][None], ab[1][None])[0])


def kendall_tau_b(a: Sequence[float], b: Sequence[float]) -> float:
    """Kendall's tau-b of two score vectors of the same items (ties on either side handled; NaN below 3 items)."""
    ab = _pair("kendall_tau_b", a, b)
    return float("nan") if ab is None else float(_kendall_rows(ab[0][None], ab[1][None])[0])


def _undefined(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows of ``(rows, n)`` pairs where a correlation is undefined (see :func:`_pair`)."""
    return np.full(len(a), a.shape[1] < 3) | ~(np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1))


def _spearman_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`spearman` of each row pair of two ``(rows, n)`` arrays (the bootstrap's resamples at once)."""
    ra, rb = _ranks_rows(a), _ranks_rows(b)
    ra, rb = ra - ra.mean(axis=1, keepdims=True), rb - rb.mean(axis=1, keepdims=True)
    den = np.sqrt((ra ** 2).sum(axis=1) * (rb ** 2).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = (ra * rb).sum(axis=1) / den
    return np.where((den > 0) & ~_undefined(a, b), rho, np.nan)


def _kendall_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`kendall_tau_b` of each row pair of two ``(rows, n)`` arrays:
    (concordant - discordant) / sqrt((n0 - n1)(n0 - n2)) over the n0 = n(n-1)/2 pairs of items."""
    i, j = np.triu_indices(a.shape[1], k=1)
    sa, sb = np.sign(a[:, i] - a[:, j]), np.sign(b[:, i] - b[:, j])
    n0 = len(i)
    n1, n2 = (sa == 0).sum(axis=1), (sb == 0).sum(axis=1)
    den = np.sqrt(((n0 - n1) * (n0 - n2)).astype(np.float64))
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = (sa * sb).sum(axis=1) / den
    return np.where((den > 0) & ~_undefined(a, b), tau, np.nan)


def comparable_views(table: pd.DataFrame) -> list[tuple[str, str, str]]:
    """The ``(metric, region, motion)`` views a ranking can be made of, in a stable order.

    Accuracy metrics whose reduction works on summed totals (not quantiles, not timings);
    flow metrics on region ``all`` only, and on motion ``total`` where they have it (the
    headline view); track metrics per tracker (region ``point`` / ``multi``).
    """
    df = table[["metric", "region", "motion"]].drop_duplicates()
    out = []
    for (metric, region, motion) in df.itertuples(index=False):
        d = METRICS.get(metric)
        if d is None or d.kind != "accuracy" or d.reduce not in _TOTAL_RULES:
            continue
        views = df[df["metric"] == metric]
        if (views["region"] == "all").any() and region != "all":
            continue
        if ((views["region"] == region) & (views["motion"] == "total")).any() and motion != "total":
            continue
        out.append((str(metric), str(region), str(motion)))
    return sorted(set(out))


def _unit_keys(rows: pd.DataFrame) -> pd.Series:
    """A unit label per row: ``scene|seed|frame`` for per-frame rows, ``scene|seed`` for per-sequence rows."""
    frame = rows["frame"]
    has = frame.notna().to_numpy()
    base = rows["scene"].astype(str) + "|" + rows["seed"].astype(str)
    framestr = frame.astype("float64").fillna(-1).astype(np.int64).astype(str)
    return base.where(~has, base + "|" + framestr)


def unit_totals(rows: pd.DataFrame, pipelines: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """``(sums, counts)``, each ``(n_units, n_pipelines)`` float64: one side's rows of one view, per unit.

    A unit a pipeline has no row for holds 0 / 0 there (it adds nothing to that pipeline's pool).
    """
    if rows.empty:
        z = np.zeros((0, len(pipelines)))
        return z, z.copy()
    units = _unit_keys(rows)
    g = pd.DataFrame({"unit": units.to_numpy(), "pipeline": rows["pipeline"].astype(str).to_numpy(),
                      "sum": rows["sum"].to_numpy(np.float64), "count": rows["count"].to_numpy(np.float64)})
    g = g[g["count"] != 0].groupby(["unit", "pipeline"], sort=True)[["sum", "count"]].sum()
    sums = g["sum"].unstack("pipeline").reindex(columns=list(pipelines)).fillna(0.0)
    counts = g["count"].unstack("pipeline").reindex(columns=list(pipelines)).fillna(0.0)
    return sums.to_numpy(np.float64), counts.to_numpy(np.float64)


def _values(metric: str, sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Pooled values per pipeline (last axis) from totals summed over units (the axis before)."""
    s, c = sums.sum(axis=-2), counts.sum(axis=-2)
    return np.vectorize(lambda a, b: reduce_totals(metric, a, b), otypes=[np.float64])(s, c)


@dataclass
class MetricAgreement:
    """One view (metric, region, motion): both sides' values per pipeline, the rank agreement with intervals."""

    metric: str
    region: str
    motion: str
    unit: str
    higher_is_better: bool
    pipelines: list[str]
    synthetic: np.ndarray          # pooled value per pipeline on the synthetic scenes
    real: np.ndarray               # the same on the real sequences
    rank_synthetic: np.ndarray     # 1 = best
    rank_real: np.ndarray
    spearman: float
    spearman_ci: tuple[float, float]
    kendall: float
    kendall_ci: tuple[float, float]
    n_units_synthetic: int
    n_units_real: int

    @property
    def label(self) -> str:
        """``metric`` alone for region ``all``, else ``metric (region)``."""
        return self.metric if self.region == "all" else f"{self.metric} ({self.region})"

    def gap(self) -> pd.DataFrame:
        """Per pipeline: synthetic value, real value, real - synthetic, and whether real is worse."""
        diff = self.real - self.synthetic
        worse = diff < 0 if self.higher_is_better else diff > 0
        return pd.DataFrame({"pipeline": self.pipelines, "synthetic": self.synthetic, "real": self.real,
                             "real_minus_synthetic": diff, "real_worse": worse})


@dataclass
class SyntheticVsReal:
    """Every comparable view of a run that has both synthetic and real scenes."""

    synthetic_scenes: list[str]
    real_scenes: list[str]
    views: list[MetricAgreement] = field(default_factory=list)
    note: str = ""                 # why there is nothing to compare, when there is nothing


def _rank_best_first(values: np.ndarray, higher_is_better: bool) -> np.ndarray:
    return ranks(-values if higher_is_better else values)


def _interval(samples: np.ndarray, level: float) -> tuple[float, float]:
    s = samples[np.isfinite(samples)]
    if len(s) < 0.5 * len(samples) or len(s) == 0:
        return float("nan"), float("nan")
    a = (1.0 - level) / 2.0
    return float(np.quantile(s, a)), float(np.quantile(s, 1.0 - a))


def compare(table: pd.DataFrame, real_scenes: Iterable[str], *, pipelines: Sequence[str] | None = None,
            metrics: Iterable[str] | None = None, seed: int = 0, n_boot: int = N_BOOT,
            level: float = LEVEL) -> SyntheticVsReal:
    """Rank agreement and gaps between the synthetic and the real scenes of one results table.

    Parameters
    ----------
    table : DataFrame
        Results rows (``scene, seed, frame, pipeline, metric, region, motion, sum, count``);
        rows whose ``status`` is not "ok" are left out.
    real_scenes : iterable of str
        Scene labels that are real footage; every other scene of ``table`` is synthetic.
    pipelines : sequence of str, optional
        The pipelines to rank, in report order; default those of ``table`` in order of appearance.
    metrics : iterable of str, optional
        Restrict to these metric names.
    seed : int
        Seed of the bootstrap's generator.
    n_boot : int
        Bootstrap resamples (>= 100).
    level : float
        Confidence level of the intervals, in (0, 1).
    """
    if n_boot < 100:
        raise ValueError(f"n_boot: expected >= 100, got {n_boot}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level: expected in (0, 1), got {level}")
    df = table
    if "status" in df.columns:
        df = df[df["status"] == "ok"]
    real = set(map(str, real_scenes))
    scenes = pd.unique(df["scene"].astype(str)).tolist()
    out = SyntheticVsReal([s for s in scenes if s not in real], [s for s in scenes if s in real])
    if not out.real_scenes or not out.synthetic_scenes:
        out.note = ("The run has no real sequence: nothing to compare the synthetic ranking with."
                    if not out.real_scenes else
                    "The run has no synthetic scene: nothing to compare the real ranking with.")
        return out
    pipes = list(pipelines) if pipelines is not None else pd.unique(df["pipeline"].astype(str)).tolist()
    if len(pipes) < 3:
        out.note = f"A ranking needs at least 3 pipelines; the run has {len(pipes)}."
        return out
    is_real = df["scene"].astype(str).isin(real).to_numpy()
    wanted = set(metrics) if metrics is not None else None
    views_real = set(comparable_views(df[is_real]))
    rng = np.random.default_rng(seed)
    for view in comparable_views(df[~is_real]):
        if view not in views_real or (wanted is not None and view[0] not in wanted):
            continue
        metric, region, motion = view
        sel = ((df["metric"] == metric) & (df["region"] == region) & (df["motion"] == motion)).to_numpy()
        s_syn, c_syn = unit_totals(df[sel & ~is_real], pipes)
        s_real, c_real = unit_totals(df[sel & is_real], pipes)
        v_syn, v_real = _values(metric, s_syn, c_syn), _values(metric, s_real, c_real)
        if not (np.all(np.isfinite(v_syn)) and np.all(np.isfinite(v_real))):
            continue  # a pipeline without this metric on one side cannot be ranked
        d = METRICS[metric]
        rs, rr = _rank_best_first(v_syn, d.higher_is_better), _rank_best_first(v_real, d.higher_is_better)
        # bootstrap: each side's units resampled, the same units for every pipeline
        i_syn = rng.integers(0, len(s_syn), size=(n_boot, len(s_syn)))
        i_real = rng.integers(0, len(s_real), size=(n_boot, len(s_real)))
        b_syn = _values(metric, s_syn[i_syn], c_syn[i_syn])
        b_real = _values(metric, s_real[i_real], c_real[i_real])
        rho, tau = _spearman_rows(b_syn, b_real), _kendall_rows(b_syn, b_real)
        out.views.append(MetricAgreement(
            metric=metric, region=region, motion=motion, unit=d.unit, higher_is_better=d.higher_is_better,
            pipelines=pipes, synthetic=v_syn, real=v_real, rank_synthetic=rs, rank_real=rr,
            spearman=spearman(v_syn, v_real), spearman_ci=_interval(rho, level),
            kendall=kendall_tau_b(v_syn, v_real), kendall_ci=_interval(tau, level),
            n_units_synthetic=len(s_syn), n_units_real=len(s_real)))
    if not out.views:
        out.note = "No metric with a ranking on both the synthetic scenes and the real sequences."
    return out


def _fmt_ci(ci: tuple[float, float]) -> str:
    return "n/a" if not all(map(math.isfinite, ci)) else f"[{ci[0]:+.2f}, {ci[1]:+.2f}]"


def verdict(result: SyntheticVsReal) -> str:
    """One sentence: whether the synthetic ranking carries over to the real footage, and which side is harder.

    A view *agrees* when its Spearman interval lies above 0, *disagrees* when it lies below,
    and is *undecided* otherwise. The real footage is *harder* on a view when most pipelines
    score worse there.
    """
    if not result.views:
        return result.note or "Nothing to compare."
    agree = [v for v in result.views if v.spearman_ci[0] > 0]
    disagree = [v for v in result.views if v.spearman_ci[1] < 0]
    undecided = [v for v in result.views if v not in agree and v not in disagree]
    harder = [v for v in result.views if v.gap()["real_worse"].mean() > 0.5]
    best = max(result.views, key=lambda v: (np.nan_to_num(v.spearman, nan=-2.0), v.label))
    if len(agree) > len(result.views) / 2:
        head = (f"The synthetic ranking carries over to the real footage on {len(agree)} of {len(result.views)} "
                f"metrics (Spearman interval above 0)")
    elif len(disagree) > len(result.views) / 2:
        head = (f"The synthetic ranking is reversed on the real footage on {len(disagree)} of "
                f"{len(result.views)} metrics (Spearman interval below 0)")
    else:
        head = (f"The synthetic ranking does not clearly carry over to the real footage: {len(agree)} of "
                f"{len(result.views)} metrics agree, {len(disagree)} disagree, {len(undecided)} are undecided")
    tail = (f"; strongest agreement on {best.label} (Spearman {best.spearman:+.2f} {_fmt_ci(best.spearman_ci)})"
            if math.isfinite(best.spearman) else "")
    hard = (f"; the real footage is harder on {len(harder)} of {len(result.views)} metrics"
            if harder else "; the real footage is not harder than the synthetic scenes on any metric")
    return head + tail + hard + "."
