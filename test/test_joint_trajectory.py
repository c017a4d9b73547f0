"""Planned joint trajectories per grasp: the IK's own output gives the IK route's effective
mass; bad input names the field."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, book_trajectory

from grasp_safety_ros.core import Grasp, GraspSafetyEvaluator, InvalidInputError, solid_box
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, analyse
from grasp_safety_ros.core.method.joint_trajectory import (
    JointSpaceTrajectory,
    PlannedJointTrajectory,
)

BOOK = solid_box(0.34, [0.15, 0.22, 0.015])
GRASP = pin.SE3(np.eye(3), np.array([0.0, -0.1, 0.0]))


def ik_route(baxter, dt=0.05):
    trajectory = book_trajectory(dt_s=dt, goal_rotation_log=(0.2, 0.0, -0.1))
    evaluator = GraspSafetyEvaluator(baxter)
    evaluation = evaluator.evaluate(Grasp(GRASP), BOOK, trajectory, seed_positions=BAXTER_SEED)
    assert evaluation.feasible, evaluation.reason
    return evaluator, trajectory, evaluation


def exact_rates(baxter, trajectory, evaluation):
    """q̇ = J⁺ V with V the tip twist of the object trajectory (J q̇ = V exactly, 6 x 7)."""
    twists, _ = trajectory.tip_twists(GRASP, evaluation.times_s)
    model, data = baxter.model, baxter.model.createData()
    base = baxter.transform_base_to_world.rotation
    rates = []
    for q, twist in zip(evaluation.joint_positions, twists, strict=True):
        pin.computeJointJacobians(model, data, q)
        jacobian = pin.getFrameJacobian(
            model, data, baxter.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        world = np.concatenate([base @ twist[:3], base @ twist[3:]])
        rates.append(np.linalg.pinv(jacobian) @ world)
    return np.array(rates)


def test_ik_output_as_joint_trajectory_gives_the_ik_effective_mass(baxter) -> None:
    evaluator, trajectory, evaluation = ik_route(baxter)
    rates = exact_rates(baxter, trajectory, evaluation)
    # Shuffled columns plus a joint off the chain: names are matched, extras ignored.
    names = [*list(baxter.joint_names)[::-1], "head_pan"]
    positions = np.column_stack([evaluation.joint_positions[:, ::-1], np.zeros(len(rates))])
    velocities = np.column_stack([rates[:, ::-1], np.zeros(len(rates))])
    planned = PlannedJointTrajectory(tuple(names), evaluation.times_s, positions, velocities)
    joint = evaluator.evaluate(Grasp(GRASP, joint_trajectory=planned), BOOK, trajectory)
    assert joint.feasible
    np.testing.assert_array_equal(joint.times_s, evaluation.times_s)
    np.testing.assert_array_equal(joint.joint_positions, evaluation.joint_positions)
    moving = slice(1, -1)  # the tip moves: direction J q̇ = the path tangent
    np.testing.assert_allclose(
        joint.effective_mass_kg[moving], evaluation.effective_mass_kg[moving], rtol=1e-9
    )
    np.testing.assert_allclose(
        joint.directions_in_base[moving], evaluation.directions_in_base[moving], atol=1e-9
    )
    np.testing.assert_allclose(joint.tip_speed_m_s, evaluation.tip_speed_m_s, atol=1e-9)
    # At the rest ends the direction is the interpolant's limit (J q̈), an approximation of
    # the path's: close, not exact.
    np.testing.assert_allclose(
        joint.effective_mass_kg[[0, -1]], evaluation.effective_mass_kg[[0, -1]], rtol=2e-2
    )


def test_joint_positions_only_use_a_cubic_spline(baxter) -> None:
    """Without velocities the direction comes from the C2 cubic spline: close to the path
    tangent on a fine trajectory, and the tip poses are forward kinematics of the points."""
    evaluator, trajectory, evaluation = ik_route(baxter, dt=0.02)
    planned = PlannedJointTrajectory(
        baxter.joint_names, evaluation.times_s, evaluation.joint_positions
    )
    motion = JointSpaceTrajectory(baxter, planned, GRASP)
    tip = motion.tip_motion(GRASP, motion.times_s())
    for k in (0, 40, len(tip.positions) - 1):
        pose = baxter.transform_tip_to_base(evaluation.joint_positions[k])
        np.testing.assert_allclose(tip.positions[k], pose.translation, atol=1e-12)
    reference = trajectory.tip_motion(GRASP, motion.times_s())
    np.testing.assert_allclose(tip.positions, reference.positions, atol=2e-6)  # IK tolerance
    joint = evaluator.evaluate(Grasp(GRASP, joint_trajectory=planned), BOOK, trajectory)
    np.testing.assert_allclose(joint.effective_mass_kg, evaluation.effective_mass_kg, rtol=1e-2)
    rotations, positions = motion.object_poses(motion.times_s())
    object_reference = trajectory.object_poses(motion.times_s())
    np.testing.assert_allclose(positions, object_reference[1], atol=2e-6)
    np.testing.assert_allclose(rotations, object_reference[0], atol=2e-6)


def test_analyses_run_on_a_joint_trajectory(baxter) -> None:
    evaluator, trajectory, evaluation = ik_route(baxter)
    planned = PlannedJointTrajectory(
        baxter.joint_names, evaluation.times_s, evaluation.joint_positions
    )
    grasps = [Grasp(GRASP, "ik"), Grasp(GRASP, "planned", joint_trajectory=planned)]
    options = AnalysisOptions(
        metric_point="leading_point",
        points_in_object_m=box_corners_in_object([0.15, 0.22, 0.015]),
        effort=True,
        redundancy=True,
    )
    report = analyse(evaluator, grasps, BOOK, trajectory, options, BAXTER_SEED)
    assert np.all(np.isfinite(report.scores))
    np.testing.assert_allclose(report.scores[0], report.scores[1], rtol=2e-2)
    torques = [e.joint_torques for e in report.effort]
    np.testing.assert_allclose(torques[1], torques[0], rtol=0.05, atol=0.5)


def _planned(baxter, **changes):
    times = np.array([0.0, 0.5, 1.0])
    positions = np.tile(np.array(BAXTER_SEED), (3, 1))
    values = {"joint_names": baxter.joint_names, "times_s": times, "positions": positions}
    values.update(changes)
    return PlannedJointTrajectory(**values, field="grasps[1].joint_trajectory")


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"times_s": np.array([0.0, 0.5, 0.5])}, "grasps[1].joint_trajectory.points[2].time_s"),
        ({"times_s": np.array([0.0, 0.7, 0.5])}, "grasps[1].joint_trajectory.points[2].time_s"),
        ({"times_s": np.array([0.0, np.nan, 1.0])}, "grasps[1].joint_trajectory.points[1].time_s"),
        ({"times_s": np.array([0.0])}, "grasps[1].joint_trajectory.points"),
        ({"joint_names": ("a", "a")}, "grasps[1].joint_trajectory.joint_names"),
        (
            {"positions": np.array([[0.0] * 7, [np.inf] + [0.0] * 6, [0.0] * 7])},
            "grasps[1].joint_trajectory.points[1].positions",
        ),
        ({"positions": np.zeros((3, 6))}, "grasps[1].joint_trajectory.points[0].positions"),
    ],
)
def test_bad_planned_trajectories_name_the_field(baxter, changes, field) -> None:
    with pytest.raises(InvalidInputError) as error:
        _planned(baxter, **changes)
    assert error.value.field == field


def test_missing_chain_joint_and_limits_are_refused_before_any_work(baxter) -> None:
    evaluator = GraspSafetyEvaluator(baxter)
    trajectory = book_trajectory()
    planned = _planned(
        baxter,
        joint_names=(*baxter.joint_names[:-1], "head_pan"),
        positions=np.zeros((3, 7)),
    )
    with pytest.raises(InvalidInputError, match="right_w2") as error:
        evaluator.rank([Grasp(GRASP), Grasp(GRASP, joint_trajectory=planned)], BOOK, trajectory)
    assert error.value.field == "grasps[1].joint_trajectory.joint_names"
    positions = np.tile(np.array(BAXTER_SEED), (3, 1))
    positions[2, 1] = 5.0  # right_s1 beyond its limit
    planned = _planned(baxter, positions=positions)
    with pytest.raises(InvalidInputError, match="right_s1") as error:
        evaluator.rank([Grasp(GRASP, joint_trajectory=planned)], BOOK, trajectory)
    assert error.value.field == "grasps[1].joint_trajectory.points[2].positions"


def test_posture_selection_keeps_a_planned_motion_as_given(baxter) -> None:
    from grasp_safety_ros.core.method.posture import PostureConfig
    from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline

    evaluator, trajectory, evaluation = ik_route(baxter)
    # The IK route given as a planned motion: posture selection must leave it as planned.
    positions = evaluation.joint_positions.copy()
    planned = PlannedJointTrajectory(tuple(baxter.joint_names), evaluation.times_s, positions)
    grasps = (Grasp(GRASP, joint_trajectory=planned), Grasp(GRASP))
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
    request = PipelineRequest(
        grasps, BOOK, trajectory, posture=PostureConfig(restarts=4), seed_positions=BAXTER_SEED
    )
    selected = run_pipeline(evaluator, request).ranking
    planned_result = selected.evaluations[0]
    # never replaced by an IK posture: the planned motion's evaluation, as ranked
    np.testing.assert_array_equal(
        planned_result.effective_mass_kg, ranking.evaluations[0].effective_mass_kg
    )
    assert selected.postures[0].postures_tried == 1
    np.testing.assert_array_equal(planned_result.joint_positions, positions)
    assert selected.postures[1].postures_tried >= 1


def test_a_plan_without_velocities_exports_the_analysed_splines_rates(baxter) -> None:
    """Joint positions of a cubic polynomial in time: the analysed (not-a-knot) spline is
    that polynomial, so the exported q̇, q̈ are its derivatives, also at the ends where the
    plan is not at rest (a clamped spline would say q̇ = 0 there)."""
    from grasp_safety_ros.core.method.executable import rates_for_execution

    times = np.linspace(0.0, 2.0, 9)
    coefficients = np.array([0.05, -0.04, 0.03, 0.02, -0.05, 0.04, 0.01])
    positions = np.array(BAXTER_SEED) + np.outer(
        times - 0.3 * times**2 + 0.1 * times**3, coefficients
    )
    velocities = np.outer(1.0 - 0.6 * times + 0.3 * times**2, coefficients)
    accelerations = np.outer(-0.6 + 0.6 * times, coefficients)
    planned = PlannedJointTrajectory(baxter.joint_names, times, positions)
    evaluator = GraspSafetyEvaluator(baxter)
    joint = evaluator.evaluate(Grasp(GRASP, joint_trajectory=planned), BOOK, book_trajectory())
    assert joint.feasible, joint.reason
    rates, seconds = rates_for_execution(
        joint.times_s, joint.joint_positions, joint.planned_joint_rates
    )
    np.testing.assert_allclose(rates, velocities, rtol=0, atol=1e-12)
    np.testing.assert_allclose(seconds, accelerations, rtol=0, atol=1e-12)
