"""Compiled building blocks give the results of the plain ones: the kernels' joint operations,
mobilities and IK vs Pinocchio from Python, the vectorised tip path vs ObjectTrajectory.tip_path
(core/method/compiled.py, core/method/ik.py, core/kernels, core/model/trajectory.py). Equality
only, never timing."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions
from fast_paths import BOX, ROBOTS, ROUNDING, grasps_near_identity, needs_numba, reach_trajectory
from tolerances import (
    ROUNDINGS_PER_JOINT,
    assert_close_to_scale,
    condition_number,
    mass_matrices,
    rounding_tolerance,
)

from grasp_safety_ros.core import (
    EvaluationConfig,
    IKConfig,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.compiled import chain_arrays
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    translational_mobilities_in_base,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.method.ik import IKSolver, compiled_available
from grasp_safety_ros.core.model.trajectory import exp3_batch


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
