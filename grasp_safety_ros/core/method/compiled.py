"""Bridge between the method and the compiled kernels: the chain as flat arrays
(``chain_arrays``), the augmented bodies of a batch of grasps (``augmented_bodies``) and a
dispatcher-free kernel call (``call_kernel``); batches of grasps through the fused kernel are
in ``batch``, the packed values in ``packed``.

The kernels (``core.kernels``, numba) are imported only when first called.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .effective_mass import robot_inertia_arrays
from .packed import BodyInertias, ChainArrays


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
    overloads = kernel.overloads
    if len(overloads) == 1:  # the one this call ran: no second typing of the arguments
        compiled = next(iter(overloads.values()))
    else:
        from numba import typeof

        compiled = overloads.get(tuple(typeof(arg) for arg in args))
    if compiled is not None:
        _ENTRY_POINTS[kernel] = compiled.entry_point
    return result


def pose_arrays(poses: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (P, 3, 3) and translations (P, 3) [m] of P poses (``pin.SE3`` or anything
    it takes, e.g. the grasps' ``transform_tip_to_object``), as the kernels take them."""
    frames = [pin.SE3(pose) for pose in poses]
    rotations = np.array([frame.rotation for frame in frames]).reshape(-1, 3, 3)
    translations = np.array([frame.translation for frame in frames]).reshape(-1, 3)
    return rotations, translations


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


def plain_array(array: Any, dtype: Any = float) -> np.ndarray:
    """A C-contiguous, writable array of ``array`` (float64 unless ``dtype``; copied only when
    needed): numba types a read-only array apart, so a frozen input would compile the kernel
    once more."""
    array = np.ascontiguousarray(array, dtype=dtype)
    return array if array.flags.writeable else array.copy()
