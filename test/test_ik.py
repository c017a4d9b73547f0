"""IK: every returned configuration reproduces the tip pose; unreachable grasps are infeasible."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, book_trajectory, random_positions

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    IKSolver,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.ik import compiled_available


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


# --- warm start along a trajectory: no drift along the self-motion manifold ----------------

ARM7_START = np.array([-1.43, -1.209, 1.885, -2.449, 0.601, 1.371, -1.873])
"""A configuration of conftest's arm7 with every joint far from its limits along the path."""


def arm7_reach(
    robot: RobotModel, duration_s: float
) -> tuple[list[pin.SE3], np.ndarray, np.ndarray]:
    """Tip poses, times [s] and path parameters of a 101-sample quintic reach from ARM7_START
    (turn by 0.54 rad, move by 0.21 m); the same path for every duration."""
    start = robot.transform_tip_to_base(ARM7_START)
    goal = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.3, -0.2, 0.4])),
        start.translation + np.array([0.15, -0.1, 0.1]),
    )
    trajectory = ObjectTrajectory(start, goal, duration_s, duration_s / 100)
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    poses, _ = trajectory.tip_path(pin.SE3.Identity(), s_values)
    return poses, times, s_values


def self_motion_fractions(robot: RobotModel, q_path: np.ndarray) -> np.ndarray:
    """|(I - J^+ J) dq| / |dq| of each joint step dq, J the tip Jacobian at its start."""
    data = robot.model.createData()
    fractions = []
    for q, q_next in itertools.pairwise(q_path):
        jacobian = pin.computeFrameJacobian(
            robot.model, data, q, robot.tip_frame_id, pin.ReferenceFrame.LOCAL
        )
        step = pin.difference(robot.model, q, q_next)
        null_part = step - np.linalg.pinv(jacobian) @ (jacobian @ step)
        fractions.append(np.linalg.norm(null_part) / np.linalg.norm(step))
    return np.array(fractions)


def secant_path(
    solver: IKSolver, poses: list[pin.SE3], s_values: np.ndarray, q0: np.ndarray
) -> np.ndarray:
    """The warm start used before (extrapolating the previous joint step), for contrast."""
    q_path = [q0]
    for i in range(1, len(poses)):
        guess = q_path[-1]
        if i >= 2:
            ratio = (s_values[i] - s_values[i - 1]) / (s_values[i - 1] - s_values[i - 2])
            guess = q_path[-1] + ratio * (q_path[-1] - q_path[-2])
        q, converged, _ = solver.solve(poses[i], guess)
        assert converged
        q_path.append(q)
    return np.array(q_path)


BACKENDS = ["python"] + (["compiled"] if compiled_available() else [])


@pytest.mark.parametrize("backend", BACKENDS)
def test_trajectory_has_no_self_motion(backend: str, arm7: RobotModel) -> None:
    """Every joint step of a 7-DOF path is (up to the Jacobian's change over one step) in the
    row space of J: the path is the minimum-norm one. Extrapolating the previous joint step
    (the former warm start) carries null-space motion on and amplifies it while the path
    accelerates: up to ~90 % of the step on this path."""
    poses, times, s_values = arm7_reach(arm7, 1.0)
    solver = IKSolver(arm7, backend=backend)
    q0 = arm7.q_from_positions(ARM7_START)
    result = solver.solve_trajectory(poses, times, s_values, q0)
    assert result.feasible, result.reason
    assert np.all(np.abs(result.q) < 2.9)  # no joint limit (3 rad) constrains the path
    assert self_motion_fractions(arm7, result.q).max() < 1e-3
    assert self_motion_fractions(arm7, secant_path(solver, poses, s_values, q0)).max() > 0.5


@pytest.mark.parametrize("backend", BACKENDS)
def test_self_motion_does_not_make_a_path_too_fast(backend: str, arm7: RobotModel) -> None:
    """The same path in 0.2 s: the minimum-norm joint path stays under the 10 rad/s limits and
    reproduces every tip pose; the secant's self-motion would have needed more than 10 rad/s
    (the grasp was rejected as too fast)."""
    poses, times, s_values = arm7_reach(arm7, 0.2)
    solver = IKSolver(arm7, backend=backend)
    q0 = arm7.q_from_positions(ARM7_START)
    result = solver.solve_trajectory(poses, times, s_values, q0)
    assert result.feasible, result.reason
    speeds = np.abs(np.diff(result.q, axis=0)) / np.diff(times)[:, None]
    assert speeds.max() < 0.95 * arm7.velocity_limits.min()
    for q, target in zip(result.q, poses, strict=True):
        position_error, angle_error = pose_error(arm7, arm7.positions_from_q(q), target)
        assert position_error <= 1e-6 and angle_error <= 1e-6
    secant = secant_path(solver, poses, s_values, q0)
    secant_speeds = np.abs(np.diff(secant, axis=0)) / np.diff(times)[:, None]
    assert np.any(secant_speeds > arm7.velocity_limits)


@pytest.mark.parametrize("backend", BACKENDS)
def test_predictor_converges_at_the_guess(
    backend: str, arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The defect-extrapolating predictor lands within the tolerances on every sample of the
    reach sampled 201 times (no Gauss-Newton iteration); without the extrapolation (ratio
    capped at 0: the first-order predictor J^+ xi) most samples need one."""
    from grasp_safety_ros.core.method import ik

    start = arm7.transform_tip_to_base(ARM7_START)
    goal = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.3, -0.2, 0.4])),
        start.translation + np.array([0.15, -0.1, 0.1]),
    )
    trajectory = ObjectTrajectory(start, goal, 1.0, 1.0 / 200)
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    poses, _ = trajectory.tip_path(pin.SE3.Identity(), s_values)
    q0 = arm7.q_from_positions(ARM7_START)
    result = IKSolver(arm7, backend=backend).solve_trajectory(poses, times, s_values, q0)
    assert result.feasible, result.reason
    assert result.iterations[1:].max() == 0
    monkeypatch.setattr(ik, "PREDICTOR_MAX_RATIO", 0.0)
    first_order = IKSolver(arm7, backend=backend).solve_trajectory(poses, times, s_values, q0)
    assert first_order.feasible, first_order.reason
    assert first_order.iterations[1:].mean() >= 0.5
