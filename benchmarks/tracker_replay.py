"""The multi-target tracker replayed on a pipeline's captured detections: tracker changes in seconds, not minutes.

Not a speed benchmark: the accuracy loop for ``tracking.multi``. Running a pipeline over a 100-frame 1080p
clip takes minutes, almost all of it flow and detection, which a change of the tracker does not touch. So
``capture`` runs the pipeline once and keeps what its multi-target tracker was handed: the tracker's
parameters (px sizes already scaled), and per frame the detections, the camera path and the gray frame;
``replay`` runs the tracker again on that, with ``--set`` overrides of its parameters, and scores its tracks
against the sequence's truth as the harness does (:func:`harness.metrics.mot_counts`, :func:`hota_counts`:
MOTA, IDF1, HOTA, FP, FN, IDSW). With no override, replay gives the pipeline's own multi-target figures to
the digit (it is checked: ``capture`` stores them). Run from the project root:

    python benchmarks/tracker_replay.py capture SEQ_DIR --pipeline dis --out CAPTURE.npz [--set detection.KEY=V]
    python benchmarks/tracker_replay.py replay CAPTURE.npz [CAPTURE2.npz ...] [--set KEY=VALUE ...] [--merges]

``SEQ_DIR`` is a sequence folder with a ``tracks.csv`` (``aerobench render``, an entry of the render cache,
or the cache entry ``aerobench eval-video`` decoded a real clip with its ``gt.txt`` into: the ``real-clip-*``
folder). ``--set`` on ``replay`` takes the tracker's own keys (``merge_covered=false``, or
``tracking.multi.merge_covered=false`` as a pipeline file spells it); px-sized keys are given at the
clip's scale, as the capture holds them. Several captures are pooled from summed
counts. ``--merges`` lists the tracks the tracker joined into others (``merge_hits``, ``merge_covered``,
``merge_bridge_grey``), by frame, with the vehicle each one's last rows lay on; ``--breakdown`` each vehicle's
missed frames by cause (no detection, a detection box under IoU 0.5, the tracker) and each false-positive
track, as ``benchmarks/tracking_quality.py --breakdown`` prints them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms import registry  # noqa: E402
from algorithms.detection import Detection  # noqa: E402
from algorithms.tracking import MULTI_DEFAULTS, TRACK_COLUMNS, MultiTargetTracker, boxes_in_image  # noqa: E402
from benchmarks._overrides import parse_value, pipeline_with  # noqa: E402
from harness.metrics import hota_counts, mot_counts  # noqa: E402
from harness.metrics.mot import HOTACounts, MOTCounts  # noqa: E402

BOX = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]
HOTA_FIELDS = ("tp", "fn", "fp", "ass_sum", "loc_sum")


class _Recorder(MultiTargetTracker):
    """The multi-target tracker, keeping what each call hands it (the capture)."""

    last: "_Recorder | None" = None

    def __init__(self, **params):
        super().__init__(**params)
        self.given = dict(params)
        self.calls: list[tuple] = []
        _Recorder.last = self

    def step(self, frame, detections, *, offset_px=(0.0, 0.0), image=None):
        self.calls.append(("step", int(frame), [tuple(map(float, d)) for d in detections],
                           np.asarray(offset_px, np.float64).copy(), None if image is None else np.array(image)))
        super().step(frame, detections, offset_px=offset_px, image=image)

    def extrapolate(self, frame, *, offset_px=(0.0, 0.0), image=None):
        self.calls.append(("extrapolate", int(frame), [], np.asarray(offset_px, np.float64).copy(),
                           None if image is None else np.array(image)))
        super().extrapolate(frame, offset_px=offset_px, image=image)


def _tracks_frame(rows: list[dict], shape: tuple[int, int]) -> pd.DataFrame:
    """The tracker's rows as the pipeline's tracks table (boxes clipped to the image as Pipeline.run does)."""
    tracks = pd.DataFrame(rows, columns=list(TRACK_COLUMNS))
    tracks[BOX] = boxes_in_image(tracks[BOX].to_numpy(np.float64), shape)
    return tracks


def _scores(tracks: pd.DataFrame, seq) -> dict:
    """The harness's CLEAR-MOT / identity and HOTA counts of the multi tracks, as plain numbers (a capture keeps
    them as JSON); :func:`_summary` reads them back into :class:`MOTCounts` and :class:`HOTACounts`."""
    est = tracks[tracks["source"] == "multi"]
    ignore = getattr(seq, "ignore_regions", None)
    c = mot_counts(est, seq.tracks, ignore=ignore)
    h = hota_counts(est, seq.tracks, ignore=ignore)
    return {"mot": dataclasses.asdict(c), "hota": {k: getattr(h, k).tolist() for k in HOTA_FIELDS}}


def _counts(s: dict) -> tuple[MOTCounts, HOTACounts]:
    return MOTCounts(**s["mot"]), HOTACounts(**{k: np.asarray(v) for k, v in s["hota"].items()})


def _summary(s: dict) -> str:
    c, h = _counts(s)
    return (f"MOTA {c.mota:.3f}  IDF1 {c.idf1:.3f}  HOTA {h.hota:.3f}  FP {c.false_positives}  FN {c.misses}  "
            f"IDSW {c.switches}  (objects {c.objects})")


def _pooled(scores: list[dict]) -> dict:
    """Several captures' counts summed (the pooled scores are ratios of sums, as the harness pools them)."""
    mot = {k: sum(s["mot"][k] for s in scores) for k in scores[0]["mot"]}
    hota = {k: np.sum([s["hota"][k] for s in scores], axis=0).tolist() for k in HOTA_FIELDS}
    return {"mot": mot, "hota": hota}


def capture(args) -> int:
    from scenes import open_sequence

    seq = open_sequence(args.seq_dir)
    if seq.tracks is None:
        print(f"{args.seq_dir}: no tracks.csv: nothing to score a replay against", file=sys.stderr)
        return 2
    pipeline = pipeline_with(args.pipeline, args.set)
    table = registry.STAGES["tracking"]
    original = table["multi"]
    table["multi"] = _Recorder
    t0 = time.perf_counter()
    try:
        frames = [seq.frame(i) for i in range(len(seq))]
        gsd = seq.meta.get("gsd_m") if isinstance(getattr(seq, "meta", None), dict) else None
        *_, est = pipeline.run(frames, gsd_m_per_px=gsd)
    finally:
        table["multi"] = original
    rec = _Recorder.last
    if rec is None:
        print(f"{args.pipeline}: the pipeline has no multi-target tracker (tracking.multi is null)", file=sys.stderr)
        return 2
    own = _scores(est.tracks, seq)
    steps = [{"kind": k, "frame": f, "offset": off.tolist(), "has_image": img is not None}
             for k, f, _, off, img in rec.calls]
    arrays = {f"det{i}": np.asarray(d, np.float64).reshape(-1, len(Detection._fields))
              for i, (_, _, d, _, _) in enumerate(rec.calls)}
    arrays.update({f"img{i}": img for i, (_, _, _, _, img) in enumerate(rec.calls) if img is not None})
    meta = {"seq_dir": str(Path(args.seq_dir).resolve()), "pipeline": args.pipeline, "sets": args.set,
            "params": rec.given, "steps": steps, "frame_shape": list(est.frame_shape_px), "own": own}
    np.savez_compressed(args.out, meta=np.array(json.dumps(meta)), **arrays)
    print(f"{args.pipeline} on {args.seq_dir}: {len(steps)} tracker calls in {time.perf_counter() - t0:.0f} s; "
          f"the pipeline's own multi tracks: {_summary(own)}; wrote {args.out}")
    return 0


def _override(params: dict, sets: list[str]) -> dict:
    out = dict(params)
    for kv in sets:
        if "=" not in kv:
            raise SystemExit(f"--set: expected KEY=VALUE, got {kv!r}")
        key, value = kv.split("=", 1)
        key = key.removeprefix("tracking.multi.")
        if key not in MULTI_DEFAULTS:
            raise SystemExit(f"--set {kv}: {key!r} is not a key of the multi-target tracker")
        out[key] = parse_value(value)
    return out


def replay_one(path: str, sets: list[str], *, merges: bool = False, breakdown: bool = False) -> tuple[dict, dict]:
    """The tracker run again on one capture with ``sets``: (its scores, the capture's own)."""
    from scenes import open_sequence

    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        trk = MultiTargetTracker(**_override(meta["params"], sets))
        dets_of: dict[int, list] = {}
        for i, s in enumerate(meta["steps"]):
            img = z[f"img{i}"] if s["has_image"] else None
            if s["kind"] == "step":
                dets = [Detection(*row) for row in z[f"det{i}"]]
                dets_of[s["frame"]] = dets
                trk.step(s["frame"], dets, offset_px=s["offset"], image=img)
            else:
                trk.extrapolate(s["frame"], offset_px=s["offset"], image=img)
    seq = open_sequence(meta["seq_dir"])
    tracks = _tracks_frame(trk.rows(), tuple(meta["frame_shape"]))
    if merges:
        _print_merges(trk, seq)
    if breakdown:
        from benchmarks.tracking_quality import _print_breakdown, error_breakdown

        dets = [dets_of.get(f, []) for f in range(max(dets_of, default=-1) + 1)]
        fn, fp = error_breakdown(tracks[tracks["source"] == "multi"], dets, seq.tracks,
                                 frame_shape=tuple(meta["frame_shape"]))
        print(f"  misses by cause: {fn['cause'].value_counts().to_dict()}; false positives: {len(fp)} rows of "
              f"{fp['track_id'].nunique()} tracks")
        _print_breakdown(fn, fp)
    return _scores(tracks, seq), meta["own"]


def _print_merges(trk: MultiTargetTracker, seq) -> None:
    """Each join the tracker made, at the part's last frame: both tracks' boxes and the vehicle each lay on."""
    from harness.metrics.matching import box_iou

    raw = pd.DataFrame(trk._rows)  # before the offline joins: every track under its own id
    truth = seq.tracks[seq.tracks["visible"].astype(bool)]

    def on(tid: int, frame: int) -> str:
        r = raw[(raw["track_id"] == tid) & (raw["frame"] == frame)]
        t = truth[truth["frame"] == frame]
        b = r[BOX].to_numpy(np.float64)[:1]
        if not len(r) or not np.isfinite(b).all():
            return f"{tid} (no box)"
        iou = box_iou(b, t[BOX].to_numpy(np.float64))[0] if len(t) else np.zeros(0)
        k = int(np.argmax(iou)) if len(iou) else -1
        where = f"vehicle {int(t['vehicle_id'].iloc[k])} IoU {iou[k]:.2f}" if k >= 0 and iou[k] > 0 else "no vehicle"
        w, h = b[0, 2] - b[0, 0], b[0, 3] - b[0, 1]
        return f"{tid} ({w:.0f} x {h:.0f} px, on {where})"

    for part, whole in trk._merges:
        frame = int(raw.loc[raw["track_id"] == part, "frame"].max())
        print(f"  frame {frame}: track {on(part, frame)} joined into {on(whole, frame)}")


def replay(args) -> int:
    mine, own = [], []
    for path in args.captures:
        s, o = replay_one(path, args.set, merges=args.merges, breakdown=args.breakdown)
        mine.append(s)
        if "mot" not in o:  # written before the counts were kept whole: nothing to compare with
            o = None
        own.append(o)
        print(f"{path}: {_summary(s)}" + ("" if args.set or o is None else
                                          ("  (= the pipeline's)" if s == o else f"  (pipeline's: {_summary(o)})")))
    if len(mine) > 1:
        print(f"pooled: {_summary(_pooled(mine))}" + ("" if None in own else
                                                      f"   (as captured: {_summary(_pooled(own))})"))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture", help="run a pipeline on a sequence, keeping its tracker's inputs")
    c.add_argument("seq_dir")
    c.add_argument("--pipeline", default="dis")
    c.add_argument("--out", required=True)
    c.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="pipeline override")
    c.set_defaults(fn=capture)
    r = sub.add_parser("replay", help="run the tracker again on captures and score it")
    r.add_argument("captures", nargs="+")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a tracker key")
    r.add_argument("--merges", action="store_true", help="list the tracks joined into others")
    r.add_argument("--breakdown", action="store_true",
                   help="each vehicle's missed frames by cause and each false-positive track "
                        "(benchmarks/tracking_quality.py's breakdown)")
    r.set_defaults(fn=replay)
    args = ap.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
