"""Real footage into a sequence folder: the annotation parsers, decoding, range and scale, the cache key,
nothing written on a bad file (scenes.footage, scenes.formats)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from scenes import cached_sequence_result, open_sequence
from scenes.footage import (FootageSpec, export_frames, export_mot_gt, export_video, footage_hash, footage_key,
                            gt_labels_file, ingest_footage, list_frame_files, validate_footage)
from scenes.formats import FormatError, mot_label_class, read_mot_gt, read_mot_labels, read_yolo_boxes, write_flo
from harness.datasets import write_kitti_flow


def _texture(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    g = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 2.0)
    return (255 * (g - g.min()) / (g.max() - g.min())).astype(np.uint8)


def _frames_folder(folder: Path, n: int, *, h: int = 40, w: int = 64, names=None) -> list[np.ndarray]:
    folder.mkdir(parents=True, exist_ok=True)
    frames = [_texture(h, w, k) for k in range(n)]
    for k, img in enumerate(frames):
        name = names[k] if names else f"f{k}.png"
        cv2.imwrite(str(folder / name), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    return frames


# --------------------------------------------------------------------------- parsers


def test_mot_gt_columns_classes_and_ignored_rows(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("1,7,11,21,10,20,1,3,0.5\n"
                 "1,8,31,41,6,8,0,3,1\n"        # flag 0: ignored
                 "2,7,12.5,21,10,20,1,12,1\n"   # class 12 (reflection): ignored
                 "\n"
                 "2,9,1,1,4,4,1,5,1\n")
    df = read_mot_gt(p)
    assert df["frame"].tolist() == [1, 1, 2, 2] and df["id"].tolist() == [7, 8, 7, 9]
    assert df["ignore"].tolist() == [False, True, True, False]
    assert df.loc[0, "class"] == "car" and df.loc[3, "class"] == "motorbike"
    assert df.loc[0, "visible_fraction"] == 0.5 and df["line"].tolist() == [1, 2, 3, 5]
    # MOT15 (10 columns: 8-10 world coordinates) and 6 columns: class car, visibility 1
    p.write_text("3,1,5,5,2,2,1,-1,-1,-1\n4,1,5,5,2,2\n5,1,5,5,2,2,1,-1,-1\n")
    df = read_mot_gt(p)
    assert df["class"].tolist() == ["car"] * 3 and df["visible_fraction"].tolist() == [1.0] * 3


def test_mot_gt_ten_columns_carry_class_unless_they_are_mot15_world_coordinates(tmp_path):
    p = tmp_path / "gt.txt"
    # CVAT's "MOT 1.1" export and TrackEval: class and visibility in 8, 9; column 10 not read
    p.write_text("1,1,5,5,2,2,1,3,0.5,-1\n1,2,5,5,2,2,1,1,1,-1\n1,3,5,5,2,2,0,3,1,-1\n2,1,6,5,2,2,1,7,1,0\n")
    df = read_mot_gt(p)
    assert df["class"].tolist() == ["car", "pedestrian", "car", "pedestrian"]
    assert df["ignore"].tolist() == [False, False, True, False] and df.loc[0, "visible_fraction"] == 0.5
    # MOT15 3D: world coordinates (not integers) in 8-10: class car, visibility 1, nothing checked there
    p.write_text("1,1,5,5,2,2,1,12.5,3.25,0\n2,1,6,5,2,2,1,13,3.5,0\n")
    df = read_mot_gt(p)
    assert df["class"].tolist() == ["car", "car"] and df["visible_fraction"].tolist() == [1.0, 1.0]
    # a class outside MOT's table in a 10-column line is refused as in a 9-column one
    p.write_text("1,1,5,5,2,2,1,42,1,-1\n")
    with pytest.raises(FormatError, match=r"gt\.txt: line 1: class \(column 8\): expected -1 or 1\.\.13"):
        read_mot_gt(p)


def test_mot_gt_of_another_layout_is_refused_with_a_hint(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("1,1,5,5,2,2,1,4,0,1\n1,0,0,0,30,30,0,0,0,0\n")  # VisDrone-MOT: category 0, an ignored region
    with pytest.raises(FormatError, match=r"line 2: class \(column 8\).*got '0' \(a VisDrone-MOT file\? "
                                          r"--gt-format visdrone\)$"):
        read_mot_gt(p)
    p.write_text("1,1,5,5,2,2,1,1,1\n1,2,5,5,2,2,1,4,3\n")  # UAVDT: category 3 (bus) in column 9
    with pytest.raises(FormatError, match=r"line 2: visibility \(column 9\).*got '3' \(a UAVDT file\? "
                                          r"--gt-format uavdt\)$"):
        read_mot_gt(p)


def test_mot_gt_classes_named_by_a_labels_file(tmp_path):
    p = tmp_path / "gt.txt"
    # CVAT: class k is line k of labels.txt; "Cars" is car, "tractor" unknown (ignored), "person" a pedestrian
    p.write_text("1,1,5,5,2,2,1,1,1\n1,2,5,5,2,2,1,2,0.5\n1,3,5,5,2,2,1,3,1\n1,4,5,5,2,2,1,4,1,-1\n"
                 "1,5,5,5,2,2,0,1,1\n")
    df = read_mot_gt(p, labels=["Cars", "motor-cycle", "tractor", "person"])
    assert df["class"].tolist()[:2] == ["car", "motorbike"] and df.loc[3, "class"] == "pedestrian"
    assert df["ignore"].tolist() == [False, False, True, False, True]
    assert mot_label_class("Motorcycles") == (True, "motorbike") and mot_label_class("tractor") == (False, None)
    assert mot_label_class("Awning_Tricycle") == (True, "motorbike") and mot_label_class("reflection") == (True, None)
    with pytest.raises(FormatError, match=r"line 1: class \(column 8\): expected 1\.\.2, a line of labels\.txt "
                                          r"\(car, bus\), got '3'"):
        p.write_text("1,1,5,5,2,2,1,3,1\n")
        read_mot_gt(p, labels=["car", "bus"])
    lab = tmp_path / "labels.txt"
    lab.write_text("car\n\nbus\n")
    assert read_mot_labels(lab) == ["car", "bus"]
    for text, match in [("\n", r"labels\.txt: no label name"), ("car\nCar\n", r"labels\.txt: label 'Car' \(name 2\) given twice")]:
        lab.write_text(text)
        with pytest.raises(FormatError, match=match):
            read_mot_labels(lab)


def test_visdrone_and_uavdt_layouts(tmp_path):
    p = tmp_path / "v.txt"
    p.write_text("1,3,10,10,5,5,1,5,0,1\n1,0,0,0,30,30,0,0,0,0\n2,3,11,10,5,5,1,9,1,2\n")
    df = read_mot_gt(p, layout="visdrone")
    assert df["class"].tolist()[0::2] == ["van", "bus"] and df["ignore"].tolist() == [False, True, False]
    assert df["visible_fraction"].tolist()[0::2] == [0.75, 0.25]
    p.write_text("1,4,10,10,5,5,1,1,2\n1,5,30,10,5,5,3,4,3\n")
    df = read_mot_gt(p, layout="uavdt")
    assert df["class"].tolist() == ["truck", "bus"]
    assert df["visible_fraction"].tolist() == pytest.approx([1.0, 0.845 * 0.845])


@pytest.mark.parametrize("layout, text, match", [
    ("mot", "1,1,1,1,4,4,1,3,1\n1,2,1,1,4,4,1,3\n", r"gt\.txt: line 2: expected 6, 7, 9 or 10"),
    ("mot", "1,1,1,1,4,4,1,3,1\n2,x,1,1,4,4,1,3,1\n", r"gt\.txt: line 2: id \(column 2\): expected a number"),
    ("mot", "0,1,1,1,4,4,1,3,1\n", r"gt\.txt: line 1: frame \(column 1\): expected an integer >= 1"),
    ("mot", "1,1,1,1,0,4,1,3,1\n", r"gt\.txt: line 1: box size"),
    ("mot", "1,1,1,1,4,4,1,3,1\n\n1,1,9,9,4,4,1,3,1\n", r"gt\.txt: line 3: id 1 appears twice in frame 1 \(first on line 1\)"),
    ("mot", "1,1,1,1,4,4,1,42,1\n", r"gt\.txt: line 1: class \(column 8\)"),
    ("mot", "1,1,1,1,4,4,1,3,1.5\n", r"gt\.txt: line 1: visibility \(column 9\): expected 0..1"),
    ("mot", "1,1,1,1,4,nan,1,3,1\n", r"gt\.txt: line 1: bb_height \(column 6\): expected a finite number"),
    ("mot", "\n\n", r"gt\.txt: no annotation line"),
    ("visdrone", "1,1,1,1,4,4,1,12,0,0\n", r"gt\.txt: line 1: object_category \(column 8\): expected one of"),
    ("visdrone", "1,1,1,1,4,4,1,4,0\n", r"gt\.txt: line 1: expected 10 VisDrone-MOT columns"),
    ("uavdt", "1,1,1,1,4,4,1,5,1\n", r"gt\.txt: line 1: occlusion \(column 8\): expected one of \[1, 2, 3, 4\]"),
])
def test_mot_gt_bad_lines_name_file_and_line(tmp_path, layout, text, match):
    p = tmp_path / "gt.txt"
    p.write_text(text)
    with pytest.raises(FormatError, match=match):
        read_mot_gt(p, layout=layout)


def test_yolo_boxes_good_and_bad(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text("0 0.5 0.5 0.25 0.5\n\n3 0.1 0.9 0.05 0.1\n")
    b = read_yolo_boxes(p)
    assert b.shape == (2, 5) and b[1].tolist() == [3, 0.1, 0.9, 0.05, 0.1]
    p.write_text("")
    assert read_yolo_boxes(p).shape == (0, 5)
    for text, match in [("0 0.5 0.5 0.2\n", r"a\.txt: line 1: expected 5 YOLO fields"),
                        ("0 0.5 0.5 0.2 0.2\n1.5 0.5 0.5 0.2 0.2\n", r"a\.txt: line 2: class \(field 1\)"),
                        ("0 1.5 0.5 0.2 0.2\n", r"a\.txt: line 1: centre"),
                        ("0 0.5 0.5 0 0.2\n", r"a\.txt: line 1: size")]:
        p.write_text(text)
        with pytest.raises(FormatError, match=match):
            read_yolo_boxes(p)


# --------------------------------------------------------------------------- frames folders


def test_frames_sorted_naturally_range_scale_and_yolo_boxes(tmp_path):
    src = tmp_path / "clip"
    names = [f"f{k}.png" for k in range(12)]
    frames = _frames_folder(src, 12, names=names)
    assert [p.name for p in list_frame_files(src)][:3] == ["f0.png", "f1.png", "f2.png"]  # f10 after f9
    (src / "classes.txt").write_text("car\nminibus\n")
    # a box of frame 3 (the range's frame 1): edges [16, 32] x [10, 30] of the 64x40 source
    (src / "f3.txt").write_text(f"1 {24 / 64} {20 / 40} {16 / 64} {20 / 40}\n")
    spec = FootageSpec(name="clip", source=str(src), start=2, stop=10, scale=0.5)
    seq = open_sequence(ingest_footage(spec, tmp_path / "seq"))
    assert len(seq) == 8 and (seq.meta["width"], seq.meta["height"]) == (32, 20)
    assert seq.source == "real" and seq.meta["annotations"]["boxes"] == "yolo"
    assert seq.tracks is None and seq.camera is None and seq.spec is None and seq.pair_truth(0) is None
    assert not (seq.path / "tracks.csv").exists() and not (seq.path / "camera.csv").exists()
    expect = cv2.resize(frames[5], (32, 20), interpolation=cv2.INTER_AREA)
    assert np.array_equal(seq.frame(3), expect)  # source frame 5 is the range's frame 3
    b = seq.boxes
    assert len(b) == 1 and b.loc[0, "frame"] == 1 and b.loc[0, "class"] == "van"
    # edges scaled by 0.5: [8, 16] x [5, 15]; in pixel-centre coordinates [7.5, 15.5] x [4.5, 14.5] (pixels 8..15)
    assert [b.loc[0, c] for c in ("bbox_x0_px", "bbox_x1_px", "bbox_y0_px", "bbox_y1_px")] == pytest.approx(
        [7.5, 15.5, 4.5, 14.5])
    assert (b.loc[0, "x_px"], b.loc[0, "y_px"]) == pytest.approx((11.5, 9.5))


def test_mot_gt_range_scale_and_ids(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 6)
    gt = tmp_path / "gt.txt"
    # source frames 2..4 (1-based 3..5) are the range [2, 5); box left pixel 11 (1-based), 10 px wide
    gt.write_text("1,4,11,21,10,20,1,3,1\n3,4,11,21,10,20,1,3,0.75\n5,4,13,21,10,20,1,3,1\n"
                  "4,2,1,1,8,8,0,3,1\n")
    seq = open_sequence(ingest_footage(FootageSpec(name="c", source=str(src), start=2, stop=5, scale=2.0, gt=str(gt)),
                                       tmp_path / "seq"))
    t = seq.tracks
    assert t["frame"].tolist() == [0, 2] and t["vehicle_id"].tolist() == [4, 4]
    # edges [10, 20] x [20, 40] scaled by 2 -> [20, 40] x [40, 80]: pixels 20..39 x 40..79, in pixel-centre
    # coordinates [19.5, 39.5] x [39.5, 79.5]
    assert t.loc[0, ["bbox_x0_px", "bbox_x1_px", "bbox_y0_px", "bbox_y1_px"]].tolist() == [19.5, 39.5, 39.5, 79.5]
    assert t.loc[0, "x_px"] == 29.5 and t.loc[0, "visible_fraction"] == 0.75
    ign = seq.ignore_regions
    assert len(ign) == 1 and ign.loc[0, "frame"] == 1
    assert seq.meta["annotations"]["ids"] is True


def test_labels_file_beside_the_gt_names_its_classes_and_is_part_of_the_key(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 3)
    gt_dir = tmp_path / "gt"
    gt_dir.mkdir()
    gt = gt_dir / "gt.txt"
    gt.write_text("1,1,11,21,10,20,1,1,1\n1,2,31,21,10,20,1,2,1\n2,1,12,21,10,20,1,1,1\n")
    spec = FootageSpec(name="c", source=str(src), gt=str(gt))
    without = footage_hash(spec)
    seq = open_sequence(ingest_footage(spec, tmp_path / "mot"))
    assert seq.tracks["class"].tolist() == ["pedestrian", "pedestrian", "pedestrian"]  # MOT's table: 1, 2 persons
    (gt_dir / "labels.txt").write_text("truck\nbicycle\n")  # CVAT's MOT export: class k = line k
    assert gt_labels_file(spec) == gt_dir / "labels.txt" and footage_hash(spec) != without
    seq = open_sequence(ingest_footage(spec, tmp_path / "cvat"))
    assert seq.tracks["class"].tolist() == ["truck", "cyclist", "truck"]
    # read only beside a mot file
    assert gt_labels_file(FootageSpec(name="c", source=str(src), gt=str(gt), gt_format="visdrone")) is None


def test_gt_with_no_line_in_the_clips_frames_is_refused(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 4)
    gt = tmp_path / "gt.txt"
    gt.write_text("101,1,11,21,10,20,1,3,1\n140,1,12,21,10,20,1,3,1\n")  # another clip's, or frames 100.. of it
    spec = FootageSpec(name="c", source=str(src), gt=str(gt))
    with pytest.raises(FormatError, match=r"gt\.txt: no annotation in the clip's frames 1\.\.4 \(1-based\); the "
                                          r"file's frames run 101\.\.140"):
        validate_footage(spec)
    with pytest.raises(FormatError, match=r"no annotation in the clip's frames 1\.\.4"):
        ingest_footage(spec, tmp_path / "seq")
    assert not (tmp_path / "seq").exists()
    # a video: before decoding from the frame count its container states (MP4 does, Matroska not), and
    # from the frames decoded
    pytest.importorskip("av")
    frames = _frames_folder(tmp_path / "v", 4)
    vspec = FootageSpec(name="c", source=str(export_video(frames, tmp_path / "c.mp4")), gt=str(gt))
    with pytest.raises(FormatError, match=r"no annotation in the clip's frames 1\.\.4 \(1-based\)"):
        validate_footage(vspec)
    vspec = FootageSpec(name="c", source=str(export_video(frames, tmp_path / "c.mkv")), gt=str(gt))
    validate_footage(vspec)  # no frame count stated: the lines are checked, the range not yet
    with pytest.raises(FormatError, match=r"no annotation in the clip's frames 1\.\.4 \(1-based\)"):
        ingest_footage(vspec, tmp_path / "vseq")
    gt.write_text("3,1,11,21,10,20,1,3,1\n140,1,12,21,10,20,1,3,1\n")  # one line in range: read
    assert len(open_sequence(ingest_footage(vspec, tmp_path / "ok")).tracks) == 1


def test_flow_truth_for_some_pairs(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 4, h=8, w=10)
    flow_dir = tmp_path / "flow"
    flow_dir.mkdir()
    f = np.zeros((8, 10, 2), np.float32)
    f[..., 0], f[..., 1] = 1.5, -0.5
    write_flo(flow_dir / "000001.flo", f)
    valid = np.ones((8, 10), bool)
    valid[0] = False
    write_kitti_flow(flow_dir / "000002_10.png", f, valid)
    seq = open_sequence(ingest_footage(FootageSpec(name="c", source=str(src), scale=2.0, flow=str(flow_dir)),
                                       tmp_path / "seq"))
    assert seq.meta["annotations"]["flow_pairs"] == [1, 2]
    assert seq.pair_truth(0) is None and seq.has_pair_truth(1)
    t = seq.pair_truth(1)
    assert t.flow.shape == (16, 20, 2) and t.flow_camera is None and t.instances is None
    assert np.allclose(t.flow[..., 0], 3.0) and np.allclose(t.flow[..., 1], -1.0) and t.valid.all()
    t2 = seq.pair_truth(2)
    assert not t2.valid[:2].any() and t2.valid[2:].all() and np.isnan(t2.flow[:2]).all()


# --------------------------------------------------------------------------- video


def _write_mp4(path: Path, n: int, *, h: int = 48, w: int = 64) -> list[np.ndarray]:
    """A small H.264 (or MPEG-4 part 2) mp4 whose frame k has gray level 20 k + 30 (told apart after coding)."""
    import av

    frames = [np.full((h, w, 3), 20 * k + 30, np.uint8) for k in range(n)]
    codec = "libx264" if "libx264" in av.codecs_available else "mpeg4"
    with av.open(str(path), "w") as c:
        s = c.add_stream(codec, rate=12)
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        for img in frames:
            for pkt in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)
    return frames


def test_mp4_decode_range_scale_and_fps(tmp_path):
    pytest.importorskip("av")
    video = tmp_path / "clip.mp4"
    _write_mp4(video, 8)
    seq = open_sequence(ingest_footage(FootageSpec(name="v", source=str(video), start=2, stop=6, scale=0.5),
                                       tmp_path / "seq"))
    assert len(seq) == 4 and (seq.meta["width"], seq.meta["height"]) == (32, 24)
    assert seq.meta["fps"] == pytest.approx(12.0)
    for i in range(4):  # frame i of the range is source frame i + 2
        assert abs(float(seq.frame(i).mean()) - (20 * (i + 2) + 30)) < 3
    with pytest.raises(FormatError, match=r"clip\.mp4: stop 12: the video has 8 frames"):
        ingest_footage(FootageSpec(name="v", source=str(video), stop=12), tmp_path / "seq2")
    assert not (tmp_path / "seq2").exists()
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all" * 10)
    with pytest.raises(FormatError, match=r"bad\.mp4: not a readable video"):
        validate_footage(FootageSpec(name="b", source=str(bad)))


@pytest.mark.parametrize("name", ["v.mkv", "v.avi", "v.mp4"])
def test_lossless_video_export_reads_back_bit_for_bit(tmp_path, name):
    pytest.importorskip("av")
    frames = [_texture(24, 40, k) for k in range(3)]
    video = export_video(frames, tmp_path / name, fps=10)
    seq = open_sequence(ingest_footage(FootageSpec(name="v", source=str(video)), tmp_path / "seq"))
    assert len(seq) == 3 and all(np.array_equal(seq.frame(k), frames[k]) for k in range(3))
    with pytest.raises(ValueError, match="codec: expected one of ffv1, libx264rgb"):
        export_video(frames, tmp_path / "x.mp4", codec="libx264")


# --------------------------------------------------------------------------- cache


def test_cache_key_follows_the_bytes_and_the_options(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 3)
    (src / "f1.txt").write_text("0 0.5 0.5 0.1 0.1\n")
    spec = FootageSpec(name="c", source=str(src))
    h0 = footage_hash(spec)
    assert footage_hash(spec) == h0
    assert footage_hash(FootageSpec(name="c", source=str(src), scale=0.5)) != h0
    assert footage_hash(FootageSpec(name="c", source=str(src), stop=2)) != h0
    (src / "f1.txt").write_text("0 0.5 0.5 0.1 0.2\n")  # one label changed: another entry
    h1 = footage_hash(spec)
    assert h1 != h0
    img = cv2.imread(str(src / "f2.png"))
    img[0, 0] ^= 1
    cv2.imwrite(str(src / "f2.png"), img)
    assert footage_hash(spec) not in (h0, h1)
    r1 = cached_sequence_result(spec, tmp_path / "cache")
    r2 = cached_sequence_result(spec, tmp_path / "cache")
    assert r1.rendered and not r2.rendered and r1.path == r2.path and r1.key == footage_key(spec)


def test_a_bad_file_writes_nothing(tmp_path):
    src = tmp_path / "clip"
    _frames_folder(src, 3)
    gt = tmp_path / "gt.txt"
    gt.write_text("1,1,1,1,4,4,1,3,1\n2,1,1,1,-4,4,1,3,1\n")
    spec = FootageSpec(name="c", source=str(src), gt=str(gt))
    cache = tmp_path / "cache"
    with pytest.raises(FormatError, match=r"gt\.txt: line 2: box size"):
        cached_sequence_result(spec, cache)
    assert not cache.exists() or not any(cache.iterdir())
    (src / "f2.png").write_bytes(b"\x89PNG broken")
    gt.write_text("1,1,1,1,4,4,1,3,1\n")
    with pytest.raises(FormatError, match=r"f2\.png: not a readable image"):
        cached_sequence_result(spec, cache)
    assert not any(cache.iterdir())
    with pytest.raises(FormatError, match=r"f2\.png: not a readable image"):
        ingest_footage(spec, tmp_path / "seq")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "clip", "gt.txt"]  # no seq, no partial


def test_export_mot_gt_reads_back_the_same_boxes(tmp_path, tiny_sequence):
    seq = open_sequence(tiny_sequence[1])
    gt = export_mot_gt(seq.tracks, tmp_path / "gt" / "gt.txt")
    img1 = export_frames(seq, tmp_path / "img1")
    real = open_sequence(ingest_footage(FootageSpec(name="t", source=str(img1), gt=str(gt)), tmp_path / "seq"))
    truth = seq.tracks[seq.tracks["visible"] == 1].reset_index(drop=True)
    ids = ["frame", "vehicle_id"]
    assert real.tracks[ids].equals(truth[ids].astype(real.tracks[ids].dtypes.to_dict()))
    # gt.txt stores x0 + 1 with every digit, read back minus 1: the two roundings leave an ulp or so
    boxes = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]
    np.testing.assert_allclose(real.tracks[boxes].to_numpy(), truth[boxes].to_numpy(), rtol=0, atol=1e-9)
    assert all(np.array_equal(real.frame(i), seq.frame(i)) for i in range(len(seq)))


def test_export_mot_gt_leaves_parked_vehicles_out_and_keeps_the_classes(tmp_path):
    # the synthetic path counts the vehicles that move (harness.metrics.objects): so does the exported truth
    box = dict(bbox_x0_px=10.0, bbox_y0_px=20.0, bbox_x1_px=29.0, bbox_y1_px=29.0, x_px=19.5, y_px=24.5)
    tracks = pd.DataFrame([dict(frame=0, vehicle_id=1, visible=1, parked=0, **{"class": "bus"}, **box),
                           dict(frame=0, vehicle_id=2, visible=1, parked=1, **{"class": "car"}, **box),
                           dict(frame=0, vehicle_id=3, visible=1, parked=0, **{"class": "pedestrian"}, **box),
                           dict(frame=0, vehicle_id=4, visible=0, parked=0, **{"class": "car"}, **box)])
    gt = read_mot_gt(export_mot_gt(tracks, tmp_path / "gt.txt"))
    assert gt["id"].tolist() == [1, 3]
    assert gt["class"].tolist() == ["car", "pedestrian"]  # MOTChallenge's class 3 is every car-like vehicle
    # with the synthetic path's own rules (the CLI passes harness.metrics.objects'): counted rows and
    # distractors written, a distractor vehicle (here the bus, as if it stood still all clip) ignored
    counted, distractors = np.array([0, 0, 0, 0], bool), np.array([1, 0, 1, 0], bool)
    gt = read_mot_gt(export_mot_gt(tracks, tmp_path / "gt2.txt", counted=counted, distractors=distractors))
    assert gt["id"].tolist() == [1, 3] and gt["ignore"].tolist() == [True, False]
    assert gt["class"].tolist() == ["car", "pedestrian"]
    gt = read_mot_gt(export_mot_gt(tracks, tmp_path / "gt3.txt", counted=np.array([1, 1, 0, 0], bool),
                                   distractors=np.array([0, 0, 1, 0], bool)))
    assert gt["id"].tolist() == [1, 2, 3] and not gt["ignore"].any()
    with pytest.raises(ValueError, match=r"counted, distractors: expected 4 flags each"):
        export_mot_gt(tracks, tmp_path / "gt4.txt", counted=counted[:2], distractors=distractors[:2])
    # a distractor of low visibility (here the bus, as if mostly outside the image) is written with flag 0 and its
    # visibility: a real gt.txt's flags say what counts (MOTChallenge), its visibility is not cut on
    low = tracks.assign(visible_fraction=[0.3, 1.0, 1.0, 0.0])
    gt = read_mot_gt(export_mot_gt(low, tmp_path / "gt5.txt", counted=counted, distractors=distractors))
    assert gt["id"].tolist() == [1, 3] and gt["ignore"].tolist() == [True, False]
    assert gt["visible_fraction"].tolist() == [0.3, 1.0]
