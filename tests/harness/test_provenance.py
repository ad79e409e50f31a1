"""Provenance: a stable config hash, git info that tolerates no git, a machine id without host name."""

from __future__ import annotations

import platform

import numpy as np
import pytest

from harness import provenance as P


def test_config_hash_ignores_key_order_and_sees_values():
    a = {"flow": {"method": "lucas_kanade", "window": 15}, "seeds": (1, 2)}
    b = {"seeds": [1, 2], "flow": {"window": np.int64(15), "method": "lucas_kanade"}}
    assert P.config_hash(a) == P.config_hash(b)
    assert P.config_hash(a) != P.config_hash({**a, "seeds": (2, 1)})
    assert len(P.config_hash(a)) == 64


def test_config_hash_refuses_nan_and_unknown_objects():
    with pytest.raises(ValueError, match="NaN or infinite"):
        P.config_hash({"alpha": float("nan")})
    with pytest.raises(TypeError, match="cannot hash a object"):
        P.config_hash({"x": object()})


def test_git_info_without_a_repository(tmp_path):
    assert P.git_info(tmp_path) == ("unknown", False)


def test_git_info_of_the_source_tree():
    commit, dirty = P.git_info()
    assert (len(commit) == 40 and all(c in "0123456789abcdef" for c in commit)) or commit == "unknown"
    assert isinstance(dirty, bool)


def test_machine_id_names_no_host():
    info = P.machine_info()
    mid = P.machine_id(info)
    assert platform.node() not in mid or not platform.node()
    assert mid.endswith(f"{info['cores']} cores")
    assert P.machine_id({"platform": "Linux-6.1", "machine": "x86_64", "cpu": "EPYC", "cores": 2}) == \
        P.machine_id({"platform": "Linux-6.9", "machine": "x86_64", "cpu": "EPYC", "cores": 2})


def test_collect_has_versions_of_the_packages_results_depend_on():
    prov = P.collect(renderer="llvmpipe")
    assert set(prov["versions"]) >= {"numpy", "opencv", "scikit-image", "pyrender", "trimesh", "pandas", "numba"}
    assert prov["versions"]["numpy"] == np.__version__
    assert prov["python"] == platform.python_version() and prov["renderer"] == "llvmpipe"
