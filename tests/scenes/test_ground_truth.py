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


@pytest.mark.parametrize(("detail", "edges"), [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)])
def test_warping_next_frame_by_true_flow_reproduces_frame(tmp_path, detail, edges):
    # flat shading and no noise: brightness constancy holds, so I1(x + u) ~ I0(x) on valid pixels.
    # At 30 m the tiny camera has the nominal GSD (0.22 m/px); what remains is the bilinear
    # interpolation of textured content by warp_backward, well under 2 gray levels. Vehicle
    # shadows are off: a shadow moving over static ground breaks brightness constancy by design
    # (truth is the motion field; tests/scenes/test_world_truth.py covers the shadowed world).
    # world.detail 1 (realistic's structure at 1-3 m) is held to the same bound, and so is world.edges 1
    # (realistic's light kerbs and dark gutters, centre lines on minor roads, roofs of every shade)
    spec = load_scene_spec("tiny", overrides={"camera.altitude_m": 30.0, "light.shadows": False,
                                              "world.detail": detail, "world.edges": edges})
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


# -- the numba kernels against the numpy expressions they replaced --------------------------------

def _reference_surface(gt, depth, R, C, vehicle_M):
    """scenes.ground_truth.GroundTruth.surface as whole-image numpy (float32, the kernels' order)."""
    from scenes.ground_truth import SURFACE_TOL_ABS_M, SURFACE_TOL_REL, ray_boxes_depth

    D = np.asarray(depth, np.float32)
    g = -R[2, :]
    gd = (np.float32(g[0]) * gt.xn32)[None, :] + (np.float32(g[1]) * gt.yn32 + np.float32(g[2]))[:, None]
    Zg = np.full_like(gd, np.inf)
    np.divide(np.float32(C[2]), gd, out=Zg, where=gd > 0)
    tol = D * np.float32(SURFACE_TOL_REL)
    tol += np.float32(SURFACE_TOL_ABS_M)
    Z = np.where(np.abs(D - Zg) <= tol, Zg, D)
    Z[D <= 0] = np.inf
    instances = np.zeros(D.shape, np.uint16)
    best = np.full(D.shape, np.inf, np.float32)
    for vid, ((bbox, _), boxes, M) in enumerate(zip(gt.vehicle_bboxes(R, C, vehicle_M), gt.vehicle_boxes,
                                                    vehicle_M), start=1):
        if not np.isfinite(bbox[0]):
            continue
        c0, c1 = max(0, int(np.floor(bbox[0]))), min(gt.w, int(np.ceil(bbox[2])) + 1)
        r0, r1 = max(0, int(np.floor(bbox[1]))), min(gt.h, int(np.ceil(bbox[3])) + 1)
        if c0 >= c1 or r0 >= r1:
            continue
        Zv = ray_boxes_depth(R, C, M, boxes, gt.xn[c0:c1][None, :], gt.yn[r0:r1][:, None]).astype(np.float32)
        Dw = D[r0:r1, c0:c1]
        err = np.abs(Dw - Zv)
        hit = (err <= SURFACE_TOL_REL * Dw + SURFACE_TOL_ABS_M) & (Dw > 0) & (err < best[r0:r1, c0:c1])
        instances[r0:r1, c0:c1][hit] = vid
        Z[r0:r1, c0:c1][hit] = Zv[hit]
        best[r0:r1, c0:c1][hit] = err[hit]
    return Z, instances


def _reference_static_pair(gt, Z0, inst0, depth1, A, b):
    """The static part of GroundTruth.pair as whole-image numpy: (x1, y1, Z1, valid) for a static world."""
    import cv2

    from scenes.ground_truth import OCCLUSION_TOL_ABS_M, OCCLUSION_TOL_REL

    sky = ~np.isfinite(Z0)
    Z = np.where(sky, np.float32(1.0), Z0)
    F = [(np.float32(A[k, 0]) * gt.xn32)[None, :] + (np.float32(A[k, 1]) * gt.yn32 + np.float32(A[k, 2]))[:, None]
         for k in range(3)]
    for k in range(3):
        F[k] *= Z
        F[k] += np.float32(b[k])
    X, Y, W = F
    inv = np.float32(1.0) / W
    X *= inv
    X *= np.float32(gt.fx)
    X += np.float32(gt.cx)
    Y *= inv
    Y *= np.float32(gt.fy)
    Y += np.float32(gt.cy)
    inside = (X >= 0) & (X <= gt.w - 1) & (Y >= 0) & (Y <= gt.h - 1) & (W > 0) & ~sky
    D1 = cv2.remap(depth1, X, Y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    limit = D1 * np.float32(1 + OCCLUSION_TOL_REL)
    limit += np.float32(OCCLUSION_TOL_ABS_M)
    return X, Y, inside & (D1 > 0) & (W <= limit)


def test_truth_kernels_give_the_numpy_expressions_bit_for_bit():
    # the tiny world with buildings and trees (depth from the render) and its vehicles, jittering
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 3, "world.buildings.count": 4,
                                              "vehicles.count": 5})
    gen = SceneGenerator(spec)
    gt = gen.truth
    surfaces, inputs = [], []
    for i in range(3):
        t = float(gen.path.t_s[i])
        Ms = gen.vehicle_matrices(t)
        _, depth = gen.renderer.render(gen.path.R[i], gen.path.C[i], Ms)
        s = gt.surface(depth, gen.path.R[i], gen.path.C[i], Ms)
        Z_ref, inst_ref = _reference_surface(gt, depth, gen.path.R[i], gen.path.C[i], Ms)
        np.testing.assert_array_equal(s.Z, Z_ref)
        np.testing.assert_array_equal(s.instances, inst_ref)
        assert s.vehicle_bboxes == gt.vehicle_bboxes(gen.path.R[i], gen.path.C[i], Ms)
        surfaces.append(s)
        inputs.append(depth)
    assert any(s.vehicle_pixels for s in surfaces) and np.any(np.isfinite(surfaces[0].Z))
    for s0, s1, depth1 in zip(surfaces, surfaces[1:], inputs[1:]):
        truth, shift = gt.pair(s0, s1)
        A, b = s1.R.T @ s0.R, s1.R.T @ (s0.C - s1.C)
        X, Y, valid_static = _reference_static_pair(gt, s0.Z, s0.instances, depth1, A, b)
        static = s0.instances == 0
        sky = ~np.isfinite(s0.Z)
        xs, ys = np.meshgrid(gt.xs32, gt.ys32)
        u, v = X - xs, Y - ys
        u[sky], v[sky] = 0, 0
        np.testing.assert_array_equal(truth.flow_camera[..., 0], u)
        np.testing.assert_array_equal(truth.flow_camera[..., 1], v)
        np.testing.assert_array_equal(truth.flow[static], truth.flow_camera[static])
        np.testing.assert_array_equal(truth.valid[static], valid_static[static])
        import cv2
        m = cv2.mean(truth.flow_camera, mask=(truth.valid & static).view(np.uint8))
        assert shift == (m[0], m[1])
