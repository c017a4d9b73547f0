"""Effective mass of the robot + grasped object (augmented model, Khatib 1987).

The object is rigidly attached to the tip body, so the joint-space inertia M_aug includes it.
The translational block of the inverse operational-space inertia (the mobility) at the tip is
then Λ_tot⁻¹ = J M_aug⁻¹ Jᵀ, which equals (Λ_robot + Λ_obj)⁻¹ exactly (Woodbury), with no
inverse of Λ_robot. The effective mass along a unit direction u is 1 / (uᵀ Λ_tot⁻¹ u).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .inertia import ObjectInertia
from .robot import RobotModel


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
    jacobian_world = pin.getFrameJacobian(
        model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    ).reshape(6, model.nv)  # eigenpy returns a 6x1 matrix as a vector
    jacobian_base = robot.transform_base_to_world.rotation.T @ jacobian_world[:3]
    return jacobian_base @ minv @ jacobian_base.T


def effective_mass_along(mobility: np.ndarray, direction: np.ndarray) -> float:
    """M_eff = 1 / (uᵀ A u) [kg] for a 3x3 mobility A [1/kg] and a direction u (normalised)."""
    unit = np.asarray(direction, dtype=float)
    unit = unit / np.linalg.norm(unit)
    return float(1.0 / (unit @ mobility @ unit))


def worst_direction(mobility: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit direction of largest effective mass and that mass [kg] (smallest eigenvalue)."""
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (mobility + mobility.T))
    return eigenvectors[:, 0], float(1.0 / eigenvalues[0])
