"""Real footage through suites, the runner and ``aerobench eval-video``: absent truths give no rows,
bad files exit 2 writing nothing, and a rendered sequence read back as footage scores the same."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml

from harness.cli import main
from harness.suites import RealEntry, SuiteError, expand, load_suite, parse_suite

ROOT = Path(__file__).resolve().parents[2]
KIT_AIS = ROOT.parent / "shared" / "external" / "kit_ais"

# metrics that count (equal after the round trip) and that measure a distance to the truth's centre
COUNTS = ("mota", "idf1", "mot_misses", "mot_false_positives", "id_switches", "track_completeness")
DISTANCES = ("motp", "track_error", "track_raw_error", "track_pred_error", "track_ate_rmse", "track_fde")


def _frames(folder: Path, n: int = 4) -> Path:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(3)
    for k in range(n):
        img = cv2.GaussianBlur((rng.random((32, 48)) * 255).astype(np.uint8), (0, 0), 1.5)
        cv2.imwrite(str(folder / f"{k}.png"), img)
    return folder


def test_real_scene_paths_start_at_the_suite_file(tmp_path):
    _frames(tmp_path / "data" / "clip")
    (tmp_path / "data" / "gt.txt").write_text("1,1,5,5,6,6,1,3,1\n2,1,6,5,6,6,1,3,1\n")
    path = tmp_path / "suites" / "s.yaml"
    path.parent.mkdir()
    path.write_text(yaml.safe_dump({"name": "r", "seeds": [1, 2], "pipelines": ["thesis-lk"], "scenes": [
        {"real": "../data/clip", "gt": "../data/gt.txt", "frames": 3, "start": 1, "scale": 0.5}]}))
    suite = load_suite(path)
    entry = suite.scenes[0]
    assert isinstance(entry, RealEntry) and entry.real == str(tmp_path / "data" / "clip")
    cells = expand(suite, source=str(path))
    assert len(cells) == 1  # one variant whatever the seeds: seed 0
    spec = cells[0].variant.spec
    assert (cells[0].variant.seed, cells[0].variant.label, spec.start, spec.stop) == (0, "clip", 1, 4)
    assert spec.gt == str(tmp_path / "data" / "gt.txt")


@pytest.mark.parametrize("scene, match", [
    ({"real": "nowhere.mp4"}, r"scenes\[0\] \(nowhere\): .*nowhere\.mp4: no such video"),
    ({"real": "clip", "stop": 3, "frames": 2}, r"scenes\[0\]: give stop or frames, not both"),
    ({"real": "clip", "gt": "gt.txt", "gt_format": "kitti"}, r"scenes\[0\]\.gt_format"),
    ({"real": "clip", "gt": "gt.txt"}, r"gt\.txt: line 2: id \(column 2\): expected a number"),
    ({"real": "clip", "stop": 9}, r"clip: stop 9: the folder holds 4 frames"),
    ({"real": "clip"}, r"clip/1\.txt: line 2: expected 5 YOLO fields"),
])
def test_bad_real_scenes_are_refused_naming_field_file_and_line(tmp_path, scene, match):
    _frames(tmp_path / "clip")
    (tmp_path / "clip" / "1.txt").write_text("0 0.5 0.5 0.1 0.1\n0 0.5 0.5 0.1\n")  # a YOLO label, bad line 2
    (tmp_path / "gt.txt").write_text("1,1,5,5,6,6,1,3,1\n2,one,6,5,6,6,1,3,1\n")
    with pytest.raises(SuiteError, match=match):
        expand(parse_suite({"name": "r", "seeds": [1], "pipelines": ["dis"], "scenes": [scene]},
                           base_dir=tmp_path))


def test_eval_video_bad_gt_exits_2_and_writes_nothing(tmp_path, capsys, render_cache):
    clip = _frames(tmp_path / "clip")
    gt = tmp_path / "gt.txt"
    gt.write_text("1,1,5,5,6,6,1,3,1\n1,1,6,5,6,6,1,3,1\n")
    out = tmp_path / "run"
    assert main(["eval-video", str(clip), "--gt", str(gt), "--pipelines", "dis", "--out", str(out),
                 "--cache", str(render_cache), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gt.txt: line 2: id 1 appears twice in frame 1" in err[0]
    assert not out.exists()
    assert main(["eval-video", str(clip), "--frames", "2", "--out", str(out)]) == 2
    assert "--frames" in capsys.readouterr().err and not out.exists()
    assert main(["eval-video", str(clip), "--gt", str(tmp_path), "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().endswith("a folder; expected the ground-truth file (gt.txt)")
    gt.write_text("0,1,5,5,6,6,1,3,1\n")  # 0-based frames
    assert main(["eval-video", str(clip), "--gt", str(gt), "--pipelines", "dis", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("line 1: frame (column 1): expected an integer >= 1, got '0' (the "
                                             "formats number frames from 1)")
    assert not out.exists()


def test_eval_video_says_what_the_truth_holds_and_warns_when_nothing_is_counted(tmp_path, capsys, render_cache):
    clip = _frames(tmp_path / "clip")
    gt_dir = tmp_path / "gt"
    gt_dir.mkdir()
    gt = gt_dir / "gt.txt"
    # class 1 of MOT's table: pedestrians, distractors of a vehicle benchmark; frame 9 lies outside the clip
    gt.write_text("1,1,5,5,6,6,1,1,1\n2,1,6,5,6,6,1,1,1\n2,2,20,5,6,6,0,1,1\n9,1,6,5,6,6,1,1,1\n")
    args = ["eval-video", str(clip), "--gt", str(gt), "--pipelines", "dis", "--cache", str(render_cache),
            "--no-report", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "a")]) in (0, 1)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == ("truth: gt.txt (mot): 3 rows in frames 1..2, 2 ids: 0 counted vehicles (none), "
                      "2 distractors (pedestrian 2), 1 ignored; 1 rows outside the clip's frames 1..4 left out")
    assert err[1].startswith("aerobench: warning: no row of the ground truth is a counted vehicle")
    # the same file exported by CVAT names its classes in labels.txt: class 1 is its first line
    (gt_dir / "labels.txt").write_text("Car\nforklift\n")
    assert main([*args, "--out", str(tmp_path / "b")]) in (0, 1)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == ("truth: gt.txt (mot): 3 rows in frames 1..2, 2 ids: 2 counted vehicles (car 2), "
                      "0 distractors, 1 ignored; 1 rows outside the clip's frames 1..4 left out; classes named "
                      "by labels.txt (Car, forklift), not known and ignored: forklift")
    assert not any("warning" in line for line in err)


@pytest.mark.skipif(not (KIT_AIS / "MOS74-93").is_dir(), reason="../shared/external/kit_ais is not beside the clone")
def test_kit_ais_suite_files_resolve():
    suite = load_suite(ROOT / "benchmarks" / "suites" / "kit-ais.yaml")
    assert [Path(s.real).name for s in suite.scenes] == ["MOS74-93", "MOS155-179", "MunichStreet02-MOS74-93"]
    assert all(Path(s.real).is_dir() for s in suite.scenes)
    # the synthetic scenes beside the same three clips, for the report's 'Synthetic vs real'
    mixed = load_suite(ROOT / "benchmarks" / "suites" / "synthetic-vs-real.yaml")
    real = [s for s in mixed.scenes if getattr(s, "real", None)]
    assert [Path(s.real).name for s in real] == ["MOS74-93", "MOS155-179", "MunichStreet02-MOS74-93"]
    assert len(mixed.scenes) - len(real) == 2  # realistic and city


def _aggregate(table: pd.DataFrame) -> pd.DataFrame:
    from harness.metrics import aggregate

    return aggregate(table[table["kind"] == "accuracy"], by=["pipeline"]).set_index(["metric", "region", "motion"])


def test_round_trip_rendered_sequence_as_footage_scores_the_same(tmp_path, render_cache, capsys):
    """tiny, rendered, exported as a lossless video and MOTChallenge gt.txt, then run by eval-video."""
    from harness.cell_artifacts import read_tracks
    from harness.runner import run_suite
    from scenes import cached_sequence, load_scene_spec, open_sequence
    from scenes.footage import export_mot_gt, export_video

    pytest.importorskip("av")
    spec = load_scene_spec("tiny", overrides={"seed": 1})
    seq = open_sequence(cached_sequence(spec, render_cache))
    from harness.metrics.objects import counted_objects, distractor_objects

    video = export_video(seq, tmp_path / "tiny.mkv", fps=seq.meta["fps"])
    # as `aerobench export` writes it: the synthetic path's counted objects and distractors
    gt = export_mot_gt(seq.tracks, tmp_path / "gt" / "gt.txt", counted=counted_objects(seq.tracks),
                       distractors=distractor_objects(seq.tracks))

    synthetic = run_suite(parse_suite({"name": "rt", "scenes": [{"preset": "tiny"}], "seeds": [1],
                                       "pipelines": ["dis"]}),
                          tmp_path / "synthetic", workers=1, cache_dir=render_cache, progress=False)
    assert synthetic.ok
    out = tmp_path / "real"
    assert main(["eval-video", str(video), "--gt", str(gt), "--pipelines", "dis", "--out", str(out),
                 "--cache", str(render_cache), "--workers", "1", "--quiet"]) == 0
    assert (out / "report.html").is_file() and (out / "report.md").is_file()
    from harness.run_folder import read_run

    assert read_run(out).real_scenes == ["tiny"] and read_run(tmp_path / "synthetic").real_scenes == []
    real_table = pd.read_parquet(out / "results.parquet")
    assert set(real_table["status"]) == {"ok"}

    # truths the footage has not: no row at all (never a zero)
    absent = {"epe_mean", "ae_mean", "coverage", "shift_error", "jitter_residual_rms", "stab_distortion",
              "stab_cropping_ratio"}
    assert not absent & set(real_table["metric"])
    assert absent <= set(synthetic.table["metric"])

    a, b = _aggregate(synthetic.table), _aggregate(real_table)
    tracked = [k for k in a.index if k[0] in COUNTS + DISTANCES]
    assert {k[1] for k in tracked} == {"point", "multi"} and set(tracked) == {k for k in b.index if k[0] in COUNTS + DISTANCES}
    # a real reading takes the box centre as the vehicle's position: distances move by at most that offset
    t = seq.tracks[seq.tracks["visible"] == 1]
    offset = float(np.hypot((t["bbox_x0_px"] + t["bbox_x1_px"]) / 2 - t["x_px"],
                            (t["bbox_y0_px"] + t["bbox_y1_px"]) / 2 - t["y_px"]).max())
    assert 0 < offset < 1.5
    for k in tracked:
        va, vb = a.loc[k, "value"], b.loc[k, "value"]
        if k[0] in COUNTS:
            assert va == pytest.approx(vb, abs=1e-12), k
        elif np.isnan(va) or np.isnan(vb):  # a distance over no matched pair: undefined on both readings
            assert np.isnan(va) and np.isnan(vb), (k, va, vb)
        else:
            assert abs(va - vb) <= offset, (k, va, vb)

    # the pipeline saw the same frames: the multi-target tracker's tracks are the same numbers
    def multi(run_dir: Path) -> pd.DataFrame:
        (cell,) = [p for p in (run_dir / "cells").iterdir() if p.is_dir()]
        tr = read_tracks(cell)
        return tr[tr["source"] == "multi"][["frame", "track_id", "x_filt_px", "y_filt_px"]].reset_index(drop=True)

    pd.testing.assert_frame_equal(multi(tmp_path / "synthetic"), multi(out))


def test_export_writes_mot_files_and_a_lossless_video(tmp_path, render_cache, capsys):
    from scenes import cached_sequence, load_scene_spec, open_sequence
    from scenes.formats import read_mot_gt

    pytest.importorskip("av")
    seq_dir = cached_sequence(load_scene_spec("tiny", overrides={"seed": 1}), render_cache)
    seq = open_sequence(seq_dir)
    out = tmp_path / "mot"
    assert main(["export", str(seq_dir), "--out", str(out), "--video", "tiny.mkv"]) == 0
    assert sorted(p.name for p in (out / "img1").iterdir())[:2] == ["000001.png", "000002.png"]
    gt = read_mot_gt(out / "gt" / "gt.txt")
    visible = seq.tracks[seq.tracks["visible"] == 1]
    assert len(gt) == len(visible) and gt["frame"].min() == 1 and not gt["ignore"].any()
    assert (out / "tiny.mkv").stat().st_size > 0
    capsys.readouterr()
    assert main(["export", str(seq_dir), "--out", str(out)]) == 2  # not empty: refused
    assert "not an empty folder" in capsys.readouterr().err


def test_detections_on_footage_with_boxes_but_no_ids_are_scored_against_every_labelled_vehicle():
    """YOLO-labelled footage (boxes.csv, no tracks.csv): precision and recall over every vehicle (region all)."""
    import types

    from algorithms.tracking import Detection
    from harness.cell_scoring import _detection_truth
    from harness.metrics.detection import detection_rows

    boxes = pd.DataFrame({"frame": [0, 0, 1], "class": ["car", "bus", "car"], "x_px": [15.0, 60.0, 15.0],
                          "y_px": [15.0, 60.0, 15.0], "bbox_x0_px": [10.0, 50.0, 10.0],
                          "bbox_y0_px": [10.0, 50.0, 10.0], "bbox_x1_px": [20.0, 70.0, 20.0],
                          "bbox_y1_px": [20.0, 70.0, 20.0]})
    truth = _detection_truth(types.SimpleNamespace(tracks=None, boxes=boxes))
    assert truth["visible"].tolist() == [1, 1, 1]
    frame0 = truth[truth["frame"] == 0]
    dets = [Detection(15.0, 15.0, 121.0, 10.0, 10.0, 20.0, 20.0), Detection(200.0, 200.0, 9.0, 199, 199, 201, 201)]
    rows = {r["metric"]: r for r in detection_rows(dets, frame0, frame=0)}
    assert rows["det_precision"]["region"] == "all"
    assert (rows["det_precision"]["sum"], rows["det_precision"]["count"]) == (1, 2)
    assert (rows["det_recall"]["sum"], rows["det_recall"]["count"]) == (1, 2)
    assert _detection_truth(types.SimpleNamespace(tracks=None, boxes=None)) is None
