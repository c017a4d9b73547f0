"""Fast rankings give the results of the plain ones: the compiled backend vs the Python one
(core/method/ranking.py), on waypoint trajectories and third-party trajectory types too, and
both vs the implementation before the optimisation (bench/reference.py: its effective masses on
our joint paths; its IK only on non-redundant arms, as its warm start let redundant arms drift).
Equality only, never timing. (Building blocks: test_compiled_paths; pools: test_pool; shared
terms: test_terms.)"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, random_positions
from fast_paths import (
    BOX,
    ROBOTS,
    RTOL,
    assert_same_ranking,
    evaluators,
    grasps_near_identity,
    needs_numba,
    reach_trajectory,
)

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    IKConfig,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.core.model.trajectory import TipMotion


@needs_numba
@pytest.mark.parametrize(  # arm4 cannot follow 6-D paths
    "name", ["arm6", "arm7", "mixed", "continuous", "kinova"]
)
def test_compiled_ranking_equals_python_ranking(name: str) -> None:
    robot = ROBOTS[name]()
    rng = np.random.default_rng(7)
    seed = random_positions(robot, rng)
    trajectory = reach_trajectory(robot, seed)
    grasps = grasps_near_identity(6)
    python, compiled = evaluators(robot)
    expected = python.rank(grasps, BOX, trajectory, seed_positions=seed)
    assert len(expected.order) >= 3  # mostly feasible: the comparison has substance
    assert_same_ranking(compiled.rank(grasps, BOX, trajectory, seed_positions=seed), expected)


@needs_numba
def test_failures_are_the_same_in_both_backends(arm6: RobotModel) -> None:
    rng = np.random.default_rng(8)
    seed = random_positions(arm6, rng)
    trajectory = reach_trajectory(arm6, seed)
    grasps = [
        Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable"),
        Grasp(pin.SE3.Identity(), "fine"),
    ]
    for config in ({}, {"ik": IKConfig(max_joint_step=1e-3)}):
        python, compiled = evaluators(arm6, **config)
        a = python.rank(grasps, BOX, trajectory, seed_positions=seed)
        b = compiled.rank(grasps, BOX, trajectory, seed_positions=seed)
        assert [e.reason for e in a.evaluations] == [e.reason for e in b.evaluations]
    assert "from the seed or any restart" in a.evaluations[0].reason
    assert "jumps by" in a.evaluations[1].reason
    fast = ObjectTrajectory(
        trajectory.transform_object_to_base_start,
        trajectory.transform_object_to_base_goal,
        0.02,
        0.001,
    )
    python, compiled = evaluators(arm6)
    a = python.rank(grasps[1:], BOX, fast, seed_positions=seed)
    b = compiled.rank(grasps[1:], BOX, fast, seed_positions=seed)
    assert "needs speed" in a.evaluations[0].reason
    assert a.evaluations[0].reason == b.evaluations[0].reason


@needs_numba
def test_joint_jumps_of_continuous_joints_are_the_same_in_both_backends() -> None:
    robot = ROBOTS["continuous"]()
    rng = np.random.default_rng(8)
    seed = random_positions(robot, rng)
    trajectory = reach_trajectory(robot, seed)
    python, compiled = evaluators(robot, ik=IKConfig(max_joint_step=2e-3))
    grasps = grasps_near_identity(3)
    a = python.rank(grasps, BOX, trajectory, seed_positions=seed)
    b = compiled.rank(grasps, BOX, trajectory, seed_positions=seed)
    assert [e.reason for e in a.evaluations] == [e.reason for e in b.evaluations]
    assert any("jumps by" in e.reason for e in a.evaluations)


@needs_numba
def test_restarts_of_the_first_sample_are_the_same(arm7: RobotModel) -> None:
    rng = np.random.default_rng(9)
    goal = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, goal)
    far_seed = np.clip(-goal, arm7.lower_limits, arm7.upper_limits)
    python, compiled = evaluators(arm7, ik=IKConfig(max_iterations=15))
    grasps = grasps_near_identity(3)
    a = python.rank(grasps, BOX, trajectory, seed_positions=far_seed)
    b = compiled.rank(grasps, BOX, trajectory, seed_positions=far_seed)
    assert any(e.feasible and e.ik_iterations[0] > 15 for e in a.evaluations)  # restarted
    assert_same_ranking(b, a)


@needs_numba
def test_worst_case_direction_when_the_tip_does_not_move(arm6: RobotModel) -> None:
    rng = np.random.default_rng(10)
    seed = random_positions(arm6, rng)
    pose = arm6.transform_tip_to_base(seed)
    still = ObjectTrajectory(pose, pose, 0.2, 0.05)
    python, compiled = evaluators(arm6)
    a = python.rank([Grasp(pin.SE3.Identity())], BOX, still, seed_positions=seed)
    b = compiled.rank([Grasp(pin.SE3.Identity())], BOX, still, seed_positions=seed)
    assert a.evaluations[0].direction_is_worst_case.all()
    assert_same_ranking(b, a)


def load_reference() -> ModuleType:
    """bench/reference.py (the implementation before the optimisation), or skip."""
    path = Path(__file__).resolve().parents[1] / "bench" / "reference.py"
    if not path.is_file():
        pytest.skip("bench/reference.py not present")
    spec = importlib.util.spec_from_file_location("bench_reference", path)
    assert spec is not None and spec.loader is not None
    reference = importlib.util.module_from_spec(spec)
    sys.modules["bench_reference"] = reference
    spec.loader.exec_module(reference)
    return reference


BACKENDS = ["python"] + (["compiled"] if compiled_available() else [])


def test_both_backends_equal_the_implementation_before_optimisation(baxter: RobotModel) -> None:
    """On the joint path each backend finds, the effective-mass code from before the
    optimisation gives the same masses, and the same grasps are feasible. (Its IK warm start
    extrapolated the previous joint step; the predictor follows the minimum-norm path instead,
    so on a redundant arm the joint paths themselves differ by design: test_ik.py.)"""
    reference = load_reference()
    trajectory = ObjectTrajectory(
        pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start"),
        pose_from_position_quat([1.1, -0.38, 0.16], [0.5, 0.5, 0.5, 0.5], "goal"),
        2.0,
        0.04,
    )
    s_values, _, _ = trajectory.path_parameter(trajectory.times_s())
    book = solid_box(0.34, [0.15, 0.22, 0.015])
    grasps = [
        Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "g")) for y in (-0.1, 0, 0.1)
    ]
    ik = reference.ReferenceIK(baxter)
    seed_q = baxter.q_from_positions(BAXTER_SEED)
    expected = [
        reference.reference_evaluate(
            baxter, ik, g.transform_tip_to_object, book, trajectory, seed_q
        )[0]
        for g in grasps
    ]
    for backend in BACKENDS:
        evaluator = GraspSafetyEvaluator(baxter, EvaluationConfig(backend=backend, workers=1))
        ranking = evaluator.rank(grasps, book, trajectory, seed_positions=BAXTER_SEED)
        for grasp, evaluation, feasible in zip(grasps, ranking.evaluations, expected, strict=True):
            assert evaluation.feasible and feasible
            _, tangents = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
            q_path = np.array([baxter.q_from_positions(p) for p in evaluation.joint_positions])
            masses = reference.reference_effective_masses(
                baxter, grasp.transform_tip_to_object, book, q_path, tangents
            )
            np.testing.assert_allclose(evaluation.effective_mass_kg, masses, rtol=RTOL)


def test_non_redundant_paths_equal_the_implementation_before_optimisation(
    arm6: RobotModel,
) -> None:
    """A 6-DOF arm has no self-motion: the IK solution of each sample is locally unique, so
    the former warm start and the predictor reach it to the IK tolerance (1e-6)."""
    reference = load_reference()
    rng = np.random.default_rng(15)
    seed = random_positions(arm6, rng)
    trajectory = reach_trajectory(arm6, seed)
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    ik = reference.ReferenceIK(arm6)
    seed_q = arm6.q_from_positions(seed)
    grasps = grasps_near_identity(4)
    for backend in BACKENDS:
        evaluator = GraspSafetyEvaluator(arm6, EvaluationConfig(backend=backend, workers=1))
        ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=seed)
        for grasp, evaluation in zip(grasps, ranking.evaluations, strict=True):
            assert evaluation.feasible, evaluation.reason
            feasible, masses, _ = reference.reference_evaluate(
                arm6, ik, grasp.transform_tip_to_object, BOX, trajectory, seed_q
            )
            assert feasible
            np.testing.assert_allclose(evaluation.effective_mass_kg, masses, rtol=1e-5)
            poses, _ = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
            q_path, _, _ = ik.solve_trajectory(poses, times, s_values, seed_q)
            np.testing.assert_allclose(evaluation.joint_positions, q_path, rtol=0, atol=1e-5)


@needs_numba
def test_waypoint_trajectories_run_the_compiled_kernel(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    from grasp_safety_ros.core.method import ranking as ranking_module
    from grasp_safety_ros.core.model.waypoint_trajectory import WaypointTrajectory

    rng = np.random.default_rng(14)
    seed = random_positions(arm7, rng)
    quintic = reach_trajectory(arm7, seed)
    start, goal = quintic.transform_object_to_base_start, quintic.transform_object_to_base_goal
    middle = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.05, 0.0, 0.05])),
        0.5 * (start.translation + goal.translation) + np.array([0.0, 0.02, 0.0]),
    )
    waypoints = WaypointTrajectory((0.0, 0.6, 1.0), (start, middle, goal), 0.02)
    calls: list[int] = []  # grasps evaluated by the fused kernel
    fused = ranking_module.evaluate_grasps_compiled
    monkeypatch.setattr(
        ranking_module,
        "evaluate_grasps_compiled",
        lambda *args, **kwargs: calls.extend([1] * len(args[2])) or fused(*args, **kwargs),
    )
    python, compiled = evaluators(arm7)
    grasps = grasps_near_identity(4)
    expected = python.rank(grasps, BOX, waypoints, seed_positions=seed)
    assert not calls
    assert len(expected.order) >= 2
    assert_same_ranking(compiled.rank(grasps, BOX, waypoints, seed_positions=seed), expected)
    assert len(calls) == len(grasps)


class TipMotionOnly:
    """An object trajectory that gives each grasp's ``tip_motion`` but no ``object_motion``
    (as a third-party trajectory type may): the evaluator's fallback path."""

    def __init__(self, trajectory: ObjectTrajectory) -> None:
        self._trajectory = trajectory
        self.duration_s = trajectory.duration_s

    def times_s(self) -> np.ndarray:
        return self._trajectory.times_s()

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._trajectory.path_parameter(times_s)

    def object_poses(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._trajectory.object_poses(times_s)

    def tip_motion(self, transform_tip_to_object: pin.SE3, times_s: np.ndarray) -> TipMotion:
        return self._trajectory.tip_motion(transform_tip_to_object, times_s)

    def tip_twists(
        self, transform_tip_to_object: pin.SE3, times_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return self._trajectory.tip_twists(transform_tip_to_object, times_s)


@needs_numba
def test_trajectories_without_object_motion_rank_the_same(arm7: RobotModel) -> None:
    """A trajectory type without ``object_motion`` goes grasp by grasp through its own
    ``tip_motion`` (compiled: composed with the identity grasp); both backends rank it as the
    built-in type they wrap."""
    from grasp_safety_ros.core.model.trajectory import ObjectPath

    rng = np.random.default_rng(15)
    seed = random_positions(arm7, rng)
    quintic = reach_trajectory(arm7, seed)
    wrapped = TipMotionOnly(quintic)
    assert not isinstance(wrapped, ObjectPath)
    grasps = grasps_near_identity(4)
    for evaluator in evaluators(arm7):
        expected = evaluator.rank(grasps, BOX, quintic, seed_positions=seed)
        assert len(expected.order) >= 2
        assert_same_ranking(evaluator.rank(grasps, BOX, wrapped, seed_positions=seed), expected)
