"""Load one module of another source tree (an earlier commit's worktree) beside this tree's, for the
benchmarks that time the two side by side in one process."""

from __future__ import annotations

import importlib.util
import sys
import tempfile
from pathlib import Path
from types import ModuleType


def load_earlier(tree: str | Path, relpath: str, name: str) -> ModuleType:
    """``tree/relpath`` (e.g. ``algorithms/tv_l1_flow.py``) as a module named ``name``.

    Its ``@register_flow`` lines are dropped (the name is already registered by this tree's
    module). The source is copied to a file of its own in a folder that outlives the run:
    numba's on-disk cache keys on the file, so the earlier kernels compile once.
    """
    src = (Path(tree) / relpath).read_text()
    src = "\n".join("" if line.startswith("@register_flow") else line for line in src.splitlines())
    path = Path(tempfile.gettempdir()) / name / f"{name}.py"
    path.parent.mkdir(exist_ok=True)
    if not path.is_file() or path.read_text() != src:
        path.write_text(src)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # numba's cache loads re-import the module by name
    spec.loader.exec_module(mod)
    return mod
