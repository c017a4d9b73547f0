"""Fast paths give the same results as the plain ones: compiled kernels vs Pinocchio from
Python, vectorised tip path vs ObjectTrajectory.tip_path, pools vs serial, and both vs the
implementation before the optimisation (bench/reference.py: its effective masses on our joint
paths; its IK only on non-redundant arms, as its warm start let redundant arms drift).
Equality only, never timing."""

from __future__ import annotations

import importlib.util
import sys
import threading
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, ARM7_AXES, BAXTER_SEED, random_positions, serial_arm_urdf
from tolerances import (
    ROUNDINGS_PER_JOINT,
    assert_close_to_scale,
    condition_number,
    dynamics_tolerance,
    effort_tolerances,
    kinematics_tolerance,
    mass_matrices,
    rounding_tolerance,
)

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    IKConfig,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.compiled import chain_arrays
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    translational_mobilities_in_base,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.method.ik import IKSolver, compiled_available
from grasp_safety_ros.core.method.ranking import Ranking
from grasp_safety_ros.core.model.trajectory import TipMotion, exp3_batch

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
    rng = np.random.default_rng(seed)
    return [
        Grasp(pin.SE3(pin.exp3(rng.uniform(-0.2, 0.2, 3)), rng.uniform(-0.03, 0.03, 3)), f"g{k}")
        for k in range(count)
    ]


def assert_same_ranking(a: Ranking, b: Ranking, rtol: float = RTOL) -> None:
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
        for field in (
            "times_s",
            "joint_positions",
            "directions_in_base",
            "effective_mass_kg",
            "direction_is_worst_case",
            "tip_speed_m_s",
            "ik_iterations",
        ):
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


# --- building blocks ------------------------------------------------------------------------


def test_exp3_batch_equals_pinocchio() -> None:
    rng = np.random.default_rng(0)
    vectors = np.vstack([rng.normal(size=(20, 3)), 1e-7 * rng.normal(size=(5, 3)), np.zeros(3)])
    for vector, rotation in zip(vectors, exp3_batch(vectors), strict=True):
        np.testing.assert_allclose(rotation, pin.exp3(vector), rtol=0, atol=1e-15)


def test_tip_motion_equals_tip_path() -> None:
    """The vectorised tip motion (ObjectMotion composed with the grasp) against Pinocchio's
    pose products and the tangent formula, sample by sample; speeds are |tangent| ds/dt."""
    trajectory = ObjectTrajectory(
        pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start"),
        pose_from_position_quat([1.1, -0.38, 0.16], [0.0, 0.0, 0.2, 0.98], "goal"),
        2.0,
        0.05,
    )
    times = trajectory.times_s()
    s_values, s_rate, _ = trajectory.path_parameter(times)
    for grasp in grasps_near_identity(4):
        poses, tangents = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
        motion = trajectory.tip_motion(grasp.transform_tip_to_object, times)
        np.testing.assert_allclose(motion.rotations, [p.rotation for p in poses], atol=1e-15)
        np.testing.assert_allclose(motion.positions, [p.translation for p in poses], atol=1e-15)
        np.testing.assert_allclose(motion.tangents, tangents, atol=1e-15)
        np.testing.assert_allclose(
            motion.speeds, np.linalg.norm(tangents, axis=1) * s_rate, rtol=1e-15, atol=1e-15
        )


def test_chain_arrays_take_continuous_joints() -> None:
    robot = ROBOTS["continuous"]()
    assert (robot.model.nq, robot.model.nv) == (8, 6)
    chain = chain_arrays(robot)
    assert chain is not None
    np.testing.assert_array_equal(chain.continuous, [True, False, False, True, False, False])
    np.testing.assert_array_equal(chain.q_index, [0, 2, 3, 4, 6, 7])
    assert np.isinf(chain.lower_q[[0, 1, 4, 5]]).all() and np.isfinite(chain.lower_q[2])
    assert IKSolver(robot).compiled == compiled_available()  # auto: no fallback


@needs_numba
def test_integrate_and_difference_of_continuous_joints_equal_pinocchio() -> None:
    from grasp_safety_ros.core.kernels.kinematics import _integrate, _joint_difference

    robot = ROBOTS["continuous"]()
    model, chain = robot.model, chain_arrays(robot)
    assert chain is not None
    index = (chain.q_index, chain.continuous)
    rng = np.random.default_rng(12)
    out = np.empty(model.nq)
    for scale in (1.0, 1.0 + 1e-7):  # (cos, sin) slightly off the unit circle, as iterates
        for _ in range(20):
            q = robot.q_from_positions(random_positions(robot, rng)) * scale
            step = rng.uniform(-1.0, 1.0, model.nv)
            _integrate(chain, q, step, out, False)
            np.testing.assert_allclose(out, pin.integrate(model, q, step), rtol=0, atol=ROUNDING)
            q_to = pin.integrate(model, q, rng.uniform(-3.0, 3.0, model.nv))
            expected = pin.difference(model, q, q_to)
            for k in range(model.nv):
                assert _joint_difference(*index, q, q_to, k) == pytest.approx(
                    expected[k], rel=0, abs=ROUNDING
                )
    q = robot.q_from_positions(np.zeros(6))
    for angle in (1e-3, 0.5, 3.0, np.pi):  # every branch of Pinocchio's SO(2) log
        q_to = pin.integrate(model, q, np.full(6, angle))
        assert _joint_difference(*index, q, q_to, 0) == pytest.approx(
            pin.difference(model, q, q_to)[0], rel=0, abs=ROUNDING
        )


def test_configuration_is_validated() -> None:
    with pytest.raises(InvalidInputError, match="backend: must be one of auto, compiled"):
        EvaluationConfig(backend="gpu")
    with pytest.raises(InvalidInputError, match="workers: must be an integer >= 0"):
        EvaluationConfig(workers=-1)
    with pytest.raises(InvalidInputError, match="parallel_min_samples: must be an integer"):
        EvaluationConfig(parallel_min_samples=1.5)  # type: ignore[arg-type]


@needs_numba
@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_compiled_mobilities_equal_pinocchio(name: str) -> None:
    robot = ROBOTS[name]()
    chain = chain_arrays(robot)
    assert chain is not None
    rng = np.random.default_rng(5)
    positions = np.array([random_positions(robot, rng) for _ in range(10)])
    q_all = np.array([robot.q_from_positions(p) for p in positions])
    for grasp in grasps_near_identity(3):
        pose = grasp.transform_tip_to_object
        compiled = translational_mobilities_in_base(robot, BOX, pose, q_all, chain)
        batched = translational_mobilities_in_base(robot, BOX, pose, q_all)
        model = augmented_model(robot, BOX, pose)
        single = [
            translational_mobility_in_base(robot, model, model.createData(), q) for q in q_all
        ]
        # J M⁻¹ Jᵀ: conditioned by M; k as the shared terms' (the same kernels).
        matrices = mass_matrices(robot, model, positions)
        tolerance = rounding_tolerance(
            condition_number(matrices), ROUNDINGS_PER_JOINT * robot.num_joints
        )
        for ours, expected in zip(compiled, single, strict=True):
            assert_close_to_scale(ours, expected, "mobility", tolerance)
        np.testing.assert_array_equal(batched, single)


@needs_numba
@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_compiled_ik_equals_python_ik(name: str) -> None:
    robot = ROBOTS[name]()
    python, compiled = IKSolver(robot, backend="python"), IKSolver(robot, backend="compiled")
    rng = np.random.default_rng(6)
    for _ in range(10):
        goal = random_positions(robot, rng)
        target = robot.transform_tip_to_base(goal)
        start = robot.q_from_positions(
            np.clip(
                goal + rng.uniform(-0.4, 0.4, robot.num_joints),
                robot.lower_limits,
                robot.upper_limits,
            )
        )
        q_py, ok_py, it_py = python.solve(target, start)
        q_c, ok_c, it_c = compiled.solve(target, start)
        assert (ok_py, it_py) == (ok_c, it_c)
        np.testing.assert_allclose(q_c, q_py, rtol=0, atol=1e-9)


@needs_numba
def test_solve_trajectory_is_the_same_in_both_backends(arm7: RobotModel) -> None:
    rng = np.random.default_rng(13)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed)
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    poses, _ = trajectory.tip_path(pin.SE3.Identity(), s_values)
    seed_q = arm7.q_from_positions(seed)
    for config in (IKConfig(), IKConfig(max_joint_step=1e-3)):
        a = IKSolver(arm7, config, "python").solve_trajectory(poses, times, s_values, seed_q)
        b = IKSolver(arm7, config, "compiled").solve_trajectory(poses, times, s_values, seed_q)
        assert a.reason == b.reason
        np.testing.assert_array_equal(a.iterations, b.iterations)
        np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
    assert "jumps by" in a.reason


# --- whole rankings -------------------------------------------------------------------------


def evaluators(robot: RobotModel, **config: object) -> tuple[GraspSafetyEvaluator, ...]:
    base = EvaluationConfig(workers=1, **config)  # type: ignore[arg-type]
    return (
        GraspSafetyEvaluator(robot, replace(base, backend="python")),
        GraspSafetyEvaluator(robot, replace(base, backend="compiled")),
    )


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


# --- pools ----------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", ["compiled", "python"])
def test_parallel_ranking_is_identical_to_serial(backend: str, arm7: RobotModel) -> None:
    if backend == "compiled" and not compiled_available():
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(11)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    grasps = [*grasps_near_identity(8), Grasp(pin.SE3(np.eye(3), np.array([0, 0, 5.0])), "far")]
    serial = GraspSafetyEvaluator(arm7, EvaluationConfig(backend=backend, workers=1))
    pooled = GraspSafetyEvaluator(
        arm7, EvaluationConfig(backend=backend, workers=2, parallel_min_samples=1)
    )
    expected = serial.rank(grasps, BOX, trajectory, seed_positions=seed)
    progress: list[tuple[int, int]] = []
    got = pooled.rank(
        grasps, BOX, trajectory, seed_positions=seed, progress=lambda *a: progress.append(a)
    )
    assert getattr(pooled, "_grasp_pool", None) is not None  # the pool was used
    assert progress == [(k, len(grasps)) for k in range(1, len(grasps) + 1)]
    assert_identical_ranking(got, expected)
    assert_identical_ranking(pooled.rank(grasps, BOX, trajectory, seed_positions=seed), expected)


def test_warm_up_runs_with_and_without_an_evaluator(arm6: RobotModel) -> None:
    from grasp_safety_ros.core.method.warm_up import warm_up

    assert warm_up() >= 0.0
    assert warm_up(GraspSafetyEvaluator(arm6)) >= 0.0
    assert warm_up(GraspSafetyEvaluator(arm6, EvaluationConfig(backend="python"))) == 0.0


def test_small_requests_stay_serial(arm6: RobotModel) -> None:
    evaluator = GraspSafetyEvaluator(arm6, EvaluationConfig(workers=2, parallel_min_samples=10**6))
    seed = random_positions(arm6, np.random.default_rng(12))
    evaluator.rank(grasps_near_identity(2), BOX, reach_trajectory(arm6, seed), seed_positions=seed)
    assert getattr(evaluator, "_grasp_pool", None) is None


class _AbandonError(Exception):
    pass


def test_closing_the_pool_stream_starts_no_further_job() -> None:
    """Abandoning a pooled request stops it per job, not per chunk (deterministic gates)."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import evaluate_jobs

    gate = threading.Event()
    started: list[int] = []
    lock = threading.Lock()

    def evaluate(_: object, index: int) -> int:
        with lock:
            started.append(index)
        if index >= 3:  # every job but the first three waits until the stream is closed
            gate.wait(10.0)
        return index

    with ThreadPoolExecutor(max_workers=2) as executor:
        stream = evaluate_jobs(None, executor, [(k,) for k in range(100)], evaluate)
        assert [next(stream) for _ in range(3)] == [0, 1, 2]
        stream.close()
        gate.set()
    # 0, 1, 2, then each of the two workers finishes the one job it had started; the other
    # 95 jobs never start (with chunks of jobs, every started chunk would run to its end).
    assert len(started) <= 3 + 2, sorted(started)


def test_progress_that_raises_abandons_a_pooled_ranking(arm7: RobotModel) -> None:
    rng = np.random.default_rng(13)
    seed = random_positions(arm7, rng)
    trajectory = reach_trajectory(arm7, seed, dt=0.05)
    pooled = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=2, parallel_min_samples=1))
    calls: list[int] = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if done == 2:
            raise _AbandonError

    with pytest.raises(_AbandonError):
        pooled.rank(grasps_near_identity(40), BOX, trajectory, seed, progress=progress)
    assert calls == [1, 2]  # called per grasp, in order, with the pool
    # the pool is free again and gives the serial result
    serial = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    grasps = grasps_near_identity(4)
    assert_identical_ranking(
        pooled.rank(grasps, BOX, trajectory, seed), serial.rank(grasps, BOX, trajectory, seed)
    )


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


# --- The shared per-(grasp, sample) terms and their consumers ---------------------------------


def _terms_case(robot: RobotModel, seed: int) -> tuple:
    """A grasp along a short reach of ``robot``, its evaluation and its shared terms."""
    from grasp_safety_ros.core.method.terms import grasp_terms

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


TERM_ARMS = ("arm7", "baxter", "prismatic_arm", "continuous_arm", "geared_arm")


@pytest.fixture
def prismatic_arm() -> RobotModel:
    urdf = serial_arm_urdf(ARM7_AXES).replace(
        '<joint name="j3" type="revolute"', '<joint name="j3" type="prismatic"'
    )
    return RobotModel.from_urdf(urdf, "base_link", "tool")


@pytest.fixture
def geared_arm() -> RobotModel:
    """Reflected rotor inertia on every joint: M, M⁻¹ and RNEA include it (once)."""
    armature = [0.3, 0.25, 0.2, 0.1, 0.05, 0.04, 0.02]
    return RobotModel.from_urdf(
        serial_arm_urdf(ARM7_AXES), "base_link", "tool", armature_kgm2=armature
    )


@pytest.fixture
def continuous_arm() -> RobotModel:
    return RobotModel.from_urdf(
        serial_arm_urdf(ARM7_AXES, joint_type="continuous"), "base_link", "tool"
    )


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_shared_terms_equal_pinocchio(name: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, _ = _terms_case(robot, 11)
    model = augmented_model(robot, BOX, grasp.transform_tip_to_object)
    data = model.createData()
    kinematic, dynamic = kinematics_tolerance(robot), dynamics_tolerance(robot, terms)
    for i, positions in enumerate(evaluation.joint_positions):
        q = robot.q_from_positions(positions)
        pin.computeMinverse(model, data, q)
        upper = np.triu(data.Minv)
        assert_close_to_scale(
            terms.mass_matrix_inverses[i], upper + np.triu(upper, 1).T, "Minv", dynamic
        )
        pin.computeJointJacobians(model, data, q)
        tip = pin.updateFramePlacement(model, data, robot.tip_frame_id)
        jacobian = pin.getFrameJacobian(
            model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        assert_close_to_scale(terms.tip_jacobians[i], jacobian, "tip Jacobian", kinematic)
        assert_close_to_scale(terms.tip_rotations[i], tip.rotation, "tip rotation", kinematic)
        assert_close_to_scale(terms.tip_translations[i], tip.translation, "tip origin", kinematic)
        for k in range(robot.num_joints):
            placement = data.oMi[k + 1]
            assert_close_to_scale(
                terms.joint_rotations[i, k], placement.rotation, "joint R", kinematic
            )
            assert_close_to_scale(
                terms.joint_origins[i, k], placement.translation, "joint p", kinematic
            )
            motion = pin.getJointJacobian(model, data, k + 1, pin.ReferenceFrame.WORLD)[:, k]
            assert_close_to_scale(terms.joint_motions[i, k], motion, "motion subspace", kinematic)
        mobility = translational_mobility_in_base(robot, model, data, q)
        assert_close_to_scale(terms.tip_mobilities[i], mobility, "tip mobility", dynamic)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_exposed_points_from_shared_terms_equal_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    from grasp_safety_ros.core.analyses.exposed_points import (
        box_corners_in_object,
        evaluate_exposed_points,
    )

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = _terms_case(robot, 12)
    points = box_corners_in_object([0.08, 0.12, 0.2])
    reference = evaluate_exposed_points(robot, evaluation, BOX, grasp, motion, points)
    shared = evaluate_exposed_points(robot, evaluation, BOX, grasp, motion, points, terms=terms)
    tolerance = dynamics_tolerance(robot, terms)
    for field in ("effective_mass_kg", "directions_in_base"):
        assert_close_to_scale(getattr(shared, field), getattr(reference, field), field, tolerance)
    np.testing.assert_array_equal(shared.leading_point_index, reference.leading_point_index)
    np.testing.assert_array_equal(shared.worst_point_index, reference.worst_point_index)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_effort_from_shared_terms_equals_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    from grasp_safety_ros.core.analyses.effort import evaluate_effort

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = _terms_case(robot, 13)
    reference = evaluate_effort(robot, evaluation, BOX, grasp, motion)
    shared = evaluate_effort(robot, evaluation, BOX, grasp, motion, terms=terms)
    tolerances = effort_tolerances(robot, evaluation, BOX, grasp, reference)
    for field in ("joint_velocities", "joint_accelerations", "joint_torques", "peak_abs_torque"):
        expected = getattr(reference, field)
        assert_close_to_scale(getattr(shared, field), expected, field, tolerances[field])


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_point_jacobians_from_shared_terms_equal_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    """A point on each link (0.1 m off its joint origin) and the tip: linear Jacobians from the
    terms equal Pinocchio's frame Jacobians (LOCAL_WORLD_ALIGNED) of frames placed there."""
    from grasp_safety_ros.core.method.terms import point_jacobians

    robot: RobotModel = request.getfixturevalue(name)
    _, evaluation, terms, _ = _terms_case(robot, 14)
    model = robot.model.copy()
    offset = pin.SE3(np.eye(3), np.array([0.03, -0.05, 0.1]))
    frames = [
        model.addFrame(pin.Frame(f"site{k}", k + 1, 0, offset, pin.FrameType.OP_FRAME))
        for k in range(robot.num_joints)
    ]
    data = model.createData()
    tip = point_jacobians(terms, robot.num_joints - 1, terms.tip_translations[:, None])
    tolerance = kinematics_tolerance(robot)
    assert_close_to_scale(tip[:, 0], terms.tip_jacobians[:, :3], "tip as a point", tolerance)
    for i, positions in enumerate(evaluation.joint_positions[::10]):
        q = robot.q_from_positions(positions)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, frame in enumerate(frames):
            point = data.oMf[frame].translation
            ours = point_jacobians(terms, k, point[None, None])  # every sample, one point
            expected = pin.getFrameJacobian(
                model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )[:3]
            assert_close_to_scale(ours[10 * i, 0], expected, f"site on link {k}", tolerance)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_whole_arm_from_shared_terms_equals_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    """Sites of the whole arm (the defaults and a point on every link) on the compiled path:
    positions, directions, speeds, masses, energies and the regions' worst cases."""
    from grasp_safety_ros.core.analyses.whole_arm import evaluate_whole_arm, resolve_arm_sites

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = _terms_case(robot, 16)
    links = {
        frame.name
        for frame in robot.model.frames
        if frame.type == pin.FrameType.BODY and frame.parentJoint > 0
    }
    sites = resolve_arm_sites(robot, {link: [[0.03, -0.05, 0.1]] for link in sorted(links)})
    reference = evaluate_whole_arm(robot, evaluation, BOX, grasp, motion, sites)
    shared = evaluate_whole_arm(robot, evaluation, BOX, grasp, motion, sites, terms=terms)
    assert reference.stationary.any() and not reference.stationary.all()  # both branches
    np.testing.assert_array_equal(shared.stationary, reference.stationary)
    kinematic, dynamic = kinematics_tolerance(robot), dynamics_tolerance(robot, terms)
    assert_close_to_scale(
        shared.positions_in_base_m, reference.positions_in_base_m, "positions", kinematic
    )
    for field in ("speed_m_s", "energy_j"):  # the joint rates through J⁺; energies through M
        assert_close_to_scale(getattr(shared, field), getattr(reference, field), field, dynamic)
    moving = ~reference.stationary
    masses, expected = shared.effective_mass_kg, reference.effective_mass_kg
    assert_close_to_scale(masses[moving], expected[moving], "masses", dynamic)
    # At rest the mass is 1/λ_min of the mobility A, conditioned by λ_max/λ_min (here up to
    # 1e6): λ_min agrees to rounding of A's scale, so compare 1/M_eff.
    assert_close_to_scale(
        1.0 / masses[~moving], 1.0 / expected[~moving], "1/masses at rest", dynamic
    )
    assert_close_to_scale(
        shared.directions_in_base[moving],
        reference.directions_in_base[moving],
        "directions",
        dynamic,
    )
    still = reference.stationary  # eigenvectors: up to sign
    signs = np.sign(
        np.einsum(
            "ka,ka->k", shared.directions_in_base[still], reference.directions_in_base[still]
        )
    )
    assert_close_to_scale(
        shared.directions_in_base[still] * signs[:, None],
        reference.directions_in_base[still],
        "directions at rest",
        dynamic,
    )
    for a, b in zip(shared.regions, reference.regions, strict=True):
        assert (a.region, a.worst_site, a.worst_sample, a.admissible) == (
            b.region,
            b.worst_site,
            b.worst_sample,
            b.admissible,
        )
        assert a.peak_contact_force_n == pytest.approx(b.peak_contact_force_n, rel=dynamic)
        assert a.worst_force_ratio == pytest.approx(b.worst_force_ratio, rel=dynamic)
