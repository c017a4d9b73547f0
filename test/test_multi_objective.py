"""Safety + grasp quality: weighted ranking and the Pareto-optimal set."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grasp_safety_ros.core import GraspEvaluation, InvalidInputError
from grasp_safety_ros.core.analyses.multi_objective import (
    min_max_normalise,
    pareto_set,
    rank_evaluations_with_quality,
    rank_with_quality,
)
from grasp_safety_ros.core.method.ranking import order_by_score

# Values on a grid (ties occur, and min-max normalisation cannot merge distinct values by
# rounding); NaN marks an infeasible grasp.
score_values = st.one_of(
    st.sampled_from([1.0, 1.5, 2.0, 2.5]),
    st.floats(0.1, 10.0).map(lambda x: round(x, 6)),
    st.just(float("nan")),
)
quality_values = st.one_of(
    st.sampled_from([0.0, 0.5, 1.0]), st.floats(-5.0, 5.0).map(lambda x: round(x, 6))
)
candidates = st.lists(
    st.tuples(score_values, quality_values),
    min_size=1,
    max_size=12,
)


def evaluation(index: int, score: float) -> GraspEvaluation:
    feasible = not math.isnan(score)
    return GraspEvaluation(
        index,
        f"g{index}",
        feasible,
        "" if feasible else "unreachable",
        score,
        np.zeros(1),
        np.zeros((1, 1)),
        np.zeros((1, 3)),
        np.ones(1),
        np.zeros(1, dtype=bool),
        np.zeros(1),
        np.zeros(1, dtype=int),
    )


@settings(max_examples=100, deadline=None)
@given(candidates)
def test_full_safety_weight_reproduces_the_safety_order(pairs: list) -> None:
    scores, quality = zip(*pairs, strict=True)
    evaluations = [evaluation(k, s) for k, s in enumerate(scores)]
    ranking = rank_evaluations_with_quality(evaluations, quality, safety_weight=1.0)
    assert ranking.order == order_by_score(evaluations)
    assert rank_evaluations_with_quality(evaluations, None, 0.3).order == ranking.order


@settings(max_examples=100, deadline=None)
@given(candidates)
def test_zero_safety_weight_orders_by_quality(pairs: list) -> None:
    scores, quality = zip(*pairs, strict=True)
    ranking = rank_with_quality(scores, quality, safety_weight=0.0)
    expected = sorted(
        (k for k, s in enumerate(scores) if not math.isnan(s)),
        key=lambda k: (-quality[k], scores[k], k),
    )
    assert list(ranking.order) == expected


def dominates(a: int, b: int, scores: np.ndarray, quality: np.ndarray) -> bool:
    return bool(
        scores[a] <= scores[b]
        and quality[a] >= quality[b]
        and (scores[a] < scores[b] or quality[a] > quality[b])
    )


@settings(max_examples=150, deadline=None)
@given(candidates)
def test_pareto_set_properties(pairs: list) -> None:
    scores, quality = (np.array(column, dtype=float) for column in zip(*pairs, strict=True))
    members = set(pareto_set(scores, quality))
    feasible = [k for k in range(len(scores)) if not math.isnan(scores[k])]
    assert members <= set(feasible)
    assert bool(members) == bool(feasible)
    for member in members:
        assert not any(dominates(k, member, scores, quality) for k in feasible)
    for other in set(feasible) - members:
        assert any(dominates(m, other, scores, quality) for m in members)
    ranking = rank_with_quality(scores, quality, 0.5)
    assert set(ranking.pareto_set) == members
    if ranking.order:  # the weighted-sum winner is always Pareto-optimal
        assert ranking.order[0] in members


def test_worked_example() -> None:
    """Scores 1, 2, 3 (safety_norm 0, 0.5, 1), qualities 0.2, 0.9, 0.5 (norm 0, 1, 3/7)."""
    ranking = rank_with_quality([1.0, 2.0, 3.0, float("nan")], [0.2, 0.9, 0.5, 7.0], 0.4)
    np.testing.assert_allclose(ranking.safety_normalised[:3], [0.0, 0.5, 1.0])
    np.testing.assert_allclose(ranking.quality_normalised[:3], [0.0, 1.0, 3.0 / 7.0])
    np.testing.assert_allclose(
        ranking.combined[:3], [0.4, 0.4 * 0.5 + 0.6, 0.6 * 3.0 / 7.0], rtol=1e-15
    )
    assert math.isnan(ranking.combined[3]) and math.isnan(ranking.quality_normalised[3])
    assert ranking.order == (1, 0, 2)
    assert ranking.pareto_set == (0, 1)  # 2 is dominated by 1 (2 < 3 and 0.9 > 0.5)


def test_ties_and_constant_columns() -> None:
    ranking = rank_with_quality([2.0, 1.0, 2.0], [0.5, 0.5, 0.5], 0.5)
    np.testing.assert_array_equal(ranking.quality_normalised, [0.0, 0.0, 0.0])
    assert ranking.order == (1, 0, 2)
    single = rank_with_quality([float("nan"), 3.0], [1.0, 0.0], 0.7)
    assert single.order == (1,) and single.combined[1] == pytest.approx(0.7)
    assert single.pareto_set == (1,)
    equal = rank_with_quality([1.0, 1.0], [0.3, 0.3], 0.5)
    assert equal.order == (0, 1) and equal.pareto_set == (0, 1)  # equals do not dominate


def test_no_quality_is_the_pure_safety_ranking() -> None:
    ranking = rank_with_quality([3.0, 1.0, 2.0, 1.0], None, 0.2)
    assert not ranking.quality_given and ranking.safety_weight == 1.0
    assert ranking.order == (1, 3, 2, 0)
    assert ranking.pareto_set == (1, 3)
    assert rank_with_quality([3.0, 1.0], [], 0.2).order == (1, 0)


def test_normalise_all_infeasible() -> None:
    assert np.all(np.isnan(min_max_normalise(np.array([1.0, 2.0]), np.array([False, False]))))
    ranking = rank_with_quality([float("nan")] * 2, [0.1, 0.2])
    assert ranking.order == () and ranking.pareto_set == ()


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (([1.0, 2.0], [0.5], 0.5), "grasp_quality"),
        (([1.0, 2.0], [0.5, float("nan")], 0.5), "grasp_quality"),
        (([1.0, 2.0], [0.5, float("inf")], 0.5), "grasp_quality"),
        (([1.0, 2.0], [0.5, 0.1], 1.5), "safety_weight"),
        (([1.0, 2.0], [0.5, 0.1], -0.1), "safety_weight"),
        (([1.0, float("inf")], [0.5, 0.1], 0.5), "scores"),
    ],
)
def test_bad_input_is_refused(args: tuple, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field):
        rank_with_quality(*args)
