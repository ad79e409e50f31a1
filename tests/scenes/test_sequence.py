"""The sequence folder: contract columns, round trip, determinism, atomic writes, the cache."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from scenes import (
    ManifestError,
    cached_sequence,
    cached_sequence_result,
    load_scene_spec,
    open_sequence,
    render_sequence,
)
from scenes.generate import SceneGenerator

pytestmark = pytest.mark.gl

CAMERA_COLUMNS = ["frame", "t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz", "fx_px", "fy_px", "cx_px",
                  "cy_px", "jitter_x_px", "jitter_y_px", "global_dx_px", "global_dy_px", "k1", "k2",
                  "line_delay_s", "exposure_s"]
TRACK_COLUMNS = ["frame", "vehicle_id", "x_px", "y_px", "bbox_x0_px", "bbox_y0_px", "bbox_x1_px",
                 "bbox_y1_px", "visible", "speed_mps", "parked", "class", "visible_fraction"]


def test_folder_follows_the_contract(tiny_sequence):
    spec, folder = tiny_sequence
    n = spec.image.n_frames
    for sub, count in (("frames", n), ("instances", n), ("flow", n - 1), ("valid", n - 1)):
        assert len(list((folder / sub).iterdir())) == count, sub
    assert sorted(p.name for p in (folder / "flow").iterdir())[0] == "000000.npz"
    assert not (folder / "flow_camera").exists()  # the compact file holds both fields
    seq = open_sequence(folder, verify=True)
    assert list(seq.camera.columns) == CAMERA_COLUMNS
    assert list(seq.tracks.columns) == TRACK_COLUMNS
    assert len(seq.tracks) == n * spec.vehicles.count
    assert seq.meta["width"] == 160 and seq.meta["height"] == 120 and seq.meta["n_frames"] == n
    assert seq.meta["generator_version"] and seq.meta["gl_renderer"]
    assert seq.spec == spec
    assert (folder / "preview.png").stat().st_size > 0
    frame = seq.frame(0)
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    t = seq.pair_truth(n - 2)
    assert t.flow.dtype == np.float32 and t.valid.dtype == bool and t.instances.dtype == np.uint16
    with pytest.raises(IndexError, match="pair index 5"):
        seq.pair_truth(n - 1)


def test_loading_gives_the_arrays_that_were_generated(tiny_sequence):
    spec, folder = tiny_sequence
    seq = open_sequence(folder)
    for fo in SceneGenerator(spec).frames():
        np.testing.assert_array_equal(seq.frame(fo.index), fo.rgb)
        np.testing.assert_array_equal(seq.instances(fo.index), fo.instances)
        if fo.pair is not None:
            t = seq.pair_truth(fo.pair_index)
            np.testing.assert_array_equal(t.flow, fo.pair.flow)
            np.testing.assert_array_equal(t.flow_camera, fo.pair.flow_camera)
            np.testing.assert_array_equal(t.valid, fo.pair.valid)


def _manifest_files(folder):
    return json.loads((folder / "MANIFEST.json").read_text())["files"]


def test_same_spec_renders_bit_identical_folders(tiny_sequence, tmp_path):
    spec, folder = tiny_sequence
    again = render_sequence(spec, tmp_path / "again")
    assert _manifest_files(again) == _manifest_files(folder)
    other = render_sequence(load_scene_spec("tiny", overrides={"seed": spec.seed + 1}), tmp_path / "other")
    assert _manifest_files(other)["frames/000000.png"] != _manifest_files(folder)["frames/000000.png"]


def test_noise_is_seeded_and_changes_frames_not_truth(tmp_path):
    noisy = load_scene_spec("tiny", overrides={"sensor.noise.gaussian_std": 3.0, "image.n_frames": 2})
    a = render_sequence(noisy, tmp_path / "a")
    b = render_sequence(noisy, tmp_path / "b")
    assert _manifest_files(a) == _manifest_files(b)
    clean = render_sequence(load_scene_spec("tiny", overrides={"image.n_frames": 2}), tmp_path / "c")
    fa, fc = _manifest_files(a), _manifest_files(clean)
    assert fa["frames/000000.png"] != fc["frames/000000.png"]
    assert fa["flow/000000.npz"] == fc["flow/000000.npz"]


def test_refuses_to_overwrite_and_leaves_no_partial_folder(tmp_path):
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 3})
    out = tmp_path / "seq"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        render_sequence(spec, out)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]

    def crash(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_sequence(spec, tmp_path / "crashed", progress=crash)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]

    render_sequence(spec, out, overwrite=True)
    assert not (out / "keep.txt").exists()
    open_sequence(out, verify=True)


def test_partial_folder_and_edited_file_are_detected(tiny_sequence, tmp_path):
    import shutil

    _, folder = tiny_sequence
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    flo = copy / "flow" / "000001.npz"
    data = bytearray(flo.read_bytes())
    data[len(data) // 2 + 4] ^= 0xFF
    flo.write_bytes(bytes(data))
    with pytest.raises(ManifestError, match=r"000001\.npz: .*differs"):
        open_sequence(copy, verify=True)
    (copy / "MANIFEST.json").unlink()
    with pytest.raises(ManifestError, match="partial"):
        open_sequence(copy)


def test_cache_reuses_and_rebuilds_corrupt_entries(tmp_path):
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 3})
    first = cached_sequence_result(spec, tmp_path)
    assert first.rendered
    again = cached_sequence_result(spec, tmp_path)
    assert not again.rendered and again.path == first.path
    good = _manifest_files(first.path)

    # truncated big file: caught by its size
    flo = first.path / "flow" / "000000.npz"
    flo.write_bytes(flo.read_bytes()[:-100])
    rebuilt = cached_sequence_result(spec, tmp_path)
    assert rebuilt.rendered and _manifest_files(rebuilt.path) == good

    # one byte edited in a small file: caught by its hash
    csv = rebuilt.path / "camera.csv"
    text = csv.read_bytes()
    csv.write_bytes(text[:-3] + (b"9" if text[-3:-2] != b"9" else b"8") + text[-2:])
    assert cached_sequence_result(spec, tmp_path).rendered

    # partial entry (no manifest): never used
    (rebuilt.path / "MANIFEST.json").unlink()
    assert cached_sequence_result(spec, tmp_path).rendered
    open_sequence(cached_sequence(spec, tmp_path), verify=True)
    assert [p.name for p in tmp_path.iterdir()] == [first.path.name]


def test_cache_keeps_the_entry_another_process_finished_first(tmp_path, monkeypatch):
    import scenes.cache as cache

    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2})
    theirs = cached_sequence_result(spec, tmp_path / "other")
    target = tmp_path / "cache" / theirs.key
    real_write = cache._write_into

    def write_then_race(spec_, tmp, progress, timings):
        real_write(spec_, tmp, progress, timings)
        import shutil
        shutil.copytree(theirs.path, target)  # the other process renames its entry in first

    monkeypatch.setattr(cache, "_write_into", write_then_race)
    result = cached_sequence_result(spec, tmp_path / "cache")
    assert not result.rendered and result.path == target
    assert [p.name for p in (tmp_path / "cache").iterdir()] == [theirs.key]


def test_a_killed_renders_partial_folder_is_removed_but_a_live_ones_is_kept(tmp_path):
    import subprocess
    import sys

    import scenes.cache as cache

    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2})
    key = cache.cache_key(spec)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    orphan = tmp_path / f".{key}.partial-{cache._HOST}-{int(dead.stdout)}-abc"
    alive = tmp_path / f".{key}.partial-{cache._HOST}-{os.getpid()}-def"
    other_host = tmp_path / f".{key}.partial-elsewhere-{int(dead.stdout)}-ghi"
    for p in (orphan, alive, other_host):
        (p / "frames").mkdir(parents=True)
    cached_sequence_result(spec, tmp_path)
    assert not orphan.exists()
    assert alive.exists() and other_host.exists()  # still rendering, or another machine's: not ours to judge


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint32)


def test_flo_export_and_old_flo_folders_read_the_same_truth_bit_for_bit(tiny_sequence, tmp_path):
    from scenes.sequence import read_pair_flow, write_manifest

    spec, folder = tiny_sequence
    flo = render_sequence(spec, tmp_path / "flo", flow_format="flo")
    n = spec.image.n_frames
    assert len(list((flo / "flow").glob("*.flo"))) == n - 1 == len(list((flo / "flow_camera").glob("*.flo")))
    compact, exported = open_sequence(folder), open_sequence(flo, verify=True)
    assert (compact.flow_format, exported.flow_format) == ("npz", "flo")
    for i in range(n - 1):
        a, b = compact.pair_truth(i), exported.pair_truth(i)
        np.testing.assert_array_equal(_bits(a.flow), _bits(b.flow))
        np.testing.assert_array_equal(_bits(a.flow_camera), _bits(b.flow_camera))
        for path in (folder, flo):
            f, c = read_pair_flow(path, i)
            np.testing.assert_array_equal(_bits(f), _bits(a.flow))
            np.testing.assert_array_equal(_bits(c), _bits(a.flow_camera))
    assert read_pair_flow(flo, n - 1) == (None, None)
    # a folder written before the compact format: .flo files and no flow_format in meta.json
    meta = json.loads((flo / "meta.json").read_text())
    del meta["flow_format"], meta["layout"]
    (flo / "meta.json").write_text(json.dumps(meta))
    (flo / "MANIFEST.json").unlink()
    write_manifest(flo)
    old = open_sequence(flo, verify=True)
    assert old.flow_format == "flo"
    np.testing.assert_array_equal(_bits(old.pair_truth(1).flow), _bits(compact.pair_truth(1).flow))
    with pytest.raises(ValueError, match=r"flow_format: expected one of npz, flo, got 'exr'"):
        render_sequence(spec, tmp_path / "exr", flow_format="exr")
    assert not (tmp_path / "exr").exists()


def test_writer_threads_change_no_byte_and_a_writer_error_reaches_the_caller(tmp_path, monkeypatch):
    import scenes.sequence as sequence

    spec = load_scene_spec("tiny", overrides={"image.n_frames": 3})
    a = render_sequence(spec, tmp_path / "threads0", writer_threads=0)
    b = render_sequence(spec, tmp_path / "threads3", writer_threads=3)
    assert _manifest_files(a) == _manifest_files(b)

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(sequence, "encode_flow_npz", broken)
    with pytest.raises(OSError, match="No space left on device"):
        render_sequence(spec, tmp_path / "broken", writer_threads=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["threads0", "threads3"]  # no partial folder left


def test_cache_entry_of_another_layout_is_rendered_again(tmp_path):
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2})
    first = cached_sequence_result(spec, tmp_path)
    manifest = first.path / "MANIFEST.json"
    doc = json.loads(manifest.read_text())
    assert doc["layout"] == 2 and doc["flow_format"] == "npz"
    doc["layout"] = 1
    manifest.write_text(json.dumps(doc))
    again = cached_sequence_result(spec, tmp_path)
    assert again.rendered and json.loads(manifest.read_text())["layout"] == 2
