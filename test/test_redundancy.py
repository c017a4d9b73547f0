"""Redundancy resolution: tip trajectory kept, effective mass never higher, 6-DOF unchanged."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED

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
from grasp_safety_ros.core.effective_mass import (
    augmented_model,
    effective_mass_along,
    translational_mobility_in_base,
    worst_direction,
)
from grasp_safety_ros.core.redundancy import RedundancyConfig, resolve_redundancy
from grasp_safety_ros.core.validation import pose_from_position_quat

BOOK = solid_box(0.34, [0.15, 0.22, 0.015])
BOX = solid_box(1.5, [0.1, 0.2, 0.3], [0.02, 0.0, 0.05])


def trajectory_from_configuration(
    robot: RobotModel, positions: np.ndarray, grasp: Grasp
) -> ObjectTrajectory:
    """An object motion that starts where the tip is at ``positions`` (reachable by design)."""
    start = robot.transform_tip_to_base(positions) * grasp.transform_tip_to_object.inverse()
    goal = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.15, -0.1, 0.2])),
        start.translation + np.array([0.08, -0.06, 0.05]),
    )
    return ObjectTrajectory(start, goal, 2.0, 0.05)


def recomputed_effective_mass(
    robot: RobotModel,
    obj: ObjectInertia,
    grasp: Grasp,
    evaluation: GraspEvaluation,
    joint_positions: np.ndarray,
) -> np.ndarray:
    model = augmented_model(robot, obj, grasp.transform_tip_to_object)
    data = model.createData()
    masses = []
    for positions, direction, worst in zip(
        joint_positions,
        evaluation.directions_in_base,
        evaluation.direction_is_worst_case,
        strict=True,
    ):
        mobility = translational_mobility_in_base(
            robot, model, data, robot.q_from_positions(positions)
        )
        masses.append(
            worst_direction(mobility)[1] if worst else effective_mass_along(mobility, direction)
        )
    return np.array(masses)


def check_resolution(
    robot: RobotModel,
    obj: ObjectInertia,
    grasp: Grasp,
    trajectory: ObjectTrajectory,
    evaluation: GraspEvaluation,
    config: RedundancyConfig,
) -> None:
    result = resolve_redundancy(robot, evaluation, obj, grasp, trajectory, config)
    assert result.applied, result.reason
    s_values, _, _ = trajectory.path_parameter(evaluation.times_s)
    for positions, s in zip(result.joint_positions, s_values, strict=True):
        target = trajectory.transform_object_to_base(float(s)) * grasp.transform_tip_to_object
        reached = robot.transform_tip_to_base(positions)
        assert np.linalg.norm(reached.translation - target.translation) <= 1e-6
        assert np.linalg.norm(pin.log3(reached.rotation.T @ target.rotation)) <= 1e-6
        assert np.all(positions >= robot.lower_limits) and np.all(positions <= robot.upper_limits)
    assert result.max_position_error_m <= 1e-6 and result.max_orientation_error_rad <= 1e-6
    assert np.all(result.effective_mass_kg <= evaluation.effective_mass_kg + 1e-9)
    np.testing.assert_allclose(
        result.effective_mass_kg,
        recomputed_effective_mass(robot, obj, grasp, evaluation, result.joint_positions),
        rtol=1e-9,
    )
    steps = np.abs(np.diff(result.joint_positions, axis=0))
    assert steps.max() <= config.max_joint_step
    elapsed = np.diff(result.times_s)[:, None]
    limits = robot.velocity_limits
    assert np.all(steps <= limits * elapsed * (1 + 1e-9))
    np.testing.assert_array_equal(result.original_effective_mass_kg, evaluation.effective_mass_kg)
    np.testing.assert_array_equal(result.original_joint_positions, evaluation.joint_positions)
    assert result.original_score == pytest.approx(evaluation.score, rel=1e-15)
    assert result.score < result.original_score  # it does lower the effective mass
    assert result.samples_improved > 0
    assert np.all(result.reduction_kg >= -1e-9)


def test_arm7_keeps_the_tip_and_lowers_the_effective_mass(arm7: RobotModel) -> None:
    positions = np.array([0.3, 0.6, -0.4, -1.1, 0.5, 0.8, -0.2])
    grasp = Grasp(pin.SE3(pin.exp3(np.array([0.3, 0.1, -0.2])), np.array([0.0, 0.05, -0.12])))
    trajectory = trajectory_from_configuration(arm7, positions, grasp)
    evaluation = GraspSafetyEvaluator(arm7).evaluate(
        grasp, BOX, trajectory, seed_positions=positions
    )
    assert evaluation.feasible, evaluation.reason
    check_resolution(arm7, BOX, grasp, trajectory, evaluation, RedundancyConfig())


def test_baxter_book_keeps_the_tip_and_lowers_the_effective_mass(baxter: RobotModel) -> None:
    trajectory = ObjectTrajectory(
        pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start"),
        pose_from_position_quat([1.1, -0.38, 0.16], [0.5, 0.5, 0.5, 0.5], "goal"),
        2.0,
        0.05,
    )
    grasp = Grasp(pose_from_position_quat([-0.075, 0.1, 0.0], [0, 0, 0, 1], "grasp"))
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        grasp, BOOK, trajectory, seed_positions=BAXTER_SEED
    )
    assert evaluation.feasible, evaluation.reason
    check_resolution(baxter, BOOK, grasp, trajectory, evaluation, RedundancyConfig())


def test_six_joint_arm_is_returned_unchanged(arm6: RobotModel) -> None:
    positions = np.array([0.1, 0.4, -1.2, 0.3, -0.7, 0.5])
    grasp = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.1])))
    trajectory = trajectory_from_configuration(arm6, positions, grasp)
    evaluation = GraspSafetyEvaluator(arm6).evaluate(
        grasp, BOX, trajectory, seed_positions=positions
    )
    assert evaluation.feasible, evaluation.reason
    result = resolve_redundancy(arm6, evaluation, BOX, grasp, trajectory)
    assert not result.applied and "no redundancy" in result.reason
    np.testing.assert_array_equal(result.joint_positions, evaluation.joint_positions)
    np.testing.assert_array_equal(result.effective_mass_kg, evaluation.effective_mass_kg)
    assert result.score == result.original_score == pytest.approx(evaluation.score, rel=1e-15)
    assert result.samples_improved == 0


def test_switched_off_and_infeasible_are_unchanged(arm7: RobotModel) -> None:
    positions = np.array([0.3, 0.6, -0.4, -1.1, 0.5, 0.8, -0.2])
    grasp = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.1])))
    trajectory = trajectory_from_configuration(arm7, positions, grasp)
    evaluation = GraspSafetyEvaluator(arm7).evaluate(
        grasp, BOX, trajectory, seed_positions=positions
    )
    off = resolve_redundancy(
        arm7, evaluation, BOX, grasp, trajectory, RedundancyConfig(enabled=False)
    )
    assert not off.applied and "switched off" in off.reason
    np.testing.assert_array_equal(off.joint_positions, evaluation.joint_positions)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])))
    infeasible = GraspSafetyEvaluator(arm7).evaluate(
        far, BOX, trajectory, seed_positions=positions
    )
    result = resolve_redundancy(arm7, infeasible, BOX, far, trajectory)
    assert not result.feasible and not result.applied and np.isnan(result.score)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"enabled": "yes"}, "redundancy.enabled"),
        ({"iterations_per_sample": -1}, "redundancy.iterations_per_sample"),
        ({"initial_step_rad": 0.0}, "redundancy.initial_step_rad"),
        ({"min_step_rad": 0.1, "initial_step_rad": 0.05}, "redundancy.min_step_rad"),
        ({"max_joint_step": float("inf")}, "redundancy.max_joint_step"),
        ({"metric": "median"}, "redundancy.metric"),
    ],
)
def test_bad_settings_are_refused(kwargs: dict, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field.replace(".", r"\.")):
        RedundancyConfig(**kwargs)
