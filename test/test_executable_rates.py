"""q̇ and q̈ for execution (core/method/executable.py) are scipy's clamped CubicSpline's
derivatives at the knots, bit for bit: the same operations in the same order (LAPACK dgtsv's
elimination, row interchanges included, then PPoly's evaluation), alone and batched."""

from __future__ import annotations

import numpy as np
import pytest
from fast_paths import needs_numba
from scipy.interpolate import CubicSpline

from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method.executable import (
    ROW_SOLVE_COLUMNS,
    clamped_spline_velocities,
    joint_velocities_accelerations,
    rates_for_execution_many,
)


def scipy_rates(times: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    spline = CubicSpline(times, positions, axis=0, bc_type="clamped")
    return spline(times, 1), spline(times, 2)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal as doubles, sign of zero included (NaN payloads aside: none here)."""
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def random_case(rng: np.random.Generator, columns: int) -> tuple[np.ndarray, np.ndarray]:
    samples = int(rng.integers(2, 40))
    # steps from 1 ms to 30 s: above 1 s the elimination interchanges rows (first row's 1)
    steps = rng.uniform(0.1, 3.0, samples - 1) * 10.0 ** rng.uniform(-2, 1)
    times = rng.uniform(-5, 5) + np.concatenate([[0.0], np.cumsum(steps)])
    positions = rng.standard_normal((samples, columns)) * 10.0 ** rng.uniform(-3, 3)
    if columns:
        positions[:, -1] = 0.0  # a joint at rest: zeros of both signs in the elimination
    return times, positions


@pytest.mark.parametrize("columns", [0, 1, 7, ROW_SOLVE_COLUMNS + 1])
def test_rates_equal_scipys_clamped_spline_bit_for_bit(columns: int) -> None:
    rng = np.random.default_rng(columns)
    interchanged = 0
    for _ in range(150):
        times, positions = random_case(rng, columns)
        interchanged += bool(np.any(np.diff(times)[1:] > 1.0))
        velocities, accelerations = joint_velocities_accelerations(times, positions)
        expected_velocities, expected_accelerations = scipy_rates(times, positions)
        assert same_bits(velocities, expected_velocities)
        assert same_bits(accelerations, expected_accelerations)
    assert interchanged > 10  # the pivoting branch ran


@needs_numba
@pytest.mark.parametrize("columns", [0, 1, 7, 70])
def test_compiled_velocities_equal_scipys_bit_for_bit(columns: int) -> None:
    """The whole arm's kernel (no fused multiply-adds) rounds as scipy: same bits, the
    pivoting branch and two samples included."""
    rng = np.random.default_rng(100 + columns)
    interchanged = two_samples = 0
    for _ in range(150):
        times, positions = random_case(rng, columns)
        interchanged += bool(np.any(np.diff(times)[1:] > 1.0))
        two_samples += len(times) == 2
        velocities = clamped_spline_velocities(times, positions)
        assert same_bits(velocities, scipy_rates(times, positions)[0])
        again = clamped_spline_velocities(times, positions[::-1].copy())  # kept elimination
        assert same_bits(again, scipy_rates(times, positions[::-1])[0])
    assert interchanged > 10 and two_samples
    one = clamped_spline_velocities(np.array([0.5]), np.ones((1, 3)))
    assert one.shape == (1, 3) and not np.any(one)


def test_batched_rates_equal_one_at_a_time_and_keep_planned_rates() -> None:
    rng = np.random.default_rng(3)
    times = np.linspace(0.0, 2.0, 201)
    other_times = np.linspace(0.0, 1.0, 11)
    planned = (np.ones((11, 7)), np.zeros((11, 7)))
    trajectories = [(times, rng.standard_normal((201, 7)).cumsum(0), None) for _ in range(70)]
    trajectories += [(other_times, rng.standard_normal((11, 7)), planned)]
    trajectories += [(other_times, rng.standard_normal((11, 3)), None)]
    results = rates_for_execution_many(trajectories)
    assert results[70] is planned
    for (t, q, plan), (velocities, accelerations) in zip(trajectories, results, strict=True):
        if plan is None:
            expected_velocities, expected_accelerations = scipy_rates(t, q)
            assert same_bits(velocities, expected_velocities)
            assert same_bits(accelerations, expected_accelerations)


def test_bad_times_are_refused_with_the_field_name() -> None:
    with pytest.raises(InvalidInputError, match="times_s"):
        joint_velocities_accelerations(np.array([0.0, 0.0, 1.0]), np.zeros((3, 2)))
    with pytest.raises(InvalidInputError, match="joint_positions"):
        joint_velocities_accelerations(np.array([0.0, 1.0]), np.zeros((3, 2)))
    zeros = joint_velocities_accelerations(np.array([0.0]), np.ones((1, 2)))
    assert not np.any(zeros[0]) and not np.any(zeros[1])


@needs_numba
@pytest.mark.parametrize("times", [[0.0, 0.5, 0.5, 1.0], [0.0, 1.0, 0.5, 2.0]])
def test_both_paths_refuse_times_that_do_not_increase(times: list[float]) -> None:
    """The compiled whole-arm path refuses what the numpy path refuses (it returned NaN)."""
    positions = np.ones((len(times), 2))
    for rates in (joint_velocities_accelerations, clamped_spline_velocities):
        with pytest.raises(InvalidInputError, match="times_s: must be strictly increasing"):
            rates(np.array(times), positions)
