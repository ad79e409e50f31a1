"""Scene specs: presets, overrides, rejections with messages that name the field and the file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes import SceneSpecError, list_presets, load_scene_spec, render_sequence, spec_hash
from scenes.motion import ornstein_uhlenbeck
from scenes.render import GL_SYSTEM_PACKAGES, RendererUnavailableError

REQUIRED_PRESETS = {"nominal", "jitter", "drift", "fast-vehicles", "urban-parallax", "noisy", "tiny", "thesis"}


def test_presets_exist_load_and_describe_themselves():
    presets = list_presets()
    assert REQUIRED_PRESETS <= set(presets)
    for name, description in presets.items():
        spec = load_scene_spec(name)
        assert spec.name == name
        assert description and "\n" not in description


def test_tiny_preset_is_small():
    spec = load_scene_spec("tiny")
    assert (spec.image.width_px, spec.image.height_px) == (160, 120)
    assert spec.image.n_frames <= 8 and 2 <= spec.vehicles.count <= 3


def test_dotted_overrides_set_fields_and_change_the_hash():
    base = load_scene_spec("nominal")
    spec = load_scene_spec("nominal", overrides={"camera.jitter.roll_std_deg": 0.5, "seed": 11})
    assert spec.camera.jitter.roll_std_deg == 0.5 and spec.seed == 11
    assert spec.camera.altitude_m == base.camera.altitude_m
    assert spec_hash(spec) != spec_hash(base)
    assert spec_hash(load_scene_spec("nominal")) == spec_hash(base)


def _write(tmp_path, text):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("yaml_text", "pattern"),
    [
        ("camera:\n  jitterz: {}\n", r"camera\.jitterz: unknown key"),
        ("camera:\n  jitter: {roll_std_deg: .nan}\n", r"camera\.jitter\.roll_std_deg: .*finite"),
        ("image: {width_px: -640}\n", r"image\.width_px: .*greater than or equal"),
        ("image: {n_frames: 1}\n", r"image\.n_frames: .*greater than or equal to 2"),
        ("vehicles: {speed_range_mps: [10.0, 900.0]}\n", r"vehicles\.speed_range_mps: .*too fast"),
        ("camera: {tilt_deg: 60, intrinsics: {hfov_deg: 100}}\n", r"camera\.tilt_deg: .*horizon"),
        ("light: {mode: moon}\n", r"light\.mode: .*'flat' or 'sun'"),
        ("light: {sun_elevation_deg: 2}\n", r"light\.sun_elevation_deg: .*greater than or equal to 10"),
        ("light: {ambient: 1.5}\n", r"light\.ambient: .*less than or equal to 1"),
        ("photometry: {lighting: sun}\n", r"photometry: this section was split .*photometry\.lighting -> light\.mode"),
        ("world: {road_irregularity: 2}\n", r"world\.road_irregularity: .*less than or equal to 1"),
        ("world: {parking_fraction: 0.5, built_fraction: 0.4, wood_fraction: 0.3}\n",
         r"world: parking_fraction \+ built_fraction \+ wood_fraction: expected <= 1, got 1.2"),
        ("world: {trees: {crown_diameter_range_m: [6.0, 2.0]}}\n",
         r"world\.trees: crown_diameter_range_m: expected 0 < low <= high, got \(6.0, 2.0\)"),
        ("world: {trees: {leaf_colour: red}}\n", r"world\.trees\.leaf_colour: unknown key"),
        ("world: {trees: {conifer_fraction: 1.5}}\n", r"world\.trees\.conifer_fraction: .*less than or equal to 1"),
        ("world: {crosswalk_fraction: -0.1}\n", r"world\.crosswalk_fraction: .*greater than or equal to 0"),
    ],
)
def test_bad_spec_file_is_rejected_naming_field_and_file_and_nothing_is_written(tmp_path, yaml_text, pattern):
    path = _write(tmp_path, yaml_text)
    with pytest.raises(SceneSpecError, match=pattern) as info:
        load_scene_spec(path)
    assert str(path) in str(info.value)
    out = tmp_path / "out"
    with pytest.raises(SceneSpecError):
        render_sequence(path, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.yaml"]


def test_unknown_preset_lists_the_valid_ones():
    with pytest.raises(SceneSpecError, match=r"unknown preset.*nominal.*tiny"):
        load_scene_spec("nominel")


def test_bad_override_names_the_dotted_field():
    with pytest.raises(SceneSpecError, match=r"camera\.jitter\.roll_stdd_deg: unknown key"):
        load_scene_spec("tiny", overrides={"camera.jitter.roll_stdd_deg": 0.5})
    with pytest.raises(SceneSpecError, match=r"camera\.altitude_m: .*finite"):
        load_scene_spec("tiny", overrides={"camera.altitude_m": math.inf})


def test_too_fast_vehicle_message_gives_pixels_per_frame():
    with pytest.raises(SceneSpecError, match=r"moves [0-9.]+ px per frame .* expected <= [0-9.]+ px"):
        load_scene_spec("tiny", overrides={"vehicles.speed_range_mps": [5.0, 400.0]})


def test_ornstein_uhlenbeck_has_the_stated_std_and_correlation_time():
    # stationary std sigma and lag-1 autocorrelation exp(-dt / tau) (the jitter model of thesis 3.2)
    rng = np.random.Generator(np.random.PCG64(1234))
    sigma, dt, tau = 0.7, 0.1, 0.5
    x = ornstein_uhlenbeck(rng, 200_000, dt, tau, np.array([sigma]))[:, 0]
    assert abs(x.std() - sigma) < 0.02 * sigma
    rho = np.corrcoef(x[:-1], x[1:])[0, 1]
    assert abs(rho - math.exp(-dt / tau)) < 0.01


def test_missing_gl_backend_names_the_system_packages(monkeypatch):
    import scenes.render as render

    class _NoGL:
        class OffscreenRenderer:
            def __init__(self, *a, **k):
                raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(render, "_pyrender", lambda: _NoGL)
    with pytest.raises(RendererUnavailableError, match=GL_SYSTEM_PACKAGES):
        render.get_renderer(17, 19)
    assert (17, 19) not in render._RENDERERS


@pytest.mark.parametrize("preset", ["tiny", "nominal", "fast-vehicles", "urban-parallax", "thesis"])
@pytest.mark.parametrize("seed", [1, 2, 7])
def test_vehicles_never_drive_through_each_other(preset, seed):
    import numpy as np

    from scenes.generate import SceneGenerator

    spec = load_scene_spec(preset, overrides={"seed": seed})
    vehicles = SceneGenerator(spec).vehicles
    times_s = np.arange(spec.image.n_frames) / spec.image.fps
    paths = [np.array([v.pose(float(t))[:2] for t in times_s]) for v in vehicles]
    closest_m = min((np.hypot(*(a - b).T).min() for i, a in enumerate(paths) for b in paths[i + 1:]),
                    default=np.inf)
    assert closest_m >= spec.vehicles.length_m + 1.0 - 1e-9
