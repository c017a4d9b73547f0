"""The effort analysis's compiled batch (``evaluate_efforts``: one kernel call over every
(grasp, sample)) equals its Pinocchio reference (``evaluate_effort`` per grasp and sample) to
rounding, on the arms of test_performance_paths and at rank-deficient Jacobians; a static arm
holds the gravity torques; a batch gives each grasp what it gives that grasp alone."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM7_AXES, serial_arm_urdf
from fast_paths import BOX, TERM_ARMS, needs_numba, terms_case
from tolerances import assert_close_to_scale, effort_tolerances, kinematics_tolerance

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    ObjectInertia,
    ObjectTrajectory,
    RobotModel,
)
from grasp_safety_ros.core.analyses.effort import (
    EffortEvaluation,
    evaluate_effort,
    evaluate_efforts,
)
from grasp_safety_ros.core.method.compiled import augmented_bodies
from grasp_safety_ros.core.method.effective_mass import augmented_model
from grasp_safety_ros.core.method.ranking import GraspEvaluation
from grasp_safety_ros.core.method.terms import batch_terms, configurations

PER_SAMPLE = ("joint_velocities", "joint_accelerations", "joint_torques")
SUMMARIES = ("peak_abs_torque", "rms_torque", "peak_fraction_of_limit", "rms_fraction_of_limit")


def assert_effort_close(
    batched: EffortEvaluation,
    reference: EffortEvaluation,
    robot: RobotModel,
    evaluation: GraspEvaluation,
    grasp: Grasp,
    object_inertia: ObjectInertia = BOX,
) -> None:
    """Equal to the tolerances ``effort_tolerances`` derives from the grasp's problem."""
    assert batched.feasible == reference.feasible
    assert batched.index == reference.index and batched.name == reference.name
    np.testing.assert_array_equal(batched.times_s, reference.times_s)
    np.testing.assert_array_equal(batched.effort_limits, reference.effort_limits)
    if not reference.feasible:
        for field in PER_SAMPLE:
            assert getattr(batched, field).shape == (0, len(reference.effort_limits))
        for field in SUMMARIES:
            assert np.all(np.isnan(getattr(batched, field)))
        return
    tolerances = effort_tolerances(robot, evaluation, object_inertia, grasp, reference)
    for field in PER_SAMPLE:
        assert getattr(batched, field).shape == getattr(reference, field).shape
        assert_close_to_scale(
            getattr(batched, field), getattr(reference, field), field, tolerances[field]
        )
    for field in SUMMARIES:
        expected = getattr(reference, field)
        known = np.isfinite(expected)
        np.testing.assert_array_equal(np.isfinite(getattr(batched, field)), known)
        assert_close_to_scale(
            getattr(batched, field)[known], expected[known], field, tolerances[field]
        )


def assert_effort_identical(a: EffortEvaluation, b: EffortEvaluation) -> None:
    for field in ("times_s", *PER_SAMPLE, *SUMMARIES, "effort_limits"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    assert (a.index, a.name, a.feasible) == (b.index, b.name, b.feasible)


def infeasible_case(robot: RobotModel, trajectory: ObjectTrajectory) -> tuple:
    """A grasp 10 m from the tip: no IK solution, an infeasible evaluation."""
    far = Grasp(pin.SE3(np.eye(3), np.array([10.0, 0.0, 0.0])), "far")
    evaluation = GraspSafetyEvaluator(robot).evaluate(far, BOX, trajectory, index=1)
    assert not evaluation.feasible
    return far, evaluation


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_batch_equals_pinocchio_per_grasp(name: str, request: pytest.FixtureRequest) -> None:
    """Two feasible grasps on different trajectories with an infeasible one between them,
    with and without the shared terms, vs the Pinocchio loop of each grasp."""
    robot: RobotModel = request.getfixturevalue(name)
    chain = GraspSafetyEvaluator(robot).ik.chain
    first, evaluation1, _, motion1 = terms_case(robot, 21)
    second, evaluation2, _, motion2 = terms_case(robot, 22)
    far, infeasible = infeasible_case(robot, motion1)
    evaluations = [evaluation1, infeasible, replace(evaluation2, index=2)]
    grasps, motions = [first, far, second], [motion1, motion1, motion2]
    references = [
        evaluate_effort(robot, e, BOX, g, m)
        for e, g, m in zip(evaluations, grasps, motions, strict=True)
    ]
    batched = evaluate_efforts(robot, evaluations, BOX, grasps, motions, chain=chain)
    for ours, reference, e, g in zip(batched, references, evaluations, grasps, strict=True):
        assert_effort_close(ours, reference, robot, e, g)
    # The same on the shared terms (axis 0 as the evaluations; none for the infeasible one).
    samples = len(evaluation1.times_s)
    positions = np.zeros((3, samples, robot.num_joints))
    positions[0], positions[2] = evaluation1.joint_positions, evaluation2.joint_positions
    transforms = [pin.SE3(g.transform_tip_to_object) for g in grasps]
    bodies = augmented_bodies(
        robot,
        BOX,
        np.array([t.rotation for t in transforms]),
        np.array([t.translation for t in transforms]),
    )
    terms = batch_terms(
        chain, bodies, configurations(robot, positions), np.array([samples, 0, samples])
    )
    shared = evaluate_efforts(robot, evaluations, BOX, grasps, motions, terms=terms, chain=chain)
    for ours, reference, e, g in zip(shared, references, evaluations, grasps, strict=True):
        assert_effort_close(ours, reference, robot, e, g)


@needs_numba
@pytest.mark.parametrize("name", ("arm7", "baxter", "continuous_arm"))
def test_a_batch_gives_each_grasp_what_it_gives_it_alone(
    name: str, request: pytest.FixtureRequest
) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    chain = GraspSafetyEvaluator(robot).ik.chain
    first, evaluation1, _, motion = terms_case(robot, 23)
    far, infeasible = infeasible_case(robot, motion)
    second = Grasp(first.transform_tip_to_object * pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.01])))
    evaluation2 = GraspSafetyEvaluator(robot).evaluate(
        second, BOX, motion, index=2, seed_positions=evaluation1.joint_positions[0]
    )
    assert evaluation2.feasible, evaluation2.reason
    cases = [(evaluation1, first), (infeasible, far), (evaluation2, second)]
    together = evaluate_efforts(
        robot, [c[0] for c in cases], BOX, [c[1] for c in cases], motion, chain=chain
    )
    for (evaluation, grasp), ours in zip(cases, together, strict=True):
        alone = evaluate_efforts(robot, [evaluation], BOX, [grasp], motion, chain=chain)[0]
        assert_effort_identical(ours, alone)


@needs_numba
@pytest.mark.parametrize("name", ("arm7", "prismatic_arm", "continuous_arm"))
def test_single_sample(name: str, request: pytest.FixtureRequest) -> None:
    """One sample mid-way: no finite differences (no self-motion), the tip's twist only."""
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, _, motion = terms_case(robot, 24)
    middle = len(evaluation.times_s) // 2
    single = replace(
        evaluation,
        times_s=evaluation.times_s[middle : middle + 1],
        joint_positions=evaluation.joint_positions[middle : middle + 1],
    )
    reference = evaluate_effort(robot, single, BOX, grasp, motion)
    assert np.any(reference.joint_velocities != 0.0)
    chain = GraspSafetyEvaluator(robot).ik.chain
    batched = evaluate_efforts(robot, [single], BOX, [grasp], motion, chain=chain)[0]
    assert_effort_close(batched, reference, robot, single, grasp)


@needs_numba
@pytest.mark.parametrize("name", ("arm7", "baxter", "geared_arm", "continuous_arm"))
def test_a_static_arm_holds_the_gravity_torques(name: str, request: pytest.FixtureRequest) -> None:
    """Start = goal: q̇ = q̈ = 0 and τ = g(q) of the arm with the object (Pinocchio's
    generalised gravity of the augmented model; armature plays no part)."""
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, _, motion = terms_case(robot, 25)
    start = motion.transform_object_to_base_start
    still = ObjectTrajectory(start, start, 1.0, 0.1)
    evaluation = GraspSafetyEvaluator(robot).evaluate(
        grasp, BOX, still, seed_positions=evaluation.joint_positions[0]
    )
    assert evaluation.feasible, evaluation.reason
    held = np.repeat(evaluation.joint_positions[:1], len(evaluation.times_s), axis=0)
    evaluation = replace(evaluation, joint_positions=held)  # without the IK's own jitter
    chain = GraspSafetyEvaluator(robot).ik.chain
    effort = evaluate_efforts(robot, [evaluation], BOX, [grasp], still, chain=chain)[0]
    model = augmented_model(robot, BOX, grasp.transform_tip_to_object)
    data = model.createData()
    gravity = np.array(
        [
            pin.computeGeneralizedGravity(model, data, robot.q_from_positions(p))
            for p in evaluation.joint_positions
        ]
    )
    # The object's rotation log is ~1e-17 (log3 of R0ᵀ R0 rounded), not exactly zero.
    assert np.abs(effort.joint_velocities).max() < 1e-12
    assert np.abs(effort.joint_accelerations).max() < 1e-12
    # RNEA at rest: the placements' roundings outwards, then the forces' sums inwards.
    tolerance = 2.0 * kinematics_tolerance(robot)
    assert_close_to_scale(effort.joint_torques, gravity, "gravity torques", tolerance)
    assert_close_to_scale(effort.peak_abs_torque, np.abs(gravity).max(axis=0), "peak", tolerance)


def _override_case(robot: RobotModel, positions: np.ndarray) -> tuple:
    """An arm7 evaluation's samples and motion with the joint path replaced by ``positions``
    (N, n) for ``robot`` (the analysis takes any path: RedundancyResolution's)."""
    arm7 = RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES), "base_link", "tool")
    grasp, evaluation, _, motion = terms_case(arm7, 26)
    count = len(evaluation.times_s)
    path = np.broadcast_to(positions, (count, robot.num_joints)).copy()
    return grasp, replace(evaluation, joint_positions=path), motion


@needs_numba
@pytest.mark.parametrize("joints", [4, 7])
def test_rank_deficient_and_short_chains(joints: int) -> None:
    """Arms whose joints all turn about parallel axes (rank 3: numpy's rcond cut-off, in the
    Jacobi SVD), and generic 7- and 4-joint arms (J is 6 x 4: the tall case)."""
    generic = ARM7_AXES if joints == 7 else ("z", "y", "y", "x")
    rng = np.random.default_rng(joints)
    for axes in (generic, ("z",) * joints):
        robot = RobotModel.from_urdf(serial_arm_urdf(axes), "base_link", "tool")
        chain = GraspSafetyEvaluator(robot).ik.chain
        posture = rng.uniform(-1.0, 1.0, joints)
        grasp, evaluation, motion = _override_case(robot, posture)
        data = robot.model.createData()
        pin.computeJointJacobians(robot.model, data, robot.q_from_positions(posture))
        jacobian = pin.getFrameJacobian(
            robot.model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        rank = np.linalg.matrix_rank(jacobian, 1e-10 * np.linalg.norm(jacobian, 2))
        assert rank == (min(joints, 6) if axes == generic else 3)
        # Self-motion too: the path drifts along s, so the null-space rates are non-zero.
        drift = evaluation.joint_positions + 0.2 * motion.path_parameter(evaluation.times_s)[0][
            :, None
        ] * np.linspace(-1.0, 1.0, joints)
        evaluation = replace(evaluation, joint_positions=drift)
        reference = evaluate_effort(robot, evaluation, BOX, grasp, motion)
        batched = evaluate_efforts(robot, [evaluation], BOX, [grasp], motion, chain=chain)[0]
        assert_effort_close(batched, reference, robot, evaluation, grasp)


def test_without_the_kernels_the_batch_is_the_reference(arm7: RobotModel) -> None:
    """chain None: Pinocchio grasp by grasp, the same objects as ``evaluate_effort``."""
    grasp, evaluation, _, motion = terms_case(arm7, 27)
    batched = evaluate_efforts(arm7, [evaluation], BOX, [grasp], motion)[0]
    assert_effort_identical(batched, evaluate_effort(arm7, evaluation, BOX, grasp, motion))


def test_a_path_of_the_wrong_shape_is_refused(arm7: RobotModel) -> None:
    from grasp_safety_ros.core import InvalidInputError

    grasp, evaluation, _, motion = terms_case(arm7, 28)
    chain = GraspSafetyEvaluator(arm7).ik.chain
    with pytest.raises(InvalidInputError, match="joint_positions"):
        evaluate_efforts(arm7, [evaluation], BOX, [grasp], motion, [np.zeros((3, 7))], chain=chain)


@needs_numba
def test_planned_joint_trajectories_in_a_batch(baxter: RobotModel) -> None:
    """A grasp along its own planned joint trajectory (JointSpaceTrajectory: the object's
    motion from the joints) next to one along the object trajectory: each equals its
    reference."""
    from test_joint_trajectory import BOOK, GRASP, ik_route

    from grasp_safety_ros.core.method.joint_trajectory import PlannedJointTrajectory

    evaluator, trajectory, evaluation = ik_route(baxter)
    planned = PlannedJointTrajectory(
        baxter.joint_names, evaluation.times_s, evaluation.joint_positions
    )
    grasps = [Grasp(GRASP, "ik"), Grasp(GRASP, "planned", joint_trajectory=planned)]
    motions = [evaluator.trajectory_for(g, trajectory) for g in grasps]
    evaluations = [
        evaluator.evaluate(g, BOOK, m, index=k)
        for k, (g, m) in enumerate(zip(grasps, motions, strict=True))
    ]
    assert all(e.feasible for e in evaluations)
    batched = evaluate_efforts(
        baxter, evaluations, BOOK, grasps, motions, chain=evaluator.ik.chain
    )
    for ours, e, g, m in zip(batched, evaluations, grasps, motions, strict=True):
        assert_effort_close(ours, evaluate_effort(baxter, e, BOOK, g, m), baxter, e, g, BOOK)


@needs_numba
def test_batches_without_a_feasible_grasp(arm7: RobotModel) -> None:
    chain = GraspSafetyEvaluator(arm7).ik.chain
    assert evaluate_efforts(arm7, [], BOX, [], [], chain=chain) == ()
    _, _, _, motion = terms_case(arm7, 29)
    far, infeasible = infeasible_case(arm7, motion)
    efforts = evaluate_efforts(arm7, [infeasible] * 2, BOX, [far] * 2, motion, chain=chain)
    for effort in efforts:
        reference = evaluate_effort(arm7, infeasible, BOX, far, motion)
        assert_effort_close(effort, reference, arm7, infeasible, far)
