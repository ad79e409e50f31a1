"""Lucas-Kanade vs Horn-Schunck: paired differences with bootstrap confidence intervals and a verdict.

The question of the thesis (Liu 2009, chapter 3.3 and 4) is which flow method
serves aerial video better. Two means side by side cannot answer it: scenes and
frames differ far more among themselves than the methods do. So each comparison
is *paired*: the LK pipeline and its HS twin (same stages, only the flow method
differs) ran on the same rendered frame pairs, and the unit is one frame pair
(scene, seed, frame). Per unit both sides have an endpoint-error total and pixel
count; the difference is

    d = sum_LK / count_LK - sum_HS / count_HS       (pooled over the units, px)

i.e. the difference of the pooled per-pixel means the report's other tables show.
Its 95 % confidence interval is a percentile bootstrap over the units (resampled
with replacement, :data:`N_BOOT` times, an explicit seeded ``numpy.random.Generator``),
so the same results give the same interval. The verdict says "no clear difference"
whenever the interval contains 0.

Trajectories are compared the same way (:func:`compare_tracking`: MOTA, IDF1, HOTA and the point
error ``track_error``, per tracker), with one difference: their unit is a sequence (scene, seed),
since MOTA, IDF1 and HOTA are ratios of counts summed over a whole sequence. Each side's pooled
value is the metric's own reduction of the summed counts (``1 - sum / count`` for MOTA), so the
difference is that of the values the report's tables show. A metric one side lacks (a pipeline
without a multi-target tracker, a metric the run did not compute) is a comparison with no unit,
shown as "n/a", never as a zero.

Public functions
----------------
pair_pipelines(specs) -> [(lk, hs)]            twins by flow method in the resolved pipeline dicts
paired_units(table, lk, hs, *, metric, region, motion, by) -> DataFrame
bootstrap_difference(sum_a, count_a, sum_b, count_b, *, rng, n_boot, level, reduce) -> (d, lo, hi)
compare_pair(table, lk, hs, *, metric, regions, motions, seed) -> [Comparison]
compare_tracking(table, lk, hs, *, metrics, seed) -> [Comparison]       per tracker and metric
by_scene_seed(table, lk, hs, *, metric, regions, motions) -> DataFrame   the difference per (scene, seed)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["LK", "HS", "N_BOOT", "LEVEL", "TRACKING_METRICS", "Comparison", "pair_pipelines", "paired_units",
           "bootstrap_difference", "compare_pair", "compare_tracking", "by_scene_seed", "verdict"]

LK, HS = "lucas_kanade", "horn_schunck"
N_BOOT = 4000
LEVEL = 0.95
_UNIT = ["scene", "seed", "frame"]
_SEQUENCE = ["scene", "seed"]
# the trajectory rows of the comparison (issue 21): multi-target scores, then the point error
TRACKING_METRICS = ("mota", "idf1", "hota", "track_error")
# their direction where neither harness.metrics nor the table says it (a metric this run did not compute)
_HIGHER_IS_BETTER = {"mota": True, "idf1": True, "hota": True, "track_error": False}
_TRACKERS = ("point", "multi")  # region of a track row: the tracker; others after these, sorted
# pooled value from summed totals, per reduction rule of harness.metrics (vectorised over resamples)
_REDUCE = {"mean": lambda s, c: s / c, "complement": lambda s, c: 1.0 - s / c,
           "rate": lambda s, c: 100.0 * s / c, "rms": lambda s, c: np.sqrt(s / c)}


def _flow_method(spec: Mapping) -> str | None:
    flow = spec.get("flow")
    return str(flow.get("method")) if isinstance(flow, Mapping) and flow.get("method") else None


def _stages_but_flow(spec: Mapping) -> dict:
    return {k: v for k, v in spec.items() if k not in ("name", "description", "flow")}


def pair_pipelines(specs: Mapping[str, Mapping]) -> list[tuple[str, str]]:
    """LK / HS twins among resolved pipeline dicts: ``(lk_name, hs_name)`` in the order of ``specs``.

    A pipeline whose flow method is ``lucas_kanade`` is paired with the first pipeline whose flow
    method is ``horn_schunck`` and whose every other stage (global motion, jitter, compensation,
    filters, detection, tracking) is identical, so the pair differs in the flow method alone.
    Pipelines without such a twin are left out.
    """
    hs = [n for n, s in specs.items() if _flow_method(s) == HS]
    out, used = [], set()
    for name, spec in specs.items():
        if _flow_method(spec) != LK:
            continue
        twin = next((h for h in hs if h not in used and _stages_but_flow(specs[h]) == _stages_but_flow(spec)), None)
        if twin is not None:
            used.add(twin)
            out.append((name, twin))
    return out


def paired_units(table: pd.DataFrame, lk: str, hs: str, *, metric: str = "epe_mean", region: str = "all",
                 motion: str = "total", by: tuple[str, ...] = tuple(_UNIT)) -> pd.DataFrame:
    """One row per unit both pipelines scored: ``*by, sum_lk, count_lk, sum_hs, count_hs``.

    The unit is a frame pair (``by`` = scene, seed, frame) by default; ``("scene", "seed")`` pools
    each sequence (the unit of sequence-level scores such as MOTA). ``table`` is a results table
    (rows of failed cells are left out here); a unit present for one pipeline only is dropped (it
    cannot be paired).
    """
    by = list(by)
    rows = table[(table["metric"] == metric) & (table["region"] == region) & (table["motion"] == motion)
                 & (table["status"] == "ok") & (table["count"] > 0)]
    sides = []
    for pipe, tag in ((lk, "lk"), (hs, "hs")):
        g = rows[rows["pipeline"] == pipe].groupby(by, as_index=False)[["sum", "count"]].sum()
        sides.append(g.rename(columns={"sum": f"sum_{tag}", "count": f"count_{tag}"}))
    return sides[0].merge(sides[1], on=by, how="inner").sort_values(by, kind="stable").reset_index(drop=True)


def bootstrap_difference(sum_a: np.ndarray, count_a: np.ndarray, sum_b: np.ndarray, count_b: np.ndarray, *,
                         rng: np.random.Generator, n_boot: int = N_BOOT, level: float = LEVEL,
                         reduce: str = "mean") -> tuple[float, float, float]:
    """Difference of pooled means ``sum(sum_a)/sum(count_a) - sum(sum_b)/sum(count_b)`` and its
    percentile-bootstrap interval over the paired units.

    With ``reduce`` another rule of :mod:`harness.metrics` turns each side's summed totals into its
    value before the difference: ``complement`` (1 - sum / count, MOTA), ``rate`` (100 sum / count),
    ``rms`` (sqrt(sum / count)); ``mean`` is sum / count.

    Parameters
    ----------
    sum_a, count_a, sum_b, count_b : (n,) float
        Per unit totals (e.g. summed endpoint error in px and pixel count) of both sides.
    rng : numpy.random.Generator
        The resampling stream (pass a seeded one for a reproducible interval).
    n_boot : int
        Bootstrap resamples.
    level : float
        Two-sided confidence level in (0, 1).

    Returns
    -------
    (d, lo, hi) : floats
        NaN for all three when there is no unit; ``lo == hi == d`` for a single unit.
    """
    arrays = [np.asarray(x, np.float64) for x in (sum_a, count_a, sum_b, count_b)]
    n = arrays[0].shape[0]
    if any(a.shape != (n,) for a in arrays):
        raise ValueError(f"expected four (n,) arrays of one length, got shapes {[a.shape for a in arrays]}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level: expected a probability in (0, 1), got {level}")
    if reduce not in _REDUCE:
        raise ValueError(f"reduce: expected one of {', '.join(_REDUCE)}, got {reduce!r}")
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    f = _REDUCE[reduce]
    sa, ca, sb, cb = arrays
    d = f(sa.sum(), ca.sum()) - f(sb.sum(), cb.sum())
    idx = rng.integers(0, n, size=(n_boot, n))
    boot = f(sa[idx].sum(1), ca[idx].sum(1)) - f(sb[idx].sum(1), cb[idx].sum(1))
    lo, hi = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
    return float(d), float(lo), float(hi)


@dataclass(frozen=True)
class Comparison:
    """One paired comparison (a region and motion of one LK / HS twin)."""

    lk: str
    hs: str
    metric: str
    unit: str
    region: str
    motion: str
    n_units: int
    n_lk_lower: int       # units where LK's value (an error: LK's error) is the lower one
    lk_value: float       # pooled over the units (over every unit of its own where the pair has none)
    hs_value: float
    diff: float           # lk_value - hs_value
    lo: float
    hi: float
    higher_is_better: bool = False
    n_lk_higher: int = 0  # units where LK's value is the higher one

    @property
    def sentence(self) -> str:
        return verdict(self)

    @property
    def n_lk_better(self) -> int:
        """Units where LK's value is the better one (by the metric's direction)."""
        return self.n_lk_higher if self.higher_is_better else self.n_lk_lower

    @property
    def better(self) -> str | None:
        """``"LK"`` or ``"HS"`` when the interval excludes 0, else None (no clear difference, or no unit)."""
        if self.n_units == 0 or not (np.isfinite(self.lo) and np.isfinite(self.hi)):
            return None
        if self.hi < 0:
            return "HS" if self.higher_is_better else "LK"
        if self.lo > 0:
            return "LK" if self.higher_is_better else "HS"
        return None


def verdict(c: Comparison) -> str:
    """One sentence from the numbers: who has the lower error (the higher score) and by how much, or no
    clear difference."""
    if c.motion == "track":
        return _tracking_verdict(c)
    where = f"{c.region} pixels, {c.motion} motion"
    ci = f"95 % CI {c.lo:+.3f} to {c.hi:+.3f} {c.unit}"
    if c.n_units == 0 or not np.isfinite(c.diff):
        return f"{where}: no frame pair scored by both {c.lk} and {c.hs}."
    count = f"LK lower on {c.n_lk_lower} of {c.n_units} frame pairs"
    if c.hi < 0:
        return (f"{where}: LK ({c.lk}) is better, its error {-c.diff:.3f} {c.unit} lower than HS ({c.hs}) "
                f"({ci}; {count}).")
    if c.lo > 0:
        return (f"{where}: HS ({c.hs}) is better, its error {c.diff:.3f} {c.unit} lower than LK ({c.lk}) "
                f"({ci}; {count}).")
    return f"{where}: no clear difference between {c.lk} and {c.hs} (the {ci} contains 0; {count})."


def _tracking_verdict(c: Comparison) -> str:
    where = f"{c.metric}, {c.region} tracker"
    unit = f" {c.unit}" if c.unit not in ("", "ratio") else ""
    if c.n_units == 0 or not np.isfinite(c.diff):
        missing = [name for name, v in ((c.lk, c.lk_value), (c.hs, c.hs_value)) if not np.isfinite(v)]
        return (f"{where}: n/a ({' and '.join(missing)} without it)." if missing else
                f"{where}: n/a (no sequence scored by both {c.lk} and {c.hs}).")
    ci = f"95 % CI {c.lo:+.3f} to {c.hi:+.3f}{unit}"
    count = f"LK better on {c.n_lk_better} of {c.n_units} sequences"
    better = c.better
    if better is None:
        return f"{where}: no clear difference between {c.lk} and {c.hs} (the {ci} contains 0; {count})."
    word = "higher" if c.higher_is_better else "lower"
    name, other = (c.lk, c.hs) if better == "LK" else (c.hs, c.lk)
    return (f"{where}: {better} ({name}) is better, its {c.metric} {abs(c.diff):.3f}{unit} {word} than "
            f"{'HS' if better == 'LK' else 'LK'} ({other}) ({ci}; {count}).")


def _paired_by_region(table: pd.DataFrame, lk: str, hs: str, *, metric: str, regions: tuple[str, ...],
                      motions: tuple[str, ...]):
    """``(region, motion, units)`` for every motion x region whose paired units are not empty."""
    for motion in motions:
        for region in regions:
            u = paired_units(table, lk, hs, metric=metric, region=region, motion=motion)
            if not u.empty:
                yield region, motion, u


def compare_pair(table: pd.DataFrame, lk: str, hs: str, *, metric: str = "epe_mean",
                 regions: tuple[str, ...] = ("background", "vehicles"), motions: tuple[str, ...] = ("total", "local"),
                 seed: int = 0) -> list[Comparison]:
    """:class:`Comparison` of ``lk`` against ``hs`` for every motion x region with paired units.

    The bootstrap stream is ``numpy.random.default_rng(seed)``, one per comparison, so each
    interval depends only on its own units.
    """
    unit_col = table.loc[table["metric"] == metric, "unit"]
    unit = str(unit_col.iloc[0]) if len(unit_col) else ""
    out = []
    for region, motion, u in _paired_by_region(table, lk, hs, metric=metric, regions=regions, motions=motions):
        d, lo, hi = bootstrap_difference(u["sum_lk"], u["count_lk"], u["sum_hs"], u["count_hs"],
                                         rng=np.random.default_rng(seed))
        per_unit = u["sum_lk"] / u["count_lk"] - u["sum_hs"] / u["count_hs"]
        out.append(Comparison(lk=lk, hs=hs, metric=metric, unit=unit, region=region, motion=motion,
                              n_units=len(u), n_lk_lower=int((per_unit < 0).sum()),
                              lk_value=float(u["sum_lk"].sum() / u["count_lk"].sum()),
                              hs_value=float(u["sum_hs"].sum() / u["count_hs"].sum()),
                              diff=d, lo=lo, hi=hi))
    return out


def by_scene_seed(table: pd.DataFrame, lk: str, hs: str, *, metric: str = "epe_mean",
                  regions: tuple[str, ...] = ("background", "vehicles"),
                  motions: tuple[str, ...] = ("total", "local")) -> pd.DataFrame:
    """The pooled difference LK - HS per (scene, seed): one row per scene and seed, one column
    ``"<region> / <motion>"`` per comparison (NaN where that pair has no unit)."""
    parts = []
    for region, motion, u in _paired_by_region(table, lk, hs, metric=metric, regions=regions, motions=motions):
        g = u.groupby(["scene", "seed"], sort=True)[["sum_lk", "count_lk", "sum_hs", "count_hs"]].sum()
        parts.append((g["sum_lk"] / g["count_lk"] - g["sum_hs"] / g["count_hs"]).rename(f"{region} / {motion}"))
    if not parts:
        return pd.DataFrame(columns=["scene", "seed"])
    return pd.concat(parts, axis=1).reset_index()


def _metric_rule(table: pd.DataFrame, metric: str) -> tuple[str, bool, str] | None:
    """(reduce rule, higher_is_better, unit) of ``metric``: harness.metrics' definition, else the table's
    columns with the rule ``mean``; None for a rule a difference of pooled values cannot use."""
    from harness.metrics import METRICS

    rows = table.loc[table["metric"] == metric, ["unit", "higher_is_better"]]
    unit = str(rows["unit"].iloc[0]) if len(rows) else ""
    d = METRICS.get(metric)
    if d is not None:
        return (d.reduce, bool(d.higher_is_better), unit or d.unit) if d.reduce in _REDUCE else None
    hib = bool(rows["higher_is_better"].iloc[0]) if len(rows) else _HIGHER_IS_BETTER.get(metric, False)
    return ("mean", hib, unit)


def compare_tracking(table: pd.DataFrame, lk: str, hs: str, *, metrics: tuple[str, ...] = TRACKING_METRICS,
                     seed: int = 0) -> list[Comparison]:
    """:class:`Comparison` of ``lk`` against ``hs`` per tracker (``point``, ``multi``: the ``region`` of the
    track rows, motion ``track``) and metric, paired per sequence (scene, seed).

    Every tracker either pipeline has rows for gets every metric of ``metrics``: where one side (or
    both) lacks the metric, a comparison with no unit whose missing side's value is NaN ("n/a" in
    the report). Each interval uses ``numpy.random.default_rng(seed)`` of its own.
    """
    rows = table[(table["motion"] == "track") & (table["status"] == "ok") & table["pipeline"].isin([lk, hs])]
    present = set(pd.unique(rows["region"].astype(str)))
    trackers = [t for t in _TRACKERS if t in present] + sorted(present - set(_TRACKERS))
    out = []
    for tracker in trackers:
        for metric in metrics:
            rule = _metric_rule(table, metric)
            reduce, hib, unit = rule if rule is not None else ("mean", False, "")
            sides = []
            for pipe in (lk, hs):
                r = rows[(rows["pipeline"] == pipe) & (rows["region"] == tracker) & (rows["metric"] == metric)
                         & (rows["count"] > 0)]
                sides.append(float(_REDUCE[reduce](r["sum"].sum(), r["count"].sum()))
                             if len(r) and rule is not None else float("nan"))
            u = (paired_units(table, lk, hs, metric=metric, region=tracker, motion="track", by=tuple(_SEQUENCE))
                 if rule is not None and all(np.isfinite(sides)) else pd.DataFrame())
            if u.empty:
                nan = float("nan")
                out.append(Comparison(lk=lk, hs=hs, metric=metric, unit=unit, region=tracker, motion="track",
                                      n_units=0, n_lk_lower=0, lk_value=sides[0], hs_value=sides[1], diff=nan,
                                      lo=nan, hi=nan, higher_is_better=hib))
                continue
            f = _REDUCE[reduce]
            d, lo, hi = bootstrap_difference(u["sum_lk"], u["count_lk"], u["sum_hs"], u["count_hs"],
                                             rng=np.random.default_rng(seed), reduce=reduce)
            per_unit = f(u["sum_lk"], u["count_lk"]) - f(u["sum_hs"], u["count_hs"])
            out.append(Comparison(lk=lk, hs=hs, metric=metric, unit=unit, region=tracker, motion="track",
                                  n_units=len(u), n_lk_lower=int((per_unit < 0).sum()),
                                  lk_value=float(f(u["sum_lk"].sum(), u["count_lk"].sum())),
                                  hs_value=float(f(u["sum_hs"].sum(), u["count_hs"].sum())),
                                  diff=d, lo=lo, hi=hi, higher_is_better=hib, n_lk_higher=int((per_unit > 0).sum())))
    return out
