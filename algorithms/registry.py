"""One registry of pipeline stages, keyed by kind and by the stable names YAML uses.

``STAGES[kind][name]`` is the function (or class) of a stage; ``kind`` is one of the
pipeline's stages (``global_motion``, ``flow``, ``jitter``, ``threshold``, ``spatial``,
``temporal``, ``detection``, ``tracking``). A name is the function's own name
(``ncc_global_motion``, ``lucas_kanade``, ``horn_schunck``, ``dis``, ...) unless given.
Entries are added by decorators at import time, by the built-in modules and by plugins
alike (a suite's ``imports:``); the pipeline resolves every stage here, and the methods
a pipeline dict names (``global_motion.method``, ``flow.method``) are checked here, so an
unknown name raises ``KeyError`` listing the valid ones. ``FLOW_METHODS`` is
``STAGES["flow"]`` (the same dict), kept under its own name because plugins use it.

A flow method can register its rough cost relative to Lucas-Kanade (``cost=``); the
runner orders cells by it (:func:`flow_cost`), no result depends on it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

__all__ = ["STAGES", "FLOW_METHODS", "FLOW_COSTS", "DEFAULT_FLOW_COST", "register_stage", "register_flow",
           "get_stage", "get_flow_method", "flow_cost", "describe"]

F = TypeVar("F", bound=Callable)

# stage kind -> name -> function (or class)
STAGES: dict[str, dict[str, Callable]] = {}
# name -> flow function ``(frame0, frame1, **params) -> (flow (H, W, 2) float32, valid (H, W) bool)``
FLOW_METHODS: dict[str, Callable] = STAGES.setdefault("flow", {})
# flow method name -> rough cost of a pair per pixel relative to Lucas-Kanade (ordering of cells only)
FLOW_COSTS: dict[str, float] = {}
DEFAULT_FLOW_COST = 2.0


def _first_doc_line(fn: Callable) -> str:
    doc = (fn.__doc__ or "").strip()
    return doc.splitlines()[0] if doc else ""


def register_stage(kind: str, *, name: str | None = None) -> Callable[[F], F]:
    """Register a stage function (or class) of ``kind`` under ``name`` (default: its own name)."""
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"kind: expected a non-empty string, got {kind!r}")

    def deco(fn: F) -> F:
        key = name or fn.__name__
        table = STAGES.setdefault(kind, {})
        if key in table and table[key] is not fn:
            raise ValueError(f"{kind} stage {key!r} is registered twice")
        table[key] = fn
        return fn

    return deco


def register_flow(fn: F | None = None, *, cost: float | None = None):
    """Register a flow method under its function name: ``@register_flow`` or ``@register_flow(cost=4.0)``.

    ``cost`` is the method's rough time per pair and pixel relative to Lucas-Kanade
    (default :data:`DEFAULT_FLOW_COST`).
    """
    if cost is not None and (isinstance(cost, bool) or not isinstance(cost, (int, float))
                             or not math.isfinite(cost) or cost <= 0):
        raise ValueError(f"cost: expected a finite number > 0, got {cost!r}")

    def deco(f: F) -> F:
        register_stage("flow")(f)
        if cost is not None:
            FLOW_COSTS[f.__name__] = float(cost)
        return f

    return deco if fn is None else deco(fn)


def flow_cost(name: str) -> float:
    """The relative cost registered with flow method ``name`` (:data:`DEFAULT_FLOW_COST` when none)."""
    return FLOW_COSTS.get(name, DEFAULT_FLOW_COST)


def _lookup(table: dict[str, Callable], name: str, what: str) -> Callable:
    try:
        return table[name]
    except KeyError:
        valid = ", ".join(sorted(table)) or "(none registered)"
        raise KeyError(f"unknown {what} {name!r}; valid: {valid}") from None


def get_stage(kind: str, name: str) -> Callable:
    """The ``kind`` stage registered as ``name``."""
    if kind not in STAGES:
        raise KeyError(f"unknown stage kind {kind!r}; valid: {', '.join(sorted(STAGES))}")
    return _lookup(STAGES[kind], name, f"{kind} stage")


def get_flow_method(name: str) -> Callable:
    """The flow method registered as ``name``."""
    return _lookup(FLOW_METHODS, name, "flow method")


def describe() -> dict[str, dict[str, str]]:
    """One-line descriptions of every registered stage, by kind (flow methods under ``"flow"``)."""
    return {kind: {n: _first_doc_line(f) for n, f in sorted(table.items())} for kind, table in sorted(STAGES.items())}
