"""Timed waypoint trajectories: the two-waypoint form is the quintic; C2 interpolation through
every waypoint, at rest at both ends; the evaluator and the analyses accept them."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest
from conftest import book_trajectory

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    solid_box,
)
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, analyse
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.model.trajectory import MAX_SAMPLES
from grasp_safety_ros.core.model.waypoint_trajectory import WaypointTrajectory, right_jacobian_so3

BOOK = solid_box(0.34, [0.15, 0.22, 0.015])
GRASPS = [Grasp(pin.SE3(np.eye(3), np.array([0.0, y, 0.0])), f"g{y}") for y in (-0.1, 0.0, 0.1)]


def three_waypoints(dt: float = 0.02, turn: float = 0.4) -> WaypointTrajectory:
    """The issue's book path, with the last orientation turned by ``turn`` rad about x."""
    q = [0.5, 0.5, 0.5, 0.5]
    poses = [
        pose_from_position_quat([1.0, 0.0, 0.03], q, "w0"),
        pose_from_position_quat([1.05, -0.2, 0.12], q, "w1"),
        pose_from_position_quat([1.1, -0.38, 0.16], q, "w2"),
    ]
    poses[1].rotation = poses[1].rotation @ pin.exp3(np.array([0.0, 0.2, 0.1]))
    poses[2].rotation = poses[2].rotation @ pin.exp3(np.array([turn, 0.0, 0.0]))
    return WaypointTrajectory((0.0, 1.2, 2.5), tuple(poses), dt)


def five_waypoints() -> WaypointTrajectory:
    rng = np.random.default_rng(3)
    poses = [pin.SE3(pin.exp3(rng.normal(size=3)), rng.uniform(-1, 1, 3)) for _ in range(5)]
    return WaypointTrajectory((0.0, 0.7, 1.1, 2.0, 2.4), tuple(poses), 0.05)


def test_two_waypoints_equal_the_start_goal_form(baxter) -> None:
    quintic = book_trajectory(dt_s=0.02, goal_rotation_log=(0.3, -0.2, 0.1))
    pair = WaypointTrajectory(
        (0.0, 2.0),
        (quintic.transform_object_to_base_start, quintic.transform_object_to_base_goal),
        0.02,
    )
    times = quintic.times_s()
    np.testing.assert_allclose(pair.times_s(), times, rtol=0, atol=1e-12)
    for a, b in zip(pair.object_poses(times), quintic.object_poses(times), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    for python in (False, True):
        config = EvaluationConfig(backend="python") if python else EvaluationConfig()
        evaluator = GraspSafetyEvaluator(baxter, config)
        seed = (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0)
        ranked = [evaluator.rank(GRASPS, BOOK, t, seed) for t in (quintic, pair)]
        assert ranked[0].order == ranked[1].order
        for a, b in zip(ranked[0].evaluations, ranked[1].evaluations, strict=True):
            assert a.feasible and b.feasible
            np.testing.assert_allclose(a.times_s, b.times_s, rtol=0, atol=1e-12)
            np.testing.assert_allclose(a.effective_mass_kg, b.effective_mass_kg, rtol=1e-12)


@pytest.mark.parametrize("make", [three_waypoints, five_waypoints])
def test_passes_every_waypoint_at_its_time_and_samples_it(make) -> None:
    trajectory = make()
    times = np.array(trajectory.waypoint_times_s)
    rotations, positions = trajectory.object_poses(times)
    for k, pose in enumerate(trajectory.transforms_object_to_base):
        np.testing.assert_allclose(positions[k], pose.translation, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rotations[k], pose.rotation, rtol=0, atol=1e-12)
    samples = trajectory.times_s()
    assert np.all(np.diff(samples) > 0)
    assert set(times.tolist()) <= set(samples.tolist())
    regular = np.arange(0.0, trajectory.duration_s + 1e-12, trajectory.dt_s)
    assert np.abs(samples[:, None] - regular[None, :]).min(axis=0).max() < 1e-9


def _one_sided_derivatives(object_poses, t: float, side: float, h: float) -> np.ndarray:
    """Velocity, acceleration, body angular velocity (from log3(R_iᵀR_{i+1})) and angular
    acceleration at t from samples on one side only (t, t ± h, t ± 2h, t ± 3h): second-order
    one-sided differences, so a jump across t shows up and a smooth path agrees."""
    times = t + side * h * np.arange(4)
    rotations, positions = object_poses(times)
    velocity = side * (-3 * positions[0] + 4 * positions[1] - positions[2]) / (2 * h)
    acceleration = (2 * positions[0] - 5 * positions[1] + 4 * positions[2] - positions[3]) / h**2
    # ω at the midpoints t ± h/2, t ± 3h/2, t ± 5h/2, extrapolated to t.
    w = np.array([side * pin.log3(rotations[k].T @ rotations[k + 1]) / h for k in range(3)])
    omega = (15 * w[0] - 10 * w[1] + 3 * w[2]) / 8
    alpha = side * (-2 * w[0] + 3 * w[1] - w[2]) / h  # derivative at t of the parabola
    return np.concatenate([velocity, acceleration, omega, alpha])


def _jumps(object_poses, t: float, h: float = 1e-3) -> tuple[float, float, float, float]:
    """Jumps of velocity, acceleration, angular velocity and acceleration across t."""
    left = _one_sided_derivatives(object_poses, t, -1.0, h)
    right = _one_sided_derivatives(object_poses, t, 1.0, h)
    jump = np.abs(left - right)
    return tuple(float(jump[3 * k : 3 * k + 3].max()) for k in range(4))


@pytest.mark.parametrize("make", [three_waypoints, five_waypoints])
def test_continuous_velocity_and_acceleration_at_interior_waypoints(make) -> None:
    trajectory = make()
    for t in trajectory.waypoint_times_s[1:-1]:
        velocity, acceleration, omega, alpha = _jumps(trajectory.object_poses, t)
        assert velocity < 1e-5 and omega < 1e-5
        assert acceleration < 1e-3 and alpha < 1e-3


def test_the_continuity_check_detects_a_kink() -> None:
    """The same check on the piecewise-geodesic path at constant speed per segment (C0 only)
    reports jumps: the test above can fail."""
    trajectory = three_waypoints()
    knots = np.array(trajectory.waypoint_times_s)
    poses = trajectory.transforms_object_to_base

    def piecewise(times):
        rotations, positions = [], []
        for t in times:
            k = min(int(np.searchsorted(knots, t, side="right")) - 1, len(knots) - 2)
            u = (t - knots[k]) / (knots[k + 1] - knots[k])
            a, b = poses[k], poses[k + 1]
            rotations.append(a.rotation @ pin.exp3(u * pin.log3(a.rotation.T @ b.rotation)))
            positions.append((1 - u) * a.translation + u * b.translation)
        return np.array(rotations), np.array(positions)

    velocity, _, omega, _ = _jumps(piecewise, knots[1])
    assert velocity > 1e-2 and omega > 1e-2


@pytest.mark.parametrize("make", [three_waypoints, five_waypoints])
def test_at_rest_at_both_ends(make) -> None:
    trajectory = make()
    h = 1e-5
    for t, sign in ((0.0, 1.0), (trajectory.duration_s, -1.0)):
        inside = np.array([t + sign * h, t + sign * 2 * h])
        rotations, positions = trajectory.object_poses(np.concatenate([[t], inside]))
        # p(t ± h) − p(t) = O(h³) when velocity and acceleration are zero.
        assert np.abs(positions[1] - positions[0]).max() < 1e-10
        assert np.linalg.norm(pin.log3(rotations[0].T @ rotations[1])) < 1e-10
        twist, twist_rate = trajectory.tip_twists(pin.SE3.Identity(), np.array([t]))
        np.testing.assert_allclose(twist, 0.0, atol=1e-12)
        np.testing.assert_allclose(twist_rate, 0.0, atol=1e-6)


def test_tip_velocity_and_twist_match_finite_differences() -> None:
    trajectory = three_waypoints()
    grasp = pin.SE3(pin.exp3(np.array([0.1, -0.2, 0.3])), np.array([0.05, -0.1, 0.02]))
    times = np.array([0.3, 1.2, 1.9])
    h = 1e-5
    plus = trajectory.tip_motion(grasp, times + h)
    minus = trajectory.tip_motion(grasp, times - h)
    motion = trajectory.tip_motion(grasp, times)
    velocity = (plus.positions - minus.positions) / (2 * h)
    np.testing.assert_allclose(motion.speeds, np.linalg.norm(velocity, axis=1), rtol=1e-7)
    directions = motion.tangents / np.linalg.norm(motion.tangents, axis=1)[:, None]
    np.testing.assert_allclose(
        directions, velocity / np.linalg.norm(velocity, axis=1)[:, None], atol=1e-8
    )
    twist, twist_rate = trajectory.tip_twists(grasp, times)
    np.testing.assert_allclose(twist[:, :3], velocity, rtol=1e-7, atol=1e-9)
    twist_plus, _ = trajectory.tip_twists(grasp, times + h)
    twist_minus, _ = trajectory.tip_twists(grasp, times - h)
    np.testing.assert_allclose(twist_rate, (twist_plus - twist_minus) / (2 * h), atol=1e-5)


def test_rest_end_tangent_is_the_limit_direction() -> None:
    trajectory = three_waypoints()
    grasp = pin.SE3(np.eye(3), np.array([0.0, 0.1, 0.0]))
    for t, sign in ((0.0, 1.0), (trajectory.duration_s, -1.0)):
        ends = trajectory.tip_motion(grasp, np.array([t, t + sign * 1e-3]))
        chord = sign * (ends.positions[1] - ends.positions[0])
        limit = ends.tangents[0] / np.linalg.norm(ends.tangents[0])
        assert float(limit @ chord / np.linalg.norm(chord)) > 1 - 1e-4
        assert ends.speeds[0] == pytest.approx(0.0, abs=1e-15)


def test_right_jacobian_is_pinocchios() -> None:
    rng = np.random.default_rng(0)
    vectors = np.concatenate([rng.normal(size=(5, 3)), 1e-6 * rng.normal(size=(2, 3))])
    for phi, jr in zip(vectors, right_jacobian_so3(vectors), strict=True):
        np.testing.assert_allclose(jr, pin.Jexp3(phi), atol=1e-12)


def test_rotation_beyond_pi_stays_continuous() -> None:
    """Quarter turns about z to 3π/2: the unwrapped rotation vectors keep the path smooth."""
    poses = tuple(
        pin.SE3(pin.exp3(np.array([0.0, 0.0, a])), np.zeros(3)) for a in (0, 1.6, 3.2, 4.7)
    )
    trajectory = WaypointTrajectory((0.0, 1.0, 2.0, 3.0), poses, 0.01)
    rotations, _ = trajectory.object_poses(trajectory.times_s())
    steps = [np.linalg.norm(pin.log3(a.T @ b)) for a, b in itertools.pairwise(rotations)]
    assert max(steps) < 0.05


@pytest.mark.parametrize(
    ("times", "dt", "field"),
    [
        ((0.0, 1.0, 1.0), 0.1, "trajectory.waypoints[2].time_s"),
        ((0.0, 2.0, 1.0), 0.1, "trajectory.waypoints[2].time_s"),
        ((0.0, float("nan"), 2.0), 0.1, "trajectory.waypoints[1].time_s"),
        ((0.5, 1.0, 2.0), 0.1, "trajectory.waypoints[0].time_s"),
        ((0.0,), 0.1, "trajectory.waypoints"),
        ((0.0, 1.0, 2.0), 0.0, "trajectory.dt_s"),
        ((0.0, 1.0, 2.0), 3.0, "trajectory.dt_s"),
        ((0.0, 1.0, 2.0), 2.0 / MAX_SAMPLES, "trajectory.dt_s"),
    ],
)
def test_bad_waypoints_name_the_field(times, dt, field) -> None:
    poses = tuple(pin.SE3(np.eye(3), np.array([0.1 * k, 0.0, 0.0])) for k in range(len(times)))
    with pytest.raises(InvalidInputError) as error:
        WaypointTrajectory(times, poses, dt)
    assert error.value.field == field


def test_non_finite_pose_is_refused() -> None:
    poses = [pin.SE3(np.eye(3), np.zeros(3)) for _ in range(3)]
    poses[1] = pin.SE3(np.eye(3), np.array([np.inf, 0.0, 0.0]))
    with pytest.raises(InvalidInputError, match=r"waypoints\[1\]"):
        WaypointTrajectory((0.0, 1.0, 2.0), tuple(poses), 0.1)


def test_evaluation_and_analyses_accept_waypoints(baxter) -> None:
    """Compiled and Python evaluators agree on a waypoint path (the compiled kernel takes its
    tip path from ``tip_motion``), and every analysis runs on it."""
    trajectory = three_waypoints(dt=0.05)
    seed = (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0)
    evaluator = GraspSafetyEvaluator(baxter)
    ranking = evaluator.rank(GRASPS, BOOK, trajectory, seed)
    python = GraspSafetyEvaluator(baxter, EvaluationConfig(backend="python")).rank(
        GRASPS, BOOK, trajectory, seed
    )
    for a, b in zip(ranking.evaluations, python.evaluations, strict=True):
        assert a.feasible, a.reason
        np.testing.assert_array_equal(a.times_s, trajectory.times_s())
        np.testing.assert_allclose(a.effective_mass_kg, b.effective_mass_kg, rtol=1e-9)
        np.testing.assert_array_equal(a.ik_iterations, b.ik_iterations)
        # At rest at both ends, moving in between.
        assert abs(a.tip_speed_m_s[0]) < 1e-12 and abs(a.tip_speed_m_s[-1]) < 1e-12
        assert np.all(a.tip_speed_m_s[1:-1] > 0)
    options = AnalysisOptions(
        metric_point="leading_point",
        points_in_object_m=box_corners_in_object([0.15, 0.22, 0.015]),
        redundancy=True,
        effort=True,
    )
    report = analyse(evaluator, GRASPS, BOOK, trajectory, options, seed, ranking=ranking)
    assert all(np.isfinite(report.scores))
    assert all(a.duration_s == pytest.approx(2.5) for a in report.iso)
    assert all(e.feasible and np.all(np.isfinite(e.joint_torques)) for e in report.effort)
