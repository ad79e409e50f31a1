"""tracks.csv as an annotator boxes a frame: the box clipped to the image, the visible fraction counted in it."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from scenes.ground_truth import GroundTruth, canvas_in_image, clip_box_to_image
from scenes.world import Box

W, H = 160, 120
K = np.array([[100.0, 0.0, 79.5], [0.0, 100.0, 59.5], [0.0, 0.0, 1.0]])
# nadir camera 50 m up: camera x = world x, camera y = world -y, looking down world -z (camera-to-world columns)
R_NADIR = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
C_NADIR = np.array([0.0, 0.0, 50.0])
CAR = [Box(centre=(0.0, 0.0, 0.75), size=(4.0, 2.0, 1.5))]


def _at(x_px: float, y_px: float) -> np.ndarray:
    """Vehicle-to-world matrix of a car whose centre (0.75 m above the ground) projects to (x_px, y_px)."""
    M = np.eye(4)
    depth_m = C_NADIR[2] - CAR[0].centre[2]
    M[0, 3] = (x_px - K[0, 2]) / K[0, 0] * depth_m
    M[1, 3] = -(y_px - K[1, 2]) / K[1, 1] * depth_m
    return M


def test_clip_box_to_image_keeps_a_box_inside_and_cuts_one_at_the_border():
    assert clip_box_to_image((10.0, 20.0, 30.5, 40.25), W, H) == (10.0, 20.0, 30.5, 40.25)
    # the image covers [-0.5, W - 0.5] x [-0.5, H - 0.5] (pixel centres at integers)
    assert clip_box_to_image((-12.0, 100.0, 8.0, 130.0), W, H) == (-0.5, 100.0, 8.0, H - 0.5)
    assert clip_box_to_image((150.0, -3.0, 170.0, 5.0), W, H) == (150.0, -0.5, W - 0.5, 5.0)
    # wholly outside, or no box (behind the camera): no box in the image
    assert np.isnan(clip_box_to_image((-30.0, 10.0, -1.0, 20.0), W, H)).all()
    assert np.isnan(clip_box_to_image((np.nan,) * 4, W, H)).all()


def test_a_car_half_outside_the_image_shows_about_half_of_itself_and_one_inside_all_of_itself():
    gt = GroundTruth(K, W, H, [CAR, CAR])
    Ms = [_at(-0.5, 60.0), _at(80.0, 60.0)]  # car 1 centred on the left border, car 2 in the middle
    boxes = gt.vehicle_bboxes(R_NADIR, C_NADIR, Ms)
    (b1, c1), (b2, _) = boxes
    assert b1[0] < -0.5 < b1[2] and c1[0] == pytest.approx(-0.5)
    # nothing rendered in front (depth 0 everywhere): the image border is all that hides a car
    vis = gt.visible_fractions(np.zeros((H, W), np.float32), R_NADIR, C_NADIR, Ms, boxes)
    # its sides lean outwards in a nadir view, so the half towards the image centre shows a little more
    assert vis[0] == pytest.approx(0.5, abs=0.06)
    assert vis[1] == 1.0
    clipped = clip_box_to_image(b1, W, H)
    assert clipped[0] == -0.5 and clipped[1:] == pytest.approx(b1[1:])
    assert clip_box_to_image(b2, W, H) == pytest.approx(b2)
    # an in-view mask (a lens's canvas) counts only its pixels: the left half of the image out of view
    in_view = np.ones((H, W), bool)
    in_view[:, :80] = False
    vis = gt.visible_fractions(np.zeros((H, W), np.float32), R_NADIR, C_NADIR, Ms, boxes, in_view=in_view)
    assert vis[0] == 0.0 and vis[1] == pytest.approx(0.5, abs=0.06)
    with pytest.raises(ValueError, match=r"in_view: expected shape \(120, 160\), got \(120, 80\)"):
        gt.visible_fractions(np.zeros((H, W), np.float32), R_NADIR, C_NADIR, Ms, boxes, in_view=in_view[:, :80])


def test_the_canvas_of_a_lens_is_in_the_image_where_the_lens_maps_it_there():
    from scenes.sensor import LensGeometry

    lens = LensGeometry.build(K, W, H, k1=-0.08, k2=0.01)
    mask = canvas_in_image(lens, W, H)
    cw, ch = lens.canvas_size_px
    assert mask.shape == (ch, cw) and (cw, ch) != (W, H)
    # the canvas reaches beyond the image (its border is out of view); a barrel lens (k1 < 0) squeezes the
    # periphery, so the image sees more than W x H undistorted pixels (here 12 % more), not the whole canvas
    assert not mask[0].any() and not mask[-1].any() and not mask[:, 0].any() and not mask[:, -1].any()
    assert W * H < mask.sum() < 1.2 * W * H < mask.size
    # where each output pixel looks on the canvas (its nearest canvas pixel) is in view, away from the border
    cx, cy = np.rint(lens.canvas_x[2:-2, 2:-2]).astype(int), np.rint(lens.canvas_y[2:-2, 2:-2]).astype(int)
    assert mask[cy, cx].all()


def _tracks(overrides: dict) -> tuple[pd.DataFrame, object]:
    from scenes import load_scene_spec
    from scenes.generate import SceneGenerator

    gen = SceneGenerator(load_scene_spec("tiny", {"image.n_frames": 12, **overrides}))
    for _ in gen.frames():
        pass
    return pd.DataFrame(gen.track_table()), gen


@pytest.mark.gl
def test_tracks_csv_boxes_are_the_projected_boxes_clipped_to_the_image():
    # tiny (seed 7) over 12 frames: vehicle 1 leaves through the bottom border in frames 8-10
    t, gen = _tracks({})
    cut = 0
    for i in range(gen.spec.image.n_frames):
        ts = float(gen.path.t_s[i])
        R, C = gen.pose_at(ts)
        for vid, (box, centre) in enumerate(gen.truth.vehicle_bboxes(R, C, gen.vehicle_matrices(ts)), start=1):
            row = t[(t["frame"] == i) & (t["vehicle_id"] == vid)].iloc[0]
            got = row[["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]].to_numpy(np.float64)
            np.testing.assert_array_equal(got, clip_box_to_image(box, W, H))
            assert (row["x_px"], row["y_px"]) == centre  # the position stays the whole vehicle's projected centre
            if row["visible"] and not np.array_equal(got, box):
                cut += 1
                # the share it shows is about the share of its box in the image (a car along the motion fills it)
                share = (got[2] - got[0]) * (got[3] - got[1]) / ((box[2] - box[0]) * (box[3] - box[1]))
                assert row["visible_fraction"] == pytest.approx(share, abs=0.1)
    assert cut >= 3
    v = t[t["visible"] == 1]
    assert ((v["bbox_x0_px"] >= -0.5) & (v["bbox_y0_px"] >= -0.5) & (v["bbox_x1_px"] <= W - 0.5)
            & (v["bbox_y1_px"] <= H - 0.5)).all()
    assert ((t["visible"] == 0) == (t["visible_fraction"] == 0)).all()


@pytest.mark.gl
def test_under_a_lens_the_visible_fraction_counts_the_image_not_the_canvas():
    # the canvas of a barrel lens reaches beyond the image: a car whose centre has left the image shows under
    # about half of itself, though all of it may still lie on the canvas
    t, _ = _tracks({"sensor.lens.k1": -0.08})
    v = t[t["visible"] == 1]
    out = (v["x_px"] < -0.5) | (v["x_px"] > W - 0.5) | (v["y_px"] < -0.5) | (v["y_px"] > H - 0.5)
    assert out.sum() >= 1
    assert (v.loc[out, "visible_fraction"] < 0.6).all()
    inside = ((v["bbox_x0_px"] > 2) & (v["bbox_y0_px"] > 2) & (v["bbox_x1_px"] < W - 3) & (v["bbox_y1_px"] < H - 3))
    assert inside.sum() >= 10 and (v.loc[inside, "visible_fraction"] > 0.9).all()
    assert ((v["bbox_x0_px"] >= -0.5) & (v["bbox_y1_px"] <= H - 0.5)).all()


def test_motchallenge_boxes_are_edges_from_pixel_1_and_ours_are_centred_on_pixels():
    from scenes.formats import box_of_mot, mot_box

    # a box over pixels 3..12 (0-based) is [2.5, 12.5] here, 10 px wide; MOTChallenge numbers that pixel 4 and puts
    # bb_left on its left edge: 4, width 10
    assert mot_box(2.5, 7.5, 12.5, 9.5) == (4.0, 9.0, 10.0, 2.0)
    assert box_of_mot(4.0, 9.0, 10.0, 2.0) == (2.5, 7.5, 12.5, 9.5)
    x = np.array([0.25, -0.5, 100.125])
    np.testing.assert_array_equal(box_of_mot(*mot_box(x, x + 1, x + 20, x + 3)), (x, x + 1, x + 20, x + 3))
