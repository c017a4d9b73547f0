"""The compiled kinematics' own sine and cosine (``_sincos``) against libm's, on every quadrant,
at the quadrant boundaries, far out and beyond its range (where it defers to libm)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_safety_ros.core.method.ik import compiled_available

needs_numba = pytest.mark.skipif(not compiled_available(), reason="numba is not installed")

SINCOS_ABS_ERROR = 2.3e-16
"""The bound ``_sincos`` documents (one ulp of 1 is 2.2e-16)."""


def angles(rng: np.random.Generator) -> np.ndarray:
    """Joint-like angles, far ones, multiples of pi/4 and their neighbours, both zeros (compared
    by value: the sine of _sincos(-0.0) is +0.0 where libm gives -0.0)."""
    multiples = np.arange(-64, 65) * (np.pi / 4)
    return np.concatenate(
        [
            rng.uniform(-7.0, 7.0, 20_000),
            rng.uniform(-1e5, 1e5, 5_000),
            multiples,
            np.nextafter(multiples, np.inf),
            np.nextafter(multiples, -np.inf),
            multiples + 1e-9,
            [0.0, -0.0, 5e-324, 1e-300, 1e5, -1e5],
        ]
    )


@needs_numba
def test_sincos_equals_libm_to_one_ulp_of_one() -> None:
    from grasp_safety_ros.core.kernels.kinematics import _sincos

    worst = 0.0
    for angle in angles(np.random.default_rng(3)):
        sin_value, cos_value = _sincos(float(angle))
        worst = max(worst, abs(sin_value - math.sin(angle)), abs(cos_value - math.cos(angle)))
    assert worst <= SINCOS_ABS_ERROR


@needs_numba
def test_sincos_defers_to_libm_beyond_its_range() -> None:
    from grasp_safety_ros.core.kernels.kinematics import _sincos

    for angle in (1e5 + 1.0, -3e7, 1e300):
        assert _sincos(angle) == (math.sin(angle), math.cos(angle))
    for angle in (math.inf, -math.inf, math.nan):
        assert all(math.isnan(value) for value in _sincos(angle))
