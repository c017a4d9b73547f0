"""Quintic trajectory: end conditions, zero end velocity/acceleration, geodesic orientation."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_rotation

from grasp_safety_ros.core import InvalidInputError, ObjectTrajectory
from grasp_safety_ros.core.model.trajectory import quintic_time_scaling


def make_trajectory(seed: int = 0, duration: float = 2.0, dt: float = 0.01) -> ObjectTrajectory:
    rng = np.random.default_rng(seed)
    start = pin.SE3(random_rotation(rng), rng.uniform(-1, 1, 3))
    goal = pin.SE3(random_rotation(rng), rng.uniform(-1, 1, 3))
    return ObjectTrajectory(start, goal, duration, dt)


def test_time_scaling_boundary_conditions_and_derivatives() -> None:
    s, ds, dds = quintic_time_scaling(np.array([0.0, 1.0]))
    np.testing.assert_allclose(s, [0.0, 1.0])
    np.testing.assert_allclose(ds, [0.0, 0.0])
    np.testing.assert_allclose(dds, [0.0, 0.0])
    tau = np.linspace(0.05, 0.95, 19)
    h = 1e-6
    s_plus, ds_plus, _ = quintic_time_scaling(tau + h)
    s_minus, ds_minus, _ = quintic_time_scaling(tau - h)
    _, ds, dds = quintic_time_scaling(tau)
    np.testing.assert_allclose((s_plus - s_minus) / (2 * h), ds, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose((ds_plus - ds_minus) / (2 * h), dds, rtol=1e-6, atol=1e-8)


def test_end_poses_and_zero_end_velocity() -> None:
    trajectory = make_trajectory()
    times = trajectory.times_s()
    assert times[0] == 0.0 and times[-1] == pytest.approx(2.0)
    assert len(times) == 201
    s, s_rate, s_accel = trajectory.path_parameter(times)
    start = trajectory.transform_object_to_base(s[0])
    goal = trajectory.transform_object_to_base(s[-1])
    assert start.isApprox(trajectory.transform_object_to_base_start, 1e-12)
    assert goal.isApprox(trajectory.transform_object_to_base_goal, 1e-12)
    assert s_rate[0] == s_rate[-1] == 0.0
    assert s_accel[0] == pytest.approx(0.0) and s_accel[-1] == pytest.approx(0.0)


def test_last_sample_is_the_goal_when_duration_is_not_a_multiple_of_dt() -> None:
    trajectory = make_trajectory(duration=1.0, dt=0.3)
    np.testing.assert_allclose(trajectory.times_s(), [0.0, 0.3, 0.6, 0.9, 1.0])


def test_orientation_is_geodesic() -> None:
    """Angle from the start grows linearly in s about one fixed axis (body frame)."""
    trajectory = make_trajectory(seed=3)
    start = trajectory.transform_object_to_base_start.rotation
    total = pin.log3(start.T @ trajectory.transform_object_to_base_goal.rotation)
    for s in np.linspace(0.0, 1.0, 11):
        rotation = trajectory.transform_object_to_base(float(s)).rotation
        np.testing.assert_allclose(pin.log3(start.T @ rotation), s * total, atol=1e-12)


def test_tip_path_tangent_matches_finite_differences() -> None:
    trajectory = make_trajectory(seed=5)
    grasp = pin.SE3(random_rotation(np.random.default_rng(9)), np.array([0.1, -0.2, 0.05]))
    s = np.linspace(0.0, 1.0, 7)
    h = 1e-6
    poses, tangents = trajectory.tip_path(grasp, s)
    plus, _ = trajectory.tip_path(grasp, s + h)
    minus, _ = trajectory.tip_path(grasp, s - h)
    for i in range(len(s)):
        expected = trajectory.transform_object_to_base(float(s[i])) * grasp
        assert poses[i].isApprox(expected, 1e-12)
        derivative = (plus[i].translation - minus[i].translation) / (2 * h)
        np.testing.assert_allclose(tangents[i], derivative, atol=1e-8)


@pytest.mark.parametrize(
    ("duration", "dt", "field"),
    [
        (0.0, 0.1, "trajectory.duration_s"),
        (1.0, 2.0, "trajectory.dt_s"),
        (float("nan"), 0.1, "trajectory.duration_s"),
        (1e6, 1e-3, "trajectory.dt_s"),
    ],
)
def test_bad_timing_is_refused(duration: float, dt: float, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field.replace(".", r"\.")):
        ObjectTrajectory(pin.SE3.Identity(), pin.SE3.Identity(), duration, dt)
