"""Tolerances of the comparisons of compiled and reference paths, derived from the problem:
k · cond · eps, with cond the condition number of the matrices a quantity goes through (the
mass matrix, the tip Jacobian the pseudo-inverse keeps) and k the roundings each path commits,
stated where it is chosen, so that they hold on any CPU and numba target."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from grasp_safety_ros.core import Grasp, ObjectInertia, RobotModel
from grasp_safety_ros.core.analyses.effort import EffortEvaluation
from grasp_safety_ros.core.method.effective_mass import augmented_model
from grasp_safety_ros.core.method.points import PSEUDO_INVERSE_RCOND
from grasp_safety_ros.core.method.ranking import GraspEvaluation
from grasp_safety_ros.core.method.terms import SampleTerms

EPS = float(np.finfo(float).eps)
"""Unit roundoff of float64 (2.2e-16)."""


def condition_number(matrices: np.ndarray, rcond: float = 0.0) -> float:
    """The largest 2-norm condition number σ_max / σ_min over a stack (..., m, n) of matrices;
    singular values at or below ``rcond`` σ_max are dropped, as a pseudo-inverse with that
    ``rcond`` drops them (a rank-deficient J is conditioned by the directions it keeps)."""
    values = np.linalg.svd(np.asarray(matrices, dtype=float), compute_uv=False)
    values = values.reshape(-1, values.shape[-1])
    largest = values[:, :1]
    kept = np.where(values > rcond * largest, values, np.inf)
    # an all-zero matrix keeps no value (inf: 0 / inf = 0): condition 1 at least, never a
    # tolerance of 0
    return max(float(np.max(largest[:, 0] / kept.min(axis=1))), 1.0)


def rounding_tolerance(condition: float, k: float) -> float:
    """k · cond · eps: the relative error two float64 evaluations of the same quantity may
    show when they round differently (another summation order, fused multiply-adds, another
    CPU or numba target), for a problem of condition number ``cond``. ``k`` counts the
    roundings each path commits (stated by each caller)."""
    return k * condition * EPS


def assert_close_to_scale(
    actual: np.ndarray, expected: np.ndarray, what: str, tolerance: float
) -> None:
    """max |actual - expected| <= tolerance · max |expected| (a relative error of the array,
    so that entries near zero are held to their array's scale, not to their own)."""
    assert np.shape(actual) == np.shape(expected), what
    scale = max(float(np.max(np.abs(expected))), 1e-300)
    error = float(np.max(np.abs(np.asarray(actual) - expected))) / scale
    assert error <= tolerance, f"{what}: relative error {error:.2e} > {tolerance:.2e}"


ROUNDINGS_PER_JOINT = 8
"""k of the shared terms' tolerances, per joint of the chain: each joint's placement composes a
3x3 rotation and a translation (3-term dot products, fused multiply-adds or not), and each
consumer then sums n-term products (M⁻¹ and J⁺ applied), so roundings grow with the chain's
length. The 8 is calibrated, not derived: it bounds the errors measured on every arm here (at
most ~1.3 of 8) with a margin; the linear growth in n is the derived part."""


def kinematics_tolerance(robot: RobotModel) -> float:
    """Forward kinematics and Jacobians: rotations are orthogonal (condition 1), the error
    is the rounding of the joints' compositions."""
    return rounding_tolerance(1.0, ROUNDINGS_PER_JOINT * robot.num_joints)


def terms_condition(terms: SampleTerms) -> float:
    """The worse of cond(M) (of the augmented chain, from M⁻¹) and cond(J) (the tip's) over
    the samples: the consumers apply M⁻¹ (masses, mobilities) or J⁺ (rates)."""
    return max(
        condition_number(terms.mass_matrix_inverses),
        condition_number(terms.jacobians_tip_in_world, PSEUDO_INVERSE_RCOND),
    )


def dynamics_tolerance(robot: RobotModel, terms: SampleTerms) -> float:
    """Consumers of M⁻¹ or J⁺: the kinematics' roundings amplified by the condition."""
    return rounding_tolerance(terms_condition(terms), ROUNDINGS_PER_JOINT * robot.num_joints)


def mass_matrices(robot: RobotModel, model: pin.Model, joint_positions: np.ndarray) -> np.ndarray:
    """(N, n, n) M of ``model`` (the robot's, or one built on it) along a joint path."""
    data, matrices = model.createData(), []
    for positions in joint_positions:
        upper = np.triu(pin.crba(model, data, robot.q_from_positions(positions)))
        matrices.append(upper + np.triu(upper, 1).T)
    return np.array(matrices)


def path_tolerance(
    robot: RobotModel, object_inertia: ObjectInertia, grasp: Grasp, joint_positions: np.ndarray
) -> float:
    """``dynamics_tolerance`` of a grasp's joint path without its terms: k · cond · eps, cond
    the worse of M's (the chain carrying the object) and the tip Jacobian's along the path."""
    model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    data, jacobians = robot.model.createData(), []
    for positions in joint_positions:
        pin.computeJointJacobians(robot.model, data, robot.q_from_positions(positions))
        jacobians.append(
            pin.getFrameJacobian(
                robot.model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )
        )
    condition = max(
        condition_number(mass_matrices(robot, model, joint_positions)),
        condition_number(jacobians, PSEUDO_INVERSE_RCOND),
    )
    return rounding_tolerance(condition, ROUNDINGS_PER_JOINT * robot.num_joints)


def effort_tolerances(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    reference: EffortEvaluation,
) -> dict[str, float]:
    """Relative tolerances of an effort's fields (compiled vs Pinocchio) from the problem, with
    k = ROUNDINGS_PER_JOINT · n:

    - q̇ = J⁺ξ + (I - J⁺J) q̇_fd: k · cond(J) · eps (the singular values J⁺ keeps).
    - q̈ adds the null-space part's second differences of the positions over samples Δt apart:
      the [1, -2, 1] / Δt² stencil (norm 4 / Δt²) amplifies the positions' rounding eps·|q|
      (the two paths unwrap and difference them in another order), relative to max |q̈|;
      k = 4 for the two difference passes and the unwrap's running sums.
    - τ = M q̈ + h(q, q̇): k · cond(M) · eps plus ‖M‖ times q̈'s error, relative to max |τ|;
      the summaries (peaks, RMS, fractions of constant limits) as τ.
    """
    k = ROUNDINGS_PER_JOINT * robot.num_joints
    model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    masses = mass_matrices(robot, model, evaluation.joint_positions)
    kinematics, jacobians = robot.model.createData(), []
    for positions in evaluation.joint_positions:
        pin.computeJointJacobians(robot.model, kinematics, robot.q_from_positions(positions))
        jacobians.append(
            pin.getFrameJacobian(
                robot.model, kinematics, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )
        )
    velocities = rounding_tolerance(condition_number(jacobians, PSEUDO_INVERSE_RCOND), k)
    accelerations = velocities
    largest_acceleration = float(np.abs(reference.joint_accelerations).max())
    if len(evaluation.times_s) > 1 and largest_acceleration > 0.0:
        step_s = float(np.diff(evaluation.times_s).min())
        stencil = 4.0 * float(np.abs(evaluation.joint_positions).max()) / step_s**2
        accelerations += rounding_tolerance(stencil / largest_acceleration, 4)
    largest_torque = max(float(np.abs(reference.joint_torques).max()), 1e-300)
    mass_norm = float(np.linalg.norm(masses, 2, axis=(1, 2)).max())
    torques = (
        rounding_tolerance(condition_number(masses), k)
        + mass_norm * accelerations * largest_acceleration / largest_torque
    )
    return {
        "joint_velocities": velocities,
        "joint_accelerations": accelerations,
        **dict.fromkeys(
            (
                "joint_torques",
                "peak_abs_torque",
                "rms_torque",
                "peak_fraction_of_limit",
                "rms_fraction_of_limit",
            ),
            torques,
        ),
    }
