"""Bad input gets a clear error and nothing is lost: one table row per bad input.

Each row says how the bad input is made, what is called (the ``aerobench`` CLI in-process,
or a library function), the expected outcome (exit code, or exception class), a regex the
message must match (it names the problem and where: field, file, line), and the test checks
that nothing was written: the temporary folder of the row is unchanged and holds no temp files.
Bad inputs that need a rendered sequence or a finished run (cache corruption, disk full, an
old results file) follow the table as their own tests, with the same checks.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import io
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
import pytest
import yaml
from tests.reliability.rel_support import assert_bit_identical, partial_files, suite, tree_state

from harness import gate as G
from harness import results as R
from harness.cli import main
from scenes.formats import FormatError, atomic_write_bytes, read_flo, read_png, write_flo, write_png

# --------------------------------------------------------------------------- how rows are run


def cli(*argv: str) -> tuple[int, str]:
    """``aerobench ARGV`` in this process: (exit code, stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's own usage errors
            code = int(exc.code)
    return code, err.getvalue()


def call(fn: Callable[[], Any]) -> tuple[Any, str]:
    """A library call: (the exception class, its message), or (0, repr of the result)."""
    try:
        out = fn()
    except (ValueError, TypeError, KeyError, OSError) as exc:
        return type(exc), str(exc)
    return 0, repr(out)


@dataclass
class Row:
    id: str
    make: Callable[[Path], Any]  # writes the bad input under tmp, returns what act needs
    act: Callable[[Path, Any], tuple[Any, str]]  # the command or call
    expect: Any  # exit code, or exception class
    match: str  # regex the message must match; {tmp} is the row's folder


def run_suite_cli(tmp: Path, suite_file: Path) -> tuple[int, str]:
    return cli("run", suite_file, "--out", tmp / "out", "--quiet", "--no-report", "--cache", tmp / "no-cache")


def suite_file(data: dict | str, name: str = "suite.yaml") -> Callable[[Path], Path]:
    def make(tmp: Path) -> Path:
        p = tmp / name
        p.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
        return p
    return make


def scene_override(**overrides) -> dict:
    s = suite()
    s["scenes"][0]["overrides"].update(overrides)
    return s


def scene_file(text: str) -> Callable[[Path], Path]:
    def make(tmp: Path) -> Path:
        p = tmp / "scene.yaml"
        p.write_text(text)
        return p
    return make


def render_cli(tmp: Path, scene: Path) -> tuple[int, str]:
    return cli("render", scene, "--out", tmp / "seq")


def frames(h=24, w=32, dtype=np.uint8, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.random((h, w)) * 200).astype(dtype)


def flow_method(name: str, f0, f1):
    import algorithms.pipeline  # noqa: F401  (fills the registry with every built-in method)
    from algorithms.registry import get_flow_method

    return call(lambda: get_flow_method(name)(f0, f1))


def constant_frames_are_no_error(tmp: Path, _) -> tuple[Any, str]:
    # a degenerate input, not a bad one: the documented answer is an empty valid mask, never NaN
    import algorithms.pipeline  # noqa: F401
    from algorithms.registry import get_flow_method

    f = np.full((24, 32), 90, np.uint8)
    flow, valid = get_flow_method("lucas_kanade")(f, f)
    return 0, f"finite={bool(np.isfinite(flow).all())} valid={int(valid.sum())}"


# --------------------------------------------------------------------------- files for the flow rows


def truncated_png(tmp: Path) -> Path:
    p = tmp / "frame.png"
    write_png(p, frames(dtype=np.uint8))
    p.write_bytes(p.read_bytes()[:60])
    return p


def flo_with_tag(tmp: Path) -> Path:
    p = tmp / "bad_tag.flo"
    write_flo(p, np.zeros((4, 5, 2), np.float32))
    raw = bytearray(p.read_bytes())
    raw[0:4] = np.array([1.5], "<f4").tobytes()
    p.write_bytes(bytes(raw))
    return p


def flo_wrong_size(tmp: Path) -> Path:
    p = tmp / "short.flo"
    write_flo(p, np.zeros((4, 5, 2), np.float32))
    p.write_bytes(p.read_bytes()[:-8])
    return p


def kitti_8bit(tmp: Path) -> Path:
    p = tmp / "000000_10.png"
    write_png(p, np.zeros((6, 8, 3), np.uint8))
    return p


def middlebury_with_truncated_frame(tmp: Path) -> Path:
    d = tmp / "mb" / "Pair"
    d.mkdir(parents=True)
    f = np.dstack([frames()] * 3)
    write_png(d / "frame10.png", f)
    write_png(d / "frame11.png", f)
    (d / "frame11.png").write_bytes((d / "frame11.png").read_bytes()[:50])
    write_flo(d / "flow10.flo", np.zeros((24, 32, 2), np.float32))
    return tmp / "mb"


# --------------------------------------------------------------------------- gate fixtures


def _results_table(metrics=("epe_mean", "coverage"), status="ok") -> pd.DataFrame:
    rows = [{"metric": m, "frame": 0, "region": "all", "motion": "total", "kind": "accuracy",
             "value": 0.5, "sum": 50.0, "count": 100.0, "unit": "px", "higher_is_better": False} for m in metrics]
    return R.rows_to_frame(rows, cell_id="c1", scene="tiny", seed=1, pipeline="thesis-lk", machine="box",
                           status=status)


def make_gate_run(tmp: Path, *, base_suite="reliability", base_metrics=("epe_mean", "coverage"),
                  rules: str | None = None, baseline_text: str | None = None) -> dict:
    run = tmp / "run"
    R.write_table(_results_table(), run / R.RESULTS_FILE)
    R.write_run_json(run, {"suite": "reliability", "config_hash": "h", "provenance": {"machine": "box"}})
    base = tmp / "baseline.json"
    if baseline_text is not None:
        base.write_text(baseline_text)
    elif base_suite is not None:
        G.write_baseline(G.make_baseline(_results_table(base_metrics), {"suite": base_suite,
                                                                        "provenance": {"machine": "box"}}), base)
    argv = ["gate", run, "--baseline", base]
    if rules is not None:
        (tmp / "rules.yaml").write_text(rules)
        argv += ["--rules", tmp / "rules.yaml"]
    argv += ["--junit", tmp / "junit.xml"]  # must not be written when the gate cannot decide
    return {"argv": argv}


def gate_cli(tmp: Path, ctx: dict) -> tuple[int, str]:
    return cli(*ctx["argv"])


def old_schema_run(tmp: Path) -> dict:
    import pyarrow as pa
    import pyarrow.parquet as pq

    ctx = make_gate_run(tmp)
    table = pa.Table.from_pandas(_results_table().assign(schema_version=0), preserve_index=False)
    table = table.replace_schema_metadata({b"aerobench.schema_version": b"0"})
    pq.write_table(table, tmp / "run" / R.RESULTS_FILE)
    return ctx


def locked_run_dir(tmp: Path):
    out = tmp / "out"
    out.mkdir()
    fh = open(out / ".lock", "w")  # what a running aerobench holds (released when the row ends)
    fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return {"suite": suite_file(suite())(tmp), "lock": fh}


def run_into_locked(tmp: Path, ctx) -> tuple[int, str]:
    try:
        return cli("run", ctx["suite"], "--out", tmp / "out", "--resume", "--quiet", "--no-report")
    finally:
        ctx["lock"].close()


def middlebury_pair(tmp: Path) -> Path:
    d = tmp / "mb" / "Pair"
    d.mkdir(parents=True)
    f = np.dstack([frames()] * 3)
    write_png(d / "frame10.png", f)
    write_png(d / "frame11.png", f)
    write_flo(d / "flow10.flo", np.zeros((24, 32, 2), np.float32))
    return tmp / "mb"


def middlebury_with_truncated_flo(tmp: Path) -> Path:
    root = middlebury_pair(tmp)
    flo = root / "Pair" / "flow10.flo"
    flo.write_bytes(flo.read_bytes()[:112])
    return root


def run_with_a_failed_cell(tmp: Path) -> Path:
    run = tmp / "run"
    failed = _results_table(("cell_failed",), status="failed").assign(error="RuntimeError: boom")
    R.write_table(failed, run / R.RESULTS_FILE)
    R.write_run_json(run, {"suite": "reliability", "config_hash": "h", "provenance": {"machine": "box"}})
    return run


def out_under_a_file(tmp: Path) -> Path:
    (tmp / "blocker").write_text("a regular file where the run folder's parent should be")
    return suite_file(suite())(tmp)


# --------------------------------------------------------------------------- the table

DUPLICATE_KEY = """name: dup
scenes:
  - preset: tiny
seeds: [1]
seeds: [2]
pipelines: [dis]
"""
BROKEN_YAML = """name: broken
scenes:
  - preset: tiny
    overrides: {image.n_frames: 3
seeds: [1]
pipelines: [dis]
"""

ROWS = [
    # ---- suite files (aerobench run SUITE): refused before anything is written
    Row("suite-yaml-syntax", suite_file(BROKEN_YAML), run_suite_cli, 2,
        r"suite\.yaml: YAML syntax error at line \d+, column \d+"),
    Row("suite-duplicate-key", suite_file(DUPLICATE_KEY), run_suite_cli, 2, r"suite\.yaml: YAML syntax error at line 5.*'seeds' appears twice"),
    Row("suite-unknown-key", suite_file(suite(colour="red")), run_suite_cli, 2, r"suite\.yaml.*colour"),
    Row("suite-wrong-type", suite_file(suite(seeds="many")), run_suite_cli, 2, r"suite\.yaml.*seeds"),
    Row("suite-nan", suite_file(scene_override(**{"image.fps": float("nan")})), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*image\.fps.*(nan|finite)"),
    Row("suite-inf", suite_file(scene_override(**{"camera.altitude_m": float("inf")})), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*altitude_m.*(inf|finite)"),
    Row("suite-negative-width", suite_file(scene_override(**{"image.width_px": -160})), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*image\.width_px"),
    Row("suite-zero-height", suite_file(scene_override(**{"image.height_px": 0})), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*image\.height_px"),
    Row("suite-one-frame", suite_file(scene_override(**{"image.n_frames": 1})), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*image\.n_frames"),
    Row("suite-vehicle-too-fast", suite_file(scene_override(**{"vehicles.speed_range_mps": [6.0, 400.0]})),
        run_suite_cli, 2, r"suite\.yaml.*vehicles\.speed_range_mps.*too fast for the scene"),
    Row("suite-unknown-preset", suite_file(suite(scenes=[{"preset": "tinyy"}])), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*'tinyy'.*valid.*\btiny\b"),
    Row("suite-unknown-pipeline", suite_file(suite(pipelines=["thesis-lkk"])), run_suite_cli, 2,
        r"suite\.yaml.*pipelines\[0\].*'thesis-lkk'.*valid.*thesis-lk\b"),
    Row("suite-unknown-metric", suite_file(suite(metrics=["epe_meen"])), run_suite_cli, 2,
        r"suite\.yaml: metrics\[0\]: unknown metric 'epe_meen'; valid: .*epe_mean"),
    Row("suite-empty-sweep", suite_file(suite(scenes=[{"preset": "tiny", "sweep": {}}])), run_suite_cli, 2,
        r"suite\.yaml.*scenes\[0\].*an empty sweep"),
    Row("suite-sweep-no-values", suite_file(suite(scenes=[{"preset": "tiny", "sweep": {"camera.altitude_m": []}}])),
        run_suite_cli, 2, r"suite\.yaml.*'camera\.altitude_m' has no values"),
    Row("suite-unknown-flow-method",
        suite_file(suite(pipelines=[{"name": "x", "base": "thesis-lk", "spec": {"flow": {"method": "lucas_kanad"}}}])),
        run_suite_cli, 2, r"suite\.yaml.*pipelines\[0\].*'lucas_kanad'.*valid.*lucas_kanade"),
    Row("suite-unknown-param",
        suite_file(suite(pipelines=[{"name": "x", "base": "thesis-lk", "spec": {"flow": {"params": {"windw": 15}}}}])),
        run_suite_cli, 2, r"suite\.yaml.*pipelines\[0\].*windw"),
    Row("suite-nan-param",
        suite_file(suite(pipelines=[{"name": "x", "base": "thesis-hs",
                                     "spec": {"flow": {"params": {"alpha": float("nan")}}}}])),
        run_suite_cli, 2, r"suite\.yaml.*pipelines\[0\].*alpha.*(nan|finite)"),
    Row("suite-missing-file", lambda tmp: tmp / "nope.yaml", run_suite_cli, 2,
        r"nope\.yaml: no such suite file, and not a built-in suite \(.*smoke"),
    Row("suite-repeated-seeds", suite_file(suite(seeds=[1, 1])), run_suite_cli, 2, r"suite\.yaml.*seeds repeat"),
    # ---- scene files (aerobench render SCENE)
    Row("scene-yaml-syntax", scene_file("image: {width_px: 64\nseed: 1\n"), render_cli, 2,
        r"scene\.yaml: not valid YAML.*line \d+"),
    Row("scene-unknown-key", scene_file("image: {width_px: 64, colour: red}\n"), render_cli, 2,
        r"scene\.yaml.*image\.colour: unknown key"),
    Row("scene-wrong-type", scene_file("image: {width_px: wide}\n"), render_cli, 2,
        r"scene\.yaml.*image\.width_px.*'wide'"),
    Row("scene-nan", scene_file("camera: {altitude_m: .nan}\n"), render_cli, 2, r"scene\.yaml.*camera\.altitude_m"),
    Row("scene-negative-size", scene_file("image: {height_px: -1}\n"), render_cli, 2,
        r"scene\.yaml.*image\.height_px.*-1"),
    Row("scene-bad-set", scene_file("seed: 1\n"), lambda tmp, p: cli("render", p, "--out", tmp / "seq", "--set", "seed"),
        2, r"--set: expected key=value"),
    Row("scene-unknown-preset", lambda tmp: "tinyy", render_cli, 2, r"'tinyy': unknown preset; valid presets: .*tiny"),
    # ---- frames and flow (library calls)
    Row("frames-mismatched-shapes", lambda tmp: None,
        lambda tmp, _: flow_method("horn_schunck", frames(24, 32), frames(24, 30)), ValueError,
        r"frame0 and frame1 differ in size: \(24, 32\) vs \(24, 30\)"),
    Row("frames-nan-pixels", lambda tmp: None,
        lambda tmp, _: flow_method("lucas_kanade", np.where(frames() > 100, np.nan, 1.0).astype(np.float32),
                                   frames(dtype=np.float32)), ValueError, r"frame0: \d+ pixel\(s\) are NaN or infinite"),
    Row("frames-complex-dtype", lambda tmp: None,
        lambda tmp, _: flow_method("dis", frames().astype(np.complex64), frames()), TypeError,
        r"frame0: expected an integer or real image .* got dtype complex64"),
    Row("frames-bool-dtype", lambda tmp: None,
        lambda tmp, _: flow_method("farneback", frames(), frames() > 9), TypeError, r"frame1: .*got dtype bool"),
    Row("frames-one-pixel", lambda tmp: None,
        lambda tmp, _: flow_method("lucas_kanade", np.zeros((1, 1)), np.zeros((1, 1))), ValueError,
        r"frame0: expected an image of at least 2x2 pixels"),
    Row("frames-constant", lambda tmp: None, constant_frames_are_no_error, 0, r"^finite=True valid=0$"),
    Row("flow-channels-first", lambda tmp: None,
        lambda tmp, _: call(lambda: __import__("algorithms.flow").flow.check_flow(np.zeros((2, 6, 5)))), ValueError,
        r"flow: expected \(H, W, 2\) float32, got \(2, 6, 5\) float64"),
    Row("png-truncated", truncated_png, lambda tmp, p: call(lambda: read_png(p)), FormatError,
        r"frame\.png: not a readable PNG \(truncated or corrupt\)"),
    Row("flo-bad-tag", flo_with_tag, lambda tmp, p: call(lambda: read_flo(p)), FormatError,
        r"bad_tag\.flo: not a \.flo file: tag 1\.5, expected 202021\.25"),
    Row("flo-wrong-size", flo_wrong_size, lambda tmp, p: call(lambda: read_flo(p)), FormatError,
        r"short\.flo: \d+ bytes, expected \d+ for a 5x4 \.flo file"),
    Row("kitti-8-bit", kitti_8bit,
        lambda tmp, p: call(lambda: __import__("harness.datasets").datasets.read_kitti_flow(p)), FormatError,
        r"000000_10\.png: a KITTI flow file must be a 16-bit RGB PNG.*got rgb8"),
    Row("eval-flow-truncated-frame", middlebury_with_truncated_frame,
        lambda tmp, d: cli("eval-flow", d, "--format", "middlebury", "--method", "dis"), 2,
        r"Pair/frame11\.png: not a readable PNG"),
    # ---- runs
    Row("run-out-under-a-file", out_under_a_file,
        lambda tmp, s: cli("run", s, "--out", tmp / "blocker" / "out", "--quiet", "--no-report"), 2,
        r"--out .*blocker/out: .*blocker is a file, not a folder$"),
    Row("run-out-in-proc", suite_file(suite()),
        lambda tmp, s: cli("run", s, "--out", "/proc/aerobench_out", "--quiet", "--no-report"), 2,
        r"--out /proc/aerobench_out: cannot create anything in /proc: "),
    Row("suite-set-for-overrides", suite_file(suite(scenes=[{"preset": "tiny", "set": {"image.n_frames": 3}}])),
        run_suite_cli, 2, r"scenes\[0\]\.set: unknown key; did you mean 'overrides'\?"),
    Row("eval-flow-param-type", middlebury_pair,
        lambda tmp, d: cli("eval-flow", d, "--method", "lucas_kanade", "--param", "window=abc"), 2,
        r"^aerobench: error: --param window: expected an integer, got 'abc'$"),
    Row("eval-flow-truncated-flo-is-no-param-error", middlebury_with_truncated_flo,
        lambda tmp, d: cli("eval-flow", d, "--method", "lucas_kanade"), 2,
        r"^aerobench: error: \S*Pair/flow10\.flo: 112 bytes, expected 6156 for a 32x24 \.flo file$"),
    Row("report-corrupt-baseline", lambda tmp: make_gate_run(tmp, baseline_text="{not json"),
        lambda tmp, ctx: cli("report", tmp / "run", "--baseline", tmp / "baseline.json", "--quiet"), 2,
        r"baseline\.json: baseline is not valid JSON"),
    Row("baseline-of-a-failed-run", run_with_a_failed_cell,
        lambda tmp, run: cli("baseline", run, "--out", tmp / "b.json"), 2,
        r"run: 1 cell\(s\) failed, so the baseline would lack their metrics: tiny seed 1 x thesis-lk: "
        r"RuntimeError: boom; .*--allow-failed"),
    Row("run-two-at-once", locked_run_dir, run_into_locked, 2,
        r"out: another aerobench run is writing into this folder"),
    Row("results-older-schema", old_schema_run, gate_cli, 2, r"results\.parquet: results schema v0, this aerobench reads v2"),
    Row("report-not-a-run", lambda tmp: None, lambda tmp, _: cli("report", tmp), 2, r"not a finished run folder"),
    # ---- gate (aerobench gate RUN --baseline FILE)
    Row("gate-missing-baseline", lambda tmp: make_gate_run(tmp, base_suite=None), gate_cli, 2,
        r"baseline\.json: no such file \(a missing baseline is not a pass\)"),
    Row("gate-baseline-other-suite", lambda tmp: make_gate_run(tmp, base_suite="smoke"), gate_cli, 2,
        r"baseline is for suite 'smoke', the results are of suite 'reliability'"),
    Row("gate-metric-only-in-baseline", lambda tmp: make_gate_run(tmp, base_metrics=("epe_mean", "coverage", "epe_rms")),
        gate_cli, 2, r"1 in the baseline but not in the results: .*epe_rms"),
    Row("gate-metric-only-in-results", lambda tmp: make_gate_run(tmp, base_metrics=("epe_mean",)), gate_cli, 2,
        r"1 in the results but not in the baseline: .*coverage"),
    Row("gate-rule-names-no-metric", lambda tmp: make_gate_run(tmp, rules="rules: {epe_meen: abs 0.1}\n"), gate_cli, 2,
        r"rules\.yaml: rule 'epe_meen' names no metric; valid: .*epe_mean"),
    Row("gate-rule-percent-abs", lambda tmp: make_gate_run(tmp, rules="rules: {epe_mean: abs 5%}\n"), gate_cli, 2,
        r"rules\.yaml: epe_mean: .*a percentage is relative; write 'rel 5%'"),
    Row("gate-baseline-not-json", lambda tmp: make_gate_run(tmp, baseline_text="{not json"), gate_cli, 2,
        r"baseline\.json: baseline is not valid JSON"),
    Row("gate-baseline-foreign", lambda tmp: make_gate_run(tmp, baseline_text='{"format": "pytest-benchmark"}'),
        gate_cli, 2, r"baseline\.json: not an aerobench baseline: format 'pytest-benchmark'"),
]


@pytest.mark.parametrize("row", ROWS, ids=[r.id for r in ROWS])
def test_bad_input_is_refused_clearly_and_writes_nothing(row: Row, tmp_path):
    tmp = tmp_path / "row"
    tmp.mkdir()
    ctx = row.make(tmp)
    before = tree_state(tmp)
    got, message = row.act(tmp, ctx)
    after = tree_state(tmp)
    if isinstance(row.expect, type):
        assert isinstance(got, type) and issubclass(got, row.expect), (got, message)
    else:
        assert got == row.expect, message
    assert re.search(row.match, message, re.S), f"{message!r} does not match {row.match!r}"
    assert "Traceback" not in message
    if row.id == "run-two-at-once":
        before.pop("out/.lock", None), after.pop("out/.lock", None)  # the lock file holds the pid
    assert after == before, f"written or changed: {sorted(set(after.items()) ^ set(before.items()))}"
    assert not partial_files(tmp)


def test_the_table_is_big_enough():
    assert len(ROWS) >= 30 and len({r.id for r in ROWS}) == len(ROWS)


# --------------------------------------------------------------------------- beyond the table


@pytest.mark.gl
@pytest.mark.slow
def test_a_truncated_or_edited_cache_entry_is_detected_and_rebuilt(reference_run, rel_cache, tmp_path):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from harness.runner import render_task
    from harness.suites import expand, parse_suite
    from scenes.sequence import ManifestError, verify_manifest

    spec = expand(parse_suite(suite()))[0].variant.spec
    from scenes import cache_key

    entry = rel_cache / cache_key(spec)
    original = tree_state(entry)
    caches = {}
    for how in ("truncated", "edited"):
        cache = tmp_path / how
        shutil.copytree(entry, cache / entry.name)
        victim = cache / entry.name / ("frames/000001.png" if how == "truncated" else "flow/000000.npz")
        raw = bytearray(victim.read_bytes())
        if how == "truncated":
            raw = raw[: len(raw) // 2]
        else:  # same size, one value changed in the middle: only a hash sees it
            raw[len(raw) // 2] ^= 0x40
        victim.write_bytes(bytes(raw))
        with pytest.raises(ManifestError, match=re.escape(str(victim)) + r": .*(truncated|edited)"):
            verify_manifest(cache / entry.name)
        caches[how] = cache
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        got = {how: pool.submit(render_task, "k", spec, str(c)).result(timeout=120) for how, c in caches.items()}
    for how, cache in caches.items():
        assert got[how]["error"] is None and got[how]["reused"] is False, got[how]  # rebuilt, not used
        assert tree_state(cache / entry.name) == original  # rebuilt to the same bytes
        assert [p.name for p in cache.iterdir()] == [entry.name]  # no partial or trash folder left
    assert tree_state(entry) == original


def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


class FullDisk(io.BytesIO):
    """``os.fdopen`` of a disk that fills up: writes to temp files named ``.<FULL>.*`` raise ENOSPC."""

    full: tuple[str, ...] = ()

    def __init__(self, fd, *a, **k):
        self.name = os.path.basename(os.readlink(f"/proc/self/fd/{fd}"))
        self.fd = fd
        super().__init__()

    def write(self, data):
        if self.name.startswith(self.full):
            _enospc()
        return os.write(self.fd, data)

    def fileno(self):
        return self.fd

    def close(self):
        if not self.closed:
            os.close(self.fd)
        super().close()


def full_disk(monkeypatch, *names: str) -> None:
    monkeypatch.setattr(FullDisk, "full", tuple(f".{n}." for n in names))
    monkeypatch.setattr(os, "fdopen", FullDisk)


def test_disk_full_in_an_atomic_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "run.json"
    target.write_text('{"status": "ok"}\n')
    full_disk(monkeypatch, "run.json")
    with pytest.raises(OSError, match=r"No space left on device: '.*run\.json'") as info:
        atomic_write_bytes(target, b'{"status": "running"}\n')
    assert info.value.errno == errno.ENOSPC
    assert target.read_text() == '{"status": "ok"}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.json"]
    atomic_write_bytes(tmp_path / "other.json", b"{}")  # the fake disk only fills for run.json
    assert (tmp_path / "other.json").read_bytes() == b"{}"


def test_disk_full_while_collecting_loses_no_cell_and_resume_finishes(reference_run, tmp_path, rel_cache,
                                                                      monkeypatch):
    from harness.runner import run_suite
    from harness.suites import parse_suite

    run = tmp_path / "run"
    shutil.copytree(reference_run.run_dir, run, ignore=shutil.ignore_patterns(".lock"))
    (run / R.RESULTS_FILE).unlink()
    (run / R.SUMMARY_FILE).unlink()
    cells = tree_state(run / "cells")

    with monkeypatch.context() as m:
        full_disk(m, R.RESULTS_FILE)
        with pytest.raises(OSError, match=r"No space left on device: '.*results\.parquet'"):
            run_suite(parse_suite(suite()), run, resume=True, workers=1, cache_dir=rel_cache, progress=False)
    assert not (run / R.RESULTS_FILE).exists() and not partial_files(run)
    assert tree_state(run / "cells") == cells  # every finished cell is still there, unchanged

    again = run_suite(parse_suite(suite()), run, resume=True, workers=1, cache_dir=rel_cache, progress=False)
    assert again.ok and again.reused_cells == again.cells == 4
    assert_bit_identical(R.read_results(run), reference_run.table)
    umask = int(re.search(r"Umask:\s*([0-7]+)", Path("/proc/self/status").read_text()).group(1), 8)
    assert (run / R.RESULTS_FILE).stat().st_mode & 0o777 == 0o666 & ~umask  # as open() makes it, not mkstemp's 0600


def _two_seed_table(failed_seed: int | None = None) -> pd.DataFrame:
    parts = []
    for seed in (1, 2):
        status = "failed" if seed == failed_seed else "ok"
        rows = ([{"metric": "cell_failed", "value": np.nan, "sum": np.nan, "count": 0.0}] if status == "failed" else
                [{"metric": "epe_mean", "frame": 0, "region": "all", "motion": "total", "kind": "accuracy",
                  "value": 0.5, "sum": 50.0, "count": 100.0, "unit": "px", "higher_is_better": False}])
        parts.append(R.rows_to_frame(rows, cell_id=f"c{seed}", scene="tiny", seed=seed, pipeline="thesis-lk",
                                     machine="box", status=status, error="RuntimeError: boom" if status != "ok" else ""))
    return pd.concat(parts, ignore_index=True)


def test_a_failed_cell_never_passes_the_gate_even_when_other_seeds_fill_its_aggregate():
    baseline = G.make_baseline(_two_seed_table(), {"suite": "s", "provenance": {"machine": "box"}})
    assert G.compare(_two_seed_table(), baseline, suite="s").passed
    result = G.compare(_two_seed_table(failed_seed=2), baseline, suite="s")
    assert not result.passed and result.exit_code == 1
    (f,) = result.failures
    assert "cell c2 seed 2 failed: RuntimeError: boom" in f.reason
    assert "tiny / thesis-lk: cell failed: RuntimeError: boom" in G.to_markdown(result) and "boom" in G.to_junit_xml(result)
    assert "nan" not in G.to_markdown(result)


def test_an_empty_comparison_is_an_error_not_a_pass():
    empty = R.rows_to_frame([])
    baseline = G.make_baseline(empty, {"suite": "s"})
    with pytest.raises(G.GateError, match=r"nothing to compare"):
        G.compare(empty, baseline, suite="s")


def test_an_edit_inside_a_large_cached_file_is_detected(tmp_path):
    from scenes.sequence import ManifestError, verify_manifest, write_manifest

    seq = tmp_path / "seq"
    write_flo(seq / "flow" / "000000.flo", np.zeros((480, 640, 2), np.float32))  # a nominal-size truth field
    write_manifest(seq)
    victim = seq / "flow" / "000000.flo"
    raw = bytearray(victim.read_bytes())
    raw[len(raw) // 4] ^= 0x40  # one flow value changed, a quarter into the file
    victim.write_bytes(bytes(raw))
    with pytest.raises(ManifestError, match=r"000000\.flo"):
        verify_manifest(seq)


def test_resume_removes_temp_files_a_kill_left_in_the_run_folder(reference_run, tmp_path, rel_cache):
    from harness.runner import run_suite
    from harness.suites import parse_suite

    run = tmp_path / "run"
    shutil.copytree(reference_run.run_dir, run, ignore=shutil.ignore_patterns(".lock"))
    for name in (".run.json.k1l2.tmp", ".results.parquet.a8b9.tmp", ".summary.csv.x7y6.tmp"):
        (run / name).write_bytes(b"half a file")  # what atomic writers leave when killed between write and rename
    assert run_suite(parse_suite(suite()), run, resume=True, workers=1, cache_dir=rel_cache, progress=False).ok
    assert not partial_files(run), partial_files(run)
