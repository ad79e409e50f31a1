"""The public API of ``algorithms``: every export resolves to its home module's object, lazily."""

import subprocess
import sys

import pytest

import algorithms
from algorithms.registry import FLOW_METHODS


def test_every_export_resolves_to_the_object_in_its_module():
    import importlib

    for name in algorithms.__all__:
        obj = getattr(algorithms, name)
        home = importlib.import_module(algorithms._EXPORTS[name])
        assert obj is getattr(home, name), name


def test_flow_methods_are_registered_under_their_function_names():
    import algorithms.pipeline  # noqa: F401  (imports every flow method module)
    from algorithms import horn_schunck, lucas_kanade

    assert callable(lucas_kanade) and callable(horn_schunck)  # functions, not modules of the same name
    assert FLOW_METHODS["lucas_kanade"] is lucas_kanade and FLOW_METHODS["horn_schunck"] is horn_schunck
    for name in ("lucas_kanade", "horn_schunck", "farneback", "dis", "tvl1", "ilk", "tv_l1"):
        assert FLOW_METHODS[name] is getattr(algorithms, name)


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="has no attribute 'lucas_kanad'"):
        algorithms.lucas_kanad  # noqa: B018


def test_importing_the_flow_convention_stays_light():
    # scenes imports algorithms.flow only: that must not load numba or the pipeline
    code = ("import sys, algorithms.flow; "
            "print(any(m in sys.modules for m in ('numba', 'algorithms.pipeline', 'skimage')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
