"""Effective mass of the robot + grasped object (augmented model, Khatib 1987).

The object is rigidly attached to the tip body, so the joint-space inertia M_aug includes it.
The translational block of the inverse operational-space inertia (the mobility) at the tip is
then Λ_tot⁻¹ = J M_aug⁻¹ Jᵀ, which equals (Λ_robot + Λ_obj)⁻¹ exactly (Woodbury), with no
inverse of Λ_robot. The effective mass along a unit direction u is 1 / (uᵀ Λ_tot⁻¹ u).

``translational_mobilities_in_base`` evaluates a whole trajectory at once, with Pinocchio
(``computeMinverse``) or with the compiled kernel of ``core/kernels/effective_mass.py``
(composite-rigid-body mass matrix and a Cholesky factor); both give the same matrices to
rounding.
"""

from __future__ import annotations

import weakref

import numpy as np
import pinocchio as pin

from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .packed import BodyInertias, ChainArrays

STATIONARY_TANGENT_M = 1e-9
"""Below this |d p_tip / ds| [m] the tip does not translate and the worst direction is used."""


def augmented_model(
    robot: RobotModel, object_inertia: ObjectInertia, transform_tip_to_object: pin.SE3
) -> pin.Model:
    """A copy of the robot's chain model with the object's inertia merged into the tip body.

    Args:
        robot: The chain model.
        object_inertia: Object inertia in the object frame.
        transform_tip_to_object: The grasp: pose of the tip frame in the object frame.
    """
    model = robot.model.copy()
    tip = model.frames[robot.tip_frame_id]
    transform_object_to_joint = tip.placement * pin.SE3(transform_tip_to_object).inverse()
    inertia_in_joint = transform_object_to_joint.act(object_inertia.spatial_inertia_in_object())
    model.inertias[tip.parentJoint] = model.inertias[tip.parentJoint] + inertia_in_joint
    return model


_ROBOT_INERTIAS: weakref.WeakKeyDictionary[RobotModel, BodyInertias] = weakref.WeakKeyDictionary()
"""robot_inertia_arrays of each RobotModel in use."""


def robot_inertia_arrays(robot: RobotModel) -> BodyInertias:
    """The chain's body inertias as arrays: mass [kg] (n,), centre of mass in the joint frame
    [m] (n, 3), rotational inertia about it, joint axes [kg m^2] (n, 3, 3); computed once per
    robot (read-only)."""
    cached = _ROBOT_INERTIAS.get(robot)
    if cached is not None:
        return cached
    inertias = [robot.model.inertias[j] for j in range(1, robot.model.njoints)]
    masses = np.array([inertia.mass for inertia in inertias])
    levers = np.array([inertia.lever for inertia in inertias]).reshape(-1, 3)
    rotational = np.array([inertia.inertia for inertia in inertias]).reshape(-1, 3, 3)
    arrays = BodyInertias(masses, levers, rotational)
    for array in arrays:
        array.setflags(write=False)
    return _ROBOT_INERTIAS.setdefault(robot, arrays)


def augmented_inertia_arrays(
    robot: RobotModel,
    object_inertia: ObjectInertia,
    grasp_rotations: np.ndarray,
    grasp_translations: np.ndarray,
) -> BodyInertias:
    """Body inertias of ``augmented_model`` for G grasps at once (the arrays of
    ``robot_inertia_arrays`` with a leading grasp axis), without copying the model.

    Args:
        grasp_rotations: (G, 3, 3) rotations of the tip frame in the object frame.
        grasp_translations: (G, 3) its origin in the object frame [m].

    The object's inertia moves to the tip body's joint frame and is added to the body's as
    Pinocchio adds inertias (parallel-axis term m_a m_b / (m_a + m_b) of their lever arms).
    """
    model = robot.model
    tip = model.frames[robot.tip_frame_id]
    spatial = object_inertia.spatial_inertia_in_object()  # Pinocchio's symmetric tensor
    rotations = np.asarray(grasp_rotations, dtype=float).reshape(-1, 3, 3)
    translations = np.asarray(grasp_translations, dtype=float).reshape(-1, 3)
    # Object frame in the joint frame: tip placement * grasp^-1 (matmul: einsum's dispatch
    # costs more than the arithmetic at these sizes).
    rotation = tip.placement.rotation @ rotations.transpose(0, 2, 1)
    translation = tip.placement.translation - (rotation @ translations[:, :, None])[:, :, 0]
    object_mass = spatial.mass
    object_com = rotation @ spatial.lever + translation
    object_tensor = rotation @ spatial.inertia @ rotation.transpose(0, 2, 1)
    body = model.inertias[tip.parentJoint]
    mass = body.mass + object_mass
    mass_inverse = 1.0 / max(mass, float(np.finfo(float).eps))
    arm = body.lever - object_com  # (G, 3)
    skew_square = arm[:, :, None] * arm[:, None, :] - (arm * arm).sum(axis=1)[
        :, None, None
    ] * np.eye(3)
    tensor = body.inertia + object_tensor - (body.mass * object_mass * mass_inverse) * skew_square
    lever = (body.mass * mass_inverse) * body.lever + (object_mass * mass_inverse) * object_com
    masses, levers, rotational = robot_inertia_arrays(robot)
    count, k = len(rotations), tip.parentJoint - 1
    batch = BodyInertias(
        np.repeat(masses[None], count, axis=0),
        np.repeat(levers[None], count, axis=0),
        np.repeat(rotational[None], count, axis=0),
    )
    batch.masses[:, k] = mass
    batch.levers[:, k] = lever
    batch.rotational_inertias[:, k] = tensor
    return batch


def translational_mobilities_in_base(
    robot: RobotModel,
    object_inertia: ObjectInertia,
    transform_tip_to_object: pin.SE3,
    q_all: np.ndarray,
    chain: ChainArrays | None = None,
) -> np.ndarray:
    """``translational_mobility_in_base`` of the augmented model for every row of ``q_all``.

    Args:
        robot: The chain model.
        object_inertia: Object inertia in the object frame.
        transform_tip_to_object: The grasp.
        q_all: Configurations (N, nq).
        chain: ``compiled.chain_arrays(robot)``: the compiled kernel (numba); None: Pinocchio.

    Returns:
        (N, 3, 3) mobilities [1/kg], base axes.
    """
    q_all = np.ascontiguousarray(q_all, dtype=float)
    out = np.empty((len(q_all), 3, 3))
    if chain is not None:
        from ..kernels.effective_mass import translational_mobilities
        from ..kernels.ik import thread_workspace

        grasp = pin.SE3(transform_tip_to_object)
        bodies = augmented_inertia_arrays(
            robot, object_inertia, grasp.rotation[None], grasp.translation[None]
        )
        translational_mobilities(chain, bodies, q_all, out, thread_workspace(robot.model.nv))
        return out
    model = augmented_model(robot, object_inertia, transform_tip_to_object)
    data = model.createData()
    upper = np.triu(np.ones((model.nv, model.nv), dtype=bool))
    rotation_base_to_world = robot.transform_base_to_world.rotation
    frame_id = robot.tip_frame_id
    for i, q in enumerate(q_all):
        pin.computeMinverse(model, data, q)
        minv = np.where(upper, data.Minv, data.Minv.T)  # computeMinverse fills the upper part
        pin.computeJointJacobians(model, data, q)
        jacobian_tip_in_world = pin.getFrameJacobian(
            model, data, frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        ).reshape(6, model.nv)
        jacobian_tip_in_base = rotation_base_to_world.T @ jacobian_tip_in_world[:3]
        out[i] = jacobian_tip_in_base @ minv @ jacobian_tip_in_base.T
    return out


def effective_masses_along(mobilities: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """``effective_mass_along`` for (N, 3, 3) mobilities and (N, 3) directions [kg]."""
    units = directions / np.sqrt(np.einsum("ni,ni->n", directions, directions))[:, None]
    masses: np.ndarray = 1.0 / np.einsum("ni,nij,nj->n", units, mobilities, units)
    return masses


def translational_mobility_in_base(
    robot: RobotModel, model: pin.Model, data: pin.Data, q: np.ndarray
) -> np.ndarray:
    """[Λ⁻¹]₃ₓ₃ = J_v M⁻¹ J_vᵀ [1/kg] at the tip origin, base axes, for configuration q.

    ``model`` is the robot's chain model or an augmented copy of it; ``data`` is its data.
    """
    pin.computeMinverse(model, data, q)
    minv_upper = np.triu(data.Minv)
    minv = minv_upper + np.triu(minv_upper, 1).T
    pin.computeJointJacobians(model, data, q)
    jacobian_tip_in_world = pin.getFrameJacobian(
        model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    ).reshape(6, model.nv)  # eigenpy returns a 6x1 matrix as a vector
    jacobian_tip_in_base = robot.transform_base_to_world.rotation.T @ jacobian_tip_in_world[:3]
    mobility: np.ndarray = jacobian_tip_in_base @ minv @ jacobian_tip_in_base.T
    return mobility


def effective_mass_along(mobility: np.ndarray, direction: np.ndarray) -> float:
    """M_eff = 1 / (uᵀ A u) [kg] for a 3x3 mobility A [1/kg] and a direction u (normalised)."""
    unit = np.asarray(direction, dtype=float)
    unit = unit / np.linalg.norm(unit)
    return float(1.0 / (unit @ mobility @ unit))


def worst_direction(mobility: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit direction of largest effective mass and that mass [kg] (smallest eigenvalue)."""
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (mobility + mobility.T))
    return eigenvectors[:, 0], float(1.0 / eigenvalues[0])
