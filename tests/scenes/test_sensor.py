"""The sensor: each effect changes the frames as specified, and the ground truth stays exact under it."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from algorithms.flow import as_gray, warp_backward
from scenes import SceneSpecError, load_scene_spec, open_sequence, render_sequence
from scenes.generate import SceneGenerator
from scenes.sensor import (
    Compressor,
    EncoderUnavailableError,
    add_noise,
    apply_haze,
    distort_normalised,
    pose_at,
    undistort_normalised,
)

NO_JITTER = {f"camera.jitter.{k}": 0.0 for k in
             ("roll_std_deg", "pitch_std_deg", "yaw_std_deg", "x_std_m", "y_std_m", "z_std_m")}
# nothing standing on the ground: no buildings, trees, woods or hedges
BARE_GROUND = {"world.buildings.count": 0, "world.trees.density_per_ha": 0.0,
               "world.trees.wood_density_per_ha": 0.0, "world.trees.hedge_fraction": 0.0}
# an oblique, turning, climbing, jittering camera over a world without vehicles or buildings:
# the ground is a plane, so its flow is a homography of the saved poses
FLAT_WORLD = {**BARE_GROUND, "vehicles.count": 0, "camera.tilt_deg": 20.0, "camera.drift.heading_rate_deg_s": 3.0,
              "camera.drift.climb_rate_mps": 2.0, "camera.jitter.roll_std_deg": 0.5,
              "camera.jitter.x_std_m": 0.3, "image.n_frames": 3}


def _generate(overrides: dict):
    spec = load_scene_spec("tiny", overrides=overrides)
    gen = SceneGenerator(spec)
    return spec, gen, list(gen.frames())


def _warp_residual(f0_rgb, f1_rgb, truth) -> tuple[float, float]:
    """Mean |I1(x + flow) - I0(x)| on valid pixels, and the same without motion compensation."""
    f0, f1 = as_gray(f0_rgb), as_gray(f1_rgb)
    warped, _ = warp_backward(f1, truth.flow)
    v = truth.valid
    return float(np.abs(warped - f0)[v].mean()), float(np.abs(f1 - f0)[v].mean())


def _quat_to_R(row) -> np.ndarray:
    return Rotation.from_quat([row.qx, row.qy, row.qz, row.qw]).as_matrix()


def _homography(K: np.ndarray, R: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Image of the ground plane z = 0: x ~ K R^T [e1 e2 -C] (X, Y, 1)."""
    return K @ R.T @ np.column_stack([[1, 0, 0], [0, 1, 0], -C])


def _apply(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q = H @ np.stack([x.ravel(), y.ravel(), np.ones(x.size)])
    return (q[0] / q[2]).reshape(x.shape), (q[1] / q[2]).reshape(x.shape)


# -- appearance effects: the truth does not change ------------------------------------------

@pytest.mark.gl
@pytest.mark.parametrize("effect", [
    {"sensor.motion_blur.exposure_s": 0.05, "sensor.motion_blur.subframes": 5},
    {"sensor.haze.extinction_per_km": 4.0},
    {"sensor.noise.gaussian_std": 2.0, "sensor.noise.full_well_e": 3000.0},
    {"sensor.lens.blur_sigma_px": 0.8},
    {"sensor.compression.codec": "jpeg", "sensor.compression.jpeg_quality": 85},
    {"sensor.compression.codec": "h264", "sensor.compression.h264_crf": 23},
], ids=["motion-blur", "haze", "noise", "optics-blur", "jpeg", "h264"])
def test_appearance_effects_change_frames_not_truth_and_truth_still_warps(effect):
    _, _, clean = _generate(FLAT_WORLD)
    _, _, seen = _generate({**FLAT_WORLD, **effect})
    assert np.abs(seen[1].rgb.astype(np.int16) - clean[1].rgb).mean() > 0.3  # the effect is there
    for a, b in zip(seen[1:], clean[1:]):
        np.testing.assert_array_equal(a.pair.flow, b.pair.flow)
        np.testing.assert_array_equal(a.pair.valid, b.pair.valid)
        np.testing.assert_array_equal(a.instances, b.instances)
    # the truth still explains the frames: on the clean frames warping by it removes most of the
    # difference, and the effect adds to that residual no more than it changed the two frames
    # (triangle inequality: |W(s1) - s0| <= |W(c1) - c0| + |W(s1 - c1)| + |s0 - c0|)
    clean_true, clean_zero = _warp_residual(clean[0].rgb, clean[1].rgb, clean[1].pair)
    assert clean_zero > 5.0 and clean_true < 0.3 * clean_zero, (clean_true, clean_zero)
    err_true, _ = _warp_residual(seen[0].rgb, seen[1].rgb, seen[1].pair)
    v = seen[1].pair.valid
    changed = sum(float(np.abs(as_gray(s.rgb) - as_gray(c.rgb))[v].mean()) for s, c in zip(seen[:2], clean[:2]))
    assert err_true <= clean_true + changed + 0.25, (err_true, clean_true, changed)


@pytest.mark.gl
def test_motion_blur_smears_along_the_motion_only():
    # camera flying to image right (heading east, crab -90): the ground moves along -x,
    # so blur takes x-gradient energy and leaves y-gradients nearly alone (on a straight road grid,
    # whose edges are horizontal or vertical: a curved road's edges lose y-gradient too)
    move_x = {**NO_JITTER, **BARE_GROUND, "world.road_irregularity": 0.0, "vehicles.count": 0, "camera.heading_deg": 90.0, "camera.drift.crab_deg": -90.0,
              "image.n_frames": 2, "camera.ground_speed_mps": 30.0}
    _, _, sharp = _generate(move_x)
    _, _, blurred = _generate({**move_x, "sensor.motion_blur.exposure_s": 0.08, "sensor.motion_blur.subframes": 9})
    g_sharp, g_blur = as_gray(sharp[0].rgb), as_gray(blurred[0].rgb)
    ratio_x = np.abs(np.diff(g_blur, axis=1)).mean() / np.abs(np.diff(g_sharp, axis=1)).mean()
    ratio_y = np.abs(np.diff(g_blur, axis=0)).mean() / np.abs(np.diff(g_sharp, axis=0)).mean()
    # averaging along x also lowers the y-differences of the isotropic ground texture a little;
    # along the motion the loss is clearly larger
    assert ratio_x < 0.75 * ratio_y and ratio_y > 0.7, (ratio_x, ratio_y)


# -- lens distortion --------------------------------------------------------------------------

def test_distortion_round_trip_and_agreement_with_opencv():
    rng = np.random.default_rng(3)
    xn, yn = rng.uniform(-0.6, 0.6, 500), rng.uniform(-0.45, 0.45, 500)
    k1, k2 = -0.15, 0.03
    xd, yd = distort_normalised(xn, yn, k1=k1, k2=k2)
    xu, yu = undistort_normalised(xd, yd, k1=k1, k2=k2)
    assert max(np.abs(xu - xn).max(), np.abs(yu - yn).max()) < 1e-12
    # OpenCV's distortion model with only k1, k2 is the same Brown-Conrady radial model
    pts = cv2.undistortPoints(np.stack([xd, yd], axis=1).reshape(-1, 1, 2), np.eye(3),
                              np.array([k1, k2, 0.0, 0.0]),
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14))
    assert np.abs(pts.reshape(-1, 2) - np.stack([xn, yn], axis=1)).max() < 1e-6


def test_distortion_that_folds_the_image_is_refused():
    with pytest.raises(SceneSpecError, match=r"sensor\.lens: k1 -0\.9.*fold"):
        load_scene_spec("tiny", overrides={"sensor.lens.k1": -0.9})


@pytest.mark.gl
@pytest.mark.parametrize(("k1", "k2"), [(-0.15, 0.02), (0.1, 0.0)], ids=["barrel", "pincushion"])
def test_distorted_flat_world_flow_is_the_distorted_plane_homography(k1, k2):
    # independent of scenes.sensor: OpenCV undistorts, the polynomial is written out here
    spec, _, frames = _generate({**FLAT_WORLD, "sensor.lens.k1": k1, "sensor.lens.k2": k2})
    gen_cam = SceneGenerator(spec)
    K = gen_cam.path.K
    h, w = spec.image.height_px, spec.image.width_px
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    und = cv2.undistortPoints(np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2), K,
                              np.array([k1, k2, 0.0, 0.0]), P=K,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)).reshape(h, w, 2)
    for fo in frames[1:]:
        i = fo.pair_index
        H = (_homography(K, gen_cam.path.R[i + 1], gen_cam.path.C[i + 1])
             @ np.linalg.inv(_homography(K, gen_cam.path.R[i], gen_cam.path.C[i])))
        x1, y1 = _apply(H, und[..., 0], und[..., 1])
        xn, yn = (x1 - K[0, 2]) / K[0, 0], (y1 - K[1, 2]) / K[1, 1]
        g = 1 + k1 * (xn**2 + yn**2) + k2 * (xn**2 + yn**2) ** 2
        expected = np.stack([K[0, 0] * xn * g + K[0, 2] - xs, K[1, 1] * yn * g + K[1, 2] - ys], axis=-1)
        truth = fo.pair
        assert truth.valid.mean() > 0.85
        err = np.abs(truth.flow - expected)[truth.valid]
        assert err.max() < 0.01, (i, err.max())
        err_true, err_zero = _warp_residual(frames[i].rgb, fo.rgb, truth)
        assert err_true < 0.15 * err_zero and err_true < 2.5, (err_true, err_zero)


@pytest.mark.gl
@pytest.mark.parametrize("effect", [
    {"sensor.lens.k1": -0.2, "sensor.lens.k2": 0.04},
    {"sensor.rolling_shutter.line_delay_s": 6e-4, "sensor.rolling_shutter.band_rows": 4},
    {"sensor.lens.k1": 0.1, "sensor.rolling_shutter.line_delay_s": 4e-4, "sensor.rolling_shutter.band_rows": 8},
], ids=["distortion", "rolling-shutter", "both"])
def test_vehicle_instances_sit_on_the_vehicles_as_exposed_and_tracks_follow_them(effect):
    overrides = {**NO_JITTER, "vehicles.count": 6, "vehicles.parked_fraction": 0.0, "image.n_frames": 3,
                 "vehicles.speed_range_mps": [10.0, 14.0], **effect}
    spec, gen, frames = _generate(overrides)
    rows = {(r[0], r[1]): r for r in gen.track_rows}  # (frame, vehicle) -> row
    checked = 0
    for fo in frames[1:]:
        truth, i = fo.pair, fo.pair_index
        for vid in np.unique(truth.instances[truth.instances > 0]):
            mine = truth.valid & (truth.instances == vid)
            if mine.sum() < 10:
                continue
            ys, xs = np.nonzero(truth.instances == vid)
            a, b = rows[(i, vid)], rows[(i + 1, vid)]
            # the distorted track centre lies inside the vehicle's distorted pixels
            assert xs.min() - 1 <= a[2] <= xs.max() + 1 and ys.min() - 1 <= a[3] <= ys.max() + 1
            step = np.array([b[2] - a[2], b[3] - a[3]])
            # the centre (inside the body) and the visible top differ by perspective, and under a
            # rolling shutter each is read at its own band's time: up to one band's readout apart
            band_s = spec.sensor.rolling_shutter.band_rows * spec.sensor.rolling_shutter.line_delay_s
            tol = 0.15 + np.abs(step).max() * spec.image.fps * band_s
            assert np.abs(truth.flow[mine].mean(axis=0) - step).max() < tol
            checked += 1
    assert checked >= 3


@pytest.mark.gl
def test_every_effect_at_once_truth_still_warps_with_vehicles_and_buildings():
    scene = {"image.n_frames": 3, "world.buildings.count": 4, "world.buildings.height_range_m": [6.0, 12.0],
             "vehicles.count": 4, "vehicles.parked_fraction": 0.0}
    sensor = {"sensor.motion_blur.exposure_s": 0.02, "sensor.motion_blur.subframes": 3,
              "sensor.rolling_shutter.line_delay_s": 2e-4, "sensor.rolling_shutter.band_rows": 8,
              "sensor.lens.k1": -0.1, "sensor.lens.k2": 0.01, "sensor.haze.extinction_per_km": 1.5,
              "sensor.noise.gaussian_std": 1.0, "sensor.noise.full_well_e": 8000.0,
              "sensor.compression.codec": "jpeg", "sensor.compression.jpeg_quality": 90}
    _, _, clean = _generate(scene)
    _, _, seen = _generate({**scene, **sensor})
    for a, b in zip(seen[1:], clean[1:]):
        err_seen, zero_seen = _warp_residual(seen[a.index - 1].rgb, a.rgb, a.pair)
        err_clean, _ = _warp_residual(clean[b.index - 1].rgb, b.rgb, b.pair)
        assert a.pair.valid.mean() > 0.85 and (a.instances > 0).any()
        # what remains is the noise, codec and resampling, not a misplaced truth
        assert err_seen < err_clean + 3.0 and err_seen < 0.3 * zero_seen, (err_seen, err_clean, zero_seen)


# -- rolling shutter -------------------------------------------------------------------------

def _interpolated_pose(cam, t_s: float):
    """Camera pose between frames from camera.csv: slerp rotation, linear centre (the documented convention)."""
    times = cam.t_s.to_numpy()
    rots = Rotation.from_quat(cam[["qx", "qy", "qz", "qw"]].to_numpy())
    k = int(np.clip(np.searchsorted(times, t_s, side="right") - 1, 0, len(times) - 2))
    s = (t_s - times[k]) / (times[k + 1] - times[k])
    R = (rots[k] * Rotation.from_rotvec(s * (rots[k].inv() * rots[k + 1]).as_rotvec())).as_matrix()  # may extrapolate
    C0 = cam.loc[k, ["x_m", "y_m", "z_m"]].to_numpy(float)
    C1 = cam.loc[k + 1, ["x_m", "y_m", "z_m"]].to_numpy(float)
    return R, C0 + s * (C1 - C0)


@pytest.mark.gl
def test_rolling_shutter_flat_world_flow_is_the_per_band_homography(tmp_path):
    band_rows, delay_s = 6, 4e-4
    spec = load_scene_spec("tiny", overrides={**FLAT_WORLD, "sensor.rolling_shutter.line_delay_s": delay_s,
                                              "sensor.rolling_shutter.band_rows": band_rows})
    seq = open_sequence(render_sequence(spec, tmp_path / "seq"))
    cam = seq.camera
    assert (cam.line_delay_s == delay_s).all() and seq.meta["sensor"]["band_rows"] == band_rows
    K = seq.K
    h, w = seq.meta["height"], seq.meta["width"]
    n_bands = -(-h // band_rows)

    def band_homographies(i):
        out = []
        for b in range(n_bands):
            r0, r1 = b * band_rows, min(h, (b + 1) * band_rows)
            t = cam.t_s[i] + (0.5 * (r0 + r1 - 1) - K[1, 2]) * delay_s
            out.append(_homography(K, *_interpolated_pose(cam, t)))
        return out

    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    for i in range(len(seq) - 1):
        H0, H1 = band_homographies(i), band_homographies(i + 1)
        expected = np.full((h, w, 2), np.nan)
        for b in range(n_bands):
            rows = slice(b * band_rows, (b + 1) * band_rows)
            Xg, Yg = _apply(np.linalg.inv(H0[b]), xs[rows], ys[rows])  # ground point of each pixel
            for b1 in range(n_bands):  # the band of frame i+1 whose pose puts the point inside it
                x1, y1 = _apply(H1[b1], Xg, Yg)
                lands = (np.floor(y1 + 0.5) // band_rows == b1) & np.isnan(expected[rows][..., 0])
                expected[rows][lands] = np.stack([x1 - xs[rows], y1 - ys[rows]], axis=-1)[lands]
        truth = seq.pair_truth(i)
        assert truth.valid.mean() > 0.85
        err = np.abs(truth.flow - expected)[truth.valid]
        assert err.max() < 0.01, (i, err.max())
        err_true, err_zero = _warp_residual(seq.frame(i), seq.frame(i + 1), truth)
        assert err_true < 0.15 * err_zero and err_true < 2.5, (err_true, err_zero)  # as without the effect


@pytest.mark.gl
def test_line_delay_is_recovered_from_the_flow_under_known_camera_motion():
    # nadir, flying north (image up) at s px/s: a row read (y - cy) * delta late. A ground point
    # moving down the image by v px per frame is read v * delta later in the next frame, so
    # v = s (1 / fps + v delta): delta = (v - v_gs) / (s v) with v_gs = s / fps the global shutter's.
    # Rendered in bands of one row, a point is read at the time of the row nearest to it, so
    # the truth obeys v = s (1 / fps + round(v) delta) exactly
    delay_s = 6e-4
    fast = {**NO_JITTER, **BARE_GROUND, "vehicles.count": 0, "camera.ground_speed_mps": 50.0, "image.n_frames": 3}
    spec, _, gs = _generate(fast)
    _, _, rs = _generate({**fast, "sensor.rolling_shutter.line_delay_s": delay_s,
                          "sensor.rolling_shutter.band_rows": 1})
    v_gs = np.median(gs[1].pair.flow[..., 1][gs[1].pair.valid])
    s_px = v_gs * spec.image.fps
    for fo in rs[1:]:
        t = fo.pair
        v = t.flow[..., 1][t.valid]
        assert v.std() < 0.01  # a translation: the same for every row
        delta = (v.mean() - v_gs) / (s_px * np.rint(v.mean()))
        assert abs(delta - delay_s) < 0.001 * delay_s, delta
    # the same from estimated flow (DIS on the rendered frames), within the estimator's error
    from algorithms.reference import dis

    est, valid = dis(rs[1].rgb, rs[2].rgb)
    inner = valid & rs[2].pair.valid
    inner[:16] = inner[-16:] = False
    v_est = np.median(est[..., 1][inner])
    delta_est = (v_est - v_gs) / (s_px * v_est)
    assert abs(delta_est - delay_s) < 0.2 * delay_s, (delta_est, v_est, v_gs)


@pytest.mark.gl
def test_one_band_instant_readout_truth_equals_the_pinhole_truth():
    # the banded machinery (per-pixel rays, band fixed point) on a global shutter must give the
    # pinhole path's numbers: one band, a readout too short to move anything
    scene = {"image.n_frames": 3, "vehicles.count": 4, "vehicles.parked_fraction": 0.0}
    _, _, pinhole = _generate(scene)
    _, gen, banded = _generate({**scene, "sensor.rolling_shutter.line_delay_s": 1e-12,
                                "sensor.rolling_shutter.band_rows": 120})
    assert gen.banded
    for a, b in zip(banded[1:], pinhole[1:]):
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.instances, b.instances)
        np.testing.assert_array_equal(a.pair.valid, b.pair.valid)
        assert np.abs(a.pair.flow - b.pair.flow).max() < 1e-3
        assert np.abs(a.pair.flow_camera - b.pair.flow_camera).max() < 1e-3


def test_pose_between_frames_is_exact_at_frames_and_on_the_geodesic():
    rng = np.random.default_rng(2)
    R = Rotation.random(3, random_state=4).as_matrix()
    C = rng.normal(size=(3, 3))
    t = np.array([0.0, 0.1, 0.2])
    for k in range(3):
        Rk, Ck = pose_at(t, R, C, float(t[k]))
        np.testing.assert_array_equal(Rk, R[k])
        np.testing.assert_array_equal(Ck, C[k])
    Rm, Cm = pose_at(t, R, C, 0.13)
    expected = Slerp([0.1, 0.2], Rotation.from_matrix(R[1:]))([0.13]).as_matrix()[0]
    assert np.abs(Rm - expected).max() < 1e-12
    np.testing.assert_allclose(Cm, C[1] + 0.3 * (C[2] - C[1]), atol=1e-12)


def test_readout_and_exposure_longer_than_a_frame_are_refused():
    with pytest.raises(SceneSpecError, match=r"sensor\.rolling_shutter\.line_delay_s: reading 120 rows"):
        load_scene_spec("tiny", overrides={"sensor.rolling_shutter.line_delay_s": 1e-3})
    with pytest.raises(SceneSpecError, match=r"sensor\.motion_blur\.exposure_s: .*longer than the frame"):
        load_scene_spec("tiny", overrides={"sensor.motion_blur.exposure_s": 0.2})
    with pytest.raises(SceneSpecError, match=r"subframes: expected an odd number"):
        load_scene_spec("tiny", overrides={"sensor.motion_blur.subframes": 4})


# -- haze, noise, compression as functions --------------------------------------------------

def test_haze_follows_koschmieder():
    img = np.full((2, 3, 3), 100.0, np.float32)
    distance = np.array([[0.0, 500.0, 1000.0], [2000.0, np.inf, 250.0]], np.float32)
    out = apply_haze(img.copy(), distance, extinction_per_km=2.0, airlight=220.0)
    t = np.exp(-2.0 * distance / 1000.0)
    np.testing.assert_allclose(out[..., 0], 100.0 * t + 220.0 * (1 - t), rtol=1e-6)
    with pytest.raises(ValueError, match=r"expected img \(H, W, 3\) and distance \(H, W\)"):
        apply_haze(img, distance.T, extinction_per_km=1.0, airlight=200.0)


def test_shot_noise_variance_grows_with_the_signal_and_read_noise_adds():
    rng = np.random.default_rng(11)
    full_well, read = 2000.0, 1.5
    for level in (40.0, 160.0):
        img = np.full((200, 200, 3), level, np.float32)
        out = add_noise(img, rng, gaussian_std=read, full_well_e=full_well)
        expected_var = level * 255.0 / full_well + read**2  # Poisson: var(e) = mean(e), in gray levels
        assert abs(out.mean() - level) < 0.1
        assert abs(out.var() / expected_var - 1) < 0.03, (level, out.var(), expected_var)


def test_shot_noise_is_exact_poisson_when_dark_and_matches_its_moments_when_bright():
    """Below POISSON_EXACT_BELOW_E electrons whole electrons are drawn; above, N(lambda, lambda)."""
    from scenes.sensor import POISSON_EXACT_BELOW_E

    rng = np.random.default_rng(5)
    full_well = 4000.0
    scale = full_well / 255.0
    dark_level = 0.5 * POISSON_EXACT_BELOW_E / scale  # lambda = 50 electrons
    img = np.full((300, 300, 1), dark_level, np.float32)
    electrons = add_noise(img, rng, gaussian_std=0.0, full_well_e=full_well) * np.float32(scale)
    np.testing.assert_allclose(electrons, np.rint(electrons), atol=1e-3)  # counts
    assert abs(electrons.mean() - 50.0) < 0.1 and abs(electrons.var() / 50.0 - 1) < 0.03
    for lam in (POISSON_EXACT_BELOW_E * 1.01, 3000.0):
        img = np.full((300, 300, 1), lam / scale, np.float32)
        e = add_noise(img, rng, gaussian_std=0.0, full_well_e=full_well).astype(np.float64) * scale
        assert abs(e.mean() / lam - 1) < 1e-3 and abs(e.var() / lam - 1) < 0.03, (lam, e.mean(), e.var())


def _texture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.random((120, 160, 3)).astype(np.float32), (0, 0), 1.5)
    img = (img - img.min()) / (img.max() - img.min())
    return (img * 255).astype(np.uint8)


def test_jpeg_error_grows_as_quality_falls():
    img = _texture(1)
    errors = [np.abs(Compressor("jpeg", width_px=160, height_px=120, fps=10, jpeg_quality=q)(img).astype(float)
                     - img).mean() for q in (95, 60, 20)]
    assert 0 < errors[0] < errors[1] < errors[2], errors


def test_h264_is_a_deterministic_stream_whose_error_grows_with_crf():
    frames = [np.roll(_texture(2), 2 * k, axis=1) for k in range(4)]

    def run(crf):
        c = Compressor("h264", width_px=160, height_px=120, fps=10, h264_crf=crf, h264_gop=30)
        return [c(f) for f in frames]

    a, b = run(28), run(28)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    err = [np.mean([np.abs(o.astype(float) - f).mean() for o, f in zip(run(crf), frames)]) for crf in (12, 28, 45)]
    assert 0 < err[0] < err[1] < err[2], err


def test_missing_video_encoder_names_the_pip_extra(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_av(name, *args, **kwargs):
        if name == "av":
            raise ImportError("No module named 'av'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_av)
    with pytest.raises(EncoderUnavailableError, match=r"pip install 'aerobench\[video\]'"):
        Compressor("h264", width_px=160, height_px=120, fps=10)


def test_old_photometry_noise_and_blur_keys_name_the_sensor_section(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text("photometry: {noise_std: 4.0, blur_sigma_px: 0.7}\n")
    with pytest.raises(SceneSpecError, match=r"photometry\.noise_std -> sensor\.noise\.gaussian_std.*"
                                             r"photometry\.blur_sigma_px -> sensor\.lens\.blur_sigma_px") as info:
        load_scene_spec(path)
    assert str(path) in str(info.value)


@pytest.mark.gl
def test_sequence_records_the_sensor_for_readers(tmp_path):
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2, "sensor.lens.k1": -0.1, "sensor.lens.k2": 0.02,
                                              "sensor.motion_blur.exposure_s": 0.02})
    folder = render_sequence(spec, tmp_path / "seq")
    seq = open_sequence(folder, verify=True)
    meta = json.loads((folder / "meta.json").read_text())["sensor"]
    assert meta["k1"] == -0.1 and meta["k2"] == 0.02 and meta["line_delay_s"] == 0.0
    assert meta["exposure_s"] == 0.02 and meta["subframes"] == 5
    assert (seq.camera.k1 == -0.1).all() and (seq.camera.k2 == 0.02).all()


def test_realistic_preset_has_every_effect_and_sweep_sensor_sweeps_each():
    from harness.suites import expand, load_suite

    sensor = load_scene_spec("realistic").sensor
    defaults = type(sensor)()
    for group in type(sensor).model_fields:
        assert getattr(sensor, group) != getattr(defaults, group), f"realistic leaves sensor.{group} off"
    swept = {c.variant.sweep_param for c in expand(load_suite("sweep-sensor"))}
    for effect in ("motion_blur.exposure_s", "rolling_shutter.line_delay_s", "lens.k1", "lens.blur_sigma_px",
                   "haze.extinction_per_km",
                   "noise.full_well_e", "compression.jpeg_quality", "compression.h264_crf"):
        assert f"sensor.{effect}" in swept, effect
    assert load_scene_spec("noisy").sensor.noise.gaussian_std > 0


@pytest.mark.gl
def test_banded_truth_skipping_road_users_outside_a_band_changes_nothing(monkeypatch):
    """The banded truth runs its per-pixel pass only for road users whose box reaches a band, and
    projects every vehicle's corners in one batch: the truth and the tracks are those of a pass
    over every vehicle in every band, one projection each, bit for bit."""
    from scenes.ground_truth import BandedGroundTruth

    overrides = {"vehicles.count": 8, "vehicles.parked_fraction": 0.25, "vehicles.speed_range_mps": [20.0, 30.0],
                 "image.n_frames": 3, "sensor.lens.k1": -0.1, "sensor.rolling_shutter.line_delay_s": 2e-4,
                 "sensor.rolling_shutter.band_rows": 16, "sensor.motion_blur.exposure_s": 0.01,
                 "sensor.motion_blur.subframes": 3}
    spec, gen, fast = _generate(overrides)
    fast_rows = list(gen.track_rows)
    skipped = sum(len(gen.vehicles) - len(gen.banded_truth._reaching(
        gen.path.R[0], gen.path.C[0], gen.vehicle_matrices(0.0), b)) for b in range(gen.banded_truth.n_bands))
    assert skipped > 0  # some road user is outside some band: the test compares something

    def every_vehicle(self, R, C, vehicle_M, band):
        return list(range(1, len(vehicle_M) + 1))

    def one_by_one(self, s):
        mid = np.full(1, self.n_bands // 2)
        out = []
        for vid, corners in enumerate(self.corner_truth.vehicle_corners, start=1):
            pts = np.vstack([corners, corners.mean(axis=0)])
            x, y, z, _ = self.project(pts, np.full(len(pts), vid), s, np.repeat(mid, len(pts)))
            if (z <= 0).any():
                out.append(((np.nan,) * 4, (np.nan, np.nan)))
                continue
            xd, yd = self._to_output(x, y)
            out.append(((xd[:-1].min(), yd[:-1].min(), xd[:-1].max(), yd[:-1].max()), (xd[-1], yd[-1])))
        return out

    monkeypatch.setattr(BandedGroundTruth, "_reaching", every_vehicle)
    monkeypatch.setattr(BandedGroundTruth, "vehicle_bboxes", one_by_one)
    _, gen_ref, ref = _generate(overrides)
    for a, b in zip(fast[1:], ref[1:]):
        for name in ("flow", "flow_camera", "valid", "instances"):
            np.testing.assert_array_equal(getattr(a.pair, name), getattr(b.pair, name), err_msg=name)
    assert len(fast_rows) == len(gen_ref.track_rows)
    for r, q in zip(fast_rows, gen_ref.track_rows):
        np.testing.assert_array_equal(np.array(r[:11], float), np.array(q[:11], float))
        assert r[11:] == q[11:]
