"""Bridge between the method and the compiled kernels: the chain as flat arrays
(``chain_arrays``) and one grasp through the fused kernel (``evaluate_grasp_compiled``).

The kernels (``core.kernels``, numba) are imported only when first called.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pinocchio as pin

from ..model.robot import RobotModel
from .effective_mass import STATIONARY_TANGENT_M, augmented_inertia_arrays, robot_inertia_arrays

if TYPE_CHECKING:
    from ..model.inertia import ObjectInertia
    from ..model.trajectory import ObjectTrajectory
    from .ik import IKSolver


class ChainArrays(NamedTuple):
    """A serial chain of 1-DOF joints as flat arrays, for the compiled kernels.

    Joint k (chain order) moves in the frame ``placement_k`` of joint k-1 (of the world for
    k = 0): rotation about, or translation along, the unit ``axis_k`` (joint frame).
    """

    placement_rotations: np.ndarray  # (n, 3, 3)
    placement_translations: np.ndarray  # (n, 3) [m]
    axes: np.ndarray  # (n, 3), unit
    prismatic: np.ndarray  # (n,) 1.0 for prismatic joints, 0.0 for revolute ones
    tip_rotation: np.ndarray  # (3, 3): tip frame in the last joint's frame
    tip_translation: np.ndarray  # (3,) [m]
    base_rotation: np.ndarray  # (3, 3): base frame in the world frame
    lower_q: np.ndarray  # (n,)
    upper_q: np.ndarray  # (n,)


def chain_arrays(robot: RobotModel) -> ChainArrays | None:
    """The chain of ``robot`` as arrays, or None when the compiled kernels cannot handle it.

    Supported: a serial chain of revolute and prismatic joints (Pinocchio's RX/RY/RZ,
    PX/PY/PZ and their unaligned variants; not continuous joints), the tip frame on the last.
    """
    arrays = chain_arrays_or_reason(robot)
    return arrays if isinstance(arrays, ChainArrays) else None


_NOT_COMPILED = "not supported by the compiled kernels"


def chain_arrays_or_reason(robot: RobotModel) -> ChainArrays | str:
    """``chain_arrays``, or the reason the compiled kernels cannot handle the chain (e.g.
    ``continuous joint j3 not supported by the compiled kernels``)."""
    model = robot.model
    n = model.nv
    for k in range(1, model.njoints):
        joint = model.joints[k]
        if joint.nq != joint.nv:
            return f"continuous joint {model.names[k]} {_NOT_COMPILED}"
        if joint.nv != 1:
            return f"{joint.shortname()} joint {model.names[k]} ({joint.nv} DOF) {_NOT_COMPILED}"
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
            if abs(np.linalg.norm(linear) - 1.0) > 1e-12:
                return f"joint {model.names[k + 1]} (non-unit axis) {_NOT_COMPILED}"
            axes[k], prismatic[k] = linear, 1.0
    placements = [model.jointPlacements[k] for k in range(1, n + 1)]
    tip = model.frames[robot.tip_frame_id].placement
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    arrays = ChainArrays(
        placement_rotations=np.array([p.rotation for p in placements]),
        placement_translations=np.array([p.translation for p in placements]),
        axes=axes,
        prismatic=prismatic,
        tip_rotation=np.array(tip.rotation),
        tip_translation=np.array(tip.translation),
        base_rotation=np.array(robot.transform_base_to_world.rotation),
        lower_q=lower,
        upper_q=upper,
    )
    for array in arrays:
        array.setflags(write=False)
    return arrays


_ROBOT_INERTIAS: weakref.WeakKeyDictionary[Any, tuple[np.ndarray, ...]] = (
    weakref.WeakKeyDictionary()
)
"""robot_inertia_arrays of each RobotModel in use."""


class CompiledGraspResult(NamedTuple):
    """What ``evaluate_grasp_compiled`` returns; arrays have one row per sample if feasible."""

    reason: str
    q: np.ndarray
    iterations: np.ndarray
    mobilities: np.ndarray
    effective_masses: np.ndarray
    directions: np.ndarray
    worst: np.ndarray
    tangent_norms: np.ndarray


def evaluate_grasp_compiled(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory,
    transform_tip_to_object: Any,
    times_s: np.ndarray,
    s_values: np.ndarray,
    seed_q: np.ndarray,
) -> CompiledGraspResult:
    """One grasp with the fused kernel ``evaluate_grasp`` (solver.compiled must be true).

    Directions and effective masses of samples where the tip does not translate (``worst``)
    are left for the caller. Random restarts of sample 0 run here, as in ``solve_first``.
    """
    from ..kernels.grasp import evaluate_grasp  # imports numba: only when first needed
    from ..kernels.ik import solve_pose

    chain, config, robot = solver.chain, solver.config, solver.robot
    assert chain is not None
    count = len(s_values)
    n = robot.model.nq
    robot_arrays = _ROBOT_INERTIAS.get(robot)
    if robot_arrays is None:
        robot_arrays = _ROBOT_INERTIAS.setdefault(robot, robot_inertia_arrays(robot))
    masses, levers, rotational = augmented_inertia_arrays(
        robot, object_inertia, transform_tip_to_object, robot_arrays
    )
    velocity_limits = np.asarray(robot.velocity_limits, dtype=float)
    check_velocity = (
        config.check_velocity_limits & np.isfinite(velocity_limits) & (velocity_limits > 0)
    )
    start = trajectory.transform_object_to_base_start
    base = robot.transform_base_to_world
    times_s = np.ascontiguousarray(times_s, dtype=float)
    s_values = np.ascontiguousarray(s_values, dtype=float)
    target_rotations = np.empty((count, 3, 3))
    target_translations = np.empty((count, 3))
    tangents = np.empty((count, 3))
    tangent_norms = np.empty(count)
    q_all = np.empty((count, n))
    iterations = np.zeros(count, dtype=np.int64)
    q_fail = np.empty(n)
    mobilities = np.empty((count, 3, 3))
    effective_masses = np.empty(count)
    directions = np.empty((count, 3))
    worst = np.zeros(count, dtype=np.bool_)
    fixed = (
        np.ascontiguousarray(base.translation),
        np.ascontiguousarray(start.rotation),
        np.ascontiguousarray(start.translation),
        np.ascontiguousarray(trajectory.transform_object_to_base_goal.translation),
        np.ascontiguousarray(trajectory.rotation_log_in_object, dtype=float),
        np.ascontiguousarray(transform_tip_to_object.rotation),
        np.ascontiguousarray(transform_tip_to_object.translation),
        times_s,
        s_values,
    )
    limits = (
        config.position_tolerance_m,
        config.orientation_tolerance_rad,
        config.max_iterations,
        config.max_iteration_step,
        config.max_joint_step,
        check_velocity,
        velocity_limits,
        masses,
        levers,
        rotational,
        STATIONARY_TANGENT_M,
        target_rotations,
        target_translations,
        tangents,
        tangent_norms,
        q_all,
        iterations,
        q_fail,
        mobilities,
        effective_masses,
        directions,
        worst,
    )
    status, index, joint, value = evaluate_grasp(
        *chain, *fixed, np.asarray(seed_q, dtype=float), False, *limits
    )
    if status == 4:  # sample 0 failed from the seed: deterministic random restarts
        total = int(iterations[0])
        converged = False
        for restart in solver.restarts():
            q0, converged, restart_iterations = solve_pose(
                *chain,
                target_rotations[0],
                target_translations[0],
                restart,
                config.position_tolerance_m,
                config.orientation_tolerance_rad,
                config.max_iterations,
                config.max_iteration_step,
            )
            total += int(restart_iterations)
            if converged:
                break
            q_fail = q0
        if not converged:
            empty = np.empty(0)
            return CompiledGraspResult(
                solver.first_sample_reason(q_fail, times_s),
                np.empty((0, n)),
                np.zeros(0, dtype=np.int64),
                np.empty((0, 3, 3)),
                empty,
                np.empty((0, 3)),
                np.zeros(0, dtype=bool),
                empty,
            )
        status, index, joint, value = evaluate_grasp(*chain, *fixed, q0, True, *limits)
        iterations[0] = total
    if status != 0:
        reason = solver.failure_reason(status, index, joint, value, q_fail, times_s)
        return CompiledGraspResult(
            reason,
            q_all[:index],
            iterations[:index],
            mobilities[:index],
            effective_masses[:index],
            directions[:index],
            worst[:index],
            tangent_norms[:index],
        )
    return CompiledGraspResult(
        "", q_all, iterations, mobilities, effective_masses, directions, worst, tangent_norms
    )
