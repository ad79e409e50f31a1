"""The aerobench command: listing, exit codes, one-line errors, and the smoke suite gated like CI does."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
from tests.harness.harness_testdata import ROOT, TINY_SUITE

from harness.cli import main

SMOKE_BASELINE = ROOT / "harness" / "baselines" / "smoke.json"
GATE_RULES = ROOT / "harness" / "gate_rules.yaml"


def test_list_names_presets_suites_pipelines_and_metrics(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    sections = {}
    current = None
    for line in out.splitlines():
        if line and not line.startswith(" "):
            current = line.rstrip(":")
            sections[current] = {}
        elif line.strip():
            name, _, desc = line.strip().partition("  ")
            sections[current][name] = desc.strip()
    stage_title = "pipeline stage keys (the flow key names a flow method)"
    assert list(sections) == ["scene presets", "suites", "pipelines", "flow methods", stage_title, "metrics"]
    assert {"lucas_kanade", "horn_schunck", "dis", "farneback", "tvl1", "ilk", "tv_l1"} <= set(sections["flow methods"])
    assert sections["flow methods"]["lucas_kanade"].startswith("params: window, levels, iterations")
    assert list(sections[stage_title]) == ["global_motion", "jitter", "compensation", "flow", "threshold",
                                           "spatial", "temporal", "detection", "tracking"]
    assert '"method": "lucas_kanade"' in sections[stage_title]["flow"]
    assert {"tiny", "nominal", "jitter", "drift", "fast-vehicles", "urban-parallax", "noisy"} <= set(sections["scene presets"])
    assert {"smoke", "standard", "sweep-jitter", "sweep-speed", "sweep-noise"} <= set(sections["suites"])
    assert {"thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis"} <= set(sections["pipelines"])
    assert {"epe_mean", "shift_error", "track_error"} <= set(sections["metrics"])
    for title in ("suites", "metrics"):
        missing = [n for n, d in sections[title].items() if not d]
        assert not missing, f"{title} without a one-line description: {missing}"


@pytest.mark.parametrize("text, field", [
    ("name: x\nscenes: [{preset: tiny}]\nseeds: [1\n", r"YAML syntax error at line \d+"),
    ("name: x\nscenes: [{preset: tiny, jitter: 1}]\nseeds: [1]\npipelines: [dis]\n", r"scenes\[0\]\.jitter"),
    ("name: x\nscenes: [{preset: tiny}]\nseeds: [1]\npipelines: [lk]\n", r"pipelines\[0\]: unknown pipeline 'lk'; valid: "),
    ("name: x\nscenes: [{preset: tiny, sweep: {}}]\nseeds: [1]\npipelines: [dis]\n", r"scenes\[0\]\.sweep: an empty sweep"),
])
def test_a_bad_suite_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, text, field):
    suite = tmp_path / "bad.yaml"
    suite.write_text(text)
    out = tmp_path / "run"
    assert main(["run", str(suite), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("aerobench: error: ")
    assert str(suite) in err
    import re

    assert re.search(field, err), err
    assert "Traceback" not in err
    assert not out.exists()


def test_a_non_empty_run_folder_exits_2(tmp_path, capsys, write_suite):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.parquet").write_bytes(b"precious")
    suite = write_suite(copy.deepcopy(TINY_SUITE))
    assert main(["run", str(suite), "--out", str(tmp_path / "run")]) == 2
    assert "pass --resume" in capsys.readouterr().err
    assert (tmp_path / "run" / "results.parquet").read_bytes() == b"precious"


def test_usage_errors_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "smoke"])  # --out missing
    assert exc.value.code == 2
    assert main(["gate", str(tmp_path), "--baseline", str(tmp_path / "b.json")]) == 2
    assert "not a finished run folder" in capsys.readouterr().err
    assert main(["run", "smoke", "--out", str(tmp_path / "r"), "--executor", "dask"]) == 2
    assert "scheduler" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
    assert main(["eval-flow", str(tmp_path), "--format", "middlebury", "--method", "lucsa_kanade"]) == 2
    assert "unknown flow method 'lucsa_kanade'; valid: " in capsys.readouterr().err


@pytest.mark.gl
def test_render_writes_a_sequence_folder(tmp_path, capsys):
    out = tmp_path / "seq"
    assert main(["render", "tiny", "--out", str(out), "--set", "image.n_frames=3", "--set", "seed=4"]) == 0
    assert (out / "MANIFEST.json").is_file() and (out / "preview.png").is_file()
    assert len(list((out / "frames").glob("*.png"))) == 3
    assert "seed: 4" in (out / "scene.yaml").read_text()
    assert main(["render", "tiny", "--out", str(tmp_path / "x"), "--set", "image.n_frame=3"]) == 2
    assert "n_frame" in capsys.readouterr().err


@pytest.mark.gl
def test_render_exports_flo_on_request(tmp_path):
    out = tmp_path / "seq"
    assert main(["render", "tiny", "--out", str(out), "--set", "image.n_frames=2", "--flow-format", "flo"]) == 0
    assert [p.name for p in (out / "flow").iterdir()] == ["000000.flo"]
    assert [p.name for p in (out / "flow_camera").iterdir()] == ["000000.flo"]
    assert main(["render", "tiny", "--out", str(tmp_path / "compact"), "--set", "image.n_frames=2"]) == 0
    assert [p.name for p in (tmp_path / "compact" / "flow").iterdir()] == ["000000.npz"]


@pytest.mark.gl
@pytest.mark.slow
def test_smoke_run_passes_the_committed_baseline(tmp_path, cli_env):
    """What CI does: run the smoke suite end to end (report included), then gate it."""
    out = tmp_path / "smoke"
    run = subprocess.run([sys.executable, "-m", "harness.cli", "run", "smoke", "--out", str(out), "--quiet"],
                         cwd=ROOT, env=cli_env, capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr
    assert (out / "report.html").is_file() and (out / "report.md").is_file()
    # that the run's report (figures drawn early, the table handed over in memory) is the one a later
    # `aerobench report` writes: tests/reports/test_report.py and tests/harness/test_results.py
    junit = tmp_path / "gate.xml"
    gate = subprocess.run([sys.executable, "-m", "harness.cli", "gate", str(out), "--baseline", str(SMOKE_BASELINE),
                           "--rules", str(GATE_RULES), "--junit", str(junit)],
                          cwd=ROOT, env=cli_env, capture_output=True, text=True, timeout=60)
    assert gate.returncode == 0, gate.stdout + gate.stderr
    assert "<testsuite" in junit.read_text()


def test_the_committed_baseline_is_of_the_smoke_suite():
    from harness.gate import read_baseline

    baseline = read_baseline(SMOKE_BASELINE)
    assert baseline["suite"] == "smoke"
    pipelines = {m["pipeline"] for m in baseline["metrics"]}
    assert {"thesis-lk", "thesis-hs", "pyramidal-lk", "pyramidal-hs", "dis"} <= pipelines
    assert Path(GATE_RULES).is_file()


def _middlebury_pair(root: Path) -> Path:
    """A one-pair Middlebury folder: a smooth texture moved 1 px right, with its exact flow."""
    import cv2
    import numpy as np

    from scenes.formats import write_flo, write_png

    rng = np.random.default_rng(5)
    big = cv2.GaussianBlur((rng.random((70, 90)) * 255).astype(np.float32), (0, 0), 2.0)
    pair = root / "pair"
    write_png(pair / "frame10.png", big[3:67, 4:84].round().astype(np.uint8))
    write_png(pair / "frame11.png", big[3:67, 3:83].round().astype(np.uint8))
    flow = np.zeros((64, 80, 2), np.float32)
    flow[..., 0] = 1.0
    write_flo(pair / "flow10.flo", flow)
    return root


def test_eval_flow_takes_method_parameters_and_reports_each_pair(tmp_path, capsys):
    root = _middlebury_pair(tmp_path)
    assert main(["eval-flow", str(root), "--format", "middlebury", "--method", "lucas_kanade",
                 "--param", "levels=2", "--param", "iterations=2"]) == 0
    out = capsys.readouterr().out
    assert "lucas_kanade (levels=2, iterations=2) on 1 middlebury pair(s)" in out
    assert "middlebury:pair epe_mean" in out


@pytest.mark.parametrize("param, match", [
    ("level=4", r"--param: horn_schunck has no parameter level; valid: alpha, iterations"),
    ("levels", r"--param: expected key=value \(e.g. levels=4\)"),
    ("levels=0", r"--param: horn_schunck rejected \{'levels': 0\}"),
])
def test_eval_flow_rejects_bad_parameters_with_exit_2(tmp_path, capsys, param, match):
    import re

    root = _middlebury_pair(tmp_path)
    assert main(["eval-flow", str(root), "--format", "middlebury", "--method", "horn_schunck",
                 "--param", param]) == 2
    assert re.search(match, capsys.readouterr().err)


def test_render_into_a_file_says_so_in_one_line(tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("x")
    assert main(["render", "tiny", "--out", str(target)]) == 2
    err = capsys.readouterr().err
    assert err == f"aerobench: error: --out {target}: is a file; expected a folder to write the sequence into\n"


def test_an_os_error_is_one_line_without_errno(tmp_path, capsys):
    from harness.cli import _error_text

    exc = NotADirectoryError(20, "Not a directory", str(tmp_path / "f" / "x"))
    assert _error_text(exc) == f"Not a directory: {tmp_path / 'f' / 'x'}"
    assert "[Errno" not in _error_text(PermissionError(13, "Permission denied", "/root/x"))


def test_help_says_how_to_add_a_flow_method(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "register_flow" in out and "imports:" in out and "Benchmark your own method" in out


def test_report_takes_a_gate_verdict_and_checks_its_files(tmp_path, capsys):
    assert main(["report", str(tmp_path), "--gate", str(tmp_path / "v.json")]) == 2
    assert "not a finished run folder" in capsys.readouterr().err
    (tmp_path / "results.parquet").write_bytes(b"")
    assert main(["report", str(tmp_path), "--gate", str(tmp_path / "v.json")]) == 2
    assert capsys.readouterr().err == f"aerobench: error: --gate: {tmp_path / 'v.json'}: no such file\n"


def test_report_refuses_fewer_than_one_worker(tmp_path, capsys):
    (tmp_path / "results.parquet").write_bytes(b"")
    assert main(["report", str(tmp_path), "--workers", "0"]) == 2
    assert capsys.readouterr().err == "aerobench: error: --workers: expected at least 1, got 0\n"


# --------------------------------------------------------------------------- eval-flow: layouts and errors


def _sintel_tree(root: Path, *, passes=("clean",), flows: bool = True) -> Path:
    """A one-scene Sintel training tree: frames 1..2 of each pass, the flow of pair 1 (zero)."""
    import numpy as np

    from scenes.formats import write_flo, write_png

    rng = np.random.default_rng(3)
    for pass_ in passes:
        for n in (1, 2):
            write_png(root / pass_ / "alley_1" / f"frame_{n:04d}.png", rng.integers(0, 255, (40, 48, 3), np.uint8))
    (root / "flow").mkdir(parents=True, exist_ok=True)
    if flows:
        write_flo(root / "flow" / "alley_1" / "frame_0001.flo", np.zeros((40, 48, 2), np.float32))
    return root


def _eval(capsys, *argv) -> tuple[int, str, str]:
    code = main(["eval-flow", *map(str, argv)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_eval_flow_blames_the_data_not_param_for_data_problems(tmp_path, capsys):
    import numpy as np

    from scenes.formats import write_png

    # a Sintel tree without flow files
    sintel = _sintel_tree(tmp_path / "sintel", flows=False)
    code, _, err = _eval(capsys, sintel, "--format", "sintel", "--method", "lucas_kanade")
    assert code == 2 and "--param" not in err and err.count("\n") == 1
    assert f"{sintel / 'flow'}: no <scene>/frame_NNNN.flo files" in err
    # a truncated .flo
    root = _middlebury_pair(tmp_path / "mb")
    flo = root / "pair" / "flow10.flo"
    flo.write_bytes(flo.read_bytes()[:100])
    code, _, err = _eval(capsys, root, "--format", "middlebury", "--method", "lucas_kanade")
    assert code == 2 and "--param" not in err
    assert f"{flo}: 100 bytes, expected" in err
    # an 8-bit KITTI flow PNG
    kitti = tmp_path / "kitti"
    for k in (10, 11):
        write_png(kitti / "image_2" / f"000000_{k}.png", np.zeros((4, 6, 3), np.uint8))
    write_png(kitti / "flow_occ" / "000000_10.png", np.zeros((4, 6, 3), np.uint8))
    code, _, err = _eval(capsys, kitti, "--format", "kitti", "--method", "dis")
    assert code == 2 and "--param" not in err
    assert f"{kitti / 'flow_occ' / '000000_10.png'}: a KITTI flow file must be a 16-bit RGB PNG" in err


def test_eval_flow_points_at_the_training_root_when_given_a_scene_folder(tmp_path, capsys):
    sintel = _sintel_tree(tmp_path / "sintel")
    code, _, err = _eval(capsys, sintel / "clean" / "alley_1", "--format", "sintel", "--method", "dis")
    assert code == 2 and "--param" not in err
    assert "not a Sintel layout" in err and "ROOT/clean/<scene>/frame_NNNN.png" in err


@pytest.mark.parametrize("method, param, message", [
    ("lucas_kanade", "window=abc", "--param window: expected an integer, got 'abc'"),
    ("lucas_kanade", "window=2.5", "--param window: expected an integer, got 2.5"),
    ("horn_schunck", "alpha=strong", "--param alpha: expected a number, got 'strong'"),
    ("lucas_kanade", "gaussian_window=3", "--param gaussian_window: expected true or false, got 3"),
    ("horn_schunck", "warps=many", "--param warps: expected an integer or null, got 'many'"),
])
def test_eval_flow_param_types_come_from_the_method_signature(tmp_path, capsys, method, param, message):
    root = _middlebury_pair(tmp_path)
    code, _, err = _eval(capsys, root, "--format", "middlebury", "--method", method, "--param", param)
    assert code == 2
    assert err == f"aerobench: error: {message}\n"


def test_eval_flow_a_method_failing_without_param_names_the_method_and_pair(tmp_path, capsys, monkeypatch):
    from algorithms import registry

    def broken(frame0, frame1, *, knob: int = 1):
        raise ValueError("frame0: too small for this method")

    monkeypatch.setitem(registry.FLOW_METHODS, "broken_for_test", broken)
    root = _middlebury_pair(tmp_path)
    code, _, err = _eval(capsys, root, "--format", "middlebury", "--method", "broken_for_test")
    assert code == 2 and "--param" not in err
    assert "--method broken_for_test failed on pair pair: frame0: too small for this method" in err
    code, _, err = _eval(capsys, root, "--format", "middlebury", "--method", "broken_for_test", "--param", "knob=2")
    assert code == 2 and "--param: broken_for_test rejected {'knob': 2} on pair pair: frame0: too small" in err


@pytest.mark.parametrize("names, reversed_", [
    (("frame10.png", "frame11.png", "flow10.flo"), False),
    (("b_second.png", "a_first.png", "truth.flo"), True),  # frames in name order: a_first.png is frame 0
    (("img9.png", "img10.png", "gt.png"), False),           # numbers compared as numbers; a 16-bit KITTI truth
])
def test_eval_flow_takes_a_plain_pair_folder(tmp_path, capsys, names, reversed_):
    """Two frames and one truth file, in one folder: --format pair, and found without --format."""
    import cv2
    import numpy as np

    from harness.datasets import write_kitti_flow
    from scenes.formats import write_flo, write_png

    rng = np.random.default_rng(5)
    big = cv2.GaussianBlur((rng.random((70, 90)) * 255).astype(np.float32), (0, 0), 2.0)
    first, second, truth = names
    folder = tmp_path / "mine"
    write_png(folder / first, big[3:67, 4:84].round().astype(np.uint8))
    write_png(folder / second, big[3:67, 3:83].round().astype(np.uint8))
    flow = np.zeros((64, 80, 2), np.float32)
    flow[..., 0] = 1.0
    if reversed_:  # the truth from the frame that sorts first to the other: -1 px
        flow[..., 0] = -1.0
    (write_flo if truth.endswith(".flo") else write_kitti_flow)(folder / truth, flow)
    (folder / "notes.txt").write_text("not a frame")
    for fmt in (["--format", "pair"], []):
        code, out, err = _eval(capsys, folder, *fmt, "--method", "dis")
        assert code == 0, err
        assert "on the pair of a pair folder in" in out
        epe = float(next(line for line in out.splitlines() if line.startswith("pair:mine epe_mean")).split()[2])
        assert epe < 0.2, out


def test_eval_flow_imports_your_own_method(tmp_path, capsys, monkeypatch):
    root = _middlebury_pair(tmp_path / "data")
    (tmp_path / "own_eval_flow_xyz.py").write_text(
        "import numpy as np\n"
        "from algorithms.registry import register_flow\n\n\n"
        "@register_flow\n"
        "def own_eval_one_px(frame0, frame1, *, u_px: float = 1.0):\n"
        "    h, w = frame0.shape[:2]\n"
        "    flow = np.zeros((h, w, 2), np.float32)\n"
        "    flow[..., 0] = u_px\n"
        "    return flow, np.ones((h, w), bool)\n")
    monkeypatch.chdir(tmp_path)
    code, _, err = _eval(capsys, root, "--method", "own_eval_one_px")
    assert code == 2 and "--import the module that registers it" in err
    code, out, err = _eval(capsys, root, "--method", "own_eval_one_px", "--import", "own_eval_flow_xyz",
                           "--param", "u_px=1")
    assert code == 0, err
    assert "own_eval_one_px (u_px=1.0) on 1 middlebury pair(s)" in out
    assert "middlebury:pair epe_mean 0.0000" in out


def test_eval_flow_a_folder_that_is_no_pair_says_the_rule(tmp_path, capsys):
    import numpy as np

    from scenes.formats import write_png

    for name in ("a.png", "b.png", "c.png"):
        write_png(tmp_path / name, np.zeros((4, 6, 3), np.uint8))
    code, _, err = _eval(capsys, tmp_path, "--format", "pair", "--method", "dis")
    assert code == 2
    assert ("expected two frame images and one ground-truth file (a .flo, or a 16-bit RGB KITTI flow PNG); "
            "found 3 image(s), 0 .flo, 0 16-bit PNG") in err


def test_eval_flow_pass_chooses_the_sintel_pass(tmp_path, capsys):
    sintel = _sintel_tree(tmp_path / "sintel", passes=("clean",))
    code, _, err = _eval(capsys, sintel, "--format", "sintel", "--pass", "final", "--method", "dis")
    assert code == 2 and "expected folders final/ and flow/" in err
    _sintel_tree(sintel, passes=("final",))
    code, out, err = _eval(capsys, sintel, "--format", "sintel", "--pass", "final", "--method", "dis")
    assert code == 0, err
    assert "on 1 sintel (final pass) pair(s)" in out
    code, out, err = _eval(capsys, sintel, "--method", "dis")  # the layout found, the clean pass by default
    assert code == 0 and "on 1 sintel (clean pass) pair(s)" in out
    code, _, err = _eval(capsys, sintel, "--format", "middlebury", "--pass", "final", "--method", "dis")
    assert code == 2 and err == "aerobench: error: --pass: only for --format sintel, got --format middlebury\n"


def test_eval_flow_help_documents_every_layout(capsys):
    with pytest.raises(SystemExit):
        main(["eval-flow", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    for text in ("ROOT/clean/<scene>/frame_NNNN.png", "ROOT/flow/<scene>/frame_NNNN.flo", "ROOT/image_2/NNNNNN_10.png",
                 "ROOT/flow_occ/NNNNNN_10.png", "frame10.png frame11.png flow10.flo", "16-bit", "--pass"):
        assert text in out, text


# --------------------------------------------------------------------------- report, baseline: bad files, failed cells


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("option, text, match", [
    ("--baseline", "{not json", r"corrupt\.json: baseline is not valid JSON"),
    ("--baseline", '{"format": "something-else"}', r"corrupt\.json: not an aerobench baseline: format 'something-else'"),
    ("--gate", "[1, 2", r"corrupt\.json: gate verdict is not valid JSON"),
    ("--rules", "rules: {epe_mean: about 3}", r"corrupt\.json: epe_mean: rule 'about 3': expected 'abs <number>'"),
])
def test_report_refuses_a_corrupt_file_like_gate_and_keeps_the_old_report(tmp_path, capsys, option, text, match):
    import re

    from tests.reports.conftest import build_run

    run = build_run(tmp_path)
    (run / "report.html").write_text("the old report")
    (run / "report.md").write_text("the old report")
    before = _tree(run)
    bad = tmp_path / "corrupt.json"
    bad.write_text(text)
    assert main(["report", str(run), option, str(bad), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("aerobench: error: ") and err.count("\n") == 1 and re.search(match, err), err
    assert _tree(run) == before


def test_baseline_of_a_run_with_a_failed_cell_is_refused_unless_allowed(tmp_path, capsys):
    import json

    from tests.reports.conftest import FAILED, FAILED_ERROR, build_run

    run = build_run(tmp_path)
    out = tmp_path / "baseline.json"
    assert main(["baseline", str(run), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 cell(s) failed" in err and "--allow-failed" in err
    assert f"{FAILED[0]}" in err and FAILED[2] in err and "diverged" in err
    assert not out.exists()
    assert main(["baseline", str(run), "--out", str(out), "--allow-failed"]) == 0
    captured = capsys.readouterr()
    assert "warning: 1 cell(s) failed" in captured.err and "their metrics are not in the baseline" in captured.err
    recorded = json.loads(out.read_text())["failed_cells"]
    assert [(c["scene"], c["pipeline"], c["error"]) for c in recorded] == [
        (f"{FAILED[0]}[noise_sigma=10]", FAILED[2], FAILED_ERROR)]
    # the gate of the same run on it: the failed cell fails the gate, in words, never as nan
    summary, junit = tmp_path / "gate.md", tmp_path / "gate.xml"
    assert main(["gate", str(run), "--baseline", str(out), "--summary", str(summary), "--junit", str(junit)]) == 1
    printed = capsys.readouterr().out
    assert "nan" not in junit.read_text().lower() and "diverged" in junit.read_text()
    for text in (printed, summary.read_text()):
        assert "nan" not in text.lower(), text
        assert "cell failed" in text and "diverged" in text
        assert "the baseline was made with --allow-failed" in text


@pytest.mark.gl
@pytest.mark.slow
def test_a_suite_imports_its_plugin_from_its_own_folder_in_the_workers(tmp_path, cli_env):
    """`cd elsewhere; aerobench run own/my-suite.yaml`: the plugin beside the suite file reaches the
    worker processes (spawned: they import it again, from the same folders)."""
    own, elsewhere = tmp_path / "own", tmp_path / "elsewhere"
    own.mkdir()
    elsewhere.mkdir()
    (own / "own_folder_flow_xyz.py").write_text(
        "import numpy as np\n"
        "from algorithms.flow import as_gray\n"
        "from algorithms.registry import register_flow\n\n\n"
        "@register_flow\n"
        "def own_folder_zero_flow(frame0, frame1):\n"
        "    g = as_gray(frame0)\n"
        "    return np.zeros((*g.shape, 2), np.float32), np.ones(g.shape, bool)\n")
    (own / "my-suite.yaml").write_text(
        "name: mine\nimports: [own_folder_flow_xyz]\nscenes: [{preset: tiny, overrides: {image.n_frames: 4}}]\n"
        "seeds: [1]\npipelines:\n  - {name: zero, base: thesis-lk, spec: {flow: {method: own_folder_zero_flow}}}\n")
    env = {**cli_env, "PYTHONPATH": str(ROOT)}  # the project as installed; the plugin only beside the suite
    done = subprocess.run([sys.executable, "-m", "harness.cli", "run", "../own/my-suite.yaml", "--out", "run",
                           "--quiet", "--no-report", "--workers", "1"],
                          cwd=elsewhere, env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 cells (0 reused)" in done.stdout


# --------------------------------------------------------------------------- help, version, list --full


def _subparsers() -> dict:
    import argparse

    from harness.cli import build_parser

    parser = build_parser()
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def test_every_subcommand_help_has_a_summary_and_every_argument_a_help_text(capsys):
    import argparse

    subs = _subparsers()
    assert set(subs) >= {"list", "render", "run", "report", "eval-flow", "baseline", "gate"}
    for name, sub in subs.items():
        assert sub.description and sub.description[0].isupper() and sub.description.rstrip().endswith("."), name
        with pytest.raises(SystemExit):
            main([name, "--help"])
        out = " ".join(capsys.readouterr().out.split())
        assert " ".join(sub.description.split()) in out, name
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help and action.help != argparse.SUPPRESS, f"{name} {action.dest}: no help text"


def test_version(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"aerobench {version('aerobench')}\n"


def test_list_full_shows_descriptions_whole(capsys):
    from scenes import load_scene_spec

    whole = " ".join(load_scene_spec("nominal").description.split())
    assert len(whole) > 120, "the nominal preset's description is short: pick a longer one to check"
    assert main(["list"]) == 0
    short = next(line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("nominal "))
    assert short.endswith("...") and whole not in short
    for flag in ("--full", "-v"):
        assert main(["list", flag]) == 0
        out = capsys.readouterr().out
        line = next(line for line in out.splitlines() if line.strip().startswith("nominal "))
        assert whole in line
        assert not [line for line in out.splitlines() if line.endswith("...")]


# --------------------------------------------------------------------------- --out that cannot be written


def _out_case(tmp_path: Path, case: str) -> tuple[Path, str]:
    """An --out path that cannot be made, and the line that must say why."""
    import os

    if case == "proc":
        return Path("/proc/aerobench_out"), "--out /proc/aerobench_out: cannot create anything in /proc: "
    if case == "sys":
        return Path("/sys/aerobench_out"), "--out /sys/aerobench_out: cannot create anything in /sys: "
    if case == "under-a-file":
        (tmp_path / "a-file").write_text("x")
        out = tmp_path / "a-file" / "x"
        return out, f"--out {out}: {tmp_path / 'a-file'} is a file, not a folder"
    if case == "read-only":
        if os.geteuid() == 0:
            pytest.skip("root writes into a read-only folder")
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        return ro / "out", f"--out {ro / 'out'}: cannot create anything in {ro}: permission denied"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["proc", "sys", "under-a-file", "read-only"])
@pytest.mark.parametrize("command", ["run", "render", "baseline"])
def test_an_impossible_out_is_one_line_naming_what_is_wrong(tmp_path, capsys, monkeypatch, case, command):
    import harness.runner
    import scenes

    out, message = _out_case(tmp_path, case)

    def no_work(*args, **kwargs):
        raise AssertionError("work started before --out was checked")

    monkeypatch.setattr(harness.runner, "run_suite", no_work)
    monkeypatch.setattr(scenes, "render_sequence", no_work)
    monkeypatch.setattr("harness.gate.baseline_from_run", no_work)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "results.parquet").write_bytes(b"")
    argv = {"run": ["run", "smoke", "--out", str(out)], "render": ["render", "tiny", "--out", str(out)],
            "baseline": ["baseline", str(run_dir), "--out", str(out)]}[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"aerobench: error: {message}"), err
    assert "[Errno" not in err and "Traceback" not in err
