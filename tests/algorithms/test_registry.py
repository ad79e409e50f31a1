"""algorithms.registry: one table of stages that built-ins and plugins fill alike, looked up by kind and name."""

from __future__ import annotations

import numpy as np
import pytest

import algorithms.pipeline  # noqa: F401  (registers every built-in stage)
from algorithms import registry
from algorithms.registry import (DEFAULT_FLOW_COST, FLOW_METHODS, STAGES, flow_cost, get_flow_method, get_stage,
                                 register_flow, register_stage)


@pytest.fixture
def clean_registry(monkeypatch):
    """Registrations made by a test are undone after it."""
    saved = {kind: dict(table) for kind, table in STAGES.items()}
    saved_costs = dict(registry.FLOW_COSTS)
    yield
    for kind in list(STAGES):
        if kind not in saved:
            del STAGES[kind]
        else:
            STAGES[kind].clear()
            STAGES[kind].update(saved[kind])
    registry.FLOW_COSTS.clear()
    registry.FLOW_COSTS.update(saved_costs)


def test_every_stage_kind_of_the_pipeline_is_in_the_one_table():
    assert {"global_motion", "flow", "jitter", "threshold", "spatial", "temporal", "detection",
            "tracking"} <= set(STAGES)
    assert STAGES["flow"] is FLOW_METHODS  # the flow methods are that table's "flow" kind, not a second dict
    assert {"lucas_kanade", "horn_schunck", "dis", "farneback", "tvl1", "ilk"} <= set(FLOW_METHODS)
    assert get_stage("global_motion", "ncc_global_motion").__name__ == "ncc_global_motion"
    assert get_stage("tracking", "point").__name__ == "PointTracker"


def test_unknown_names_list_the_valid_ones():
    with pytest.raises(KeyError, match=r"unknown flow method 'lucas_kanad'; valid: .*lucas_kanade"):
        get_flow_method("lucas_kanad")
    with pytest.raises(KeyError, match=r"unknown stage kind 'smoothing'; valid: .*flow.*global_motion"):
        get_stage("smoothing", "x")
    with pytest.raises(KeyError, match=r"unknown global_motion stage 'phase'; valid: ncc_global_motion"):
        get_stage("global_motion", "phase")


def test_a_plugin_stage_is_registered_once_and_a_second_function_of_that_name_is_refused(clean_registry):
    @register_stage("global_motion")
    def plugin_shift(frame0, frame1, *, max_shift: int = 4):
        """A plugin's global motion method."""

    assert get_stage("global_motion", "plugin_shift") is plugin_shift
    register_stage("global_motion")(plugin_shift)  # the same function again: harmless (a module re-imported)

    def plugin_shift(frame0, frame1):  # noqa: F811 - another function under the same name
        pass

    with pytest.raises(ValueError, match=r"global_motion stage 'plugin_shift' is registered twice"):
        register_stage("global_motion")(plugin_shift)


def test_a_plugin_global_motion_method_runs_in_a_pipeline(clean_registry):
    from algorithms.global_motion import GlobalMotion
    from algorithms.pipeline import Pipeline, SequenceEstimate

    @register_stage("global_motion")
    def fixed_shift(frame0, frame1, *, dx: float = 0.0):
        """Claims the ground moved ``dx`` px right between every pair."""
        return GlobalMotion(shift_px=np.array([dx, 0.0]), peak=1.0, valid=True)

    p = Pipeline.from_dict({"name": "p", "global_motion": {"method": "fixed_shift", "params": {"dx": 2}},
                            "jitter": None, "flow": {"method": "lucas_kanade"},
                            "tracking": {"point": False, "multi": None}})
    assert p.to_dict()["global_motion"] == {"method": "fixed_shift", "params": {"dx": 2.0}}
    frames = [np.random.default_rng(i).random((32, 32)).astype(np.float32) for i in range(3)]
    *pairs, seq = list(p.run(frames))
    assert isinstance(seq, SequenceEstimate) and len(pairs) == 2
    np.testing.assert_array_equal(seq.shifts_px, [[2.0, 0.0], [2.0, 0.0]])


def test_flow_cost_is_registered_with_the_method(clean_registry):
    assert flow_cost("horn_schunck") > flow_cost("lucas_kanade") > flow_cost("dis")

    @register_flow(cost=3.0)
    def costly_flow(frame0, frame1):
        """A plugin flow method with a registered cost."""

    @register_flow
    def plain_flow(frame0, frame1):
        """A plugin flow method without one."""

    assert flow_cost("costly_flow") == 3.0 and FLOW_METHODS["costly_flow"] is costly_flow
    assert flow_cost("plain_flow") == DEFAULT_FLOW_COST
    for bad in (0, -1.0, float("nan"), True, "2"):
        with pytest.raises(ValueError, match=r"cost: expected a finite number > 0"):
            register_flow(cost=bad)
