"""Bridge between the method and the compiled kernels: the chain as flat arrays
(``chain_arrays``) and batches of grasps through the fused kernel
(``evaluate_grasps_compiled``).

The kernels (``core.kernels``, numba) are imported only when first called.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pinocchio as pin

from ..exceptions import GraspSafetyError
from ..model.robot import RobotModel
from ..model.trajectory import ObjectMotion
from .effective_mass import STATIONARY_TANGENT_M, BodyInertias, robot_inertia_arrays

if TYPE_CHECKING:
    from ..model.inertia import ObjectInertia
    from .ik import IKConfig, IKSolver


class ChainArrays(NamedTuple):
    """A serial chain of one-degree-of-freedom joints as flat arrays, for the compiled kernels
    (one value, passed to them as a whole).

    Joint k (chain order) moves in the frame ``placement_k`` of joint k-1 (of the world for
    k = 0): rotation about, or translation along, the unit ``axis_k`` (joint frame). Its
    position is q[q_index[k]]; a continuous joint holds (cos, sin) of its angle in
    q[q_index[k]], q[q_index[k] + 1] (Pinocchio's representation, nq = 2, nv = 1).
    """

    placement_rotations: np.ndarray  # (n, 3, 3)
    placement_translations: np.ndarray  # (n, 3) [m]
    axes: np.ndarray  # (n, 3), unit
    prismatic: np.ndarray  # (n,) 1.0 for prismatic joints, 0.0 for revolute ones
    continuous: np.ndarray  # (n,) bool: revolute without limits, (cos, sin) in q
    q_index: np.ndarray  # (n,) int64: first entry of joint k in q
    tip_rotation: np.ndarray  # (3, 3): tip frame in the last joint's frame
    tip_translation: np.ndarray  # (3,) [m]
    base_rotation: np.ndarray  # (3, 3): base frame in the world frame
    base_translation: np.ndarray  # (3,) [m]
    lower_q: np.ndarray  # (nq,) -inf for continuous joints
    upper_q: np.ndarray  # (nq,) +inf for continuous joints
    armature: np.ndarray  # (n,) reflected rotor inertia [kg m^2, kg if prismatic]


class IKSettings(NamedTuple):
    """IKConfig and the velocity limits as the compiled IK reads them (one value)."""

    position_tolerance: float  # [m]
    orientation_tolerance: float  # [rad]
    max_iterations: int
    max_iteration_step: float
    max_joint_step: float
    predictor_max_ratio: float  # ik.PREDICTOR_MAX_RATIO
    any_velocity_check: bool
    check_velocity: np.ndarray  # (n,) bool: joint speed checked against velocity_limits
    velocity_limits: np.ndarray  # (n,) [rad/s or m/s]


class GraspBuffers(NamedTuple):
    """Outputs and scratch of the fused kernel for G grasps of N samples (one value; axis 0
    is the grasp)."""

    target_rotations: np.ndarray  # (G, N, 3, 3) tip targets, world frame
    target_translations: np.ndarray  # (G, N, 3) [m]
    tangents: np.ndarray  # (G, N, 3) [m] tip tangents, base axes (ObjectMotion's scale)
    tangent_norms: np.ndarray  # (G, N) their norms [m]
    q_all: np.ndarray  # (G, N, nq)
    iterations: np.ndarray  # (G, N) int64
    q_fail: np.ndarray  # (G, nq) last iterate of a failed sample
    guess: np.ndarray  # (G, nq) predictor scratch
    tip_twists: np.ndarray  # (G, N, 6) log6(T_{i-1}^-1 T_i) of the tip targets, tip frame
    mobilities: np.ndarray  # (G, N, 3, 3) [1/kg], base axes
    effective_masses: np.ndarray  # (G, N) [kg]
    directions: np.ndarray  # (G, N, 3) unit, base axes
    worst: np.ndarray  # (G, N) bool: tip not translating
    outcomes: np.ndarray  # (G, 3) int64: status, sample, joint (kernels.grasp)
    outcome_values: np.ndarray  # (G,) the value of a failed check (jump [rad], speed [rad/s])


def grasp_buffers(grasps: int, count: int, nq: int) -> GraspBuffers:
    """Fresh GraspBuffers for ``grasps`` grasps of count samples of a chain with nq
    configuration entries."""
    return GraspBuffers(
        np.empty((grasps, count, 3, 3)),
        np.empty((grasps, count, 3)),
        np.empty((grasps, count, 3)),
        np.empty((grasps, count)),
        np.empty((grasps, count, nq)),
        np.zeros((grasps, count), dtype=np.int64),
        np.empty((grasps, nq)),
        np.empty((grasps, nq)),
        np.empty((grasps, count, 6)),
        np.empty((grasps, count, 3, 3)),
        np.empty((grasps, count)),
        np.empty((grasps, count, 3)),
        np.zeros((grasps, count), dtype=np.bool_),
        np.zeros((grasps, 3), dtype=np.int64),
        np.zeros(grasps),
    )


def _is_continuous(joint: Any) -> bool:
    """Whether a Pinocchio joint model is a continuous (unbounded revolute) joint."""
    name = joint.shortname()
    return name.startswith("JointModelRUB") or name == "JointModelRevoluteUnboundedUnaligned"


def chain_arrays(robot: RobotModel) -> ChainArrays | None:
    """The chain of ``robot`` as arrays, or None when the compiled kernels cannot handle it.

    Supported: a serial chain of revolute, continuous and prismatic joints (Pinocchio's
    RX/RY/RZ, RUBX/RUBY/RUBZ, PX/PY/PZ and their unaligned variants), the tip frame on the
    last.
    """
    arrays = chain_arrays_or_reason(robot)
    return arrays if isinstance(arrays, ChainArrays) else None


_NOT_COMPILED = "not supported by the compiled kernels"


def chain_arrays_or_reason(robot: RobotModel) -> ChainArrays | str:
    """``chain_arrays``, or the reason the compiled kernels cannot handle the chain (e.g.
    ``JointModelPlanar joint j3 (3 DOF) not supported by the compiled kernels``)."""
    model = robot.model
    n = model.nv
    joints = list(model.joints)[1:]
    continuous = np.array([_is_continuous(joint) for joint in joints], dtype=np.bool_)
    for k, (joint, unbounded) in enumerate(zip(joints, continuous, strict=True)):
        if joint.nv != 1 or joint.nq != (2 if unbounded else 1):
            name = model.names[k + 1]
            return f"{joint.shortname()} joint {name} ({joint.nv} DOF) {_NOT_COMPILED}"
    if model.njoints != n + 1 or any(model.parents[k] != k - 1 for k in range(1, n + 1)):
        return f"branched chain {_NOT_COMPILED}"
    if model.frames[robot.tip_frame_id].parentJoint != n:
        return f"tip frame not on the last joint: {_NOT_COMPILED}"
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    axes = np.empty((n, 3))
    prismatic = np.zeros(n)
    for k in range(n):
        subspace = np.asarray(pin.getJointJacobian(model, data, k + 1, pin.LOCAL)).reshape(6, n)
        column = subspace[:, k]
        linear, angular = column[:3], column[3:]
        if np.linalg.norm(angular) > 1e-12:
            if np.linalg.norm(linear) > 1e-12 or abs(np.linalg.norm(angular) - 1.0) > 1e-12:
                return f"joint {model.names[k + 1]} (screw motion) {_NOT_COMPILED}"
            axes[k] = angular
        else:
            if continuous[k] or abs(np.linalg.norm(linear) - 1.0) > 1e-12:
                return f"joint {model.names[k + 1]} (non-unit axis) {_NOT_COMPILED}"
            axes[k], prismatic[k] = linear, 1.0
    placements = [model.jointPlacements[k] for k in range(1, n + 1)]
    tip = model.frames[robot.tip_frame_id].placement
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    for joint, unbounded in zip(joints, continuous, strict=True):
        if unbounded:  # (cos, sin): no limit, as IKSolver
            lower[joint.idx_q : joint.idx_q + 2] = -np.inf
            upper[joint.idx_q : joint.idx_q + 2] = np.inf
    base = robot.transform_base_to_world
    arrays = ChainArrays(
        placement_rotations=np.array([p.rotation for p in placements]),
        placement_translations=np.array([p.translation for p in placements]),
        axes=axes,
        prismatic=prismatic,
        continuous=continuous,
        q_index=np.array([joint.idx_q for joint in joints], dtype=np.int64),
        tip_rotation=np.array(tip.rotation),
        tip_translation=np.array(tip.translation),
        base_rotation=np.array(base.rotation),
        base_translation=np.array(base.translation),
        lower_q=lower,
        upper_q=upper,
        armature=np.array(robot.armature_kgm2, dtype=float),
    )
    for array in arrays:
        array.setflags(write=False)
    return arrays


def ik_settings(
    config: IKConfig, velocity_limits: np.ndarray, predictor_max_ratio: float
) -> IKSettings:
    """IKSettings of an IKConfig, the chain's velocity limits (per joint) and the predictor's
    largest defect growth (``ik.PREDICTOR_MAX_RATIO``)."""
    velocity_limits = np.array(velocity_limits, dtype=float)
    check_velocity = np.array(
        config.check_velocity_limits & np.isfinite(velocity_limits) & (velocity_limits > 0),
        dtype=np.bool_,
    )
    return IKSettings(
        float(config.position_tolerance_m),
        float(config.orientation_tolerance_rad),
        int(config.max_iterations),
        float(config.max_iteration_step),
        float(config.max_joint_step),
        float(predictor_max_ratio),
        bool(check_velocity.any()),
        check_velocity,
        velocity_limits,
    )


class CompiledGraspResult(NamedTuple):
    """One grasp's result of ``evaluate_grasps_compiled``: arrays have one row per sample if
    feasible (up to the failing sample otherwise)."""

    reason: str
    q: np.ndarray
    iterations: np.ndarray
    mobilities: np.ndarray
    effective_masses: np.ndarray
    directions: np.ndarray
    worst: np.ndarray
    tangent_norms: np.ndarray


_ENTRY_POINTS: dict[Any, Any] = {}
"""The compiled overload of each kernel called through ``call_kernel``."""


def call_kernel(kernel: Any, *args: Any) -> Any:
    """kernel(*args), bypassing numba's dispatcher after the first call.

    The dispatcher types every argument on each call, in Python for tuples (tens of µs for
    the named tuples of arrays here, as much as the IK of a few samples). The arguments built
    in this module always have the same types (C-contiguous, writable float64 arrays except
    the read-only ChainArrays), so the overload the first call selected is reused.
    """
    entry = _ENTRY_POINTS.get(kernel)
    if entry is not None:
        return entry(*args)
    result = kernel(*args)
    from numba import typeof

    compiled = kernel.overloads.get(tuple(typeof(arg) for arg in args))
    if compiled is not None:
        _ENTRY_POINTS[kernel] = compiled.entry_point
    return result


def augmented_bodies(
    robot: RobotModel,
    object_inertia: ObjectInertia,
    grasp_rotations: np.ndarray,
    grasp_translations: np.ndarray,
) -> BodyInertias:
    """``effective_mass.augmented_inertia_arrays`` by the kernel ``augment_bodies`` (one call
    for the G grasps: (G, 3, 3) rotations and (G, 3) translations [m] of the tip frame in the
    object frame)."""
    from ..kernels.effective_mass import augment_bodies

    model = robot.model
    tip = model.frames[robot.tip_frame_id]
    spatial = object_inertia.spatial_inertia_in_object()
    count, n = len(grasp_rotations), model.nv
    out = BodyInertias(np.empty((count, n)), np.empty((count, n, 3)), np.empty((count, n, 3, 3)))
    call_kernel(
        augment_bodies,
        robot_inertia_arrays(robot),
        tip.parentJoint - 1,
        plain_array(tip.placement.rotation),
        plain_array(tip.placement.translation),
        (float(spatial.mass), plain_array(spatial.lever), plain_array(spatial.inertia)),
        plain_array(grasp_rotations),
        plain_array(grasp_translations),
        out,
        np.empty((4, 3)),
    )
    return out


def plain_array(array: Any) -> np.ndarray:
    """A C-contiguous, writable float64 array of ``array`` (copied only when needed)."""
    array = np.ascontiguousarray(array, dtype=float)
    return array if array.flags.writeable else array.copy()


def evaluate_grasps_compiled(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    transforms_tip_to_object: Sequence[Any],
    motion: ObjectMotion,
    times_s: np.ndarray,
    seeds_q: np.ndarray,
    motion_is_tip: bool = False,
) -> list[CompiledGraspResult]:
    """Grasps with the fused kernel ``evaluate_grasps``, in one call (solver.compiled must be
    true); one result per grasp, in order.

    Args:
        transforms_tip_to_object: The grasps (the object's inertia moves with the tip).
        seeds_q: The IK seed of sample 0: (nq,) for every grasp, or (G, nq) one per grasp.
        motion: The object's motion at the sample times (``object_motion`` of the
            trajectory), which the kernel composes with each grasp; with ``motion_is_tip``,
            the tip's own motion (composed with the identity; then one grasp).

    Directions and effective masses of samples where the tip does not translate (``worst``)
    are left for the caller. Random restarts of sample 0 run here, as in ``solve_first``.
    """
    from ..kernels.grasp import evaluate_grasps  # imports numba: only when first needed
    from ..kernels.ik import solve_pose, thread_workspace

    chain, settings, robot = solver.chain, solver.settings, solver.robot
    if chain is None or settings is None:
        raise GraspSafetyError("the compiled kernels do not support this chain")
    grasps = [pin.SE3(transform) for transform in transforms_tip_to_object]
    rotations = np.array([grasp.rotation for grasp in grasps]).reshape(-1, 3, 3)
    translations = np.array([grasp.translation for grasp in grasps]).reshape(-1, 3)
    bodies = augmented_bodies(robot, object_inertia, rotations, translations)
    if motion_is_tip:
        rotations = np.repeat(np.eye(3)[None], len(grasps), axis=0)
        translations = np.zeros((len(grasps), 3))
    count = len(grasps)
    times_s = plain_array(times_s)
    nq = robot.model.nq
    out = grasp_buffers(count, len(times_s), nq)
    ws = thread_workspace(robot.model.nv)
    motion = ObjectMotion(*(plain_array(array) for array in motion))
    seeds = plain_array(np.broadcast_to(seeds_q, (count, nq)))
    fixed = (chain, settings)
    shared = (motion, rotations, translations, times_s)
    object_twists = np.empty((len(times_s), 6))
    call_kernel(
        evaluate_grasps,
        *fixed,
        bodies,
        *shared,
        seeds,
        np.zeros(count, dtype=np.bool_),
        STATIONARY_TANGENT_M,
        object_twists,
        out,
        ws,
    )
    reasons = [""] * count
    for g in np.flatnonzero(out.outcomes[:, 0] == 4):  # sample 0 failed from the seed
        total = int(out.iterations[g, 0])
        converged = False
        q_fail = out.q_fail[g]
        for restart in solver.restarts():  # deterministic random restarts
            q0 = np.empty(nq)
            converged, restart_iterations = call_kernel(
                solve_pose,
                *fixed,
                out.target_rotations[g, 0],
                out.target_translations[g, 0],
                plain_array(restart),
                q0,
                ws,
            )
            total += int(restart_iterations)
            if converged:
                break
            q_fail = q0
        if not converged:
            reasons[g] = solver.first_sample_reason(q_fail, times_s)
            continue
        row = slice(g, g + 1)
        call_kernel(
            evaluate_grasps,
            *fixed,
            BodyInertias(*(array[row] for array in bodies)),
            motion,
            rotations[row],
            translations[row],
            times_s,
            q0[None],
            np.ones(1, dtype=np.bool_),
            STATIONARY_TANGENT_M,
            object_twists,
            GraspBuffers(*(array[row] for array in out)),
            ws,
        )
        out.iterations[g, 0] = total
    results = []
    for g in range(count):
        status, index, joint = (int(value) for value in out.outcomes[g])
        if reasons[g]:
            results.append(_no_samples(reasons[g], nq))
            continue
        if status != 0:
            value = float(out.outcome_values[g])
            reasons[g] = solver.failure_reason(status, index, joint, value, out.q_fail[g], times_s)
        else:
            index = len(times_s)
        results.append(
            CompiledGraspResult(
                reasons[g],
                out.q_all[g, :index],
                out.iterations[g, :index],
                out.mobilities[g, :index],
                out.effective_masses[g, :index],
                out.directions[g, :index],
                out.worst[g, :index],
                out.tangent_norms[g, :index],
            )
        )
    return results


def _no_samples(reason: str, nq: int) -> CompiledGraspResult:
    """The result of a grasp whose first sample has no IK solution."""
    empty = np.empty(0)
    return CompiledGraspResult(
        reason,
        np.empty((0, nq)),
        np.zeros(0, dtype=np.int64),
        np.empty((0, 3, 3)),
        empty,
        np.empty((0, 3)),
        np.zeros(0, dtype=bool),
        empty,
    )
