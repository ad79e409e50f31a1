"""scenes.motion: camera rotation and projection, vehicle routes and speed profiles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.motion import VehiclePath, polyline_arc_lengths, project, rotation_nadir, vehicle_pose_matrix


@pytest.mark.parametrize("yaw_deg", [0.0, 37.0, -120.0])
def test_nadir_rotation_is_a_proper_rotation_looking_down_with_the_heading_up_in_the_image(yaw_deg):
    R = rotation_nadir(yaw_deg)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-12)  # optical axis straight down
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    C = np.array([10.0, 20.0, 100.0])
    heading = np.array([math.sin(math.radians(yaw_deg)), math.cos(math.radians(yaw_deg)), 0.0])
    uv, z = project(K, R, C, np.stack([[10.0, 20.0, 0.0], C * [1, 1, 0] + 10 * heading]))
    np.testing.assert_allclose(uv[0], [50, 40], atol=1e-9)  # the ground under the camera: principal point
    assert z[0] == pytest.approx(100.0)
    # 10 m ahead along the heading at 100 m: 10 px up in the image (f = 100 px), none sideways
    np.testing.assert_allclose(uv[1], [50, 30], atol=1e-9)


def test_vehicle_pose_matrix_maps_the_local_forward_axis_along_theta():
    M = vehicle_pose_matrix(3.0, -2.0, math.pi / 2)
    np.testing.assert_allclose(M @ [1, 0, 0, 1], [3.0, -1.0, 0, 1], atol=1e-12)  # forward = +y in the world
    np.testing.assert_allclose(M @ [0, 1, 0, 1], [2.0, -2.0, 0, 1], atol=1e-12)  # left = -x


def test_arc_lengths_and_positions_along_an_l_shaped_route():
    route = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [10.0, 5.0]])  # a repeated vertex is dropped
    np.testing.assert_allclose(polyline_arc_lengths(route), [0, 10, 10, 15])
    car = VehiclePath(vehicle_id=1, kind="constant", route_m=route, s0_m=0.0, v0_mps=2.0)
    assert car.route_m.shape == (3, 2)
    x, y, th = car.at_arc_length(4.0)  # the heading turns smoothly from the start's 0 to the corner's 45 deg
    assert (x, y, th) == pytest.approx((4.0, 0.0, 0.4 * math.pi / 4))
    x, y, th = car.at_arc_length(10.0)  # at the corner the heading is halfway through the turn
    assert (x, y, th) == pytest.approx((10.0, 0.0, math.pi / 4))
    x, y, th = car.at_arc_length(18.0)  # beyond the end: straight on
    assert (x, y, th) == pytest.approx((10.0, 8.0, math.pi / 2))
    assert car.pose(2.5) == pytest.approx(car.at_arc_length(5.0))
    np.testing.assert_allclose(car.direction(0.0), [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(car.direction(7.5), [0.0, 1.0], atol=1e-12)  # 15 m: the end, heading north


@pytest.mark.parametrize("kind, kw", [("constant", {}), ("parked", {}),
                                      ("accelerating", {"v_max_mps": 9.0, "accel_mps2": 1.5}),
                                      ("stopping", {"accel_mps2": 2.0, "t_stop_start_s": 1.0})])
def test_distance_is_the_integral_of_speed(kind, kw):
    car = VehiclePath(vehicle_id=2, kind=kind, route_m=np.array([[0.0, 0.0], [100.0, 0.0]]), s0_m=0.0,
                      v0_mps=5.0, **kw)
    t = np.linspace(0.0, 6.0, 60001)
    v = np.array([car.speed(ti) for ti in t])
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    for k in (0, 15000, 30000, 60000):
        assert car.distance(t[k]) == pytest.approx(integral[k], abs=1e-6)
    if kind == "stopping":  # 5 m/s for 1 s, then v0^2 / (2 a) = 6.25 m of braking, then standing
        assert car.distance(6.0) == pytest.approx(11.25) and car.speed(6.0) == 0.0


def test_a_route_needs_two_points():
    with pytest.raises(ValueError, match=r"route_m: expected \(M, 2\) with M >= 2, got \(1, 2\)"):
        VehiclePath(vehicle_id=3, kind="constant", route_m=np.array([[0.0, 0.0]]), s0_m=0.0, v0_mps=1.0)
