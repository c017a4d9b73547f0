"""Joint velocities and accelerations of a sampled joint trajectory, for execution.

A grasp's evaluation gives joint positions q(t_i) at the sample times. A controller also
needs q̇ and q̈; they are defined here as the derivatives of the C2 cubic spline through the
samples, clamped with q̇ = 0 at both ends: every object trajectory the package evaluates
starts and ends at rest (the quintic's ds/dt vanishes at t = 0 and T), so the arm does too.
The spline passes through every sample; its velocity is continuous with O(dt³) error and its
acceleration continuous (piecewise linear) with O(dt²) error for a smooth q(t). The positions
themselves carry the IK's tolerance (1e-6), which shows in q̈ as ripples of order
1e-6 / dt² where a Gauss-Newton correction lands (up to 0.3 rad/s² against a 2 rad/s² peak,
Baxter book at dt = 0.01 s). The test suite checks q̇ against central differences of q(t) and
against J⁺·V of the minimum-norm IK, and q̈ against wider second differences.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InvalidInputError


def joint_velocities_accelerations(
    times_s: np.ndarray, joint_positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """q̇ [rad/s or m/s] and q̈ [rad/s² or m/s²] at the sample times (module docstring).

    Args:
        times_s: (N,) strictly increasing sample times [s].
        joint_positions: (N, n) joint positions [rad or m] (continuous joints unwrapped).

    Returns:
        (N, n) velocities and (N, n) accelerations; zeros when N < 2.
    """
    times = np.asarray(times_s, dtype=float)
    positions = np.asarray(joint_positions, dtype=float)
    if positions.ndim != 2 or len(times) != len(positions):
        raise InvalidInputError(
            "joint_positions", f"must be (N, n) with N = {len(times)} sample times"
        )
    if len(times) < 2:
        return np.zeros_like(positions), np.zeros_like(positions)
    if not np.all(np.diff(times) > 0):
        raise InvalidInputError("times_s", "must be strictly increasing")
    from scipy.interpolate import CubicSpline  # imported when first needed (start-up time)

    spline = CubicSpline(times, positions, axis=0, bc_type="clamped")
    return spline(times, 1), spline(times, 2)


def rates_for_execution(
    times_s: np.ndarray,
    joint_positions: np.ndarray,
    planned_rates: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """q̇ and q̈ to execute: a planned trajectory's, of the interpolation its analysis used
    (``planned_rates``, e.g. a GraspEvaluation's ``planned_joint_rates``) when given, else
    ``joint_velocities_accelerations``."""
    if planned_rates is not None:
        return planned_rates
    return joint_velocities_accelerations(times_s, joint_positions)
