"""Helpers the benchmark scripts share: summaries of repeated timings, a timed call, the top
functions of a profile, the largest relative difference of two arrays."""

from __future__ import annotations

import cProfile
import io
import pstats
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def summary(values: Sequence[float]) -> dict[str, float]:
    """Median, min, max and relative spread ((max - min) / median) of repeated timings."""
    median = statistics.median(values)
    return {
        "median": median,
        "min": min(values),
        "max": max(values),
        "spread_rel": (max(values) - min(values)) / median if median else 0.0,
        "repeats": len(values),
    }


def timed(function: Callable[[], Any]) -> tuple[float, Any]:
    start = time.perf_counter()
    result = function()
    return time.perf_counter() - start, result


def top_functions(profile: cProfile.Profile, total_s: float, count: int = 8) -> list[dict]:
    stats = pstats.Stats(profile, stream=io.StringIO())
    rows = []
    for (filename, line, name), (_, calls, tottime, _, _) in stats.stats.items():  # type: ignore[attr-defined]
        where = f"{Path(filename).name}:{line}({name})" if line else name
        rows.append({"function": where, "calls": calls, "share": tottime / total_s})
    rows.sort(key=lambda row: -row["share"])
    return rows[:count]


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a / b - 1.0))) if len(a) else 0.0


def python_backend_agreement(pairs: list) -> dict[str, Any]:
    """How the Python backend's evaluations agree with the compiled ones, ``pairs`` of
    (Python, compiled) GraspEvaluation: the largest relative difference of the effective
    masses where both are feasible, and whether feasibility and IK iterations are the same."""
    return {
        "python_backend_max_rel_diff": max(
            (
                rel_diff(a.effective_mass_kg, b.effective_mass_kg)
                for a, b in pairs
                if a.feasible and b.feasible
            ),
            default=0.0,
        ),
        "python_backend_same_feasibility": all(a.feasible == b.feasible for a, b in pairs),
        "python_backend_same_ik_iterations": all(
            np.array_equal(a.ik_iterations, b.ik_iterations) for a, b in pairs
        ),
    }
