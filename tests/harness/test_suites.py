"""Suites: validation with messages that name the file and the field, sweep expansion, stable cell ids."""

from __future__ import annotations

import copy
import textwrap

import pytest
import yaml
from tests.harness.harness_testdata import TINY_SUITE

from harness.suites import SuiteError, builtin_suites, expand, load_suite, parse_suite


def _suite(**changes):
    data = copy.deepcopy(TINY_SUITE)
    data.update(changes)
    return data


# --------------------------------------------------------------------------- built-ins


def test_builtin_suites_exist_and_expand():
    names = set(builtin_suites())
    assert {"smoke", "standard", "sweep-jitter", "sweep-speed", "sweep-noise"} <= names
    for name in names:
        suite = load_suite(name)
        cells = expand(suite)
        n_variants = len({(c.variant.label, c.variant.seed) for c in cells})
        assert len(cells) == n_variants * len(suite.pipelines), name
        assert suite.description, f"{name} has no description for `aerobench list`"


def test_smoke_covers_lk_hs_and_a_reference_on_tiny_scenes():
    suite = load_suite("smoke")
    assert {"thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis"} <= set(suite.pipelines)
    assert {s.preset for s in suite.scenes} == {"tiny"}


def test_sweep_suites_vary_their_axis():
    for name, key in (("sweep-jitter", "camera.jitter"), ("sweep-speed", "vehicles.speed"),
                      ("sweep-noise", "sensor.noise")):
        cells = expand(load_suite(name))
        assert all(c.variant.sweep_param.startswith(key) for c in cells), name
        assert len({str(c.variant.sweep_value) for c in cells}) >= 4, name


# --------------------------------------------------------------------------- expansion


def test_sweep_expands_to_the_grid_with_values_applied():
    data = _suite(scenes=[{"preset": "tiny", "overrides": {"image.n_frames": 3},
                           "sweep": {"sensor.noise.gaussian_std": [0.0, 2.0, 4.0],
                                     "camera.altitude_m": [60.0, 90.0]}}],
                  seeds=[1, 2])
    cells = expand(parse_suite(data))
    assert len(cells) == 3 * 2 * 2 * 2  # noise x altitude x seeds x pipelines
    for c in cells:
        noise, altitude = (float(x) for x in c.variant.sweep_value.split(","))
        assert c.variant.spec.sensor.noise.gaussian_std == noise
        assert c.variant.spec.camera.altitude_m == altitude
        assert c.variant.spec.seed == c.variant.seed
        assert c.variant.spec.image.n_frames == 3
        assert c.variant.sweep_param == "sensor.noise.gaussian_std,camera.altitude_m"
    assert len({c.cell_id for c in cells}) == len(cells)
    assert len({c.variant.scene_hash for c in cells}) == 3 * 2 * 2


def test_single_key_sweep_keeps_the_value():
    data = _suite(scenes=[{"preset": "tiny", "sweep": {"sensor.noise.gaussian_std": [1.5, 3.0]}}])
    cells = expand(parse_suite(data))
    assert sorted({c.variant.sweep_value for c in cells}) == [1.5, 3.0]
    assert {c.variant.label for c in cells} == {"tiny[sensor.noise.gaussian_std=1.5]", "tiny[sensor.noise.gaussian_std=3]"}


def test_cell_ids_are_stable_and_follow_the_config():
    a = {c.pipeline: c.cell_id for c in expand(parse_suite(_suite()))}
    assert a == {c.pipeline: c.cell_id for c in expand(parse_suite(_suite()))}
    # another pipeline parameter changes that pipeline's cell only
    changed = _suite(pipelines=["thesis-lk", {"name": "dis", "base": "dis", "spec": {"description": "other"}}])
    b = {c.pipeline: c.cell_id for c in expand(parse_suite(changed))}
    assert b["thesis-lk"] == a["thesis-lk"]
    assert b["dis"] != a["dis"]
    # another scene parameter changes every cell
    c = {c.pipeline: c.cell_id for c in expand(parse_suite(_suite(scenes=[{"preset": "tiny"}])))}
    assert not set(c.values()) & set(a.values())


# --------------------------------------------------------------------------- bad suites


def test_yaml_syntax_error_gives_the_line(write_suite):
    path = write_suite("name: x\nscenes:\n  - preset: tiny\nseeds: [1, 2\npipelines: [dis]\n")
    with pytest.raises(SuiteError, match=rf"{path}: YAML syntax error at line \d+"):
        load_suite(path)


def test_unknown_key_is_named(write_suite):
    path = write_suite(_suite(scenes=[{"preset": "tiny", "overides": {"seed": 1}}]))
    with pytest.raises(SuiteError, match=rf"{path}: scenes\[0\]\.overides: unknown key; did you mean 'overrides'\?"):
        load_suite(path)


def test_unknown_top_level_key_is_named(write_suite):
    path = write_suite(_suite(workers=4))
    with pytest.raises(SuiteError, match=r"workers: unknown key; valid: name, description, scenes"):
        load_suite(path)


def test_nan_is_refused(write_suite):
    text = "name: x\nscenes:\n  - preset: tiny\n    overrides: {sensor.noise.gaussian_std: .nan}\nseeds: [1]\npipelines: [dis]\n"
    with pytest.raises(SuiteError, match=r"scenes\[0\]\.overrides: .*sensor.noise.gaussian_std: nan is not a finite"):
        load_suite(write_suite(text))
    text = "name: x\nscenes:\n  - preset: tiny\n    sweep: {sensor.noise.gaussian_std: [1.0, .inf]}\nseeds: [1]\npipelines: [dis]\n"
    with pytest.raises(SuiteError, match=r"scenes\[0\]\.sweep: .*inf is not a finite"):
        load_suite(write_suite(text))


def test_unknown_pipeline_lists_the_valid_ones(write_suite):
    path = write_suite(_suite(pipelines=["thesis-lk", "thesis-kl"]))
    with pytest.raises(SuiteError, match=r"pipelines\[1\]: unknown pipeline 'thesis-kl'; valid: .*thesis-lk"):
        load_suite(path)
    path = write_suite(_suite(pipelines=[{"name": "x", "base": "nope"}]))
    with pytest.raises(SuiteError, match=r"pipelines\[0\]\.base: unknown pipeline 'nope'; valid: .*dis"):
        load_suite(path)


def test_unknown_metric_lists_the_valid_ones(write_suite):
    path = write_suite(_suite(metrics=["epe_typo"]))
    with pytest.raises(SuiteError, match=r"metrics\[0\]: unknown metric 'epe_typo'; valid: .*epe"):
        load_suite(path)


def test_empty_sweep_is_an_error(write_suite):
    with pytest.raises(SuiteError, match=r"scenes\[0\]\.sweep: an empty sweep"):
        load_suite(write_suite(_suite(scenes=[{"preset": "tiny", "sweep": {}}])))
    with pytest.raises(SuiteError, match=r"scenes\[0\]\.sweep: an empty sweep: 'sensor.noise.gaussian_std' has no values"):
        load_suite(write_suite(_suite(scenes=[{"preset": "tiny", "sweep": {"sensor.noise.gaussian_std": []}}])))


def test_bad_scene_parameter_names_the_scene_and_field(write_suite):
    path = write_suite(_suite(scenes=[{"preset": "tiny", "sweep": {"sensor.noise.gaussian_sd": [1.0]}}]))
    with pytest.raises(SuiteError, match=r"scenes\[0\] .*gaussian_sd"):
        expand(load_suite(path), source=str(path))


def test_unknown_preset_lists_the_valid_ones(write_suite):
    with pytest.raises(SuiteError, match=r"scenes\[0\]\.preset: unknown preset 'tinny'; valid: .*tiny"):
        load_suite(write_suite(_suite(scenes=[{"preset": "tinny"}])))


def test_duplicate_key_and_empty_lists_are_refused(write_suite):
    with pytest.raises(SuiteError, match=r"line 3.*'seeds' appears twice"):
        load_suite(write_suite("name: x\nseeds: [1]\nseeds: [2]\nscenes: [{preset: tiny}]\npipelines: [dis]\n"))
    with pytest.raises(SuiteError, match=r"seeds: List should have at least 1 item"):
        load_suite(write_suite(_suite(seeds=[])))


def test_missing_suite_names_the_builtins(tmp_path):
    with pytest.raises(SuiteError, match=r"no such suite file, and not a built-in suite \(.*smoke"):
        load_suite(tmp_path / "missing.yaml")


def test_inline_pipeline_is_its_base_with_the_changes():
    data = _suite(pipelines=[
        {"name": "lk-9", "base": "thesis-lk", "spec": {"flow": {"params": {"window": 9}}}},
        {"name": "lk-to-dis", "base": "thesis-lk", "spec": {"flow": {"method": "dis"}, "compensation": "none"}},
    ])
    specs = {c.pipeline: c.pipeline_spec for c in expand(parse_suite(data))}
    assert specs["lk-9"]["name"] == "lk-9"
    assert specs["lk-9"]["flow"] == {"method": "lucas_kanade", "params": {"window": 9}}
    # another method does not inherit the base method's parameters
    assert specs["lk-to-dis"]["flow"] == {"method": "dis"}
    assert specs["lk-to-dis"]["compensation"] == "none"
    with pytest.raises(SuiteError, match=r"pipelines\[0\] \(bad\): flow.params.windw: unknown parameter"):
        expand(parse_suite(_suite(pipelines=[{"name": "bad", "base": "thesis-lk",
                                              "spec": {"flow": {"params": {"windw": 9}}}}])))


def test_the_module_docstring_example_is_a_valid_suite():
    import harness.suites as S

    doc = S.__doc__
    example = doc[doc.index("Example::") + len("Example::"):doc.index("(``tests/harness/test_suites.py``")]
    suite = parse_suite(yaml.safe_load(textwrap.dedent(example)), source="suites.py docstring")
    cells = expand(suite)
    assert {c.pipeline for c in cells} == {"thesis-lk", "hs-alpha-5"}
    assert {c.variant.sweep_value for c in cells} == {0.0, 0.3, 0.6}
    assert next(c for c in cells if c.pipeline == "hs-alpha-5").pipeline_spec["flow"]["params"]["alpha"] == 5.0


def test_imports_find_a_module_in_the_working_folder(tmp_path, monkeypatch):
    import sys

    from harness.suites import SuiteError, import_modules

    (tmp_path / "my_local_plugin_xyz.py").write_text("LOADED = True\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    import_modules(["my_local_plugin_xyz"])
    assert sys.modules["my_local_plugin_xyz"].LOADED
    with pytest.raises(SuiteError, match=r"imports\[0\]: cannot import 'no_such_plugin_xyz' .*working folder"):
        import_modules(["no_such_plugin_xyz"])


def test_imports_are_looked_up_beside_the_suite_file_first(tmp_path, monkeypatch):
    """`cd elsewhere; aerobench run own/my-suite.yaml` imports own/my_flow.py (then the working folder)."""
    import sys

    from harness.suites import SuiteError, import_paths, load_suite

    own, elsewhere = tmp_path / "own", tmp_path / "elsewhere"
    own.mkdir()
    elsewhere.mkdir()
    (own / "beside_suite_plugin_xyz.py").write_text("WHERE = 'beside the suite'\n")
    (elsewhere / "beside_suite_plugin_xyz.py").write_text("WHERE = 'working folder'\n")
    (elsewhere / "cwd_only_plugin_xyz.py").write_text("WHERE = 'working folder'\n")
    (own / "my-suite.yaml").write_text(
        "name: mine\nimports: [beside_suite_plugin_xyz, cwd_only_plugin_xyz]\nscenes: [{preset: tiny}]\n"
        "seeds: [1]\npipelines: [thesis-lk]\n")
    monkeypatch.chdir(elsewhere)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(own), str(elsewhere))])
    for name in ("beside_suite_plugin_xyz", "cwd_only_plugin_xyz"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    suite = load_suite("../own/my-suite.yaml")
    assert import_paths(suite) == [str(own), str(elsewhere)]
    expand(suite)
    assert sys.modules["beside_suite_plugin_xyz"].WHERE == "beside the suite"
    assert sys.modules["cwd_only_plugin_xyz"].WHERE == "working folder"
    (own / "bad.yaml").write_text("name: bad\nimports: [no_such_plugin_xyz]\nscenes: [{preset: tiny}]\n"
                                  "seeds: [1]\npipelines: [thesis-lk]\n")
    with pytest.raises(SuiteError, match=rf"imports\[0\]: cannot import 'no_such_plugin_xyz' \(searched the installed "
                                         rf"packages, the suite's folder {own} and the working folder {elsewhere}\)"):
        expand(load_suite(own / "bad.yaml"))


@pytest.mark.parametrize("data, message", [
    ({"scenes": [{"preset": "tiny", "set": {"image.n_frames": 3}}]},
     "s.yaml: scenes[0].set: unknown key; did you mean 'overrides'? (valid: preset, label, overrides, sweep)"),
    ({"seed": [1]}, "s.yaml: seed: unknown key; did you mean 'seeds'?"),
    ({"pipelines": [{"name": "x", "base": "thesis-lk", "params": {}}]},
     "s.yaml: pipelines[0].params: unknown key; did you mean 'spec'? (valid: name, base, spec)"),
    ({"scenes": [{"preset": "tiny", "zzz": 1}]},
     "s.yaml: scenes[0].zzz: unknown key; valid: preset, label, overrides, sweep"),
])
def test_an_unknown_key_suggests_the_right_one(data, message):
    from harness.suites import SuiteError

    suite = {"name": "x", "scenes": [{"preset": "tiny"}], "seeds": [1], "pipelines": ["thesis-lk"]}
    suite.update(data)
    if "seed" in data:
        del suite["seeds"]
    with pytest.raises(SuiteError) as exc:
        parse_suite(suite, source="s.yaml")
    assert message in str(exc.value)
    assert "Extra inputs are not permitted" not in str(exc.value)


def test_a_suite_name_without_its_yaml_suffix_is_pointed_at_the_file(tmp_path, monkeypatch):
    (tmp_path / "my-suite.yaml").write_text("name: x\n")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SuiteError, match=r"my-suite: no such suite file, and not a built-in suite .*; "
                                         r"did you mean my-suite\.yaml\?"):
        load_suite("my-suite")


def test_an_unknown_key_of_a_real_scene_suggests_the_right_one():
    suite = {"name": "x", "scenes": [{"real": "clip.mp4", "frame": 60}], "seeds": [1], "pipelines": ["thesis-lk"]}
    with pytest.raises(SuiteError, match=r"s\.yaml: scenes\[0\]\.frame: unknown key; did you mean 'frames'\? "
                                         r"\(valid: real, label, start, stop, frames,"):
        parse_suite(suite, source="s.yaml")
