"""Input checks shared by the core: each raises InvalidInputError naming the field."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from .exceptions import InvalidInputError

QUATERNION_NORM_TOLERANCE = 1e-3
"""Accepted deviation of a quaternion's norm from 1 before it is normalised."""


def read_only(array: Any, copy: bool = False) -> np.ndarray:
    """``array`` as a numpy array that cannot be written: a copy when ``copy`` (for arrays
    shared with the caller), else the array itself, frozen in place (for arrays just made)."""
    result = np.array(array) if copy else np.asarray(array)
    result.setflags(write=False)
    return result


def finite_array(value: Any, field: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a read-only float64 array, checking type, shape and finiteness."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(field, f"must be numeric, got {value!r}") from None
    if shape is not None and array.shape != shape:
        expected = "a number" if shape == () else f"shape {list(shape)}"
        raise InvalidInputError(field, f"must have {expected}, got shape {list(array.shape)}")
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(field, f"must be finite, got {array.tolist()}")
    array.setflags(write=False)
    return array


def finite_float(
    value: Any,
    field: str,
    minimum: float | None = None,
    maximum: float | None = None,
    strict_minimum: bool = False,
) -> float:
    """Return ``value`` as a finite float in [minimum, maximum] (open at minimum if strict)."""
    if isinstance(value, bool):
        raise InvalidInputError(field, f"must be a number, got {value!r}")
    number = float(finite_array(value, field, ()))
    low_ok = minimum is None or (number > minimum if strict_minimum else number >= minimum)
    high_ok = maximum is None or number <= maximum
    if not (low_ok and high_ok):
        low = "-inf" if minimum is None else f"{minimum:g}"
        high = "inf" if maximum is None else f"{maximum:g}"
        bracket = "(" if strict_minimum else "["
        raise InvalidInputError(field, f"must be in {bracket}{low}, {high}], got {number:g}")
    return number


def rotation_from_quat_xyzw(quat_xyzw: Sequence[float] | np.ndarray, field: str) -> np.ndarray:
    """Rotation matrix of a quaternion in ROS order (x, y, z, w); near-unit ones are normalised."""
    quat = finite_array(quat_xyzw, field, (4,))
    with np.errstate(over="ignore"):  # a huge component: the norm is inf, refused below
        norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise InvalidInputError(
            field,
            f"must be a unit quaternion [x, y, z, w] (norm 1 +/- {QUATERNION_NORM_TOLERANCE:g}),"
            f" got norm {norm:.6g}",
        )
    x, y, z, w = quat / norm
    rotation: np.ndarray = pin.Quaternion(w, x, y, z).toRotationMatrix()
    return rotation


def quat_xyzw_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion in ROS order (x, y, z, w) of a rotation matrix, with w >= 0."""
    quat = pin.Quaternion(np.asarray(rotation, dtype=float))
    xyzw = np.array([quat.x, quat.y, quat.z, quat.w])
    return -xyzw if xyzw[3] < 0 else xyzw


def pose_from_position_quat(
    position_m: Sequence[float] | np.ndarray, quat_xyzw: Sequence[float] | np.ndarray, field: str
) -> pin.SE3:
    """Rigid transform from a position [m] and a quaternion in ROS order (x, y, z, w)."""
    rotation = rotation_from_quat_xyzw(quat_xyzw, f"{field}.quat_xyzw")
    position = finite_array(position_m, f"{field}.position_m", (3,))
    return pin.SE3(rotation, np.array(position))
