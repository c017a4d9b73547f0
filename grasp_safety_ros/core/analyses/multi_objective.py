"""Safety and grasp quality together: weighted ranking and the Pareto-optimal set.

Grasp planners give a quality per candidate (higher is better); the safety score is the
effective-mass score (lower is safer). Over the feasible candidates both are min-max normalised
to [0, 1]:

    safety_norm = (score − min score) / (max score − min score)
    quality_norm = (quality − min quality) / (max quality − min quality)
    combined = w·(1 − safety_norm) + (1 − w)·quality_norm,   w = safety_weight in [0, 1]

and candidates are ranked by ``combined``, highest first; ties go to the lower safety score,
then to the input order. A constant column (all feasible values equal, or a single feasible
candidate) normalises to 0 everywhere, so it does not influence the order. w = 1 is the pure
safety ranking; without qualities (None or empty) the ranking is the pure safety one.

Pareto set: the feasible candidates not dominated in (lower score, higher quality): j dominates
i when score_j <= score_i and quality_j >= quality_i with at least one strict. Equal pairs do
not dominate each other, so duplicates are all members.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float, read_only
from ..method.results import GraspEvaluation


@dataclass(frozen=True)
class QualityRanking:
    """Grasps ranked by a combination of safety and quality (arrays: one entry per grasp).

    Attributes:
        safety_weight: The w used, in [0, 1] (1 when no qualities were given).
        quality_given: False when no qualities were given (pure safety ranking).
        scores: Safety scores (lower is safer); NaN for infeasible grasps.
        quality: Grasp qualities as given (NaN when not given).
        safety_normalised: Min-max normalised score over feasible grasps; NaN if infeasible.
        quality_normalised: Min-max normalised quality over feasible grasps; NaN if infeasible
            or not given.
        combined: w·(1 − safety_normalised) + (1 − w)·quality_normalised; NaN if infeasible.
        order: Indices of the feasible grasps, best combined first.
        pareto_set: Indices of the Pareto-optimal feasible grasps, by score ascending (then
            quality descending, then index).
    """

    safety_weight: float
    quality_given: bool
    scores: np.ndarray
    quality: np.ndarray
    safety_normalised: np.ndarray
    quality_normalised: np.ndarray
    combined: np.ndarray
    order: tuple[int, ...]
    pareto_set: tuple[int, ...]


def min_max_normalise(values: np.ndarray, feasible: np.ndarray) -> np.ndarray:
    """(v − min) / (max − min) over the feasible entries; a constant column gives 0; else NaN."""
    result = np.full(len(values), np.nan)
    if not feasible.any():
        return result
    low, high = values[feasible].min(), values[feasible].max()
    span = high - low
    result[feasible] = (values[feasible] - low) / span if span > 0 else 0.0
    return result


def pareto_set(scores: Any, quality: Any, feasible: Any | None = None) -> tuple[int, ...]:
    """Positions of the feasible candidates not dominated in (lower score, higher quality).

    Sorted by score ascending, then quality descending, then position. ``feasible`` defaults
    to "score is not NaN".
    """
    score = np.asarray(scores, dtype=float)
    qualities = np.asarray(quality, dtype=float)
    mask = ~np.isnan(score) if feasible is None else np.asarray(feasible, dtype=bool)
    members: list[int] = []
    candidates = np.flatnonzero(mask)
    for i in candidates:
        others = candidates[candidates != i]
        no_worse = (score[others] <= score[i]) & (qualities[others] >= qualities[i])
        better = (score[others] < score[i]) | (qualities[others] > qualities[i])
        if not np.any(no_worse & better):
            members.append(int(i))
    return tuple(sorted(members, key=lambda k: (score[k], -qualities[k], k)))


def rank_with_quality(
    scores: Any,
    grasp_quality: Sequence[float] | np.ndarray | None,
    safety_weight: float = 0.5,
) -> QualityRanking:
    """Rank by the normalised weighted sum of safety and quality; also the Pareto set.

    Args:
        scores: Safety score per grasp (lower is safer); NaN marks an infeasible grasp.
        grasp_quality: Quality per grasp (higher is better), finite, same length as
            ``scores``; None or empty: pure safety ranking.
        safety_weight: w in [0, 1]: 1 is pure safety, 0 pure quality.
    """
    weight = finite_float(safety_weight, "safety_weight", 0.0, 1.0)
    score = np.array(scores, dtype=float).reshape(-1)
    if np.any(np.isinf(score)):
        raise InvalidInputError("scores", "must be finite (NaN marks an infeasible grasp)")
    feasible = ~np.isnan(score)
    given = grasp_quality is not None and len(grasp_quality) > 0
    if given:
        quality = np.array(finite_array(grasp_quality, "grasp_quality"), dtype=float)
        if quality.shape != score.shape:
            raise InvalidInputError(
                "grasp_quality",
                f"must have one value per grasp ({len(score)}), got shape {list(quality.shape)}",
            )
    else:
        quality = np.full(len(score), np.nan)
        weight = 1.0
    safety_norm = min_max_normalise(score, feasible)
    quality_norm = min_max_normalise(quality, feasible) if given else np.full(len(score), np.nan)
    combined = weight * (1.0 - safety_norm)
    if given:
        combined = combined + (1.0 - weight) * quality_norm
    order = tuple(
        int(k) for k in sorted(np.flatnonzero(feasible), key=lambda k: (-combined[k], score[k], k))
    )
    if given:
        pareto = pareto_set(score, quality, feasible)
    else:
        best = score[feasible].min() if feasible.any() else np.nan
        pareto = tuple(int(k) for k in np.flatnonzero(feasible & (score == best)))
    return QualityRanking(
        safety_weight=weight,
        quality_given=given,
        scores=read_only(score),
        quality=read_only(quality),
        safety_normalised=read_only(safety_norm),
        quality_normalised=read_only(quality_norm),
        combined=read_only(combined),
        order=order,
        pareto_set=pareto,
    )


def rank_evaluations_with_quality(
    evaluations: Sequence[GraspEvaluation],
    grasp_quality: Sequence[float] | np.ndarray | None,
    safety_weight: float = 0.5,
) -> QualityRanking:
    """rank_with_quality on the evaluations' scores (infeasible grasps: NaN).

    Positions in the result are positions in ``evaluations`` (= GraspEvaluation.index when
    the evaluations come from GraspSafetyEvaluator.rank).
    """
    scores = [e.score if e.feasible else float("nan") for e in evaluations]
    return rank_with_quality(scores, grasp_quality, safety_weight)
