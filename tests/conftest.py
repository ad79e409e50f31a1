"""Root fixtures and hooks of the whole test suite.

The suite runs on pytest-xdist workers, one per core (``-n auto --dist loadgroup`` in
pyproject's ``addopts``; :func:`pytest_xdist_auto_num_workers`). A module- or session-scoped fixture is built once per worker that needs it,
so the tests that share an expensive one are kept on one worker here, by an
``xdist_group`` mark added at collection (no test file needs to know about xdist):

* every test of a module that uses a module-scoped fixture: one group per module;
* every test that uses a session-scoped fixture named in :data:`SHARED_SESSION_FIXTURES`
  (a run of a suite, a rendered scene, a written report): one group per fixture definition, so
  ``tests/harness``'s and ``tests/reliability``'s ``reference_run`` are separate groups.

A test that uses both kinds of fixture goes with the session fixture's group.
Under xdist, tests marked ``slow`` are handed out first.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# session fixtures that run a suite, render a scene or write a report: built once, on the worker of their group
SHARED_SESSION_FIXTURES = ("reference_run", "tiny_sequence", "fixture_report", "tiny_run")


def _group(item: pytest.Item) -> str | None:
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return None
    module_group, session_groups = None, set()
    for name in item.fixturenames:
        defs = info.name2fixturedefs.get(name)
        if not defs:
            continue
        fixturedef = defs[-1]
        if fixturedef.scope == "module" and module_group is None:
            module_group = item.nodeid.split("::", 1)[0]
        elif fixturedef.scope == "session" and name in SHARED_SESSION_FIXTURES:
            session_groups.add(f"{name}:{fixturedef.baseid or '.'}")
    if session_groups:  # a session fixture's group wins: it is the costlier one to build twice
        return "+".join(sorted(session_groups))
    return module_group


def pytest_itemcollected(item: pytest.Item) -> None:
    # here, not in pytest_collection_modifyitems: xdist's own modifyitems hook reads the marks into the
    # node ids, and a conftest's modifyitems hook may run after it (tryfirst notwithstanding)
    group = _group(item)
    if group is not None:
        item.add_marker(pytest.mark.xdist_group(group))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("PYTEST_XDIST_WORKER") and config.getvalue("loadgroup"):
        # xdist 3.8 names the group in item._nodeid, which pytest 9 no longer reads (the id is
        # item._id): give the scheduler the "<nodeid>@<group>" it expects ourselves
        from _pytest.nodeid import NodeId

        for item in items:
            mark = item.get_closest_marker("xdist_group")
            if mark is not None and "@" not in item.nodeid and hasattr(item, "_id"):
                item._id = NodeId.parse(f"{item.nodeid}@{mark.args[0]}")
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # xdist hands out the groups first (largest first), then single tests in this order: the
        # slow ones (end-to-end runs, renders) first, so that no long test is left to run alone at the end
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one worker per usable core, at most 4 (the tests spawn worker pools of their own)."""
    return max(1, min(len(os.sched_getaffinity(0)), 4))


@pytest.fixture(scope="session")
def shared_render_cache(tmp_path_factory) -> Path:
    """One render cache for the whole session, shared by the xdist workers of this session.

    The cache is safe for concurrent writers (each entry is written to a temporary folder and
    renamed into place; the first complete entry wins), so workers may share it: a scene one
    worker rendered is reused by the other. Without xdist it is a fresh folder of this session.
    """
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # basetemp is <session>/popen-gwN: its parent belongs to this session and to its workers only
        path = tmp_path_factory.getbasetemp().parent / "shared-render-cache"
        path.mkdir(exist_ok=True)
        return path
    return tmp_path_factory.mktemp("shared-render-cache")
