"""The scores of a grasp: aggregates of its per-sample effective mass (numpy only, so the
command line can name them without loading the method)."""

from __future__ import annotations

import numpy as np

from ..exceptions import InvalidInputError

METRICS = ("mean", "max", "integral")
"""Aggregates of the per-sample effective mass: mean [kg], max [kg], integral [kg s]."""


def check_metric(metric: str, field_name: str = "metric") -> str:
    """Return ``metric`` if it is one of METRICS, else raise InvalidInputError."""
    if metric not in METRICS:
        raise InvalidInputError(field_name, f"must be one of {', '.join(METRICS)}, got {metric!r}")
    return metric


def aggregate(effective_mass_kg: np.ndarray, times_s: np.ndarray, metric: str) -> float:
    """Score of per-sample effective masses: mean [kg], max [kg] or trapezoid integral [kg s]."""
    check_metric(metric)
    if metric == "mean":
        masses = np.asarray(effective_mass_kg)
        return float(masses.sum() / len(masses))  # = np.mean, without its overhead
    if metric == "max":
        return float(np.max(effective_mass_kg))
    return float(np.trapezoid(effective_mass_kg, times_s)) if len(times_s) > 1 else 0.0


def score_bound_weights(times_s: np.ndarray, metric: str) -> tuple[bool, np.ndarray, float]:
    """How a lower bound of the score grows, sample by sample, from effective masses m_i > 0
    (the early stop of ``kernels.grasp.follow_postures``).

    Returns:
        (is_max, weights, margin): the bound is the running max of the masses (``max``), else
        their running sum weighted by ``weights`` (N,) (1/N for the mean, the trapezoid's
        weights [s] for the integral, so that the full sum is the score); ``margin`` is the
        relative rounding of the bound and of ``aggregate``'s score (both sums of N positive
        terms): a bound above score * (1 + margin) certainly exceeds that score as computed.
    """
    check_metric(metric)
    count = len(times_s)
    margin = 4.0 * (count + 4) * float(np.finfo(float).eps)
    if metric == "integral":
        weights = np.zeros(count)
        if count > 1:
            steps = np.diff(times_s)
            weights[:-1] += 0.5 * steps
            weights[1:] += 0.5 * steps
        return False, weights, margin
    return metric == "max", np.full(count, 1.0 / max(count, 1)), margin
