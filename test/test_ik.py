"""IK: every returned configuration reproduces the tip pose; unreachable grasps are infeasible."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, random_positions

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    IKSolver,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.validation import pose_from_position_quat


def pose_error(robot: RobotModel, positions: np.ndarray, target: pin.SE3) -> tuple[float, float]:
    reached = robot.transform_tip_to_base(positions)
    position_error = float(np.linalg.norm(reached.translation - target.translation))
    angle_error = float(np.linalg.norm(pin.log3(reached.rotation.T @ target.rotation)))
    return position_error, angle_error


@pytest.mark.parametrize("arm", ["arm6", "arm7"])
def test_solve_reaches_random_reachable_poses(arm: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(arm)
    solver = IKSolver(robot)
    rng = np.random.default_rng(2)
    for _ in range(10):
        goal_positions = random_positions(robot, rng)
        target = robot.transform_tip_to_base(goal_positions)
        start = goal_positions + rng.uniform(-0.3, 0.3, robot.num_joints)
        q, converged, _ = solver.solve(
            target, robot.q_from_positions(np.clip(start, robot.lower_limits, robot.upper_limits))
        )
        assert converged
        position_error, angle_error = pose_error(robot, robot.positions_from_q(q), target)
        assert position_error <= 1e-6 and angle_error <= 1e-6


def book_trajectory(dt: float = 0.05) -> ObjectTrajectory:
    return ObjectTrajectory(
        pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start"),
        pose_from_position_quat([1.1, -0.38, 0.16], [0.5, 0.5, 0.5, 0.5], "goal"),
        2.0,
        dt,
    )


def test_every_sample_reproduces_the_tip_pose(baxter: RobotModel) -> None:
    trajectory = book_trajectory()
    grasp = Grasp(pose_from_position_quat([-0.075, 0.1, 0.0], [0, 0, 0, 1], "grasp"))
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        grasp, solid_box(0.34, [0.15, 0.22, 0.015]), trajectory, seed_positions=BAXTER_SEED
    )
    assert evaluation.feasible, evaluation.reason
    s_values, _, _ = trajectory.path_parameter(evaluation.times_s)
    for positions, s in zip(evaluation.joint_positions, s_values, strict=True):
        target = trajectory.transform_object_to_base(float(s)) * grasp.transform_tip_to_object
        position_error, angle_error = pose_error(baxter, positions, target)
        assert position_error <= 1e-6 and angle_error <= 1e-6
        assert np.all(positions >= baxter.lower_limits) and np.all(
            positions <= baxter.upper_limits
        )


def test_unreachable_grasp_is_infeasible_with_a_reason(baxter: RobotModel) -> None:
    far = Grasp(pose_from_position_quat([0.0, 0.0, 3.0], [0, 0, 0, 1], "grasp"), "far")
    ranking = GraspSafetyEvaluator(baxter).rank(
        [far, Grasp(pose_from_position_quat([-0.075, 0.0, 0.0], [0, 0, 0, 1], "g"), "ok")],
        solid_box(0.34, [0.15, 0.22, 0.015]),
        book_trajectory(),
        seed_positions=BAXTER_SEED,
    )
    assert ranking.order == (1,)
    far_result = ranking.evaluations[0]
    assert not far_result.feasible
    assert "IK did not converge at sample 0" in far_result.reason
    assert np.isnan(far_result.score) and len(far_result.effective_mass_kg) == 0


def test_joint_jump_is_infeasible(arm6: RobotModel) -> None:
    """A trajectory that needs a large joint change between samples is refused."""
    from grasp_safety_ros.core import IKConfig

    solver = IKSolver(arm6, IKConfig(max_joint_step=1e-3, check_velocity_limits=False))
    positions = np.zeros(arm6.num_joints)
    poses = [arm6.transform_tip_to_base(positions + d) for d in (0.0, 0.05)]
    result = solver.solve_trajectory(
        poses, np.array([0.0, 0.1]), np.array([0.0, 1.0]), arm6.q_from_positions(positions)
    )
    assert not result.feasible and "jumps by" in result.reason
