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

The spline is computed here as scipy's ``CubicSpline(..., bc_type="clamped")`` computes it,
operation for operation (its tridiagonal system by LAPACK's ``dgtsv`` elimination, row
interchanges included, then its piecewise-polynomial coefficients and their derivatives at
the knots), so the numbers are scipy's bit for bit (``test/test_executable_rates.py``) without
importing scipy.interpolate (a quarter of a second of every command's start-up). Trajectories
sampled at the same times share one elimination whose row operations run over all of their
joints at once (``rates_for_execution_many``: a report's grasps in one pass).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

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
    return rates_for_execution_many([(times_s, joint_positions, None)])[0]


def rates_for_execution(
    times_s: np.ndarray,
    joint_positions: np.ndarray,
    planned_rates: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """q̇ and q̈ to execute: a planned trajectory's, of the interpolation its analysis used
    (``planned_rates``, e.g. a GraspEvaluation's ``planned_joint_rates``) when given, else
    ``joint_velocities_accelerations``."""
    return rates_for_execution_many([(times_s, joint_positions, planned_rates)])[0]


GROUP_TRAJECTORIES = 64
"""Trajectories (of the same times) whose splines are computed together, at most (their arrays
then stay in the processor's cache)."""


def check_increasing(times_s: np.ndarray) -> None:
    """InvalidInputError unless the sample times [s] strictly increase."""
    if not np.all(np.diff(times_s) > 0):
        raise InvalidInputError("times_s", "must be strictly increasing")


def rates_for_execution_many(
    trajectories: Sequence[tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]],
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``rates_for_execution`` of each (times_s, joint_positions, planned_rates), the same
    numbers, the splines of the trajectories sampled at the same times computed together."""
    results: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(trajectories)
    groups: dict[bytes, list[int]] = {}
    checked = []
    for k, (times_s, joint_positions, planned_rates) in enumerate(trajectories):
        times = np.asarray(times_s, dtype=float)
        positions = np.asarray(joint_positions, dtype=float)
        if positions.ndim != 2 or len(times) != len(positions):
            raise InvalidInputError(
                "joint_positions", f"must be (N, n) with N = {len(times)} sample times"
            )
        checked.append((times, positions))
        if planned_rates is not None:
            results[k] = planned_rates
        elif len(times) < 2:
            results[k] = (np.zeros_like(positions), np.zeros_like(positions))
        else:
            check_increasing(times)
            groups.setdefault(times.tobytes(), []).append(k)
    for group in groups.values():
        for first in range(0, len(group), GROUP_TRAJECTORIES):
            members = group[first : first + GROUP_TRAJECTORIES]
            positions = np.concatenate([checked[k][1] for k in members], axis=1)
            velocities, accelerations = _clamped_spline_rates(checked[members[0]][0], positions)
            start = 0
            for k in members:
                stop = start + checked[k][1].shape[1]
                results[k] = (velocities[:, start:stop], accelerations[:, start:stop])
                start = stop
    return results  # type: ignore[return-value]


def _clamped_spline_rates(
    times: np.ndarray, positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives at the knots of scipy's clamped CubicSpline through
    (times, positions) (N >= 2 strictly increasing times; module docstring)."""
    dx = np.diff(times)
    slope = np.diff(positions, axis=0) / dx[:, None]
    rates = np.empty_like(positions)
    rates[1:-1] = 3 * (dx[1:, None] * slope[:-1] + dx[:-1, None] * slope[1:])
    rates[0] = rates[-1] = 0.0  # q̇ = 0 at both ends
    lower = [*dx[1:].tolist(), 0.0]
    diagonal = [1.0, *(2 * (dx[:-1] + dx[1:])).tolist(), 1.0]
    upper = [0.0, *dx[:-1].tolist()]
    elimination = _tridiagonal_elimination(lower, diagonal, upper)
    if rates.shape[1] <= ROW_SOLVE_COLUMNS:
        rates = np.array([_solve_column(elimination, column) for column in rates.T.tolist()])
        rates = rates.T.reshape(positions.shape)
    else:
        _solve_rows(elimination, rates)
    # the knots' derivatives of scipy's PPoly (its evaluate_poly1): at knot i < N-1 the
    # offset into interval i is 0.0, at the last knot it is the last interval's length
    t = (rates[:-1] + rates[1:] - 2 * slope) / dx[:, None]
    c0, c1, c2 = t / dx[:, None], (slope - rates[:-1]) / dx[:, None] - t, rates[:-1]
    offset = np.zeros_like(times)
    offset[-1] = dx[-1]
    interval = np.minimum(np.arange(len(times)), len(dx) - 1)
    c0, c1, c2, z1 = c0[interval], c1[interval], c2[interval], (1.0 * offset)[:, None]
    velocities = 0.0 + c2 * 1.0 * 1.0 + c1 * z1 * 2.0 + c0 * (z1 * offset[:, None]) * 3.0
    accelerations = 0.0 + c1 * 1.0 * 2.0 + c0 * z1 * 6.0
    return velocities, accelerations


def clamped_spline_velocities(times_s: np.ndarray, joint_positions: np.ndarray) -> np.ndarray:
    """``joint_velocities_accelerations``' velocities alone, bit for bit, by the compiled
    kernel ``kernels.points.clamped_spline_velocities`` (numba must be installed): for the
    whole arm's many columns (a report's grasps x joints), where the elimination row by row
    in numpy costs more than the rest of the whole arm's q̇.

    Args:
        times_s: (N,) strictly increasing sample times [s] (else InvalidInputError, as
            ``joint_velocities_accelerations``).
        joint_positions: (N, m) positions [rad or m], columns apart (continuous unwrapped).
    """
    from ..kernels.points import clamped_spline_velocities as kernel
    from .compiled import call_kernel, plain_array

    times, positions = plain_array(times_s), plain_array(joint_positions)
    velocities = np.zeros_like(positions)
    if len(times) < 2 or not positions.shape[1]:
        return velocities
    check_increasing(times)
    key = times.tobytes()
    with _ELIMINATIONS_LOCK:  # a library may call from several threads
        elimination = _ELIMINATIONS.get(key)
    if elimination is None:
        dx = np.diff(times)
        lower = [*dx[1:].tolist(), 0.0]
        diagonal = [1.0, *(2 * (dx[:-1] + dx[1:])).tolist(), 1.0]
        upper = [0.0, *dx[:-1].tolist()]
        steps, d, du, dl = _tridiagonal_elimination(lower, diagonal, upper)
        elimination = (
            np.array([interchanged for interchanged, _ in steps], dtype=bool),
            np.array([fact for _, fact in steps]),
            np.array(d),
            np.array(du),
            np.array(dl),
        )
        with _ELIMINATIONS_LOCK:
            if len(_ELIMINATIONS) >= KEPT_ELIMINATIONS:
                _ELIMINATIONS.pop(next(iter(_ELIMINATIONS)), None)  # the oldest
            _ELIMINATIONS[key] = elimination
    call_kernel(kernel, times, positions, *elimination, velocities, np.empty(positions.shape[1]))
    return velocities


KEPT_ELIMINATIONS = 16
"""Sample times whose spline elimination (``clamped_spline_velocities``) is kept for the next
call with the same times: its Python loop costs as much as the kernel on 10 grasps' joints."""
_ELIMINATIONS: dict[bytes, tuple[np.ndarray, ...]] = {}
_ELIMINATIONS_LOCK = threading.Lock()


ROW_SOLVE_COLUMNS = 24
"""Above this many joint columns the elimination runs by numpy rows over all columns at once,
at or below it by Python floats column by column (fewer calls; the same operations)."""
Elimination = tuple[list[tuple[bool, float]], list[float], list[float], list[float]]


def _tridiagonal_elimination(
    lower: list[float], diagonal: list[float], upper: list[float]
) -> Elimination:
    """LAPACK ``dgtsv``'s Gaussian elimination with partial pivoting of a tridiagonal matrix
    (sub-, main and super-diagonal; N >= 2), on Python floats (IEEE doubles rounded as the
    Fortran's): per row (interchanged, factor), and the U factor's three diagonals."""
    d, du, dl = list(diagonal), list(upper), list(lower)
    n = len(d)
    steps = []
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            fact = dl[i] / d[i]
            d[i + 1] = d[i + 1] - fact * du[i]
            dl[i] = 0.0
            steps.append((False, fact))
        else:
            fact = d[i] / dl[i]
            d[i] = dl[i]
            temp = d[i + 1]
            d[i + 1] = du[i] - fact * temp
            if i < n - 2:
                dl[i] = du[i + 1]
                du[i + 1] = -fact * dl[i]
            du[i] = temp
            steps.append((True, fact))
    return steps, d, du, dl


def _solve_column(elimination: Elimination, b: list[float]) -> list[float]:
    """``dgtsv``'s forward elimination and back substitution of one right-hand side."""
    steps, d, du, dl = elimination
    n = len(d)
    if any(interchanged for interchanged, _ in steps):
        for i, (interchanged, fact) in enumerate(steps):
            if interchanged:
                b[i], b[i + 1] = b[i + 1], b[i] - fact * b[i + 1]
            else:
                b[i + 1] = b[i + 1] - fact * b[i]
    else:  # the usual case (steps under 1 s: the first row's 1 is the larger), one pass
        previous = b[0]
        for i, (_, fact) in enumerate(steps, 1):
            previous = b[i] = b[i] - fact * previous
    after = b[n - 1] = b[n - 1] / d[n - 1]
    x = b[n - 2] = (b[n - 2] - du[n - 2] * after) / d[n - 2]
    for i in range(n - 3, -1, -1):
        x, after = (b[i] - du[i] * x - dl[i] * after) / d[i], x
        b[i] = x
    return b


def _solve_rows(elimination: Elimination, b: np.ndarray) -> None:
    """``dgtsv``'s forward elimination and back substitution of the right-hand sides, the
    columns of ``b`` (N, m), in place: each element sees the Fortran's operations."""
    steps, d, du, dl = elimination
    n = len(d)
    for i, (interchanged, fact) in enumerate(steps):
        if interchanged:
            upper_row = b[i + 1].copy()
            b[i + 1] = b[i] - fact * upper_row
            b[i] = upper_row
        else:
            b[i + 1] -= fact * b[i]
    b[n - 1] /= d[n - 1]
    b[n - 2] = (b[n - 2] - du[n - 2] * b[n - 1]) / d[n - 2]
    for i in range(n - 3, -1, -1):
        b[i] = (b[i] - du[i] * b[i + 1] - dl[i] * b[i + 2]) / d[i]


def joint_path_velocities(
    times_s: np.ndarray,
    joint_positions: Sequence[np.ndarray],
    continuous: np.ndarray,
    compiled: bool = False,
) -> np.ndarray:
    """q̇ (G, N, n) [rad/s or m/s] of G joint paths (N, n) sampled at the same ``times_s``:
    the clamped spline's rates through the samples, the ``continuous`` (n,) joints unwrapped,
    all paths in one spline (its columns are independent: each path's rates are those of a
    spline through it alone); ``compiled``: by the kernel (``clamped_spline_velocities``, the
    same bits)."""
    positions = np.array(joint_positions, dtype=float)  # (G, N, n)
    if continuous.any() and positions.shape[1] > 1:
        positions[..., continuous] = np.unwrap(positions[..., continuous], axis=1)
    grasps, count, n = positions.shape
    columns = np.moveaxis(positions, 0, 1).reshape(count, grasps * n)
    if compiled:
        rates = clamped_spline_velocities(times_s, columns)
    else:
        rates = joint_velocities_accelerations(times_s, columns)[0]
    return np.moveaxis(rates.reshape(count, grasps, n), 1, 0)
