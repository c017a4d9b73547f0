"""The compiled SE(3) log and its Jacobian equal Pinocchio's on every branch: generic angles,
the Taylor branch near 0 and the near-pi branch (each of its three axis choices)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_ros.core.method.ik import compiled_available

needs_numba = pytest.mark.skipif(not compiled_available(), reason="numba is not installed")


def rotations_on_every_branch(rng: np.random.Generator) -> list[np.ndarray]:
    """Rotations about random axes: generic angles, tiny ones, and within 1e-7 of pi about
    axes dominated by x, y and z in turn (log3's largest-diagonal choice)."""
    rotations = []
    for angle in (0.3, 1.7, 3.0, 1e-9, 1e-5):
        axis = rng.normal(size=3)
        rotations.append(pin.exp3(angle * axis / np.linalg.norm(axis)))
    for dominant in range(3):
        for offset in (0.0, 1e-9, 1e-7):
            axis = rng.normal(scale=0.2, size=3)
            axis[dominant] = 1.0
            axis *= rng.choice((-1.0, 1.0))
            rotations.append(pin.exp3((np.pi - offset) * axis / np.linalg.norm(axis)))
    return rotations


@needs_numba
def test_log6_and_jlog6_equal_pinocchio_on_every_branch() -> None:
    from grasp_safety_ros.core.kernels.lie_group import _jlog6, _log6

    rng = np.random.default_rng(7)
    twist, jacobian = np.empty(6), np.empty((6, 6))
    for rotation in rotations_on_every_branch(rng):
        translation = rng.uniform(-1.0, 1.0, 3)
        rotation = np.ascontiguousarray(rotation)
        _log6(rotation, translation, twist)
        expected = pin.log6(pin.SE3(rotation, translation)).vector
        np.testing.assert_allclose(twist, expected, rtol=0.0, atol=1e-12)
        _jlog6(rotation, translation, jacobian)
        np.testing.assert_allclose(
            jacobian, pin.Jlog6(pin.SE3(rotation, translation)), rtol=0.0, atol=1e-9
        )


@needs_numba
def test_near_pi_branch_is_exercised() -> None:
    """The oracle above would pass trivially if no rotation reached log3's near-pi branch:
    the angle must be pi to within Pinocchio's precision<2> threshold for some of them."""
    from grasp_safety_ros.core.kernels._jit import _PREC2

    rotations = rotations_on_every_branch(np.random.default_rng(7))
    near_pi = [r for r in rotations if (np.trace(r) - 1.0) / 2.0 < -1.0 + _PREC2]
    assert len(near_pi) >= 6
