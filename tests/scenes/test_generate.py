"""scenes.generate: camera quaternions, independent random streams, the camera table."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scenes import load_scene_spec
from scenes.generate import SceneGenerator, rotation_to_quaternion


def test_quaternions_agree_with_scipy_on_every_branch_with_a_non_negative_w():
    mats = list(Rotation.random(200, random_state=7).as_matrix())
    # traces near -1: the three branches that divide by a diagonal element
    mats += [Rotation.from_rotvec(np.pi * 0.999 * axis).as_matrix() for axis in np.eye(3)]
    for R in mats:
        q = np.array(rotation_to_quaternion(R))
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        ref = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        np.testing.assert_allclose(q, ref, atol=1e-9)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-12


@pytest.mark.gl
def test_more_vehicles_change_neither_the_camera_jitter_nor_the_ground():
    few = SceneGenerator(load_scene_spec("tiny", {"image.n_frames": 3, "vehicles.count": 1}))
    many = SceneGenerator(load_scene_spec("tiny", {"image.n_frames": 3, "vehicles.count": 5}))
    assert len(few.vehicles) == 1 and len(many.vehicles) == 5
    np.testing.assert_array_equal(few.path.jitter_px, many.path.jitter_px)
    np.testing.assert_array_equal(few.path.C, many.path.C)
    assert [r["x_m"] for r in few.camera_rows()] == [r["x_m"] for r in many.camera_rows()]
    rows = few.camera_rows()
    assert [r["frame"] for r in rows] == [0, 1, 2]
    assert rows[-1]["global_dx_px"] is None  # the last frame has no next one
    R = Rotation.from_quat([rows[0][k] for k in ("qx", "qy", "qz", "qw")]).as_matrix()
    np.testing.assert_allclose(R, few.path.R[0], atol=1e-12)
