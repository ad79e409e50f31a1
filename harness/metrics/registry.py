"""The metric registry: what each metric means, and the row every scoring function returns.

Every metric is a :class:`MetricDef` in the plain-dict registry :data:`METRICS`
(name -> unit, direction, weighting, how totals reduce to a value, one-line
description for ``aerobench list``), filled by :func:`register_metric` in the module
that computes it. :func:`_row` builds a results row from a metric's totals (one
place for its columns); :func:`timing_rows` turns a pipeline's ``stage_ms`` into rows.

Public: METRICS, MetricDef, register_metric, metric_def, describe_metrics,
timing_metric_name, timing_rows, REDUCES, STAGES.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Mapping
from dataclasses import dataclass

import pandas as pd

REDUCES = ("mean", "rms", "rate", "total", "complement", "quantile", "alpha_mean")
# stages of algorithms.pipeline that report wall time (others are registered on first use)
STAGES = ("global_motion", "jitter", "compensation", "flow", "compose", "threshold", "spatial", "temporal",
          "detection", "tracking", "total")


@dataclass(frozen=True)
class MetricDef:
    """What a metric means: ``unit``, direction, weighting and how totals reduce to a value."""

    name: str
    unit: str
    higher_is_better: bool
    weighting: str
    description: str
    reduce: str = "mean"
    kind: str = "accuracy"  # "accuracy" | "timing"
    q: float | None = None  # the quantile, for reduce == "quantile"


METRICS: dict[str, MetricDef] = {}


def register_metric(name: str, unit: str, *, higher_is_better: bool, weighting: str, description: str,
                    reduce: str = "mean", kind: str = "accuracy", q: float | None = None) -> MetricDef:
    """Add a metric to :data:`METRICS` (twice with different definitions is an error)."""
    if reduce not in REDUCES:
        raise ValueError(f"metric {name!r}: reduce must be one of {REDUCES}, got {reduce!r}")
    if kind not in ("accuracy", "timing"):
        raise ValueError(f"metric {name!r}: kind must be 'accuracy' or 'timing', got {kind!r}")
    d = MetricDef(name, unit, higher_is_better, weighting, description, reduce, kind, q)
    if name in METRICS and METRICS[name] != d:
        raise ValueError(f"metric {name!r} is registered twice with different definitions")
    METRICS[name] = d
    return d


def timing_metric_name(stage: str) -> str:
    """``time_<stage>_ms``: the wall-time metric of a pipeline stage (registered on first use)."""
    name = f"time_{stage}_ms"
    if name not in METRICS:
        register_metric(name, "ms", higher_is_better=False, kind="timing",
                        weighting="per frame pair, mean over pairs",
                        description=f"wall time of the {stage} stage per frame pair")
    return name


def metric_def(name: str) -> MetricDef:
    """The definition of ``name``; an unknown name raises ``KeyError`` listing the valid ones."""
    try:
        return METRICS[name]
    except KeyError:
        raise KeyError(f"unknown metric {name!r}; valid: {', '.join(sorted(METRICS))}") from None


def describe_metrics(pattern: str = "*") -> pd.DataFrame:
    """A table of the registered metrics matching a glob ``pattern``, for ``aerobench list``."""
    rows = [{"metric": d.name, "unit": d.unit, "better": "higher" if d.higher_is_better else "lower",
             "kind": d.kind, "weighting": d.weighting, "description": d.description}
            for n, d in sorted(METRICS.items()) if fnmatch.fnmatchcase(n, pattern)]
    return pd.DataFrame(rows, columns=["metric", "unit", "better", "kind", "weighting", "description"])


def _row(metric: str, value: float, total: float, count: float, *, region: str = "all", motion: str = "total",
         frame: int | None = None, track_id: int | None = None, hist: bytes = b"") -> dict:
    d = metric_def(metric)
    return {"frame": frame, "track_id": track_id, "metric": metric, "region": region, "motion": motion,
            "kind": d.kind, "value": float(value), "sum": float(total), "count": float(count),
            "unit": d.unit, "higher_is_better": d.higher_is_better, "hist": hist}


def timing_rows(stage_ms: Mapping[str, float], *, frame: int | None = None) -> list[dict]:
    """One ``time_<stage>_ms`` row per stage (``motion`` "cost"), and ``time_total_ms`` if absent."""
    rows = []
    total = 0.0
    for stage, ms in stage_ms.items():
        ms = float(ms)
        total += ms
        rows.append(_row(timing_metric_name(stage), ms, ms, 1, motion="cost", frame=frame))
    if "total" not in stage_ms and stage_ms:
        rows.append(_row("time_total_ms", total, total, 1, motion="cost", frame=frame))
    return rows


for _s in STAGES:
    timing_metric_name(_s)
