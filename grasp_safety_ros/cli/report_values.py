"""Values as the CLI's JSON and text reports write them: finite numbers or null, arrays, the
width of name columns, force ratios printed on the side of 1 their verdict is on."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import SupportsFloat

import numpy as np

from ..core.analyses.iso15066 import ADMISSIBLE_RATIO_TOLERANCE


def number(value: SupportsFloat) -> float | None:
    """A finite float, or None (JSON null) for NaN and inf."""
    finite = float(value)
    return finite if math.isfinite(finite) else None


def numbers(values: np.ndarray) -> np.ndarray:
    """An array as the JSON writer takes it (C-contiguous; ``report_json`` writes NaN and inf
    as null)."""
    return np.ascontiguousarray(values)


NAME_WIDTH = 16
"""Least width of the name columns of the tables; longer names widen them (never cut)."""


def name_width(names: Sequence[str]) -> int:
    """Width of a name column holding ``names`` whole: the longest, at least NAME_WIDTH."""
    return max([NAME_WIDTH, *(len(name) for name in names)])


def force_ratio_text(value: float) -> str:
    """F/F_max with two decimals, or as many more as it takes (up to 9) for the printed number
    to lie on the same side of 1 as the admissibility verdict (1.0029 is "1.003", not "1.00")."""
    if math.isinf(value):
        return "n/p"
    admissible = value <= 1.0 + ADMISSIBLE_RATIO_TOLERANCE
    for digits in range(2, 10):
        text = f"{value:.{digits}f}"
        if (float(text) <= 1.0) == admissible:
            return text
    return text
