"""The jit decorator of the kernels and Pinocchio's Taylor-branch thresholds.

Without numba (an optional accelerator) the decorator returns the function unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

try:  # optional accelerator
    import numba
except ImportError:  # pragma: no cover - exercised on machines without numba
    numba = None


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    if numba is None:  # pragma: no cover
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


_EPS = float(np.finfo(np.float64).eps)
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<2>()
_PREC3 = _EPS ** (1.0 / 4.0)  # ... precision<3>()
