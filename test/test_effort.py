"""Post-grasp effort: static gravity, a closed-form pendulum, the object's share, consistency."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, book_trajectory

from grasp_safety_ros.core import (
    Grasp,
    GraspEvaluation,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectInertia,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.effort import (
    evaluate_effort,
    order_by_effort,
    tip_twist_and_derivative,
)
from grasp_safety_ros.core.analyses.exposed_points import point_jacobian_in_base
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.effective_mass import augmented_model

BOOK = solid_box(0.34, [0.15, 0.22, 0.015])
GRASP = Grasp(pose_from_position_quat([-0.075, 0.1, 0.0], [0, 0, 0, 1], "grasp"), "spine")
START = pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start")
TURNING = (0.2, -0.3, 0.25)
"""The goal orientation turned about a generic axis, so that the object also rotates."""


def evaluate(robot: RobotModel, trajectory: ObjectTrajectory, obj: ObjectInertia = BOOK):
    evaluation = GraspSafetyEvaluator(robot).evaluate(
        GRASP, obj, trajectory, seed_positions=BAXTER_SEED
    )
    assert evaluation.feasible, evaluation.reason
    return evaluation


def test_static_object_needs_exactly_the_gravity_torque(baxter: RobotModel) -> None:
    trajectory = ObjectTrajectory(START, START, 1.0, 0.25)
    evaluation = evaluate(baxter, trajectory)
    effort = evaluate_effort(baxter, evaluation, BOOK, GRASP, trajectory)
    model = augmented_model(baxter, BOOK, GRASP.transform_tip_to_object)
    data = model.createData()
    np.testing.assert_allclose(effort.joint_velocities, 0.0, atol=1e-12)
    np.testing.assert_allclose(effort.joint_accelerations, 0.0, atol=1e-12)
    for positions, torque in zip(evaluation.joint_positions, effort.joint_torques, strict=True):
        gravity = pin.computeGeneralizedGravity(model, data, baxter.q_from_positions(positions))
        np.testing.assert_allclose(torque, gravity, rtol=1e-12, atol=1e-12)


def test_rest_at_both_ends_of_a_quintic_is_static(baxter: RobotModel) -> None:
    trajectory = book_trajectory(goal_rotation_log=TURNING)
    evaluation = evaluate(baxter, trajectory)
    effort = evaluate_effort(baxter, evaluation, BOOK, GRASP, trajectory)
    model = augmented_model(baxter, BOOK, GRASP.transform_tip_to_object)
    for i in (0, -1):
        q = baxter.q_from_positions(evaluation.joint_positions[i])
        gravity = pin.computeGeneralizedGravity(model, model.createData(), q)
        np.testing.assert_array_equal(effort.joint_velocities[i], 0.0)
        np.testing.assert_array_equal(effort.joint_accelerations[i], 0.0)
        np.testing.assert_allclose(effort.joint_torques[i], gravity, rtol=1e-12, atol=1e-12)


def test_object_adds_exactly_its_gravity_share(baxter: RobotModel) -> None:
    """Static: τ_with − τ_robot = −J_comᵀ m g (J_com: the object's CoM, rigidly on the tip)."""
    heavy = ObjectInertia(2.5, [0.03, -0.02, 0.04], np.diag([0.02, 0.03, 0.04]))
    trajectory = ObjectTrajectory(START, START, 1.0, 0.5)
    evaluation = evaluate(baxter, trajectory, heavy)
    effort = evaluate_effort(baxter, evaluation, heavy, GRASP, trajectory)
    com_in_tip = GRASP.transform_tip_to_object.inverse().act(heavy.com_in_object_m)
    gravity_in_base = baxter.transform_base_to_world.rotation.T @ baxter.model.gravity.linear
    for positions, torque in zip(evaluation.joint_positions, effort.joint_torques, strict=True):
        q = baxter.q_from_positions(positions)
        robot_only = pin.computeGeneralizedGravity(baxter.model, baxter.model.createData(), q)
        jacobian = point_jacobian_in_base(
            baxter, baxter.model, baxter.model.createData(), q, com_in_tip[None]
        )[0]
        share = -jacobian.T @ (heavy.mass_kg * gravity_in_base)
        np.testing.assert_allclose(torque - robot_only, share, rtol=1e-10, atol=1e-10)
        assert np.abs(share).max() > 1.0  # a real contribution, not a vacuous check


PENDULUM_URDF = """
<robot name="pendulum">
  <link name="base"/>
  <link name="arm"/>
  <joint name="hinge" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="0 0 1.0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="40" velocity="100"/>
  </joint>
</robot>
"""


def test_pendulum_closed_form() -> None:
    """Massless arm holding the object about the hinge: τ = m g l sin θ + (I_yy + m l²) θ̈."""
    robot = RobotModel.from_urdf(PENDULUM_URDF, "base", "arm")
    mass, lever, inertia_yy = 2.0, 0.7, 0.05
    obj = ObjectInertia(mass, [0.0, 0.0, -lever], np.diag([0.04, inertia_yy, 0.03]))
    grasp = Grasp(pin.SE3.Identity())
    theta_start, theta_goal = -0.4, 1.3
    hinge = np.array([0.0, 0.0, 1.0])
    trajectory = ObjectTrajectory(
        pin.SE3(pin.exp3(np.array([0.0, theta_start, 0.0])), hinge),
        pin.SE3(pin.exp3(np.array([0.0, theta_goal, 0.0])), hinge),
        1.5,
        0.01,
    )
    times = trajectory.times_s()
    s, s_rate, s_accel = trajectory.path_parameter(times)
    theta = theta_start + s * (theta_goal - theta_start)
    count = len(times)
    evaluation = GraspEvaluation(
        0,
        "hinge",
        True,
        "",
        0.0,
        times,
        theta[:, None],
        np.zeros((count, 3)),
        np.ones(count),
        np.zeros(count, dtype=bool),
        np.zeros(count),
        np.zeros(count, dtype=int),
    )
    effort = evaluate_effort(robot, evaluation, obj, grasp, trajectory)
    theta_rate = (theta_goal - theta_start) * s_rate
    theta_accel = (theta_goal - theta_start) * s_accel
    np.testing.assert_allclose(effort.joint_velocities[:, 0], theta_rate, atol=1e-12)
    np.testing.assert_allclose(effort.joint_accelerations[:, 0], theta_accel, atol=1e-11)
    expected = mass * 9.81 * lever * np.sin(theta) + (inertia_yy + mass * lever**2) * theta_accel
    np.testing.assert_allclose(effort.joint_torques[:, 0], expected, atol=1e-10)
    assert effort.peak_abs_torque[0] == pytest.approx(np.abs(expected).max(), rel=1e-10)
    assert effort.rms_torque[0] == pytest.approx(math.sqrt(np.mean(expected**2)), rel=1e-10)
    assert effort.peak_fraction_of_limit[0] == pytest.approx(effort.peak_abs_torque[0] / 40.0)
    assert effort.score("peak_fraction") == effort.peak_fraction_of_limit[0]
    assert effort.score("rms_fraction") == effort.rms_fraction_of_limit[0]


def test_twist_matches_finite_differences_of_the_tip_path() -> None:
    trajectory = book_trajectory(0.001, goal_rotation_log=TURNING)
    times = trajectory.times_s()
    s, _, _ = trajectory.path_parameter(times)
    poses, _ = trajectory.tip_path(GRASP.transform_tip_to_object, s)
    twist, twist_rate = tip_twist_and_derivative(trajectory, GRASP.transform_tip_to_object, times)
    positions = np.array([p.translation for p in poses])
    np.testing.assert_allclose(twist[:, :3], np.gradient(positions, times, axis=0), atol=1e-5)
    np.testing.assert_allclose(
        twist_rate[1:-1], np.gradient(twist, times, axis=0)[1:-1], atol=1e-5
    )
    for i in range(1, len(poses) - 1, 97):  # angular velocity from the rotation increments
        delta = pin.log3(poses[i + 1].rotation @ poses[i - 1].rotation.T)
        np.testing.assert_allclose(twist[i, 3:], delta / (times[i + 1] - times[i - 1]), atol=1e-5)


def test_joint_motion_is_consistent_with_the_samples_and_the_tip(baxter: RobotModel) -> None:
    """J q̇ is the tip twist exactly; q̇ and q̈ agree with differences of the IK samples."""
    trajectory = book_trajectory(0.01, goal_rotation_log=TURNING)
    evaluation = evaluate(baxter, trajectory)
    effort = evaluate_effort(baxter, evaluation, BOOK, GRASP, trajectory)
    times = evaluation.times_s
    twist, _ = tip_twist_and_derivative(trajectory, GRASP.transform_tip_to_object, times)
    data = baxter.model.createData()
    for i in range(0, len(times), 10):
        q = baxter.q_from_positions(evaluation.joint_positions[i])
        jacobian = pin.computeFrameJacobian(
            baxter.model, data, q, baxter.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        np.testing.assert_allclose(jacobian @ effort.joint_velocities[i], twist[i], atol=1e-10)
    velocity_fd = np.gradient(evaluation.joint_positions, times, axis=0)
    np.testing.assert_allclose(effort.joint_velocities, velocity_fd, atol=2e-3)
    acceleration_fd = np.gradient(velocity_fd, times, axis=0)
    np.testing.assert_allclose(effort.joint_accelerations[2:-2], acceleration_fd[2:-2], atol=0.05)
    model = augmented_model(baxter, BOOK, GRASP.transform_tip_to_object)
    k = len(times) // 2
    q = baxter.q_from_positions(evaluation.joint_positions[k])
    np.testing.assert_allclose(
        effort.joint_torques[k],
        pin.rnea(
            model, model.createData(), q, effort.joint_velocities[k], effort.joint_accelerations[k]
        ),
        rtol=1e-12,
    )
    np.testing.assert_allclose(effort.effort_limits, baxter.model.effortLimit)
    assert effort.max_peak_fraction == pytest.approx(
        np.max(np.abs(effort.joint_torques).max(axis=0) / baxter.model.effortLimit)
    )


def test_order_by_effort_and_infeasible(baxter: RobotModel) -> None:
    trajectory = book_trajectory(goal_rotation_log=TURNING)
    light = evaluate_effort(baxter, evaluate(baxter, trajectory), BOOK, GRASP, trajectory)
    heavy_object = BOOK.scaled(10.0)
    heavy = evaluate_effort(
        baxter, evaluate(baxter, trajectory, heavy_object), heavy_object, GRASP, trajectory
    )
    far = Grasp(pose_from_position_quat([0.0, 0.0, 3.0], [0, 0, 0, 1], "grasp"), "far")
    infeasible_evaluation = GraspSafetyEvaluator(baxter).evaluate(
        far, BOOK, trajectory, 2, seed_positions=BAXTER_SEED
    )
    infeasible = evaluate_effort(baxter, infeasible_evaluation, BOOK, far, trajectory)
    assert not infeasible.feasible and math.isnan(infeasible.score())
    heavy = dataclasses.replace(heavy, index=1)
    assert heavy.max_peak_fraction > light.max_peak_fraction
    assert order_by_effort([heavy, light, infeasible]) == (0, 1)
    assert order_by_effort([heavy, light, infeasible], "rms_fraction") == (0, 1)
    with pytest.raises(InvalidInputError, match="effort_criterion"):
        order_by_effort([light], "peak")


def test_wrong_joint_positions_are_refused(baxter: RobotModel) -> None:
    trajectory = book_trajectory(goal_rotation_log=TURNING)
    evaluation = evaluate(baxter, trajectory)
    with pytest.raises(InvalidInputError, match="joint_positions"):
        evaluate_effort(baxter, evaluation, BOOK, GRASP, trajectory, np.zeros((3, 7)))
