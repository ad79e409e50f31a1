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

Public functions
----------------
pair_pipelines(specs) -> [(lk, hs)]            twins by flow method in the resolved pipeline dicts
paired_units(table, lk, hs, *, metric, region, motion) -> DataFrame
bootstrap_difference(sum_a, count_a, sum_b, count_b, *, rng, n_boot, level) -> (d, lo, hi)
compare_pair(table, lk, hs, *, metric, regions, motions, seed) -> [Comparison]
by_scene_seed(table, lk, hs, *, metric, regions, motions) -> DataFrame   the difference per (scene, seed)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["LK", "HS", "N_BOOT", "LEVEL", "Comparison", "pair_pipelines", "paired_units", "bootstrap_difference",
           "compare_pair", "by_scene_seed", "verdict"]

LK, HS = "lucas_kanade", "horn_schunck"
N_BOOT = 4000
LEVEL = 0.95
_UNIT = ["scene", "seed", "frame"]


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
                 motion: str = "total") -> pd.DataFrame:
    """One row per frame pair both pipelines scored: ``scene, seed, frame, sum_lk, count_lk, sum_hs, count_hs``.

    ``table`` is a results table (rows of failed cells are left out here); a unit present for one
    pipeline only is dropped (it cannot be paired).
    """
    rows = table[(table["metric"] == metric) & (table["region"] == region) & (table["motion"] == motion)
                 & (table["status"] == "ok") & (table["count"] > 0)]
    sides = []
    for pipe, tag in ((lk, "lk"), (hs, "hs")):
        g = rows[rows["pipeline"] == pipe].groupby(_UNIT, as_index=False)[["sum", "count"]].sum()
        sides.append(g.rename(columns={"sum": f"sum_{tag}", "count": f"count_{tag}"}))
    return sides[0].merge(sides[1], on=_UNIT, how="inner").sort_values(_UNIT, kind="stable").reset_index(drop=True)


def bootstrap_difference(sum_a: np.ndarray, count_a: np.ndarray, sum_b: np.ndarray, count_b: np.ndarray, *,
                         rng: np.random.Generator, n_boot: int = N_BOOT, level: float = LEVEL
                         ) -> tuple[float, float, float]:
    """Difference of pooled means ``sum(sum_a)/sum(count_a) - sum(sum_b)/sum(count_b)`` and its
    percentile-bootstrap interval over the paired units.

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
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    sa, ca, sb, cb = arrays
    d = sa.sum() / ca.sum() - sb.sum() / cb.sum()
    idx = rng.integers(0, n, size=(n_boot, n))
    boot = sa[idx].sum(1) / ca[idx].sum(1) - sb[idx].sum(1) / cb[idx].sum(1)
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
    n_lk_lower: int       # units where LK's error is the lower one
    lk_value: float       # pooled over the units
    hs_value: float
    diff: float           # lk_value - hs_value
    lo: float
    hi: float

    @property
    def sentence(self) -> str:
        return verdict(self)


def verdict(c: Comparison) -> str:
    """One sentence from the numbers: who has the lower error and by how much, or no clear difference."""
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
