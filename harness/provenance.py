"""Where a result came from: source version, package versions, machine, config hash.

Nothing here names the host: the machine is described by platform, CPU model
and core count only, so results can be shared and two runs on equal hardware
compare as "the same machine" for timing gates.

Public functions
----------------
git_info(path=None) -> (commit, dirty)     of the aerobench source tree; ("unknown", False) without git
package_versions() -> dict                 numpy, opencv, scikit-image, pyrender, trimesh, pandas, numba, ...
machine_info() -> dict                     platform, machine, cpu, cores
machine_id(info=None) -> str               one line: "Linux-x86_64 | <cpu> | 2 cores"
collect(*, renderer="") -> dict            all of the above + python, for run.json ``provenance``
canonical_json(obj) -> str                 sorted keys, no spaces, NaN refused
config_hash(obj) -> str                    sha256 hex of canonical_json(obj)
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import math
import os
import platform
import subprocess
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["SOURCE_ROOT", "PACKAGES", "git_info", "package_versions", "machine_info", "machine_id", "collect",
           "canonical_json", "config_hash"]

SOURCE_ROOT = Path(__file__).resolve().parents[1]
# distribution name -> label in provenance (pyrender is installed as the pyrender2 distribution)
PACKAGES = {"numpy": "numpy", "opencv-python-headless": "opencv", "scikit-image": "scikit-image",
            "pyrender2": "pyrender", "trimesh": "trimesh", "pandas": "pandas", "numba": "numba",
            "scipy": "scipy", "pyarrow": "pyarrow"}


def git_info(path: str | os.PathLike | None = None) -> tuple[str, bool]:
    """Commit hash and dirty flag of the git tree holding ``path`` (default the aerobench source).

    Without git, or outside a repository, returns ``("unknown", False)``.
    Dirty means tracked files differ from the commit (untracked files do not count).
    """
    cwd = Path(path) if path is not None else SOURCE_ROOT
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True,
                                timeout=10, check=True).stdout.strip()
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                                capture_output=True, text=True, timeout=10, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return "unknown", False
    return commit, bool(status.strip())


def package_versions() -> dict[str, str]:
    """Installed versions of the packages results depend on ("not installed" when absent)."""
    out = {}
    for dist, label in PACKAGES.items():
        try:
            out[label] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            out[label] = "not installed"
    return out


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return " ".join(line.split(":", 1)[1].split())
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info() -> dict[str, object]:
    """Platform, architecture, CPU model and logical core count (no host name)."""
    return {"platform": f"{platform.system()}-{platform.release()}", "machine": platform.machine(),
            "cpu": _cpu_model(), "cores": os.cpu_count() or 0}


def machine_id(info: Mapping | None = None) -> str:
    """A one-line machine description, equal on equal hardware: ``"Linux-x86_64 | <cpu> | N cores"``.

    The kernel release is left out, so a kernel update does not disable timing gates.
    """
    info = dict(info or machine_info())
    system = str(info.get("platform", "")).split("-")[0]
    return f"{system}-{info.get('machine', '')} | {info.get('cpu', '')} | {info.get('cores', 0)} cores"


def collect(*, renderer: str = "") -> dict:
    """Provenance for run.json: git commit / dirty, versions, python, machine (dict and id), renderer."""
    commit, dirty = git_info()
    info = machine_info()
    return {"git_commit": commit, "git_dirty": dirty, "versions": package_versions(),
            "python": platform.python_version(), "machine": machine_id(info), "machine_info": info,
            "renderer": renderer}


def _plain(obj):
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        if not math.isfinite(f):
            raise ValueError(f"config_hash: NaN or infinite value {f!r} in the config")
        return f
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "model_dump"):  # pydantic models
        return _plain(obj.model_dump(mode="json"))
    if obj is None or isinstance(obj, (str, int, bool)):
        return obj
    raise TypeError(f"config_hash: cannot hash a {type(obj).__name__} ({obj!r})")


def canonical_json(obj) -> str:
    """JSON with sorted keys and no whitespace; tuples become lists, numpy scalars plain numbers."""
    return json.dumps(_plain(obj), sort_keys=True, separators=(",", ":"), allow_nan=False, ensure_ascii=True)


def config_hash(obj) -> str:
    """sha256 (hex) of :func:`canonical_json`: equal configs hash equal, key order does not matter."""
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()
