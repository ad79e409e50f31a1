"""The ``aerobench`` command: parse, call the library, print, pick the exit code.

Exit codes: 0 ok / gate passed, 1 a regression or failed cells, 2 bad usage or bad
input (one line on stderr, no traceback; set ``AEROBENCH_DEBUG=1`` for the traceback).

::

    aerobench list [--full]
    aerobench render SCENE --out DIR [--set key=value ...] [--flow-format npz|flo] [--quiet]
    aerobench run SUITE --out DIR [--workers N] [--resume] [--executor process|dask|dask-local]
                        [--scheduler ADDR] [--cache DIR] [--no-report] [--quiet]
    aerobench report RUN_DIR [--baseline FILE] [--gate VERDICT_JSON] [--rules FILE] [--workers N] [--quiet]
    aerobench eval-flow DIR [--format middlebury|sintel|kitti|pair] [--pass clean|final] --method NAME
                        [--param KEY=VALUE ...] [--import MODULE ...]
    aerobench eval-video VIDEO --out DIR [--gt FILE] [--gt-format mot|visdrone|uavdt] [--pipelines a,b]
                         [--scale S] [--fps F] [--frames A:B] [--workers N] [--cache DIR] [--no-report] [--quiet]
    aerobench export SEQ_DIR --out DIR [--video NAME.mkv]
    aerobench baseline RUN_DIR --out FILE [--allow-failed]
    aerobench gate RUN_DIR --baseline FILE [--rules FILE] [--junit FILE] [--summary FILE] [--json FILE]

Your own flow method: a module that registers it (``algorithms.registry.register_flow``),
listed under ``imports:`` of a suite; modules beside the suite file, then in the working folder, are
importable (README, "Benchmark your own method").
"""

from __future__ import annotations

import argparse
import inspect
import os
import sys
import textwrap
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # before anything imports OpenGL

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2

__all__ = ["main", "build_parser", "UsageError"]


class UsageError(Exception):
    """A user error the CLI reports in one line with exit code 2."""


def _user_errors() -> tuple[type[BaseException], ...]:
    from harness.executors import ExecutorError
    from harness.gate import GateError
    from harness.resume import RunFolderError
    from harness.results import ResultsError
    from harness.suites import SuiteError
    from scenes import SceneSpecError
    from scenes.formats import FormatError

    # OSError: disk full, permission denied, a file vanished; its message names the file
    return (UsageError, SuiteError, RunFolderError, ExecutorError, FormatError, GateError, ResultsError,
            SceneSpecError, OSError)


def _one_line(text: str, width: int | None = 100) -> str:
    """``text`` on one line (lines joined by "; "), shortened to ``width`` characters (None: whole)."""
    lines = [line.strip() for line in (text or "").strip().splitlines() if line.strip()]
    if not lines:
        return ""
    joined = "; ".join(lines)
    return " ".join(joined.split()) if width is None else textwrap.shorten(joined, width, placeholder=" ...")


def _error_text(exc: BaseException) -> str:
    """One line for a user error; an OS error says what failed and on which file (no "[Errno N]")."""
    if isinstance(exc, OSError) and exc.strerror:
        where = exc.filename if exc.filename is not None else "(no file named by the system)"
        return _one_line(f"{exc.strerror}: {where}", 2000)
    return _one_line(str(exc), 2000)


# --------------------------------------------------------------------------- output paths


def _why_not_writable(exc: OSError) -> str:
    import errno

    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.EROFS:
        return "read-only file system"
    if exc.errno == errno.ENOSPC:
        return "no space left on the device"
    return f"the file system refuses it ({exc.strerror or exc})"


def _check_out(path: str | os.PathLike, option: str = "--out", *, file: bool = False) -> None:
    """Refuse an output path that cannot be made or written, before any work: one UsageError line
    saying what is wrong with it. ``file``: the path is a file to write (its folder is checked).

    The nearest existing folder on the path is probed by making (and removing) a temporary folder in
    it, so a read-only mount, a pseudo file system (``/proc``) or a folder of another user is found as
    the write would find it, whoever runs the command.
    """
    import tempfile

    path = Path(path)
    if path.is_dir() if file else (path.exists() and not path.is_dir()):
        raise UsageError(f"{option} {path}: is a {'folder' if file else 'file'}; expected a "
                         f"{'file to write' if file else 'folder'}")
    probe = path.parent if file else path
    while not probe.exists() and not probe.is_symlink() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise UsageError(f"{option} {path}: {probe} is a file, not a folder")
    try:
        made = tempfile.mkdtemp(prefix=".aerobench-write-check-", dir=probe)
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot create anything in {probe}: {_why_not_writable(exc)}") from None
    os.rmdir(made)


# --------------------------------------------------------------------------- list


def _list_presets() -> dict[str, str]:
    from scenes import list_presets

    presets = list_presets()
    if isinstance(presets, dict):
        return {k: _one_line(str(v), None) for k, v in presets.items()}
    out = {}
    for name in presets:
        desc = ""
        try:
            from scenes import load_scene_spec

            spec = load_scene_spec(name)
            desc = getattr(spec, "description", "") or ""
        except Exception:  # a broken preset still lists, without its description
            desc = "(cannot be loaded)"
        out[name] = _one_line(desc, None)
    return out


def _list_suites() -> dict[str, str]:
    """Built-in suite name -> its whole description on one line."""
    from harness.suites import SuiteError, builtin_suites, load_suite

    out = {}
    for name, path in builtin_suites().items():
        try:
            out[name] = " ".join(load_suite(path).description.split()) or "(undescribed)"
        except SuiteError:
            out[name] = "(invalid)"
    return out


def _list_pipelines() -> dict[str, str]:
    from harness.suites import pipeline_names

    out = {}
    for name, p in pipeline_names().items():
        out[name] = _one_line(p.get("description") or "", None)
    return out


def _list_metrics() -> dict[str, str]:
    from harness.metrics import METRICS

    return {n: f"[{d.unit}, {'higher' if d.higher_is_better else 'lower'} is better] {_one_line(d.description, None)}"
            for n, d in sorted(METRICS.items())}


def _list_flow_methods() -> dict[str, str]:
    import algorithms.pipeline  # noqa: F401  (importing it registers every built-in flow method)
    from algorithms.registry import FLOW_METHODS, describe

    out = {}
    for name, doc in describe()["flow"].items():
        knobs = [p.name for p in inspect.signature(FLOW_METHODS[name]).parameters.values()
                 if p.kind is p.KEYWORD_ONLY]
        out[name] = f"params: {', '.join(knobs) or 'none'}. {_one_line(doc, None)}"
    return out


def _list_stage_keys() -> dict[str, str]:
    """The keys of a pipeline dict (``Pipeline.from_dict``), each with thesis-lk's resolved value."""
    import json

    from algorithms.pipeline import get_pipeline

    resolved = get_pipeline("thesis-lk").to_dict()
    return {key: f"e.g. {json.dumps(value)}" for key, value in resolved.items() if key not in ("name", "description")}


def cmd_list(args: argparse.Namespace) -> int:
    from harness.suites import describe_suites

    sections = [("scene presets", _list_presets), ("suites", _list_suites if args.full else describe_suites),
                ("pipelines", _list_pipelines), ("flow methods", _list_flow_methods),
                ("pipeline stage keys (the flow key names a flow method)", _list_stage_keys),
                ("metrics", _list_metrics)]
    for title, fn in sections:
        items = fn()
        print(f"{title}:")
        width = max((len(k) for k in items), default=0)
        keep_order = title.startswith("pipeline stage keys")  # in the order the stages run
        for name, desc in (items.items() if keep_order else sorted(items.items())):
            print(f"  {name:<{width}}  {_one_line(desc, None if args.full else 110)}".rstrip())
        print()
    return EXIT_OK


# --------------------------------------------------------------------------- render


def _parse_set(items: Sequence[str], *, option: str = "--set",
               example: str = "camera.jitter.roll_std_deg=0.5") -> dict[str, Any]:
    import yaml

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"{option}: expected key=value (e.g. {example}), got {item!r}")
        try:
            out[key.strip()] = yaml.safe_load(value) if value.strip() else ""
        except yaml.YAMLError:
            out[key.strip()] = value
    return out


def cmd_render(args: argparse.Namespace) -> int:
    from scenes import load_scene_spec, render_sequence

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: is a file; expected a folder to write the sequence into")
    _check_out(out)
    spec = load_scene_spec(args.scene, overrides=_parse_set(args.set))
    if out.exists() and any(out.iterdir()):
        raise UsageError(f"{out}: the output folder is not empty")
    from tqdm import tqdm

    from harness.scheduling import kernels_to_compile

    label = Path(args.scene).stem if args.scene.endswith((".yaml", ".yml")) else args.scene
    # the frames' PNG encoder runs in every render (the truth's kernels not under a rolling shutter,
    # the flow decoder's only when reading): cold, the first frame waits for numba to compile them all
    cold = kernels_to_compile("scenes", modules={"scenes._codec_kernels"}) if not args.quiet else []
    if any(k.endswith((".avg_filter", ".deflate_huffman")) for k in cold):
        print("compiling numerical kernels (first run only, a few seconds)...", file=sys.stderr, flush=True)
    with tqdm(total=spec.image.n_frames, desc=f"rendering {label}", unit="frame", file=sys.stderr,
              disable=args.quiet, dynamic_ncols=True) as bar:
        def progress(done: int, total: int) -> None:
            bar.update(done - bar.n)

        render_sequence(spec, out, flow_format=args.flow_format, progress=progress)
    print(f"wrote {out} (preview: {out / 'preview.png'})")
    return EXIT_OK


# --------------------------------------------------------------------------- run / report


def _write_report(run_dir: Path, baseline: str | None = None, gate: str | None = None,
                  rules: str | None = None, *, workers: int | None = None, progress: bool = True,
                  **given: Any) -> Path | dict:
    """The run's report (``reports.write_report``): HTML and Markdown beside the results, its figures
    drawn by ``workers`` processes (default one per core); ``given``: the table and figures at hand."""
    from reports import write_report

    return write_report(run_dir, baseline=baseline, gate_verdict=gate, rules=rules, workers=workers,
                        progress=progress, **given)


def _start_figures(stack: ExitStack, run_dir: Path, cells: Any, workers: int | None) -> Any:
    """The report's figure processes, started (in ``stack``) and given every scene block while the
    runner collects the results (``reports.report.start_figures``); None if there is nothing to start."""
    if cells is None:
        return None
    try:
        from reports.report import figure_pool, start_figures

        pool = stack.enter_context(figure_pool(run_dir, workers))
        return start_figures(run_dir, cells, pool) if pool is not None else None
    except Exception as exc:  # the report draws them itself then; a run must not fail for it
        print(f"aerobench: warning: the report's figures could not be started early: {type(exc).__name__}: {exc}",
              file=sys.stderr)
        return None


def _paths(report: Any) -> str:
    """What write_report returned (a path, or a dict of paths by format), for one line of output."""
    if isinstance(report, dict):
        return ", ".join(str(p) for p in report.values())
    return str(report)


def cmd_run(args: argparse.Namespace) -> int:
    return _run(args.suite, args)


def _run(suite: Any, args: argparse.Namespace) -> int:
    """Run ``suite`` (a name, a path or a Suite) as ``aerobench run`` does, report and pick the exit code."""
    from harness.runner import run_suite

    _check_out(args.out)
    if args.cache is not None:
        _check_out(args.cache, "--cache")

    with ExitStack() as stack:  # the report's figure processes, if started early
        early: dict[str, Any] = {}

        def cells_done(run_dir: Path, cells: Any) -> None:
            # the figures need only the cell folders: drawn while the results are collected
            if not args.no_report:
                early["figures"] = _start_figures(stack, run_dir, cells, args.workers)

        result = run_suite(suite, args.out, workers=args.workers, resume=getattr(args, "resume", False),
                           executor=getattr(args, "executor", "process"), scheduler=getattr(args, "scheduler", None),
                           cache_dir=args.cache,
                           progress=not args.quiet, on_cells_done=cells_done)
        print(f"{result.cells} cells ({result.reused_cells} reused), scenes {result.scenes_rendered} rendered / "
              f"{result.scenes_reused} reused, {len(result.table)} rows, {result.elapsed_s:.1f} s -> "
              f"{result.run_dir}")
        if not args.no_report:
            try:  # the table in hand: the report need not read results.parquet back
                report = _write_report(result.run_dir, workers=args.workers, progress=not args.quiet,
                                       table=result.table, figures=early.get("figures"))
            except Exception as exc:  # the results are written; a report failure must not hide them
                print(f"aerobench: warning: the report failed: {type(exc).__name__}: {exc}", file=sys.stderr)
            else:
                print(f"report: {_paths(report)}")
    if not result.ok:
        for line in result.failed_cells:
            print(f"FAILED {line}", file=sys.stderr)
        print(f"aerobench: {len(result.failed_cells)} of {result.cells} cells failed (see cells/*/error.txt)",
              file=sys.stderr)
        return EXIT_FAIL
    return EXIT_OK


def cmd_report(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    if not (run_dir / "results.parquet").is_file():
        raise UsageError(f"{run_dir}: not a finished run folder (no results.parquet)")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers: expected at least 1, got {args.workers}")
    _check_out(run_dir, "RUN_DIR")  # the report is written into it
    for option, value in (("--baseline", args.baseline), ("--gate", args.gate), ("--rules", args.rules)):
        if value is not None and not Path(value).is_file():
            raise UsageError(f"{option}: {value}: no such file")
    from harness import gate

    # a file the gate refuses (GateError, exit 2) is refused here too, before the old report is touched
    if args.baseline is not None:
        gate.read_baseline(args.baseline)
    if args.gate is not None:
        gate.read_verdict(args.gate)
    if args.rules is not None:
        gate.load_rules(args.rules)
    report = _write_report(run_dir, args.baseline, args.gate, args.rules, workers=args.workers,
                           progress=not args.quiet)
    print(f"report: {_paths(report)}")
    return EXIT_OK


# --------------------------------------------------------------------------- real footage


def _frame_range(text: str | None) -> tuple[int, int | None]:
    """``--frames A:B`` -> (start, stop): source frames A to B exclusive, 0-based; either may be left out."""
    if text is None:
        return 0, None
    a, sep, b = text.partition(":")
    try:
        start = int(a) if a.strip() else 0
        stop = int(b) if b.strip() else None
    except ValueError:
        start = stop = -1
    if not sep or start < 0 or (stop is not None and stop < start + 2):
        raise UsageError(f"--frames: expected A:B, source frames A to B (exclusive, 0-based, at least 2 frames; "
                         f"A or B may be left out), got {text!r}")
    return start, stop


def eval_video_suite(args: argparse.Namespace) -> Any:
    """The one-scene suite ``aerobench eval-video`` runs (validated; paths absolute)."""
    from harness.suites import load_suite, parse_suite

    video = Path(args.video)
    if not video.exists():
        raise UsageError(f"{video}: no such video file or frames folder")
    if args.gt is not None and not Path(args.gt).is_file():
        what = "a folder; expected the ground-truth file (gt.txt)" if Path(args.gt).is_dir() else "no such file"
        raise UsageError(f"--gt: {args.gt}: {what}")
    start, stop = _frame_range(args.frames)
    scene: dict[str, Any] = {"real": str(video.resolve()), "label": video.stem or video.name, "start": start,
                             "scale": args.scale, "gt_format": args.gt_format}
    for key, value in (("stop", stop), ("fps", args.fps),
                       ("gt", str(Path(args.gt).resolve()) if args.gt is not None else None)):
        if value is not None:
            scene[key] = value
    if args.pipelines:
        pipelines = [p.strip() for p in args.pipelines.split(",") if p.strip()]
        if not pipelines:
            raise UsageError(f"--pipelines: expected names separated by commas, got {args.pipelines!r}")
    else:
        pipelines = list(load_suite("standard").pipelines)
    data = {"name": f"eval-video-{scene['label']}",
            "description": f"aerobench eval-video {video.name}: one real clip through {', '.join(pipelines)}",
            "scenes": [scene], "seeds": [0], "pipelines": pipelines, "picture_pairs": [0]}
    return parse_suite(data, source="eval-video")


def truth_summary(spec: Any) -> tuple[str, int]:
    """One line saying what a clip's ground truth holds in its range, as the metrics will count it, and the
    number of counted rows (``harness.metrics.objects``: vehicles counted, pedestrians and cyclists
    distractors, ignored rows and regions never scored)."""
    from harness.metrics.objects import DISTRACTOR_CLASSES, VEHICLE_CLASSES
    from scenes.footage import clip_frames, gt_labels_file, read_gt
    from scenes.formats import mot_label_class, read_mot_labels

    gt = read_gt(spec)
    n = clip_frames(spec)
    inside = gt["frame"] > spec.start
    if n is not None:
        inside &= gt["frame"] <= spec.start + n
    g = gt[inside]

    def by_class(rows: Any) -> str:
        counts = rows["class"].value_counts()
        return ", ".join(f"{c} {n}" for c, n in counts.items())

    kept = g[~g["ignore"]]
    counted = kept[kept["class"].isin(VEHICLE_CLASSES)]
    distract = kept[kept["class"].isin(DISTRACTOR_CLASSES)]
    frames = f"frames {int(g['frame'].min())}..{int(g['frame'].max())}" if len(g) else "no frame"
    line = (f"{Path(spec.gt).name} ({spec.gt_format}): {len(g)} rows in {frames}, {g['id'].nunique()} ids: "
            f"{len(counted)} counted vehicles ({by_class(counted) or 'none'}), {len(distract)} distractors"
            f"{f' ({by_class(distract)})' if len(distract) else ''}, {int(g['ignore'].sum())} ignored")
    if (~inside).any():
        span = f"{spec.start + 1}..{spec.start + n}" if n is not None else f"{spec.start + 1} on"
        line += f"; {int((~inside).sum())} rows outside the clip's frames {span} left out"
    labels = gt_labels_file(spec)
    if labels is not None:
        names = read_mot_labels(labels)
        unknown = [n for n in names if not mot_label_class(n)[0]]
        line += f"; classes named by {labels.name} ({', '.join(names)})"
        if unknown:
            line += f", not known and ignored: {', '.join(unknown)}"
    return line, len(counted)


def cmd_eval_video(args: argparse.Namespace) -> int:
    from harness.suites import expand

    suite = eval_video_suite(args)
    expand(suite, source="eval-video")  # a bad file is refused here, before --out is made
    spec = suite.scenes[0].footage_spec()
    if spec.gt is not None:
        line, counted = truth_summary(spec)
        print(f"truth: {line}", file=sys.stderr)
        if counted == 0:
            print("aerobench: warning: no row of the ground truth is a counted vehicle (car, van, truck, bus, "
                  "motorbike): MOTA, IDF1 and HOTA will be n/a; check its class column (--gt-format, labels.txt)",
                  file=sys.stderr)
    return _run(suite, args)


def cmd_export(args: argparse.Namespace) -> int:
    from scenes import open_sequence
    from scenes.footage import export_frames, export_mot_gt, export_video

    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UsageError(f"--out {out}: exists and is not an empty folder")
    _check_out(out)
    seq = open_sequence(args.seq_dir)
    if args.video is not None and Path(args.video).suffix.lower() not in (".mkv", ".avi", ".mp4", ".mov"):
        raise UsageError(f"--video: expected a .mkv, .avi (FFV1), .mp4 or .mov (H.264 RGB, crf 0) name, "
                         f"got {args.video!r}")
    export_frames(seq, out / "img1")
    if seq.tracks is not None:
        from harness.metrics.objects import counted_objects, distractor_objects

        # the objects the synthetic path counts and its distractors, as gt.txt rows (flag 0 where ignored)
        export_mot_gt(seq.tracks, out / "gt" / "gt.txt", counted=counted_objects(seq.tracks),
                      distractors=distractor_objects(seq.tracks))
    if args.video is not None:
        export_video(seq, out / Path(args.video).name, fps=float(seq.meta.get("fps") or 25.0))
    print(f"wrote {out} ({len(seq)} frames in img1/" + (", gt/gt.txt" if seq.tracks is not None else "")
          + (f", {Path(args.video).name}" if args.video else "") + ")")
    return EXIT_OK


# --------------------------------------------------------------------------- datasets, gate


_KIND_WORDS = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}


def _param_kinds(method: Any) -> dict[str, tuple[type, ...]]:
    """Keyword parameter -> the accepted value types, from the method's annotations (else its default's
    type); ``type(None)`` among them when it may be null; an empty tuple when nothing is known."""
    import typing

    try:
        hints = typing.get_type_hints(method)
    except Exception:  # an annotation that cannot be evaluated: fall back on the defaults
        hints = {}
    out = {}
    for p in inspect.signature(method).parameters.values():
        if p.kind is not p.KEYWORD_ONLY:
            continue
        hint = hints.get(p.name)
        kinds = tuple(a for a in (typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, _union_type())
                                  else (hint,)) if isinstance(a, type))
        if not kinds and p.default is not p.empty and p.default is not None:
            kinds = (type(p.default),)
        out[p.name] = kinds if any(k in _KIND_WORDS for k in kinds) else ()
    return out


def _union_type() -> Any:
    import types

    return types.UnionType


def _coerce_params(params: dict[str, Any], kinds: dict[str, tuple[type, ...]]) -> dict[str, Any]:
    """``params`` (values as YAML read them) checked against the types of the method's parameters:
    an int where a float is expected becomes a float; anything else raises UsageError naming the key."""
    out = {}
    for key, value in params.items():
        accepted = kinds.get(key, ())
        if not accepted or (value is None and type(None) in accepted):
            out[key] = value
            continue
        if bool in accepted and isinstance(value, bool):
            out[key] = value
        elif int in accepted and isinstance(value, int) and not isinstance(value, bool):
            out[key] = value
        elif float in accepted and isinstance(value, (int, float)) and not isinstance(value, bool):
            out[key] = float(value)
        elif str in accepted and isinstance(value, str):
            out[key] = value
        else:
            words = [_KIND_WORDS[k] for k in accepted if k in _KIND_WORDS]
            if type(None) in accepted:
                words.append("null")
            raise UsageError(f"--param {key}: expected {' or '.join(words)}, got {value!r}")
    return out


EVAL_FLOW_LAYOUTS = """\
folder layouts (--format; without it, found from what the folder holds):
  sintel      the training folder: ROOT/clean/<scene>/frame_NNNN.png (or ROOT/final/..., --pass final)
              and ROOT/flow/<scene>/frame_NNNN.flo; ROOT/invalid/<scene>/frame_NNNN.png used when present
  kitti       ROOT/image_2/NNNNNN_10.png, NNNNNN_11.png and ROOT/flow_occ/NNNNNN_10.png: a 16-bit RGB PNG
              (u, v, valid), u = (R - 2^15) / 64 px
  middlebury  every folder under ROOT holding one .flo and two PNG frames numbered in a row with the same
              prefix: frame10.png frame11.png flow10.flo; yos9.png yos10.png correct_yos.flo (Yosemite's sky
              masked)
  pair        ROOT itself holds two frame images (.png .jpg .ppm .pgm .bmp .tif) and one truth file: a .flo,
              or else the one 16-bit RGB PNG (KITTI encoding); the frames in name order, numbers compared
              as numbers (img9.png before img10.png); other files are ignored
"""


def cmd_eval_flow(args: argparse.Namespace) -> int:
    from harness.datasets import FlowMethodError, detect_format, evaluate_flow_dataset

    from harness.metrics import aggregate

    if not Path(args.dir).is_dir():
        raise UsageError(f"{args.dir}: no such folder")
    fmt = args.format or detect_format(args.dir)
    if args.pass_ is not None and fmt != "sintel":
        raise UsageError(f"--pass: only for --format sintel, got --format {fmt}")
    pass_ = args.pass_ or "clean"
    import algorithms.pipeline  # noqa: F401  (importing it registers every flow method)
    from algorithms.registry import get_flow_method
    from harness.suites import import_modules

    import_modules(args.imports, source="--import")  # your own flow method's module (the working folder too)
    try:
        method = get_flow_method(args.method)
    except KeyError as exc:
        hint = "" if args.imports else " (your own method: --import the module that registers it)"
        raise UsageError(f"--method: {exc.args[0]}{hint}") from None
    params = _parse_set(args.param, option="--param", example="levels=4")
    knobs = [p.name for p in inspect.signature(method).parameters.values() if p.kind is p.KEYWORD_ONLY]
    unknown = sorted(set(params) - set(knobs))
    if unknown:
        raise UsageError(f"--param: {args.method} has no parameter {', '.join(unknown)}; "
                         f"valid: {', '.join(knobs)}")
    params = _coerce_params(params, _param_kinds(method))
    try:  # a data problem (missing file, truncated .flo, 8-bit KITTI PNG) propagates naming its file
        table = evaluate_flow_dataset(args.dir, format=fmt, method=args.method, params=params, pass_=pass_)
    except FlowMethodError as exc:
        if params:
            raise UsageError(f"--param: {args.method} rejected {params} on pair {exc.pair}: {exc.cause}") from None
        raise UsageError(f"--method {args.method} failed on pair {exc.pair}: {exc.cause}") from None
    pairs = table["scene"].nunique()
    float_format = lambda v: f"{v:.4f}"  # noqa: E731
    setting = ", ".join(f"{k}={v}" for k, v in params.items()) or "default parameters"
    kind = {"sintel": f"{pairs} sintel ({pass_} pass) pair(s)", "pair": "the pair of a pair folder"}.get(
        fmt, f"{pairs} {fmt} pair(s)")
    print(f"{args.method} ({setting}) on {kind} in {args.dir}:")
    per_pair = aggregate(table[table["metric"] == "epe_mean"], by=["scene"])
    print(per_pair[["scene", "metric", "value", "unit", "count"]].astype({"count": "int64"})
          .to_string(index=False, float_format=float_format))
    print("\npooled over every pair (per ground-truth-valid pixel):")
    summary = aggregate(table, by=["pipeline"])
    summary["count"] = summary["count"].astype("int64")
    print(summary[["pipeline", "metric", "value", "unit", "count"]].to_string(index=False, float_format=float_format))
    return EXIT_OK


def cmd_baseline(args: argparse.Namespace) -> int:
    from harness import gate

    run_dir = Path(args.run_dir)
    if not (run_dir / "results.parquet").is_file():
        raise UsageError(f"{run_dir}: not a finished run folder (no results.parquet)")
    _check_out(args.out, file=True)
    path = gate.baseline_from_run(run_dir, args.out, allow_failed=args.allow_failed)
    failed = gate.read_baseline(path).get("failed_cells") or []
    if failed:
        print(f"aerobench: warning: {len(failed)} cell(s) failed; their metrics are not in the baseline "
              f"(recorded under failed_cells; a gate on it says so)", file=sys.stderr)
    print(f"baseline: {path}")
    return EXIT_OK


def cmd_gate(args: argparse.Namespace) -> int:
    from harness import gate
    from scenes.formats import atomic_write_bytes

    run_dir = Path(args.run_dir)
    if not (run_dir / "results.parquet").is_file():
        raise UsageError(f"{run_dir}: not a finished run folder (no results.parquet)")
    if not Path(args.baseline).is_file():
        raise UsageError(f"--baseline: {args.baseline}: no such file (a missing baseline is not a pass)")
    if args.rules is None and not gate.DEFAULT_RULES.is_file():  # an install without the package data
        print(f"aerobench: warning: {gate.DEFAULT_RULES} is missing; gating with the built-in defaults",
              file=sys.stderr)
    for option, value in (("--junit", args.junit), ("--summary", args.summary), ("--json", args.json)):
        if value is not None:
            _check_out(value, option, file=True)
    rules = gate.load_rules(args.rules or (gate.DEFAULT_RULES if gate.DEFAULT_RULES.is_file() else None))
    outcome = gate.compare(run_dir, gate.read_baseline(args.baseline), rules)
    markdown = gate.to_markdown(outcome)
    if args.junit:
        atomic_write_bytes(args.junit, gate.to_junit_xml(outcome).encode())
    if args.json:
        gate.write_verdict(outcome, args.json)
    if args.summary:
        atomic_write_bytes(args.summary, markdown.encode())
    print(markdown)
    return outcome.exit_code


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    from harness.executors import EXECUTORS

    p = argparse.ArgumentParser(
        prog="aerobench", description="Synthetic benchmark of motion estimation in aerial video.",
        epilog="Your own flow method: write a module that registers it with "
               "algorithms.registry.register_flow, list the module under `imports:` in a suite YAML and use "
               "the method in an inline pipeline ({name: mine, base: thesis-lk, spec: {flow: {method: NAME}}}); "
               "modules beside the suite file, then in the working folder, are importable. `aerobench list` shows the flow methods and "
               "the pipeline stage keys; README.md, 'Benchmark your own method', has a complete example.")
    p.add_argument("--version", action="version", version=f"aerobench {_version()}",
                   help="print aerobench's version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("list", help="scene presets, suites, pipelines and metrics",
                       description="List every name a suite or command takes: scene presets, suites, pipelines, "
                                   "flow methods with their parameters, pipeline stage keys and metrics, one line "
                                   "each.")
    s.add_argument("-v", "--full", action="store_true",
                   help="show each description whole instead of cutting it at the line's end")
    s.set_defaults(fn=cmd_list)

    s = sub.add_parser("render", help="render one scene into a sequence folder",
                       description="Render one scene (a preset or a scene YAML) into a sequence folder: frames, "
                                   "ground-truth flow, valid masks, instances, camera path, tracks and a preview.")
    s.add_argument("scene", help="preset name or scene YAML")
    s.add_argument("--out", required=True, help="the sequence folder to write (absent or empty)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene parameter by dotted key (repeatable)")
    s.add_argument("--flow-format", choices=("npz", "flo"), default="npz",
                   help="ground-truth flow files: compact lossless flow/NNNNNN.npz (default) or Middlebury "
                        ".flo in flow/ and flow_camera/ (about 10x larger)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(fn=cmd_render)

    s = sub.add_parser("run", help="run a suite into a run folder",
                       description="Run a suite: render (or reuse from the cache) its scenes, run every pipeline on "
                                   "them, score them and write results.parquet and the report into the run folder.")
    s.add_argument("suite", help="built-in suite name or suite YAML")
    s.add_argument("--out", required=True, help="the run folder (must be empty unless --resume)")
    s.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core, fewer for a small "
                   "suite)")
    s.add_argument("--resume", action="store_true", help="finish an interrupted run in --out")
    s.add_argument("--executor", choices=EXECUTORS, default="process",
                   help="where the cells run: local worker processes (default), a dask cluster at --scheduler, "
                        "or a local dask cluster")
    s.add_argument("--scheduler", default=None, help="dask scheduler address (with --executor dask)")
    s.add_argument("--cache", default=None, help="render cache (default: $AEROBENCH_CACHE or ~/.cache/aerobench)")
    s.add_argument("--no-report", action="store_true", help="do not write report.html / report.md")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(fn=cmd_run)

    s = sub.add_parser("report", help="(re)write report.html and report.md of a run",
                       description="Rewrite report.html and report.md of a finished run from its results table, "
                                   "optionally compared with a baseline and headed by a gate verdict.")
    s.add_argument("run_dir", help="a finished run folder (holds results.parquet)")
    s.add_argument("--baseline", default=None,
                   help="a baseline JSON to compare against (directions and tolerances from the gate rules)")
    s.add_argument("--gate", default=None, metavar="VERDICT_JSON",
                   help="a verdict written by `aerobench gate --json`, shown at the top of the report")
    s.add_argument("--rules", default=None, help="gate rules YAML for the baseline comparison "
                                                 "(default: gate_rules.yaml of aerobench)")
    s.add_argument("--workers", type=int, default=None,
                   help="processes drawing the pictures and figures (default: one per core, at most one per "
                        "scene)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(fn=cmd_report)

    s = sub.add_parser("eval-flow", help="score a flow method on a Middlebury / Sintel / KITTI folder or one pair",
                       description="Score a flow method on a data set with ground-truth flow: per pair and\n"
                                   "pooled over every pair.",
                       epilog=EVAL_FLOW_LAYOUTS, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("dir", metavar="DIR", help="the data set folder (ROOT in the layouts below)")
    s.add_argument("--format", default=None, choices=("middlebury", "sintel", "kitti", "pair"),
                   help="the folder layout (default: found from what the folder holds)")
    s.add_argument("--pass", dest="pass_", default=None, choices=("clean", "final"),
                   help="Sintel's rendering pass (default clean); only with the sintel layout")
    s.add_argument("--method", required=True, help="flow method name (see aerobench list)")
    s.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE",
                   help="import a module first, e.g. one that registers your own flow method (looked up after the "
                        "installed packages in the working folder; repeatable)")
    s.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword parameter of the method, e.g. --param levels=4 (repeatable)")
    s.set_defaults(fn=cmd_eval_flow)

    s = sub.add_parser("eval-video", help="run the pipelines on one real clip (a video or a frames folder) "
                                          "and score them against its annotations",
                       description="Run the pipelines on one real clip (a video or a folder of frames) and score "
                                   "them against its annotations: a run folder and a report as `aerobench run` "
                                   "writes.")
    s.add_argument("video", help="a video (.mp4 .mov .avi .mkv) or a folder of frames (.png .jpg)")
    s.add_argument("--out", required=True, help="the run folder (must be empty)")
    s.add_argument("--gt", default=None, help="MOTChallenge-style ground truth (gt.txt); without it only the "
                                               "metrics that need no truth are scored")
    s.add_argument("--gt-format", choices=("mot", "visdrone", "uavdt"), default="mot",
                   help="column layout of --gt (default mot)")
    s.add_argument("--pipelines", default=None, help="pipelines separated by commas (default: the standard suite's)")
    s.add_argument("--scale", type=float, default=1.0, help="resize factor of frames and annotations (default 1)")
    s.add_argument("--fps", type=float, default=None, help="frame rate (default: the video's own)")
    s.add_argument("--frames", default=None, metavar="A:B", help="source frames A to B, exclusive, 0-based")
    s.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    s.add_argument("--cache", default=None, help="render cache (default: $AEROBENCH_CACHE or ~/.cache/aerobench)")
    s.add_argument("--no-report", action="store_true", help="do not write report.html / report.md")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(fn=cmd_eval_video)

    s = sub.add_parser("export", help="write a sequence folder as MOTChallenge files (img1/ frames, gt/gt.txt) "
                                      "and optionally a lossless video",
                       description="Write a sequence folder as MOTChallenge files (img1/ frames, gt/gt.txt) and "
                                   "optionally as a lossless video.")
    s.add_argument("seq_dir", help="a sequence folder (aerobench render, or an entry of the render cache)")
    s.add_argument("--out", required=True, help="the folder to write (must be empty)")
    s.add_argument("--video", default=None, help="also write the frames as this lossless video (NAME.mkv or .avi: "
                                                  "FFV1; NAME.mp4 or .mov: H.264 in RGB at crf 0)")
    s.set_defaults(fn=cmd_export)

    s = sub.add_parser("baseline", help="write the baseline of a run (for the gate)",
                       description="Write the baseline of a finished run: its aggregated metrics, for `aerobench "
                                   "gate` to compare later runs with.")
    s.add_argument("run_dir", help="a finished run folder (holds results.parquet)")
    s.add_argument("--out", required=True, help="the baseline JSON to write")
    s.add_argument("--allow-failed", action="store_true",
                   help="write the baseline although cells failed (they are recorded in it; their metrics are "
                        "missing); without it, a run with a failed cell is refused")
    s.set_defaults(fn=cmd_baseline)

    s = sub.add_parser("gate", help="compare a run with a baseline: exit 1 on a regression",
                       description="Compare a finished run with a baseline by tolerance rules: exit 0 pass, 1 a "
                                   "regression or a failed cell, 2 bad usage or input.")
    s.add_argument("run_dir", help="a finished run folder (holds results.parquet)")
    s.add_argument("--baseline", required=True,
                   help="the baseline JSON written by `aerobench baseline` (a missing one is an error, not a pass)")
    s.add_argument("--rules", default=None, help="gate rules YAML (default: gate_rules.yaml of aerobench)")
    s.add_argument("--junit", default=None, help="write a JUnit XML report here")
    s.add_argument("--summary", default=None, help="write the Markdown summary here (e.g. $GITHUB_STEP_SUMMARY)")
    s.add_argument("--json", default=None, help="write the machine-readable verdict here (for `aerobench report --gate`)")
    s.set_defaults(fn=cmd_gate)
    return p


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("aerobench")
    except PackageNotFoundError:  # a source tree that was never installed
        return "(not installed)"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``aerobench`` console command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)  # argparse exits 2 on bad usage by itself
    try:
        return args.fn(args)
    except KeyboardInterrupt:
        print("aerobench: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `aerobench list | head`: the reader left; nothing more to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13  # as a shell reports SIGPIPE
    except Exception as exc:
        if not isinstance(exc, _user_errors()) or os.environ.get("AEROBENCH_DEBUG"):
            raise
        print(f"aerobench: error: {_error_text(exc)}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
