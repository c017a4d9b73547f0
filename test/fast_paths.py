"""Shared helpers of the fast-path equality tests (test_compiled_paths, test_performance_paths,
test_pool, test_terms, test_point_kernels, test_effort_batch): the robots, grasps and reaches
they compare on, the ranking comparisons and the tolerances they use. Not a test file."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, ARM7_AXES, random_positions, serial_arm_urdf
from tolerances import assert_close_to_scale, rounding_tolerance

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.core.method.ranking import Ranking
from grasp_safety_ros.core.method.results import SAMPLE_ARRAYS
from grasp_safety_ros.core.method.terms import SampleTerms, grasp_terms

needs_numba = pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
RTOL = 1e-9
"""Rankings of two backends: each IK stops within its own tolerance, so the postures (and the
masses and worst-case directions there) agree to that, not to rounding."""
ROUNDING = rounding_tolerance(1.0, 8) * 6.0
"""Kernel vs Pinocchio on single joint operations (integrate, difference), absolute [rad]: the
kernels fuse multiply-adds (one rounding instead of two, ``kernels._jit``), so they agree to
rounding, not bit for bit: k = 8 roundings (sine, cosine, atan2, products) of angles up to
6 rad (condition 1)."""
TIP_MOTION = rounding_tolerance(1.0, 32)
"""The tip's direction and speed along the object's motion (the trajectory's, not the arm's):
a few SE(3) compositions, a norm and a division (condition 1); k = 32 (3 eps measured)."""
BOX = solid_box(0.8, [0.08, 0.12, 0.2], [0.0, 0.01, -0.02])


def reach_trajectory(
    robot: RobotModel, positions: np.ndarray, dt: float = 0.02
) -> ObjectTrajectory:
    """A short quintic trajectory of the tip pose at ``positions`` (object frame = tip frame)."""
    start = robot.transform_tip_to_base(positions)
    goal = pin.SE3(
        start.rotation @ pin.exp3(np.array([0.1, -0.05, 0.15])),
        start.translation + np.array([0.03, -0.04, 0.05]),
    )
    return ObjectTrajectory(start, goal, 1.0, dt)


def grasps_near_identity(count: int, seed: int = 3) -> list[Grasp]:
    """``count`` grasps within 0.2 rad and 3 cm of the identity."""
    rng = np.random.default_rng(seed)
    return [
        Grasp(pin.SE3(pin.exp3(rng.uniform(-0.2, 0.2, 3)), rng.uniform(-0.03, 0.03, 3)), f"g{k}")
        for k in range(count)
    ]


def assert_same_ranking(a: Ranking, b: Ranking, rtol: float = RTOL) -> None:
    """Two backends: the same order and feasibility, results equal to the IK tolerance."""
    assert a.order == b.order
    for x, y in zip(a.evaluations, b.evaluations, strict=True):
        assert x.feasible == y.feasible
        assert bool(x.reason) == bool(y.reason)
        if not x.feasible:
            continue
        np.testing.assert_array_equal(x.ik_iterations, y.ik_iterations)
        np.testing.assert_array_equal(x.direction_is_worst_case, y.direction_is_worst_case)
        np.testing.assert_allclose(x.effective_mass_kg, y.effective_mass_kg, rtol=rtol)
        np.testing.assert_allclose(x.joint_positions, y.joint_positions, rtol=0, atol=1e-8)
        assert_close_to_scale(x.tip_speed_m_s, y.tip_speed_m_s, "speeds", TIP_MOTION)
        along = ~x.direction_is_worst_case  # the motion's direction; else M's eigenvector,
        for rows, tolerance in ((along, TIP_MOTION), (~along, rtol)):  # as the masses
            if rows.any():
                ours, theirs = x.directions_in_base[rows], y.directions_in_base[rows]
                assert_close_to_scale(ours, theirs, "directions", tolerance)
        assert x.score == pytest.approx(y.score, rel=rtol)


def assert_identical_ranking(a: Ranking, b: Ranking) -> None:
    """Bit-for-bit: same code, other workers."""
    assert a.order == b.order
    for x, y in zip(a.evaluations, b.evaluations, strict=True):
        assert (x.index, x.name, x.feasible, x.reason) == (y.index, y.name, y.feasible, y.reason)
        for field in SAMPLE_ARRAYS:
            np.testing.assert_array_equal(getattr(x, field), getattr(y, field))
        assert x.score == y.score or (np.isnan(x.score) and np.isnan(y.score))


def mixed_arm_urdf() -> str:
    """A 6-DOF arm whose third and fifth joints are prismatic."""
    lines = serial_arm_urdf(ARM6_AXES, seed=4).splitlines()
    for k, line in enumerate(lines):
        if line.startswith(('<joint name="j3"', '<joint name="j5"')):
            lines[k] = line.replace('type="revolute"', 'type="prismatic"').replace(
                'lower="-3.0" upper="3.0"', 'lower="-0.5" upper="0.5"'
            )
    return "\n".join(lines)


def continuous_arm_urdf() -> str:
    """The 6-DOF test arm whose first and fourth joints are continuous (nq = 8, nv = 6)."""
    return (
        serial_arm_urdf(ARM6_AXES)
        .replace('<joint name="j1" type="revolute">', '<joint name="j1" type="continuous">')
        .replace('<joint name="j4" type="revolute">', '<joint name="j4" type="continuous">')
    )


def kinova() -> RobotModel:
    """Kinova Jaco2 j2s6s200 of example-robot-data: joints 1, 4 and 6 continuous."""
    return RobotModel.from_urdf(
        "example-robot-data:kinova", "j2s6s200_link_base", "j2s6s200_end_effector"
    )


ROBOTS = {
    "arm6": lambda: RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool"),
    "continuous": lambda: RobotModel.from_urdf(continuous_arm_urdf(), "base_link", "tool"),
    "kinova": kinova,
    "arm7": lambda: RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool"),
    "arm4": lambda: RobotModel.from_urdf(
        serial_arm_urdf(("z", "y", "y", "x"), seed=2), "base_link", "tool"
    ),
    "mixed": lambda: RobotModel.from_urdf(mixed_arm_urdf(), "base_link", "tool"),
    "geared": lambda: RobotModel.from_urdf(  # armature [kg m^2; kg on the prismatic j3, j5]
        mixed_arm_urdf(), "base_link", "tool", armature_kgm2=[0.4, 0.3, 2.0, 0.1, 1.5, 0.02]
    ),
}


def evaluators(robot: RobotModel, **config: object) -> tuple[GraspSafetyEvaluator, ...]:
    """Serial evaluators of ``robot``: the Python backend, then the compiled one."""
    base = EvaluationConfig(workers=1, **config)  # type: ignore[arg-type]
    return (
        GraspSafetyEvaluator(robot, replace(base, backend="python")),
        GraspSafetyEvaluator(robot, replace(base, backend="compiled")),
    )


def terms_case(robot: RobotModel, seed: int) -> tuple:
    """A grasp along a short reach of ``robot``, its evaluation and its shared terms."""
    rng = np.random.default_rng(seed)
    evaluator = GraspSafetyEvaluator(robot)
    for _ in range(20):  # the first random posture whose reach stays within the limits
        positions = random_positions(robot, rng)
        start = robot.transform_tip_to_base(positions)
        grasp = grasps_near_identity(1, seed)[0]
        trajectory = reach_trajectory(robot, positions)  # the tip's reach; the object's:
        trajectory = ObjectTrajectory(
            start * grasp.transform_tip_to_object.inverse(),
            trajectory.transform_object_to_base_goal * grasp.transform_tip_to_object.inverse(),
            1.0,
            0.02,
        )
        evaluation = evaluator.evaluate(grasp, BOX, trajectory, seed_positions=positions)
        if evaluation.feasible:
            break
    assert evaluation.feasible, evaluation.reason
    terms = grasp_terms(
        robot, evaluator.ik.chain, BOX, grasp.transform_tip_to_object, evaluation.joint_positions
    )
    motion = evaluator.trajectory_for(grasp, trajectory)
    return grasp, evaluation, terms, motion


def one_grasp(terms: SampleTerms) -> tuple[SampleTerms, np.ndarray]:
    """One grasp's terms (``grasp_terms``: axis 0 dropped) as a batch of one and its sample
    count, as the compiled ``*_on_terms`` analyses take them."""
    return SampleTerms(*(array[None] for array in terms)), np.array([len(terms[0])])


TERM_ARMS = ("arm7", "baxter", "prismatic_arm", "continuous_arm", "geared_arm")
