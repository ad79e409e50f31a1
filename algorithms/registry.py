"""Registries of flow methods and pipeline stage functions, keyed by their stable names.

A name is the function's own name (``lucas_kanade``, ``horn_schunck``, ``dis``, ...),
the name YAML suites and the CLI use. Entries are added by decorators at import
time; an unknown name raises ``KeyError`` that lists the valid ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

__all__ = ["FLOW_METHODS", "STAGES", "register_flow", "register_stage", "get_flow_method", "get_stage",
           "flow_cost", "DEFAULT_FLOW_COST"]

F = TypeVar("F", bound=Callable)

# name -> flow function ``(frame0, frame1, **params) -> (flow (H, W, 2) float32, valid (H, W) bool)``
FLOW_METHODS: dict[str, Callable] = {}
# stage kind ("global_motion", "jitter", "threshold", ...) -> name -> function
STAGES: dict[str, dict[str, Callable]] = {}
# name -> rough cost of a pair per pixel relative to Lucas-Kanade (only the runner's order of cells uses it)
FLOW_COSTS: dict[str, float] = {}
DEFAULT_FLOW_COST = 2.0


def _first_doc_line(fn: Callable) -> str:
    doc = (fn.__doc__ or "").strip()
    return doc.splitlines()[0] if doc else ""


def register_flow(fn: F | None = None, *, cost: float | None = None):
    """Register a flow method under its function name: ``@register_flow`` or ``@register_flow(cost=4.0)``.

    ``cost`` is the method's rough time per pair and pixel relative to Lucas-Kanade
    (default :data:`DEFAULT_FLOW_COST`); the runner hands out costly cells first with it,
    no result depends on it.
    """
    if cost is not None and (isinstance(cost, bool) or not isinstance(cost, (int, float))
                             or not math.isfinite(cost) or cost <= 0):
        raise ValueError(f"cost: expected a finite number > 0, got {cost!r}")

    def deco(f: F) -> F:
        name = f.__name__
        if name in FLOW_METHODS and FLOW_METHODS[name] is not f:
            raise ValueError(f"flow method {name!r} is registered twice")
        FLOW_METHODS[name] = f
        if cost is not None:
            FLOW_COSTS[name] = float(cost)
        return f

    return deco if fn is None else deco(fn)


def flow_cost(name: str) -> float:
    """The relative cost registered with flow method ``name`` (:data:`DEFAULT_FLOW_COST` when none)."""
    return FLOW_COSTS.get(name, DEFAULT_FLOW_COST)


def register_stage(kind: str) -> Callable[[F], F]:
    """Register a stage function of ``kind`` under its function name."""

    def deco(fn: F) -> F:
        table = STAGES.setdefault(kind, {})
        if fn.__name__ in table and table[fn.__name__] is not fn:
            raise ValueError(f"{kind} stage {fn.__name__!r} is registered twice")
        table[fn.__name__] = fn
        return fn

    return deco


def _lookup(table: dict[str, Callable], name: str, what: str) -> Callable:
    try:
        return table[name]
    except KeyError:
        valid = ", ".join(sorted(table)) or "(none registered)"
        raise KeyError(f"unknown {what} {name!r}; valid: {valid}") from None


def get_flow_method(name: str) -> Callable:
    """The flow method registered as ``name``."""
    return _lookup(FLOW_METHODS, name, "flow method")


def get_stage(kind: str, name: str) -> Callable:
    """The ``kind`` stage function registered as ``name``."""
    if kind not in STAGES:
        raise KeyError(f"unknown stage kind {kind!r}; valid: {', '.join(sorted(STAGES))}")
    return _lookup(STAGES[kind], name, f"{kind} stage")


def describe() -> dict[str, dict[str, str]]:
    """One-line descriptions of every registered flow method and stage, for ``aerobench list``."""
    out = {"flow": {n: _first_doc_line(f) for n, f in sorted(FLOW_METHODS.items())}}
    for kind, table in sorted(STAGES.items()):
        out[kind] = {n: _first_doc_line(f) for n, f in sorted(table.items())}
    return out
