"""Joint effort needed to carry the object along the trajectory (inverse dynamics, gravity on).

Joint positions q(t) come from the GraspEvaluation (or redundancy-resolved ones). Velocities
and accelerations follow from the tip's twist, exact in task space:

    J q̇ = ξ,        ξ = [d p_tip/ds · ṡ ; ω_obj · ṡ]                     (world axes)
    J q̈ = ξ̇ − J̇ q̇,  ξ̇ = [d²p_tip/ds² · ṡ² + d p_tip/ds · s̈ ; ω_obj · s̈]

(ω_obj: the object's constant angular velocity per unit s, the geodesic's log, rotated into
world axes; J̇ q̇: the tip's classical acceleration at q̈ = 0), solved with the pseudo-inverse
J⁺. For a redundant chain the null-space part, which the tip trajectory does not fix, comes from
the actual samples: the IK makes q a function of the path parameter s alone, so
q̇_fd = q'(s)·ṡ and q̈_fd = q''(s)·ṡ² + q'(s)·s̈ with q', q'' from finite differences over s
(numpy.gradient), and q̇ = J⁺ξ + (I − J⁺J) q̇_fd, likewise for q̈. Both vanish where the quintic
is at rest (t = 0 and T). For chains with at most 6 joints away from singularities the null
space is empty and the result is exact.

Torques: τ = RNEA(q, q̇, q̈) of the augmented model (the object merged into the tip body,
core.effective_mass.augmented_model), with the model's gravity in its world frame. Efforts are
N m for revolute joints and N for prismatic ones; limits are the URDF's ``effort`` (a limit
<= 0 or missing counts as unknown: NaN fractions).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import read_only
from ..method.effective_mass import augmented_inertia_arrays, augmented_model
from ..method.packed import BodyInertias
from ..method.ranking import Grasp, GraspEvaluation
from ..method.terms import SampleTerms
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import Trajectory

EFFORT_CRITERIA = ("peak_fraction", "rms_fraction")
"""Effort scores: max over joints of peak |τ| / limit, or of RMS τ / limit (lower is better)."""


def check_effort_criterion(criterion: str, field: str = "effort_criterion") -> str:
    """Return ``criterion`` if it is one of EFFORT_CRITERIA, else raise InvalidInputError."""
    if criterion not in EFFORT_CRITERIA:
        raise InvalidInputError(
            field, f"must be one of {', '.join(EFFORT_CRITERIA)}, got {criterion!r}"
        )
    return criterion


@dataclass(frozen=True)
class EffortEvaluation:
    """Joint efforts of one grasp along the trajectory (N samples, n chain joints).

    Attributes:
        index, name, feasible: As in the grasp's GraspEvaluation.
        times_s: (N,) sample times [s].
        joint_velocities: (N, n) q̇ [rad/s or m/s], chain order.
        joint_accelerations: (N, n) q̈ [rad/s² or m/s²].
        joint_torques: (N, n) τ [N m or N], gravity included.
        peak_abs_torque: (n,) max_t |τ| [N m or N].
        rms_torque: (n,) sqrt(mean_t τ²) over the samples [N m or N].
        effort_limits: (n,) URDF effort limits [N m or N]; NaN where unknown.
        peak_fraction_of_limit: (n,) peak_abs_torque / effort_limits (NaN if unknown).
        rms_fraction_of_limit: (n,) rms_torque / effort_limits (NaN if unknown).
    """

    index: int
    name: str
    feasible: bool
    times_s: np.ndarray
    joint_velocities: np.ndarray
    joint_accelerations: np.ndarray
    joint_torques: np.ndarray
    peak_abs_torque: np.ndarray
    rms_torque: np.ndarray
    effort_limits: np.ndarray
    peak_fraction_of_limit: np.ndarray
    rms_fraction_of_limit: np.ndarray

    @property
    def max_peak_fraction(self) -> float:
        """Largest peak fraction of the limit over joints with a known limit (NaN if none)."""
        return _nanmax(self.peak_fraction_of_limit)

    @property
    def max_rms_fraction(self) -> float:
        """Largest RMS fraction of the limit over joints with a known limit (NaN if none)."""
        return _nanmax(self.rms_fraction_of_limit)

    def score(self, criterion: str = "peak_fraction") -> float:
        """The effort criterion (EFFORT_CRITERIA); NaN if infeasible or no limit is known."""
        check_effort_criterion(criterion)
        if not self.feasible:
            return float("nan")
        return self.max_peak_fraction if criterion == "peak_fraction" else self.max_rms_fraction


def _nanmax(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else float("nan")


def effort_limits(robot: RobotModel) -> np.ndarray:
    """(n,) URDF effort limits in chain order [N m or N]; NaN where <= 0 or not finite."""
    limits = np.array(robot.model.effortLimit, dtype=float)
    return np.where(np.isfinite(limits) & (limits > 0.0), limits, np.nan)


def tip_twist_and_derivative(
    trajectory: Trajectory,
    transform_tip_to_object: pin.SE3,
    times_s: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Tip twist (N, 6) [m/s, rad/s] and its time derivative (N, 6), base axes.

    Linear part: velocity / classical acceleration of the tip origin; angular part: angular
    velocity / acceleration of the object (= of the tip).
    """
    return trajectory.tip_twists(transform_tip_to_object, times_s)


def evaluate_effort(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    trajectory: Trajectory,
    joint_positions: np.ndarray | None = None,
    model: pin.Model | None = None,
    terms: SampleTerms | None = None,
) -> EffortEvaluation:
    """Joint velocities, accelerations and torques with the object, per sample, and summaries.

    Args:
        joint_positions: (N, n) positions to use instead of the evaluation's (e.g.
            RedundancyResolution.joint_positions); same samples and tip poses.
        model: The ``augmented_model`` of robot, object and grasp, when already built
            (shared across analyses).
        terms: The grasp's ``method.terms.SampleTerms`` at these joint positions: then
            everything runs on arrays over the samples (``_dynamics_from_terms``); None:
            Pinocchio per sample (the reference; equal to rounding, test_performance_paths).
    """
    n = robot.num_joints
    limits = effort_limits(robot)
    if not evaluation.feasible:
        per_joint = read_only(np.full(n, np.nan), copy=True)
        per_sample = read_only(np.empty((0, n)), copy=True)
        return EffortEvaluation(
            index=evaluation.index,
            name=evaluation.name,
            feasible=False,
            times_s=read_only(np.empty(0), copy=True),
            joint_velocities=per_sample,
            joint_accelerations=per_sample,
            joint_torques=per_sample,
            peak_abs_torque=per_joint,
            rms_torque=per_joint,
            effort_limits=read_only(limits, copy=True),
            peak_fraction_of_limit=per_joint,
            rms_fraction_of_limit=per_joint,
        )
    times = np.asarray(evaluation.times_s, dtype=float)
    positions = np.asarray(
        evaluation.joint_positions if joint_positions is None else joint_positions, dtype=float
    )
    if positions.shape != (len(times), n) or not np.all(np.isfinite(positions)):
        raise InvalidInputError(
            "joint_positions",
            f"must be finite with shape {[len(times), n]}, got {list(positions.shape)}",
        )
    kinematic_model = robot.model
    # The IK makes q a function of the path parameter s only: null-space rates from
    # differences over s (unwrapped for continuous joints), then the chain rule in time.
    s_values, s_rate, s_accel = trajectory.path_parameter(times)
    if kinematic_model.nq == kinematic_model.nv:  # no continuous joint: plain differences
        steps = np.diff(positions, axis=0, prepend=np.zeros((1, n)))
        unwrapped = np.cumsum(steps, axis=0)  # the same sums, in the same order, as below
    else:
        q_all = [robot.q_from_positions(p) for p in positions]
        unwrapped = np.empty_like(positions)
        unwrapped[0] = positions[0]
        for i in range(1, len(times)):
            step = pin.difference(kinematic_model, q_all[i - 1], q_all[i])
            unwrapped[i] = unwrapped[i - 1] + step
    if len(times) > 1 and np.all(np.diff(s_values) > 0):
        dq_ds = np.gradient(unwrapped, s_values, axis=0)
        d2q_ds2 = np.gradient(dq_ds, s_values, axis=0)
    else:  # a single sample, or a path parameter that does not advance: no self-motion
        dq_ds = d2q_ds2 = np.zeros_like(positions)
    velocity_fd = dq_ds * s_rate[:, None]
    acceleration_fd = d2q_ds2 * s_rate[:, None] ** 2 + dq_ds * s_accel[:, None]
    twist_base, twist_rate_base = tip_twist_and_derivative(
        trajectory, grasp.transform_tip_to_object, times
    )
    rotation = robot.transform_base_to_world.rotation
    if terms is not None:
        twists = np.concatenate(
            [twist_base[:, :3] @ rotation.T, twist_base[:, 3:] @ rotation.T], 1
        )
        twist_rates = np.concatenate(
            [twist_rate_base[:, :3] @ rotation.T, twist_rate_base[:, 3:] @ rotation.T], 1
        )
        grasp_pose = pin.SE3(grasp.transform_tip_to_object)
        bodies = augmented_inertia_arrays(
            robot, object_inertia, grasp_pose.rotation[None], grasp_pose.translation[None]
        )
        velocities, accelerations, torques = _dynamics_from_terms(
            robot, terms, bodies, twists, twist_rates, velocity_fd, acceleration_fd
        )
        return _summary(evaluation, limits, times, velocities, accelerations, torques)
    kinematics = kinematic_model.createData()
    if model is None:
        model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    data = model.createData()
    q_all = [robot.q_from_positions(p) for p in positions]
    velocities = np.empty_like(positions)
    accelerations = np.empty_like(positions)
    torques = np.empty_like(positions)
    zero = np.zeros(kinematic_model.nv)
    for i, q in enumerate(q_all):
        pin.computeJointJacobians(kinematic_model, kinematics, q)
        jacobian = pin.getFrameJacobian(
            kinematic_model,
            kinematics,
            robot.tip_frame_id,
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        ).reshape(6, kinematic_model.nv)
        pseudo_inverse = np.linalg.pinv(jacobian, rcond=1e-10)
        null = np.eye(kinematic_model.nv) - pseudo_inverse @ jacobian
        twist = np.concatenate([rotation @ twist_base[i, :3], rotation @ twist_base[i, 3:]])
        twist_rate = np.concatenate(
            [rotation @ twist_rate_base[i, :3], rotation @ twist_rate_base[i, 3:]]
        )
        v = pseudo_inverse @ twist + null @ velocity_fd[i]
        pin.forwardKinematics(kinematic_model, kinematics, q, v, zero)
        drift = pin.getFrameClassicalAcceleration(
            kinematic_model,
            kinematics,
            robot.tip_frame_id,
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        ).vector
        a = pseudo_inverse @ (twist_rate - drift) + null @ acceleration_fd[i]
        velocities[i], accelerations[i] = v, a
        torques[i] = pin.rnea(model, data, q, v, a)
    return _summary(evaluation, limits, times, velocities, accelerations, torques)


def _summary(
    evaluation: GraspEvaluation,
    limits: np.ndarray,
    times: np.ndarray,
    velocities: np.ndarray,
    accelerations: np.ndarray,
    torques: np.ndarray,
) -> EffortEvaluation:
    """The EffortEvaluation of a feasible grasp from its per-sample q̇, q̈ and τ."""
    peak = np.abs(torques).max(axis=0)
    rms = np.sqrt(np.mean(torques**2, axis=0))
    return EffortEvaluation(
        index=evaluation.index,
        name=evaluation.name,
        feasible=True,
        times_s=read_only(times, copy=True),
        joint_velocities=read_only(velocities, copy=True),
        joint_accelerations=read_only(accelerations, copy=True),
        joint_torques=read_only(torques, copy=True),
        peak_abs_torque=read_only(peak, copy=True),
        rms_torque=read_only(rms, copy=True),
        effort_limits=read_only(limits, copy=True),
        peak_fraction_of_limit=read_only(peak / limits, copy=True),
        rms_fraction_of_limit=read_only(rms / limits, copy=True),
    )


def order_by_effort(
    efforts: Sequence[EffortEvaluation], criterion: str = "peak_fraction"
) -> tuple[int, ...]:
    """Indices of feasible grasps with a finite effort score, lowest first (ties: input order)."""
    check_effort_criterion(criterion)
    scored = [(e.score(criterion), k) for k, e in enumerate(efforts) if e.feasible]
    return tuple(efforts[k].index for _, k in sorted(s for s in scored if np.isfinite(s[0])))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (size 3), broadcast (np.cross without its axis handling)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def _dynamics_from_terms(
    robot: RobotModel,
    terms: SampleTerms,
    bodies: BodyInertias,
    twists: np.ndarray,
    twist_rates: np.ndarray,
    velocity_fd: np.ndarray,
    acceleration_fd: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q̇, q̈ and τ (N, n) of the module docstring on arrays over the N samples, from the
    shared terms (tip Jacobian, joint poses and axes, world frame) and the augmented bodies
    (``BodyInertias`` of one grasp): the same steps as the Pinocchio loop of
    ``evaluate_effort``, RNEA written out in world-frame spatial vectors (at the world origin).

    twists, twist_rates: (N, 6) tip twist and its rate, world axes [m/s, rad/s; m/s², rad/s²].
    """
    jacobian = terms.tip_jacobians  # (N, 6, n)
    n = jacobian.shape[-1]
    pseudo_inverse = np.linalg.pinv(jacobian, rcond=1e-10)  # (N, n, 6)
    null = np.eye(n) - pseudo_inverse @ jacobian
    velocities = (pseudo_inverse @ twists[..., None] + null @ velocity_fd[..., None])[..., 0]
    # Motion subspaces S_k = (linear_axes, angular_axes), world origin (SampleTerms).
    linear_axes, angular_axes = terms.joint_motions[..., :3], terms.joint_motions[..., 3:]
    origins = terms.joint_origins  # (N, n, 3)
    # Spatial velocities V_k = V_(k-1) + S_k q̇_k and the velocity-product accelerations
    # c_k = V_k × S_k q̇_k (motion cross product), cumulated down the chain.
    joint_linear = linear_axes * velocities[..., None]
    joint_angular = angular_axes * velocities[..., None]
    body_linear = np.cumsum(joint_linear, axis=1)
    body_angular = np.cumsum(joint_angular, axis=1)
    bias_linear = _cross(body_angular, joint_linear) + _cross(body_linear, joint_angular)
    bias_angular = _cross(body_angular, joint_angular)
    # The tip's classical acceleration at q̈ = 0 (the drift J̇ q̇).
    tip = terms.tip_translations
    tip_angular = body_angular[:, -1]
    tip_velocity = body_linear[:, -1] + _cross(tip_angular, tip)
    drift_linear = bias_linear.sum(axis=1)
    drift_angular = bias_angular.sum(axis=1)
    drift = np.concatenate(
        [
            drift_linear + _cross(drift_angular, tip) + _cross(tip_angular, tip_velocity),
            drift_angular,
        ],
        axis=1,
    )
    accelerations = (
        pseudo_inverse @ (twist_rates - drift)[..., None] + null @ acceleration_fd[..., None]
    )[..., 0]
    # RNEA: A_k = A_(k-1) + S_k q̈_k + c_k from A = (-gravity, 0); body forces
    # f = I A + V ×* (I V); joint torques τ_k = S_k · (f_k + ... + f_(n-1)).
    gravity = np.asarray(robot.model.gravity.linear, dtype=float)
    acc_linear = np.cumsum(linear_axes * accelerations[..., None] + bias_linear, axis=1) - gravity
    acc_angular = np.cumsum(angular_axes * accelerations[..., None] + bias_angular, axis=1)
    masses, levers, inertias = (array[0] for array in bodies)
    rotations = terms.joint_rotations  # (N, n, 3, 3)
    centres = origins + (rotations @ levers[..., None])[..., 0]
    inertias_world = rotations @ inertias @ np.swapaxes(rotations, -1, -2)
    momentum = masses[:, None] * (body_linear + _cross(body_angular, centres))
    angular_momentum = (inertias_world @ body_angular[..., None])[..., 0] + _cross(
        centres, momentum
    )
    force = masses[:, None] * (acc_linear + _cross(acc_angular, centres))
    moment = (inertias_world @ acc_angular[..., None])[..., 0] + _cross(centres, force)
    force = force + _cross(body_angular, momentum)
    moment = moment + _cross(body_angular, angular_momentum) + _cross(body_linear, momentum)
    force = np.cumsum(force[:, ::-1], axis=1)[:, ::-1]  # the subtree's total
    moment = np.cumsum(moment[:, ::-1], axis=1)[:, ::-1]
    torques = (linear_axes * force).sum(axis=-1) + (angular_axes * moment).sum(axis=-1)
    torques += np.asarray(robot.model.armature, dtype=float) * accelerations
    return velocities, accelerations, torques
