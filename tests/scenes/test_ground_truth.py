"""Ground truth against the images and against independent geometry."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.flow import as_gray, warp_backward
from scenes import load_scene_spec, open_sequence, render_sequence
from scenes.generate import SceneGenerator

pytestmark = pytest.mark.gl

NO_JITTER = {f"camera.jitter.{k}": 0.0 for k in
             ("roll_std_deg", "pitch_std_deg", "yaw_std_deg", "x_std_m", "y_std_m", "z_std_m")}


def test_warping_next_frame_by_true_flow_reproduces_frame(tmp_path):
    # flat shading and no noise: brightness constancy holds, so I1(x + u) ~ I0(x) on valid pixels.
    # At 30 m the tiny camera has the nominal GSD (0.22 m/px); what remains is the bilinear
    # interpolation of textured content by warp_backward, well under 2 gray levels. Vehicle
    # shadows are off: a shadow moving over static ground breaks brightness constancy by design
    # (truth is the motion field; tests/scenes/test_world_truth.py covers the shadowed world).
    spec = load_scene_spec("tiny", overrides={"camera.altitude_m": 30.0, "light.shadows": False})
    seq = open_sequence(render_sequence(spec, tmp_path / "seq"))
    for i in range(len(seq) - 1):
        truth = seq.pair_truth(i)
        f0, f1 = as_gray(seq.frame(i)), as_gray(seq.frame(i + 1))
        warped, _ = warp_backward(f1, truth.flow)
        v = truth.valid
        assert v.mean() > 0.9
        err_true = np.abs(warped - f0)[v].mean()
        err_zero = np.abs(f1 - f0)[v].mean()
        assert err_zero > 5.0  # the frames really move (the ground is calmer than a test pattern)
        assert err_true < 0.12 * err_zero, (i, err_true, err_zero)
        assert err_true < 2.0, (i, err_true)


def _quat_to_R(qw, qx, qy, qz):
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def _ground_homography(row) -> np.ndarray:
    """Image of the plane z = 0: x ~ K R^T (X - C) = K R^T [e1 e2 -C] (X, Y, 1)."""
    K = np.array([[row.fx_px, 0, row.cx_px], [0, row.fy_px, row.cy_px], [0, 0, 1]])
    R = _quat_to_R(row.qw, row.qx, row.qy, row.qz)
    C = np.array([row.x_m, row.y_m, row.z_m])
    return K @ R.T @ np.column_stack([[1, 0, 0], [0, 1, 0], -C])


def test_flat_world_flow_equals_plane_homography_from_saved_poses(tmp_path):
    # oblique, drifting, jittering camera over a world without vehicles or buildings
    overrides = {"vehicles.count": 0, "world.trees.density_per_ha": 0.0, "world.trees.wood_density_per_ha": 0.0,
                 "world.trees.hedge_fraction": 0.0, "world.buildings.count": 0, "camera.tilt_deg": 20.0, "camera.drift.heading_rate_deg_s": 3.0,
                 "camera.drift.climb_rate_mps": 2.0, "camera.jitter.roll_std_deg": 0.5,
                 "camera.jitter.x_std_m": 0.3}
    seq = open_sequence(render_sequence(load_scene_spec("tiny", overrides=overrides), tmp_path / "seq"))
    cam = seq.camera
    h, w = seq.meta["height"], seq.meta["width"]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    for i in range(len(seq) - 1):
        H = _ground_homography(cam.iloc[i + 1]) @ np.linalg.inv(_ground_homography(cam.iloc[i]))
        q = H @ pts
        expected = np.stack([q[0] / q[2] - pts[0], q[1] / q[2] - pts[1]], axis=-1).reshape(h, w, 2)
        truth = seq.pair_truth(i)
        assert truth.valid.mean() > 0.9
        assert not truth.instances.any()
        err = np.abs(truth.flow - expected)[truth.valid]
        assert err.max() < 0.01, (i, err.max())
        np.testing.assert_array_equal(truth.flow, truth.flow_camera)


def test_sign_convention_camera_moving_to_image_right_moves_ground_left():
    # heading east with a -90 deg crab: image up is north, the camera moves toward image +x
    spec = load_scene_spec("tiny", overrides={**NO_JITTER, "vehicles.count": 0, "camera.heading_deg": 90.0,
                                              "camera.drift.crab_deg": -90.0})
    gen = SceneGenerator(spec)
    frames = gen.frames()
    next(frames)
    truth = next(frames).pair
    u, v = truth.flow[..., 0][truth.valid], truth.flow[..., 1][truth.valid]
    expected_u = -spec.camera.ground_speed_mps / spec.image.fps / spec.gsd_m()
    assert (u < 0).all()
    assert abs(np.median(u) - expected_u) < 0.01 and np.abs(v).max() < 0.01


def test_sign_convention_vehicle_driving_to_image_right_has_larger_u_than_ground():
    # nadir, heading north, no jitter: image +x is world east (+x)
    spec = load_scene_spec("tiny", overrides={**NO_JITTER, "vehicles.count": 8, "vehicles.parked_fraction": 0.0})
    gen = SceneGenerator(spec)
    frames = gen.frames()
    next(frames)
    truth = next(frames).pair
    ground_u = np.median(truth.flow[..., 0][truth.valid & (truth.instances == 0)])
    checked = 0
    t0_s = 1.0 / spec.image.fps  # the pair is frames 1 -> 2
    for vid, vehicle in enumerate(gen.vehicles, start=1):
        mine = truth.valid & (truth.instances == vid)
        d = vehicle.direction(t0_s)
        if mine.sum() < 5 or abs(d[0]) < 0.7 or np.linalg.norm(vehicle.direction(t0_s + 0.1) - d) > 0.01:
            continue  # roads are curved: take vehicles driving mostly along x, not turning now
        u_vehicle = np.median(truth.flow[..., 0][mine])
        expected = d[0] * vehicle.v0_mps / spec.image.fps / spec.gsd_m()
        assert np.sign(u_vehicle - ground_u) == np.sign(d[0])
        assert abs((u_vehicle - ground_u) - expected) < 0.1 * abs(expected) + 0.05
        checked += 1
    assert checked >= 2


def test_vehicle_flow_follows_its_track(tiny_sequence):
    _, folder = tiny_sequence
    seq = open_sequence(folder)
    tracks = seq.tracks.set_index(["frame", "vehicle_id"])
    moved = 0
    for i in range(len(seq) - 1):
        truth = seq.pair_truth(i)
        for vid in np.unique(truth.instances[truth.instances > 0]):
            mine = truth.valid & (truth.instances == vid)
            if mine.sum() < 10:
                continue
            a, b = tracks.loc[(i, vid)], tracks.loc[(i + 1, vid)]
            track_step = np.array([b.x_px - a.x_px, b.y_px - a.y_px])
            # the projected box centre and the mean over the visible top differ by perspective only
            assert np.abs(truth.flow[mine].mean(axis=0) - track_step).max() < 0.1
            moved += 1
    assert moved >= 3


def test_global_shift_and_jitter_columns(tiny_sequence):
    _, folder = tiny_sequence
    seq = open_sequence(folder)
    cam = seq.camera
    for i in range(len(seq) - 1):
        t = seq.pair_truth(i)
        static = t.valid & (t.instances == 0)
        mean = t.flow_camera[static].astype(np.float64).mean(axis=0)
        assert abs(cam.global_dx_px[i] - mean[0]) < 1e-3 and abs(cam.global_dy_px[i] - mean[1]) < 1e-3
    assert np.isnan(cam.global_dx_px.iloc[-1])
    # tiny has jitter: the jitter columns are not all zero, and zero jitter gives exact zeros
    assert np.abs(cam[["jitter_x_px", "jitter_y_px"]].to_numpy()).max() > 0.01
    quiet = SceneGenerator(load_scene_spec("tiny", overrides=NO_JITTER))
    assert np.abs(quiet.path.jitter_px).max() < 1e-9
