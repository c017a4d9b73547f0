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
