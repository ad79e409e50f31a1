"""Command-line overrides shared by the benchmark scripts: ``KEY=VALUE`` values and pipelines with ``--set``."""

from __future__ import annotations

import copy


def parse_value(text: str):
    """An override's value: an int, a float, true / false / null, else the text itself."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False, "null": None}.get(text, text)


def pipeline_with(name: str, sets: list[str]):
    """The built-in pipeline ``name`` with ``section.key=value`` overrides (e.g. ``detection.core_rel=0.4``)."""
    from algorithms.pipeline import PIPELINES, Pipeline

    d = copy.deepcopy(PIPELINES[name])
    for kv in sets:
        if "=" not in kv:
            raise ValueError(f"--set: expected SECTION.KEY=VALUE, got {kv!r}")
        key, value = kv.split("=", 1)
        *path, leaf = key.split(".")
        node = d
        for i, k in enumerate(path):
            if node.get(k) is None:
                node[k] = {}
            if not isinstance(node[k], dict):
                at = ".".join(path[:i + 1])
                raise ValueError(f"--set {kv}: {at} is {node[k]!r} in {name}, not a section; set it whole ({at}=...)")
            node = node[k]
        node[leaf] = parse_value(value)
    return Pipeline.from_dict(d)


def scene_overrides(*, frames: int | None = None, seed: int | None = None, sets=()) -> dict:
    """A scene's overrides from ``--frames``, ``--seed`` and ``KEY=VALUE`` texts (ValueError naming a bad one)."""
    over = {}
    if frames:
        over["image.n_frames"] = frames
    if seed is not None:
        over["seed"] = seed
    for kv in sets:
        if "=" not in kv:
            raise ValueError(f"expected KEY=VALUE, got {kv!r}")
        key, value = kv.split("=", 1)
        over[key] = parse_value(value)
    return over
