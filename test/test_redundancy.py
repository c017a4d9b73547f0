"""Redundancy resolution: tip trajectory kept, effective mass never higher, 6-DOF unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM7_AXES, BAXTER_SEED, book_trajectory, serial_arm_urdf

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
from grasp_safety_ros.core.analyses.effort import evaluate_effort
from grasp_safety_ros.core.analyses.null_space import bernstein_basis, metric_weights
from grasp_safety_ros.core.analyses.redundancy import (
    RedundancyConfig,
    RedundancyResolution,
    resolve_redundancy,
)
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, analyse
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    effective_mass_along,
    translational_mobility_in_base,
    worst_direction,
)
from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.core.method.ranking import METRICS, aggregate

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


def book_grasp(y_m: float) -> Grasp:
    """The paper's book grasps, at y along the spine."""
    return Grasp(pose_from_position_quat([-0.075, y_m, 0.0], [0, 0, 0, 1], "grasp"))


def check_executable(
    robot: RobotModel,
    obj: ObjectInertia,
    grasp: Grasp,
    trajectory: ObjectTrajectory,
    evaluation: GraspEvaluation,
    result: RedundancyResolution,
) -> None:
    """Inverse dynamics (core.effort) of the resolved q(t): as smooth as the IK's, torques ok."""
    before = evaluate_effort(robot, evaluation, obj, grasp, trajectory)
    after = evaluate_effort(robot, evaluation, obj, grasp, trajectory, result.joint_positions)
    peak_acceleration = np.abs(before.joint_accelerations).max()
    assert np.abs(after.joint_accelerations).max() <= 2.0 * peak_acceleration
    assert np.abs(after.joint_velocities).max() <= 2.0 * np.abs(before.joint_velocities).max()
    allowed = np.fmax(before.effort_limits, before.peak_abs_torque)  # NaN limit: original peak
    assert np.all(after.peak_abs_torque <= allowed * (1 + 1e-6))
    # Still at rest at both ends (the quintic's ds/dt = d²s/dt² = 0 there).
    for k in (0, -1):
        np.testing.assert_allclose(after.joint_velocities[k], 0.0, atol=1e-9)
        np.testing.assert_allclose(after.joint_accelerations[k], 0.0, atol=1e-9)


def check_resolution(
    robot: RobotModel,
    obj: ObjectInertia,
    grasp: Grasp,
    trajectory: ObjectTrajectory,
    evaluation: GraspEvaluation,
    config: RedundancyConfig,
) -> RedundancyResolution:
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
    ceiling = evaluation.effective_mass_kg * (1 + config.max_sample_increase)
    assert np.all(result.effective_mass_kg <= ceiling + 1e-9)
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
    assert np.all(result.reduction_kg >= evaluation.effective_mass_kg - ceiling - 1e-9)
    check_executable(robot, obj, grasp, trajectory, evaluation, result)
    return result


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
    trajectory = book_trajectory(0.05)
    grasp = book_grasp(0.1)
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        grasp, BOOK, trajectory, seed_positions=BAXTER_SEED
    )
    assert evaluation.feasible, evaluation.reason
    check_resolution(baxter, BOOK, grasp, trajectory, evaluation, RedundancyConfig())


def test_baxter_book_resolved_motion_is_smooth(baxter: RobotModel) -> None:
    """The grasp at −0.1 m: sample-by-sample descent made q̈ 125x and τ 3.5x the IK's.

    Its optimum posture is far from the IK's at the start, where ds/dt ≈ 0; a smooth
    null-space profile lowers the score without that (q̈, q̇ and torques are checked by
    core.effort's inverse dynamics in check_executable).
    """
    trajectory = book_trajectory(0.05)
    grasp = book_grasp(-0.1)
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        grasp, BOOK, trajectory, seed_positions=BAXTER_SEED
    )
    assert evaluation.feasible, evaluation.reason
    config = RedundancyConfig()
    result = check_resolution(baxter, BOOK, grasp, trajectory, evaluation, config)
    assert result.score <= 0.995 * result.original_score  # a real gain, not rounding
    # The start posture is part of the optimisation (the arm is at rest before it).
    assert np.abs(result.joint_positions[0] - evaluation.joint_positions[0]).max() > 1e-3


def test_strict_per_sample_bound(arm7: RobotModel) -> None:
    positions = np.array([0.3, 0.6, -0.4, -1.1, 0.5, 0.8, -0.2])
    grasp = Grasp(pin.SE3(pin.exp3(np.array([0.3, 0.1, -0.2])), np.array([0.0, 0.05, -0.12])))
    trajectory = trajectory_from_configuration(arm7, positions, grasp)
    evaluation = GraspSafetyEvaluator(arm7).evaluate(
        grasp, BOX, trajectory, seed_positions=positions, metric="integral"
    )
    config = RedundancyConfig(max_sample_increase=0.0, metric="integral")
    result = check_resolution(arm7, BOX, grasp, trajectory, evaluation, config)
    assert np.all(result.effective_mass_kg <= evaluation.effective_mass_kg)


def test_bernstein_basis_is_a_partition_of_unity() -> None:
    s = np.linspace(0.0, 1.0, 11)
    for degree in range(6):
        basis = bernstein_basis(degree, s)
        assert basis.shape == (11, degree + 1) and np.all(basis >= 0)
        np.testing.assert_allclose(basis.sum(axis=1), 1.0, rtol=1e-14)
        np.testing.assert_allclose(basis[0], np.eye(degree + 1)[0])  # δ(0) = D_0
        np.testing.assert_allclose(basis[-1], np.eye(degree + 1)[-1])  # δ(1) = D_d


@pytest.mark.parametrize("metric", METRICS)
def test_metric_weights_are_the_aggregate_gradient(metric: str) -> None:
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.uniform(0.01, 0.05, 9))
    masses = rng.uniform(1.0, 2.0, 9)
    h = 1e-6
    numeric = [
        (
            aggregate(masses + h * np.eye(9)[i], times, metric)
            - aggregate(masses - h * np.eye(9)[i], times, metric)
        )
        / (2 * h)
        for i in range(9)
    ]
    np.testing.assert_allclose(metric_weights(masses, times, metric), numeric, atol=1e-8)


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
        ({"iterations": -1}, "redundancy.iterations"),
        ({"iterations": 2.0}, "redundancy.iterations"),
        ({"profile_degree": 13}, "redundancy.profile_degree"),
        ({"max_rate_ratio": 0.9}, "redundancy.max_rate_ratio"),
        ({"max_effort_fraction": 0.0}, "redundancy.max_effort_fraction"),
        ({"max_sample_increase": -1e-3}, "redundancy.max_sample_increase"),
        ({"relative_tolerance": float("nan")}, "redundancy.relative_tolerance"),
        ({"initial_step_rad": 0.0}, "redundancy.initial_step_rad"),
        ({"min_step_rad": 0.1, "initial_step_rad": 0.05}, "redundancy.min_step_rad"),
        ({"max_joint_step": float("inf")}, "redundancy.max_joint_step"),
        ({"metric": "median"}, "redundancy.metric"),
    ],
)
def test_bad_settings_are_refused(kwargs: dict, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field.replace(".", r"\.")):
        RedundancyConfig(**kwargs)


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
@pytest.mark.parametrize("case", ["arm7", "geared", "baxter", "arm7_worst"])
def test_compiled_trial_masses_equal_pinocchio(
    case: str, arm7: RobotModel, baxter: RobotModel
) -> None:
    """Each trial's effective masses from the compiled mobility kernel: the same trials are
    accepted (joint positions bit for bit), masses and score equal to 1e-12 of scale; armature
    and worst-direction samples included."""
    if case == "baxter":
        robot, obj, grasp, trajectory = baxter, BOOK, book_grasp(-0.1), book_trajectory(0.05)
        positions = np.array(BAXTER_SEED)
    else:
        robot = arm7
        if case == "geared":
            armature = [0.3, 0.25, 0.2, 0.1, 0.05, 0.04, 0.02]
            robot = RobotModel.from_urdf(
                serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool", armature_kgm2=armature
            )
        positions = np.array([0.3, 0.6, -0.4, -1.1, 0.5, 0.8, -0.2])
        grasp = Grasp(pin.SE3(pin.exp3(np.array([0.3, 0.1, -0.2])), np.array([0.0, 0.05, -0.12])))
        obj, trajectory = BOX, trajectory_from_configuration(robot, positions, grasp)
    evaluator = GraspSafetyEvaluator(robot)
    evaluation = evaluator.evaluate(grasp, obj, trajectory, seed_positions=positions)
    assert evaluation.feasible, evaluation.reason
    if case == "arm7_worst":  # the largest effective mass over directions at two samples
        worst = evaluation.direction_is_worst_case.copy()
        worst[[0, 5]] = True
        evaluation = replace(evaluation, direction_is_worst_case=worst)
        masses = recomputed_effective_mass(
            robot, obj, grasp, evaluation, evaluation.joint_positions
        )
        evaluation = replace(evaluation, effective_mass_kg=masses)
    config = RedundancyConfig(iterations=8)
    reference = resolve_redundancy(robot, evaluation, obj, grasp, trajectory, config)
    compiled = resolve_redundancy(
        robot, evaluation, obj, grasp, trajectory, config, chain=evaluator.ik.chain
    )
    assert reference.applied and reference.score < reference.original_score
    np.testing.assert_array_equal(compiled.joint_positions, reference.joint_positions)
    scale = np.abs(reference.effective_mass_kg).max()
    error = np.abs(compiled.effective_mass_kg - reference.effective_mass_kg).max() / scale
    assert error <= 1e-12, f"relative error {error:.2e}"
    assert compiled.score == pytest.approx(reference.score, rel=1e-12)
    assert compiled.samples_improved == reference.samples_improved


def test_analyse_runs_with_the_options_redundancy_settings(arm7: RobotModel) -> None:
    """AnalysisOptions.redundancy_settings reach the optimisation: no descent step allowed
    (iterations 0) leaves the score the IK's; the default settings lower it."""
    positions = np.array([0.3, 0.6, -0.4, -1.1, 0.5, 0.8, -0.2])
    grasp = Grasp(pin.SE3(pin.exp3(np.array([0.3, 0.1, -0.2])), np.array([0.0, 0.05, -0.12])))
    trajectory = trajectory_from_configuration(arm7, positions, grasp)
    evaluator = GraspSafetyEvaluator(arm7)
    options = AnalysisOptions(redundancy=True, effort=False, iso_regions=())
    kept = replace(options, redundancy_settings=RedundancyConfig(iterations=0))
    (still,) = analyse(evaluator, [grasp], BOX, trajectory, kept, positions).redundancy
    (lowered,) = analyse(evaluator, [grasp], BOX, trajectory, options, positions).redundancy
    assert still.score == still.original_score
    assert lowered.score < lowered.original_score
