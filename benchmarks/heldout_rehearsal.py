"""Rehearse the review: a 1080p stand-in for the held-out real clip, through ``aerobench eval-video``.

At review a held-out real UAV clip (1080p nadir video of a city junction, about 26
moving vehicles a frame, 100 frames, H.264, 25-30 fps, a MOTChallenge ``gt.txt``, no
ground sampling distance) is run through the real-footage path with the built-in
pipelines and MOTA is read off. This script builds the same situation from a rendered
scene and walks the same path, so that the numbers can be re-run as the algorithms change.
Not a speed benchmark in the gate's sense, but it reports the seconds each pipeline takes
(wall, one worker), because a pipeline that takes many minutes at 1080p is a review problem.
Run from the project root:

    python benchmarks/heldout_rehearsal.py [--scene city realistic city-wide] [--frames 100]
        [--size 1920x1080] [--fps 25] [--pipelines dis,tv-l1] [--scale 1 0.5] [--px-factor 1 2]
        [--seeds N ...] [--work DIR] [--cache DIR] [--set KEY=VALUE ...] [--json FILE]

Per scene:

1. render the preset at ``--size``, ``--frames``, ``--fps`` (scene overrides; ``city-wide`` is
   ``city`` from 220 m, so that a 1080p frame keeps the preset's 0.13 m a pixel and sees four
   times its ground: the real clip's density of movers), or reuse it from the render cache
   (``--cache``, default ``$AEROBENCH_CACHE``);
2. ``aerobench export SEQ --out WORK/SCENE/clip --video clip.mp4``: H.264 (lossless RGB) and
   ``gt/gt.txt``, what a user holding a real clip hands over (the export writes the visible road
   users that are not parked: moving vehicles, vehicles queued at lights, pedestrians and
   cyclists, the last two read back as distractors);
3. the clip is decoded into the render cache once (timed: ``ingest``), as eval-video's first
   run would;
4. ``aerobench eval-video clip.mp4 --gt gt/gt.txt --pipelines P --scale S --workers 1 --no-report --quiet``
   once per pipeline and ``--scale`` (default 1: the clip as handed over) (every built-in one by default, ``tvl1`` included), in its own process,
   timed (wall seconds: start-up, the pipeline on every pair, scoring, the run's files).

The built-in pipelines scale their px sizes to the frame (``detection.px_scale: auto``: the
shorter side over 480 px, 2.25 at 1080p; :data:`algorithms.pipeline.PX_SCALED_KEYS`). With
``--px-factor F``, each pipeline also runs with ``px_scale`` fixed at F (1: the sizes as given,
tuned at 640x480) through ``aerobench run`` of a one-scene suite with a ``real:`` scene.

Printed per scene and pipeline and tracker (``multi``: the multi-target tracker over the
detections; ``point``: the thesis's point tracker seeded on frame 0's vehicles): MOTA,
IDF1, HOTA, FP, FN, IDSW, the objects counted, the wall seconds of the eval-video call and
the pipeline's own stage times (``time_<stage>_ms`` summed over the pairs, the slowest
first), so that a slow pipeline says which stage is slow. ``--json FILE`` keeps it all.

One rendered world is one sample: the same ``city-wide`` spec laid out by two generator
versions scored dis MOTA 0.245 and 0.619 on its first 50 frames, more than most algorithm
changes move it. ``--seeds 1 2 3`` rehearses each scene on that many worlds (the preset's
seed replaced) and ends with each pipeline's median, lowest and highest MOTA over them: a
ranking or a change that holds over the worlds, not over one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms.pipeline import PIPELINES  # noqa: E402
from harness.results import read_results, summarize  # noqa: E402
from scenes import load_scene_spec  # noqa: E402
from scenes.cache import cached_sequence_result  # noqa: E402
from scenes.footage import FootageSpec  # noqa: E402
from benchmarks._overrides import parse_value as _value  # noqa: E402

# scene name -> (preset, overrides beyond size, frames and fps)
SCENES = {
    "city": ("city", {}),
    "realistic": ("realistic", {}),
    # the city from twice as high (its own preset now): at 1080p the city's 0.13 m a pixel (its vehicles the
    # same size in px as at 960x540) over four times the ground, so about 4x the movers in a frame
    "city-wide": ("city-wide", {}),
}
TRACK_METRICS = ("mota", "idf1", "hota", "mot_false_positives", "mot_misses", "motp")


def _aerobench(*args: str, env: dict) -> tuple[float, subprocess.CompletedProcess]:
    """Run the CLI as a user would (``python -m harness.cli``), timed; a failure stops the script."""
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "harness.cli", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True)
    wall = time.perf_counter() - t
    if proc.returncode not in (0, 1):  # 1: a failed cell, reported below with the rest
        sys.exit(f"aerobench {' '.join(args)}: exit {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return wall, proc


def _scores(run_dir: Path) -> tuple[list[dict], dict[str, float], str]:
    """Per tracker: the tracking metrics; the pipeline's stage times (ms summed over pairs); the cell's status."""
    df = read_results(run_dir)
    status = ",".join(sorted(df["status"].astype(str).unique())) if "status" in df.columns else "?"
    s = summarize(df)
    out = []
    for tracker in sorted(s.loc[s["metric"] == "mota", "region"].unique()):
        row = {"tracker": tracker}
        for m in TRACK_METRICS:
            v = s[(s["metric"] == m) & (s["region"] == tracker)]
            row[m] = float(v["value"].iloc[0]) if len(v) else float("nan")
        c = s[(s["metric"] == "mota") & (s["region"] == tracker)]
        row["objects"] = int(c["count"].iloc[0]) if len(c) else -1
        # MOTA's sum is FN + FP + IDSW of this tracker (harness.metrics.mot): its switches, the point tracker's too
        row["id_switches"] = float(c["sum"].iloc[0]) - row["mot_false_positives"] - row["mot_misses"]
        out.append(row)
    t = df[df["metric"].astype(str).str.startswith("time_") & df["frame"].notna()]
    stages = t.groupby("metric")["value"].sum().sort_values(ascending=False)
    return out, {k[5:-3]: float(v) for k, v in stages.items()}, status


def scaled_spec(factor: float) -> dict:
    """The pipeline spec (deep-merged over a built-in one) whose px sizes are ``factor`` times the built-in ones
    (``detection.px_scale``, :data:`algorithms.pipeline.PX_SCALED_KEYS`), instead of the frame's own factor."""
    return {"detection": {"px_scale": float(factor)}}


def _scaled_name(pipe: str, factor: float, args) -> str:
    return f"{pipe}-px{factor:g}"


def _run_scaled(clip: Path, gt: Path, pipe: str, scale: float, factor: float, run: Path, args, env):
    """``pipe`` with its px parameters times ``factor`` on the clip, through ``aerobench run`` of a one-scene
    suite with a ``real:`` scene (the path a suite file gives a reviewer; eval-video takes built-in names)."""
    import yaml

    suite = {"name": "heldout-px", "description": f"{pipe} with px parameters x{factor:g}",
             "scenes": [{"real": str(clip.resolve()), "label": clip.stem, "scale": scale, "gt": str(gt.resolve())}],
             "seeds": [0], "picture_pairs": [0],
             "pipelines": [{"name": _scaled_name(pipe, factor, args), "base": pipe,
                            "spec": scaled_spec(factor)}]}
    path = run.with_suffix(".yaml")
    path.write_text(yaml.safe_dump(suite, sort_keys=False))
    return _aerobench("run", str(path), "--out", str(run), "--workers", "1", "--cache", str(args.cache),
                      "--no-report", "--quiet", env=env)


def _truth_note(scene: str, seq_dir: Path) -> None:
    """What the exported truth counts, and how much of it no motion detector can see: the rows of counted
    vehicles that never move faster than 0.5 m/s in the clip (queued at a light throughout), a cap on MOTA."""
    from harness.metrics.objects import counted_objects

    t = pd.read_csv(seq_dir / "tracks.csv")
    c = t[counted_objects(t)]
    if not len(c) or "speed_mps" not in c.columns:
        return
    still = c.groupby("vehicle_id")["speed_mps"].transform("max") < 0.5
    n = t["frame"].nunique()
    print(f"[{scene}] truth: {len(c) / n:.1f} counted vehicles a frame, {int(still.sum())} of {len(c)} rows "
          f"({still.mean():.0%}) of vehicles that stand still all clip (MOTA <= {1 - still.mean():.2f} for a "
          f"detector of motion)", flush=True)


def rehearse(scene: str, args: argparse.Namespace, env: dict, *, seed: int | None = None) -> list[dict]:
    preset, extra = SCENES[scene]
    w, h = (int(v) for v in args.size.lower().split("x"))
    overrides = {"image.width_px": w, "image.height_px": h, "image.n_frames": args.frames, "image.fps": args.fps,
                 **extra, **dict((k, _value(v)) for k, v in (s.split("=", 1) for s in args.set))}
    if seed is not None:
        overrides["seed"] = seed
    spec = load_scene_spec(preset, overrides=overrides)
    t = time.perf_counter()
    seq = cached_sequence_result(spec, args.cache)
    print(f"[{scene}] {'rendered' if seq.rendered else 'reused'} {seq.path.name} ({w}x{h}, {args.frames} frames, "
          f"{args.fps:g} fps) in {time.perf_counter() - t:.0f} s", flush=True)

    _truth_note(scene, seq.path)
    work = Path(args.work) / f"{scene}-{seq.path.name}"
    clip_dir = work / "clip"
    clip, gt = clip_dir / "clip.mp4", clip_dir / "gt" / "gt.txt"
    if not (clip.is_file() and gt.is_file()):
        if clip_dir.exists():
            sys.exit(f"{clip_dir}: a partial export; remove it and run again")
        wall, _ = _aerobench("export", str(seq.path), "--out", str(clip_dir), "--video", clip.name, env=env)
        print(f"[{scene}] aerobench export: {wall:.0f} s ({clip.stat().st_size / 1e6:.0f} MB, "
              f"{sum(1 for _ in gt.open())} gt lines)", flush=True)
    rows = []
    for scale in args.scale:
        # what eval-video's first run does before any pipeline: the clip decoded into the render cache
        t = time.perf_counter()
        entry = cached_sequence_result(FootageSpec(name=clip.stem, source=str(clip.resolve()), scale=scale,
                                                   gt=str(gt.resolve())), args.cache)
        print(f"[{scene} x{scale:g}] ingest ({'decoded' if entry.rendered else 'cached'}): "
              f"{time.perf_counter() - t:.0f} s", flush=True)
        factors = args.px_factor if args.only_scaled else [None, *args.px_factor]  # None: the built-in auto
        for pipe, factor in [(p, f) for p in args.pipelines for f in factors]:
            name = pipe if factor is None else _scaled_name(pipe, factor, args)
            run = work / f"run-{name}-x{scale:g}"
            if run.exists():
                subprocess.run(["rm", "-rf", str(run)], check=True)
            if factor is None:
                wall, proc = _aerobench("eval-video", str(clip), "--gt", str(gt), "--pipelines", pipe, "--scale",
                                        repr(scale), "--out", str(run), "--workers", "1", "--cache", str(args.cache),
                                        "--no-report", "--quiet", env=env)
            else:
                wall, proc = _run_scaled(clip, gt, pipe, scale, factor, run, args, env)
            trackers, stages, status = _scores(run)
            slow = ", ".join(f"{k} {v / 1000:.0f}" for k, v in list(stages.items())[:4])
            pipe = name
            head = {"scene": scene, "seed": spec.seed, "scale": scale, "pipeline": pipe}
            for r in trackers:
                rows.append({**head, **r, "wall_s": wall, "status": status, "stages_ms": stages})
                print(f"[{scene} x{scale:g}] {pipe:13s} {r['tracker']:5s} MOTA {r['mota']:7.3f} IDF1 {r['idf1']:6.3f} "
                      f"HOTA {r['hota']:6.3f} FP {r['mot_false_positives']:6.0f} FN {r['mot_misses']:6.0f} "
                      f"IDSW {r['id_switches']:4.0f} objects {r['objects']:5d}  {wall:6.0f} s  ({status}; "
                      f"stage s: {slow})", flush=True)
            if not trackers:
                rows.append({**head, "wall_s": wall, "status": status, "stages_ms": stages})
                print(f"[{scene} x{scale:g}] {pipe:13s} no tracking rows ({status}); {wall:.0f} s", flush=True)
    return rows


def over_worlds(table: pd.DataFrame) -> pd.DataFrame:
    """Per scene, scale, pipeline and tracker: MOTA's median, lowest and highest over the worlds (seeds), and
    the pipeline's rank by median among the scene's pipelines (1 best) for each tracker."""
    keys = ["scene", "scale", "pipeline", "tracker"]
    g = table.dropna(subset=["mota"]).groupby(keys)["mota"]
    out = g.agg(worlds="count", mota_median="median", mota_min="min", mota_max="max").reset_index()
    out["rank"] = out.groupby(["scene", "scale", "tracker"])["mota_median"].rank(ascending=False, method="min")
    return out.sort_values(["scene", "scale", "tracker", "rank"]).astype({"rank": int})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", nargs="+", default=["city", "realistic"], choices=sorted(SCENES))
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--size", default="1920x1080", help="WIDTHxHEIGHT in px (default 1920x1080)")
    ap.add_argument("--fps", type=float, default=25.0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a further scene override, e.g. seed=3 (repeatable)")
    ap.add_argument("--scale", type=float, nargs="+", default=[1.0],
                    help="eval-video's --scale, one run per value (0.5: the 1080p clip at the 960x540 the "
                         "pipelines' px parameters were tuned at)")
    ap.add_argument("--px-factor", type=float, nargs="*", default=[],
                    help="beside each pipeline, the same with detection.px_scale fixed at each factor (1: the "
                         "px sizes as given for 640x480), through `aerobench run` of a one-scene real: suite")
    ap.add_argument("--only-scaled", action="store_true", help="with --px-factor: the scaled pipelines only")
    ap.add_argument("--pipelines", default=",".join(sorted(PIPELINES)),
                    help="pipelines separated by commas (default: every built-in one)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="rehearse each scene on these worlds (the preset's seed replaced) and summarise MOTA over "
                         "them (default: the preset's own seed)")
    ap.add_argument("--work", default="/tmp/aerobench-heldout", help="exports and run folders (default %(default)s)")
    ap.add_argument("--cache", default=os.environ.get("AEROBENCH_CACHE", str(Path.home() / ".cache" / "aerobench")))
    ap.add_argument("--json", default=None, help="write every row here")
    args = ap.parse_args(argv)
    args.pipelines = [p.strip() for p in args.pipelines.split(",") if p.strip()]
    unknown = [p for p in args.pipelines if p not in PIPELINES]
    if unknown:
        ap.error(f"--pipelines: unknown {unknown}; valid: {', '.join(sorted(PIPELINES))}")
    env = {**os.environ, "AEROBENCH_CACHE": str(args.cache), "PYTHONPATH": str(ROOT)}
    rows = []
    for scene in args.scene:
        for seed in args.seeds or [None]:
            rows += rehearse(scene, args, env, seed=seed)
    table = pd.DataFrame([{k: v for k, v in r.items() if k != "stages_ms"} for r in rows])
    if len(table):
        print()
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if len(table) and "mota" in table.columns and table["seed"].nunique() > 1:
        print()
        print(over_worlds(table).to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
