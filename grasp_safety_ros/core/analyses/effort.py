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
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import read_only
from ..method.compiled import augmented_bodies, pose_arrays
from ..method.dynamics import JointDynamics, joint_dynamics
from ..method.effective_mass import augmented_model
from ..method.packed import ChainArrays
from ..method.ranking import Grasp, GraspEvaluation
from ..method.terms import SampleTerms, configurations
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
) -> EffortEvaluation:
    """Joint velocities, accelerations and torques with the object, per sample, and summaries,
    by Pinocchio per sample: the reference of ``evaluate_efforts``' compiled path (equal to
    rounding, test_terms, test_effort_batch).

    Args:
        joint_positions: (N, n) positions to use instead of the evaluation's (e.g.
            RedundancyResolution.joint_positions); same samples and tip poses.
        model: The ``augmented_model`` of robot, object and grasp, when already built
            (shared across analyses).
    """
    limits = effort_limits(robot)
    if not evaluation.feasible:
        return _infeasible(evaluation, limits)
    times = np.asarray(evaluation.times_s, dtype=float)
    positions = _checked_positions(robot, evaluation, joint_positions)
    velocity_fd, acceleration_fd = _self_motion_rates(robot, positions, times, trajectory)
    twists_tip_in_base, twist_rates_tip_in_base = tip_twist_and_derivative(
        trajectory, grasp.transform_tip_to_object, times
    )
    rotation_base_to_world = robot.transform_base_to_world.rotation
    kinematics = robot.model.createData()
    if model is None:
        model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    data = model.createData()
    q_all = [robot.q_from_positions(p) for p in positions]
    velocities = np.empty_like(positions)
    accelerations = np.empty_like(positions)
    torques = np.empty_like(positions)
    for i, q in enumerate(q_all):
        v, a = _joint_rates(
            robot,
            kinematics,
            q,
            _in_world(rotation_base_to_world, twists_tip_in_base[i]),
            _in_world(rotation_base_to_world, twist_rates_tip_in_base[i]),
            velocity_fd[i],
            acceleration_fd[i],
        )
        velocities[i], accelerations[i] = v, a
        torques[i] = pin.rnea(model, data, q, v, a)
    return _summary(evaluation, limits, times, velocities, accelerations, torques)


def _self_motion_rates(
    robot: RobotModel, positions: np.ndarray, times: np.ndarray, trajectory: Trajectory
) -> tuple[np.ndarray, np.ndarray]:
    """(N, n) joint velocities and accelerations of the path ``positions`` by finite
    differences over the path parameter s and the chain rule in time (the null-space part)."""
    kinematic_model = robot.model
    n = robot.num_joints
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
    return velocity_fd, acceleration_fd


def _in_world(rotation_base_to_world: np.ndarray, twist_in_base: np.ndarray) -> np.ndarray:
    """A (6,) twist (or twist rate) in base axes rotated to world axes."""
    return np.concatenate(
        [rotation_base_to_world @ twist_in_base[:3], rotation_base_to_world @ twist_in_base[3:]]
    )


def _joint_rates(
    robot: RobotModel,
    kinematics: pin.Data,
    q: np.ndarray,
    twist: np.ndarray,
    twist_rate: np.ndarray,
    velocity_fd: np.ndarray,
    acceleration_fd: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint velocity and acceleration at ``q`` giving the tip ``twist`` and ``twist_rate``
    (world axes): the Jacobian pseudo-inverse's, plus the null-space part of the self-motion
    rates ``velocity_fd`` and ``acceleration_fd``."""
    kinematic_model = robot.model
    zero = np.zeros(kinematic_model.nv)
    pin.computeJointJacobians(kinematic_model, kinematics, q)
    jacobian = pin.getFrameJacobian(
        kinematic_model,
        kinematics,
        robot.tip_frame_id,
        pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    ).reshape(6, kinematic_model.nv)
    pseudo_inverse = np.linalg.pinv(jacobian, rcond=1e-10)
    null = np.eye(kinematic_model.nv) - pseudo_inverse @ jacobian
    v = pseudo_inverse @ twist + null @ velocity_fd
    pin.forwardKinematics(kinematic_model, kinematics, q, v, zero)
    drift = pin.getFrameClassicalAcceleration(
        kinematic_model,
        kinematics,
        robot.tip_frame_id,
        pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    ).vector
    a = pseudo_inverse @ (twist_rate - drift) + null @ acceleration_fd
    return v, a


def _infeasible(evaluation: GraspEvaluation, limits: np.ndarray) -> EffortEvaluation:
    """The EffortEvaluation of an infeasible grasp: no samples, NaN summaries."""
    n = len(limits)
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


def _checked_positions(
    robot: RobotModel, evaluation: GraspEvaluation, joint_positions: np.ndarray | None
) -> np.ndarray:
    """The joint path (N, n) to use for a feasible grasp: ``joint_positions`` or the
    evaluation's; InvalidInputError unless finite with one row per sample."""
    positions = np.asarray(
        evaluation.joint_positions if joint_positions is None else joint_positions, dtype=float
    )
    shape = (len(evaluation.times_s), robot.num_joints)
    if positions.shape != shape or not np.all(np.isfinite(positions)):
        raise InvalidInputError(
            "joint_positions",
            f"must be finite with shape {list(shape)}, got {list(positions.shape)}",
        )
    return positions


def evaluate_efforts(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    object_inertia: ObjectInertia,
    grasps: Sequence[Grasp],
    trajectories: Trajectory | Sequence[Trajectory],
    joint_positions: Sequence[np.ndarray | None] | None = None,
    terms: SampleTerms | None = None,
    chain: ChainArrays | None = None,
    executor: Executor | None = None,
) -> tuple[EffortEvaluation, ...]:
    """``evaluate_effort`` of every grasp, equal to its Pinocchio reference to rounding
    (test_effort_batch): compiled, the per-sample work of all grasps in one kernel call
    (``method.dynamics.joint_dynamics``), which moves each trajectory's object motion
    (sampled once) to each grasp's tip. Pinocchio grasp by grasp where the kernels do not
    support the chain or numba is missing.

    Args:
        trajectories: The motion of every grasp: one for all, or one per grasp
            (``GraspSafetyEvaluator.trajectory_for``).
        joint_positions: Per grasp, (N, n) positions to use instead of the evaluation's, or
            None (the evaluation's).
        terms: The grasps' ``SampleTerms`` along these positions (axis 0 as ``evaluations``;
            ``method.terms.batch_terms``), when already computed; None: the kernel computes
            the kinematics it needs (cheaper than storing them).
        chain: ``method.compiled.chain_arrays(robot)``: the compiled path; None: Pinocchio
            grasp by grasp (the reference).
        executor: On the compiled path, a thread pool that shares the kernel call out
            (``method.pool.split_grasps``; the same bits); None: serial.
    """
    count = len(evaluations)
    if isinstance(trajectories, Sequence):
        motions = list(trajectories)
    else:
        motions = [trajectories] * count
    overrides = [None] * count if joint_positions is None else list(joint_positions)
    if not len(grasps) == len(motions) == len(overrides) == count:
        raise InvalidInputError(
            "grasps", f"need one grasp, motion and path per evaluation ({count})"
        )
    if chain is None:
        return tuple(
            evaluate_effort(robot, evaluation, object_inertia, grasp, motion, path)
            for evaluation, grasp, motion, path in zip(
                evaluations, grasps, motions, overrides, strict=True
            )
        )
    limits = effort_limits(robot)
    positions, counts, motion_of, first_of_group = _packed_paths(
        robot, evaluations, motions, overrides
    )
    paths, object_rotations, object_twists = _object_motions(
        evaluations, motions, first_of_group, positions.shape[1]
    )
    rotations, translations = pose_arrays([grasp.transform_tip_to_object for grasp in grasps])
    bodies = augmented_bodies(robot, object_inertia, rotations, translations)
    model = robot.model
    q_all = positions if model.nq == model.nv else configurations(robot, positions)
    gravity = np.asarray(model.gravity.linear, dtype=float)
    dynamics = joint_dynamics(
        chain,
        bodies,
        positions,
        q_all,
        counts,
        motion_of,
        paths,
        object_rotations,
        object_twists,
        translations,
        gravity,
        terms,
        executor,
    )
    return _compiled_efforts(evaluations, limits, counts, motion_of, dynamics)


def _packed_paths(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    motions: Sequence[Trajectory],
    overrides: Sequence[np.ndarray | None],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """The feasible grasps' joint paths packed for the kernel, checked as ``_checked_positions``.

    Returns (positions (G, N, n) zero-padded, sample counts (G,), each grasp's motion group
    (G,): one per (motion, sample times), the first grasp of each group).
    """
    count, n = len(evaluations), robot.num_joints
    feasible = [k for k, evaluation in enumerate(evaluations) if evaluation.feasible]
    samples = max((len(evaluations[k].times_s) for k in feasible), default=0)
    positions = np.zeros((count, samples, n))
    counts = np.zeros(count, dtype=np.int64)
    motion_of = np.zeros(count, dtype=np.int64)
    groups: dict[tuple[int, bytes], int] = {}  # (motion, sample times) -> its index
    first_of_group: list[int] = []
    for k in feasible:
        evaluation = evaluations[k]
        path = np.asarray(
            evaluation.joint_positions if overrides[k] is None else overrides[k], dtype=float
        )
        if path.shape != (len(evaluation.times_s), n):
            _checked_positions(robot, evaluation, path)  # raises
        counts[k] = len(path)
        positions[k, : len(path)] = path
        key = (id(motions[k]), np.asarray(evaluation.times_s, dtype=float).tobytes())
        motion_of[k] = groups.setdefault(key, len(groups))
        if motion_of[k] == len(first_of_group):
            first_of_group.append(k)
    finite = np.isfinite(positions).all(axis=(1, 2))
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        _checked_positions(robot, evaluations[k], positions[k, : counts[k]])  # raises
    return positions, counts, motion_of, first_of_group


def _object_motions(
    evaluations: Sequence[GraspEvaluation],
    motions: Sequence[Trajectory],
    first_of_group: list[int],
    samples: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per motion group, zero-padded to ``samples``: the path parameter (3, N) (s, ṡ, s̈),
    the object's rotations (N, 3, 3) and its origin's twist and twist rate (2, N, 6)."""
    # Each motion's path parameter and the object's own motion (its origin's twist: the
    # identity grasp's); the kernel moves them to each grasp's tip.
    groups = len(first_of_group)
    paths = np.zeros((groups, 3, samples))
    object_rotations = np.zeros((groups, samples, 3, 3))
    object_twists = np.zeros((groups, 2, samples, 6))
    for index, k in enumerate(first_of_group):
        motion, times = motions[k], np.asarray(evaluations[k].times_s, dtype=float)
        paths[index, :, : len(times)] = motion.path_parameter(times)
        object_rotations[index, : len(times)] = motion.object_poses(times)[0]
        twist, rate = motion.tip_twists(pin.SE3.Identity(), times)
        object_twists[index, 0, : len(times)] = twist
        object_twists[index, 1, : len(times)] = rate
    return paths, object_rotations, object_twists


def _compiled_efforts(
    evaluations: Sequence[GraspEvaluation],
    limits: np.ndarray,
    counts: np.ndarray,
    motion_of: np.ndarray,
    dynamics: JointDynamics,
) -> tuple[EffortEvaluation, ...]:
    """The EffortEvaluations of the kernel's ``dynamics`` (read-only views of its arrays; the
    grasps of a motion group, ``motion_of``, share one copy of their sample times)."""
    shared_limits = read_only(limits, copy=True)
    peak_fractions = read_only(dynamics.peak_abs_torques / limits)
    rms_fractions = read_only(dynamics.rms_torques / limits)
    for array in dynamics:
        read_only(array)
    samples = dynamics.velocities.shape[1]
    velocities, accelerations, torques, peaks, rms = (list(array) for array in dynamics)
    peak_rows, rms_rows = list(peak_fractions), list(rms_fractions)
    times: dict[int, np.ndarray] = {}
    results = []
    for k, evaluation in enumerate(evaluations):
        if not evaluation.feasible:
            results.append(_infeasible(evaluation, limits))
            continue
        count, group = int(counts[k]), int(motion_of[k])
        if group not in times:
            times[group] = read_only(evaluation.times_s, copy=True)
        per_sample = (velocities[k], accelerations[k], torques[k])
        if count < samples:
            per_sample = tuple(rows[:count] for rows in per_sample)
        results.append(
            EffortEvaluation(  # positional: the fields in order
                evaluation.index,
                evaluation.name,
                True,
                times[group],
                *per_sample,
                peaks[k],
                rms[k],
                shared_limits,
                peak_rows[k],
                rms_rows[k],
            )
        )
    return tuple(results)


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
