"""Poses, transforms, quaternions, vectors and stamps between ROS messages and core types.

The quaternion order is fixed here and only here: ROS messages are (x, y, z, w), Pinocchio's
constructor is (w, x, y, z); every conversion goes through quat_xyzw_from_msg and
quaternion_msg_from_rotation. Each function raises InvalidInputError naming the message field.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, Quaternion, Transform, Vector3

from ...core.exceptions import InvalidInputError
from ...core.input_checks import (
    MAX_ABS_POSITION_M as MAX_ABS_POSITION_M,
)
from ...core.input_checks import (
    check_within_reach,
    finite_array,
    quat_xyzw_from_rotation,
    rotation_from_quat_xyzw,
)
from ...core.options import LIMITS

MAX_OBJECT_SIZE_M = LIMITS["object_size_m"].value
"""Largest radius of gyration of an object [m] (the scenario's limit: core.options.LIMITS)."""


# --- Poses -----------------------------------------------------------------------------------


def quat_xyzw_from_msg(quaternion: Quaternion) -> np.ndarray:
    """The (x, y, z, w) array of a geometry_msgs/Quaternion (the one place the order is set)."""
    return np.array([quaternion.x, quaternion.y, quaternion.z, quaternion.w], dtype=float)


def quaternion_msg_from_rotation(rotation: np.ndarray) -> Quaternion:
    """geometry_msgs/Quaternion of a rotation matrix (w >= 0)."""
    x, y, z, w = quat_xyzw_from_rotation(rotation)
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def transform_from_pose_msg(pose: Pose, field: str) -> pin.SE3:
    """Rigid transform of a geometry_msgs/Pose; checks finiteness, a unit quaternion and
    coordinates within +/- MAX_ABS_POSITION_M."""
    quat_xyzw = quat_xyzw_from_msg(pose.orientation)
    rotation = rotation_from_quat_xyzw(quat_xyzw, f"{field}.orientation")
    position = finite_array(
        [pose.position.x, pose.position.y, pose.position.z], f"{field}.position", (3,)
    )
    check_within_reach(position, f"{field}.position")
    return pin.SE3(rotation, np.array(position))


def _pose_numbers(pose: Pose) -> tuple[float, ...]:
    position, orientation = pose.position, pose.orientation
    x, y, z, w = orientation.x, orientation.y, orientation.z, orientation.w
    return (position.x, position.y, position.z, x, y, z, w)


def pose_msg_from_transform(transform: pin.SE3) -> Pose:
    """geometry_msgs/Pose of a rigid transform."""
    x, y, z = (float(v) for v in transform.translation)
    return Pose(
        position=Point(x=x, y=y, z=z), orientation=quaternion_msg_from_rotation(transform.rotation)
    )


def vector3_msg(vector: Sequence[float] | np.ndarray) -> Vector3:
    """geometry_msgs/Vector3 of three numbers."""
    x, y, z = (float(v) for v in vector)
    return Vector3(x=x, y=y, z=z)


def check_frame_id(frame_id: str, accepted: Sequence[str], field: str) -> str:
    """Return ``frame_id`` if it is one of ``accepted``, else raise naming both."""
    if frame_id not in accepted:
        names = " or ".join(f"'{name}'" for name in accepted)
        raise InvalidInputError(field, f"unknown frame_id '{frame_id}'; accepted: {names}")
    return frame_id


def stamp_to_seconds(stamp: Time) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


# --- Trajectory, grasps, inertia -------------------------------------------------------------


def duration_to_seconds(duration: Duration) -> float:
    """Seconds of a builtin_interfaces/Duration."""
    return float(duration.sec) + 1e-9 * float(duration.nanosec)


def transform_from_transform_msg(transform: Transform, field: str) -> pin.SE3:
    """Rigid transform of a geometry_msgs/Transform; checks finiteness, a unit quaternion and
    coordinates within +/- MAX_ABS_POSITION_M (as a Pose's)."""
    rotation = rotation_from_quat_xyzw(quat_xyzw_from_msg(transform.rotation), f"{field}.rotation")
    t = transform.translation
    translation = finite_array([t.x, t.y, t.z], f"{field}.translation", (3,))
    check_within_reach(translation, f"{field}.translation")  # 1e30: success with no order
    return pin.SE3(rotation, np.array(translation))


def duration_msg(seconds: float) -> Duration:
    """builtin_interfaces/Duration of a non-negative time [s], rounded to the nanosecond."""
    nanoseconds = round(float(seconds) * 1e9)
    return Duration(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def inertia_tensor_from_components(
    components: Sequence[float], field: str, mass_kg: float | None = None
) -> np.ndarray:
    """3x3 symmetric tensor of (ixx, ixy, ixz, iyy, iyz, izz), as in geometry_msgs/Inertia.

    With ``mass_kg``, every component and principal moment must be at most
    mass_kg * MAX_OBJECT_SIZE_M^2 [kg m^2] (a radius of gyration of at most MAX_OBJECT_SIZE_M,
    the CLI's bound): ixx = 1e300 made the effective masses NaN deep in the analyses.
    """
    ixx, ixy, ixz, iyy, iyz, izz = finite_array(list(components), field, (6,))
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    if mass_kg is not None:
        limit = mass_kg * MAX_OBJECT_SIZE_M**2
        largest = float(np.max(np.abs(tensor)))
        if largest <= limit:  # then the eigenvalues are finite: |lambda| <= 3 * largest
            largest = max(largest, float(np.max(np.abs(np.linalg.eigvalsh(tensor)))))
        if largest > limit:
            raise InvalidInputError(
                field,
                f"components and principal moments must be at most m * {MAX_OBJECT_SIZE_M:g}^2"
                f" = {limit:g} kg m^2 (a radius of gyration of at most {MAX_OBJECT_SIZE_M:g} m)"
                f", got {largest:g}",
            )
    return tensor
