"""Inertia uncertainty: nominal identity, monotonicity, the batched formula, ranking stability."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import BAXTER_SEED, book_trajectory

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectInertia,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.uncertainty import (
    InertiaUncertainty,
    analyse_inertia_uncertainty,
    effective_mass_for_inertias,
    perturb_inertia,
    sample_inertia_perturbations,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat

BOOK = solid_box(0.34, [0.15, 0.22, 0.015])  # a thin plate: I_z ≈ I_x + I_y
GRASPS = [
    Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "grasp"), f"spine_{y:+.1f}")
    for y in (-0.1, 0.0, 0.1)
] + [Grasp(pose_from_position_quat([0.0, 0.0, 3.0], [0, 0, 0, 1], "grasp"), "far")]
TRAJECTORY = book_trajectory()


@pytest.fixture(scope="module")
def book_evaluations(baxter: RobotModel) -> list:
    ranking = GraspSafetyEvaluator(baxter).rank(
        GRASPS, BOOK, TRAJECTORY, seed_positions=BAXTER_SEED
    )
    assert [e.feasible for e in ranking.evaluations] == [True, True, True, False]
    return list(ranking.evaluations)


def test_zero_uncertainty_gives_the_nominal_scores(
    baxter: RobotModel, book_evaluations: list
) -> None:
    for metric in ("mean", "max", "integral"):
        evaluations = [
            GraspSafetyEvaluator(baxter).evaluate(
                g, BOOK, TRAJECTORY, k, seed_positions=BAXTER_SEED, metric=metric
            )
            for k, g in enumerate(GRASPS)
        ]
        analysis = analyse_inertia_uncertainty(
            baxter, evaluations, GRASPS, BOOK, InertiaUncertainty(), metric
        )
        assert len(analysis.perturbations) == 1 and analysis.perturbations.num_invalid == 0
        assert not analysis.ranking_flips and analysis.order_stability == 1.0
        for result, evaluation in zip(analysis.grasps, evaluations, strict=True):
            if not evaluation.feasible:
                assert not result.feasible and math.isnan(result.worst_case_score)
                assert result.probability_safest == 0.0
                continue
            assert result.nominal_score == pytest.approx(evaluation.score, rel=1e-12)
            assert result.worst_case_score == result.percentile_score == result.nominal_score
        best = min((e for e in evaluations if e.feasible), key=lambda e: e.score).index
        assert analysis.nominal_safest == best
        assert analysis.grasps[best].probability_safest == 1.0
        assert "ranking stable" in analysis.message


def test_batched_effective_mass_matches_a_full_evaluation(
    baxter: RobotModel, book_evaluations: list
) -> None:
    """The IK does not depend on inertia: re-evaluating with a perturbed one gives the same."""
    perturbed = perturb_inertia(BOOK, [0.2, 0.01, -0.02, 0.005, 0.1, -0.1, 0.05])
    evaluation = book_evaluations[1]
    masses = effective_mass_for_inertias(baxter, evaluation, GRASPS[1], [BOOK, perturbed])
    np.testing.assert_allclose(masses[0], evaluation.effective_mass_kg, rtol=1e-12)
    direct = GraspSafetyEvaluator(baxter).evaluate(
        GRASPS[1], perturbed, TRAJECTORY, 1, seed_positions=BAXTER_SEED
    )
    np.testing.assert_allclose(masses[1], direct.effective_mass_kg, rtol=1e-7)


def test_more_mass_only_never_lowers_the_effective_mass(
    baxter: RobotModel, book_evaluations: list
) -> None:
    uncertainty = InertiaUncertainty(mass_fraction=0.3, num_random_samples=10)
    analysis = analyse_inertia_uncertainty(baxter, book_evaluations, GRASPS, BOOK, uncertainty)
    perturbations = analysis.perturbations
    heavier = int(np.argmax(perturbations.parameters[:, 0]))
    assert perturbations.kinds[heavier] == "corner"
    assert perturbations.parameters[heavier, 0] == pytest.approx(0.3)
    for result in analysis.grasps[:3]:
        assert result.worst_case_score >= result.nominal_score
        assert result.worst_case_sample == heavier  # monotone in the mass: the +30 % corner
        assert result.percentile_score <= result.worst_case_score
    for evaluation, grasp in zip(book_evaluations[:3], GRASPS[:3], strict=True):
        masses = effective_mass_for_inertias(
            baxter, evaluation, grasp, [BOOK, perturb_inertia(BOOK, [0.1] + [0.0] * 6)]
        )
        assert np.all(masses[1] >= masses[0])


def test_perturbed_inertias_stay_in_bounds_and_valid() -> None:
    uncertainty = InertiaUncertainty(0.1, 0.02, 0.3, num_random_samples=50, seed=3)
    perturbations = sample_inertia_perturbations(BOOK, uncertainty)
    assert perturbations.num_invalid == 0  # second-moment scaling keeps a thin plate valid
    assert len(perturbations) == 1 + 2**7 + 50
    assert perturbations.kinds[0] == "nominal" and perturbations.inertias[0] is BOOK
    nominal_moments, axes = np.linalg.eigh(BOOK.inertia_about_com_kgm2)
    for inertia in perturbations.inertias:
        assert abs(inertia.mass_kg / BOOK.mass_kg - 1.0) <= 0.1 + 1e-12
        assert np.all(np.abs(inertia.com_in_object_m - BOOK.com_in_object_m) <= 0.02 + 1e-15)
        moments = np.diag(axes.T @ inertia.inertia_about_com_kgm2 @ axes)
        assert np.all(np.abs(moments / nominal_moments - 1.0) <= 0.3 + 1e-12)
        off_diagonal = axes.T @ inertia.inertia_about_com_kgm2 @ axes - np.diag(moments)
        assert np.abs(off_diagonal).max() <= 1e-15  # principal axes not rotated
    again = sample_inertia_perturbations(BOOK, uncertainty)
    np.testing.assert_array_equal(again.parameters, perturbations.parameters)
    other = sample_inertia_perturbations(BOOK, InertiaUncertainty(0.1, 0.02, 0.3, 50, seed=4))
    assert not np.array_equal(other.parameters, perturbations.parameters)


def test_second_moment_scaling_by_hand() -> None:
    """diag(2, 3, 4): Σ = (2.5, 1.5, 0.5); Σ·(1.2, 1, 0.8) = (3, 1.5, 0.4): I = (1.9, 3.4, 4.5)."""
    nominal = ObjectInertia(1.0, np.zeros(3), np.diag([2.0, 3.0, 4.0]))
    perturbed = perturb_inertia(nominal, [0.0, 0.0, 0.0, 0.0, 0.2, 0.0, -0.2])
    np.testing.assert_allclose(perturbed.inertia_about_com_kgm2, np.diag([1.9, 3.4, 4.5]))


def test_large_errors_flip_the_book_ranking_and_small_ones_do_not(
    baxter: RobotModel, book_evaluations: list
) -> None:
    large = analyse_inertia_uncertainty(
        baxter, book_evaluations, GRASPS, BOOK, InertiaUncertainty(0.2, 0.02, 0.2)
    )
    probabilities = [g.probability_safest for g in large.grasps]
    assert sum(probabilities) == pytest.approx(1.0)
    assert large.ranking_flips and "ranking flips" in large.message
    nominal = large.nominal_safest
    assert nominal == min(book_evaluations[:3], key=lambda e: e.score).index
    assert probabilities[nominal] < 1.0
    assert probabilities[nominal] == pytest.approx(np.mean(large.safest_per_sample == nominal))
    assert large.order_stability < 1.0
    assert set(large.worst_case_order) == {0, 1, 2}
    worst = [large.grasps[k].worst_case_score for k in large.worst_case_order]
    assert worst == sorted(worst)
    small = analyse_inertia_uncertainty(
        baxter, book_evaluations, GRASPS, BOOK, InertiaUncertainty(1e-4, 1e-6, 1e-4)
    )
    assert not small.ranking_flips and small.grasps[nominal].probability_safest == 1.0


def test_percentile_is_numpys(baxter: RobotModel, book_evaluations: list) -> None:
    uncertainty = InertiaUncertainty(0.1, 0.01, 0.1, num_random_samples=20, percentile=80.0)
    analysis = analyse_inertia_uncertainty(baxter, book_evaluations, GRASPS, BOOK, uncertainty)
    for result in analysis.grasps[:3]:
        assert result.percentile_score == pytest.approx(np.percentile(result.scores, 80.0))
        assert result.scores[0] == result.nominal_score


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mass_fraction": 1.0}, "uncertainty.mass_fraction"),
        ({"mass_fraction": -0.1}, "uncertainty.mass_fraction"),
        ({"inertia_fraction": 1.5}, "uncertainty.inertia_fraction"),
        ({"com_offset_m": float("nan")}, "uncertainty.com_offset_m"),
        ({"percentile": 101.0}, "uncertainty.percentile"),
        ({"num_random_samples": -1}, "uncertainty.num_random_samples"),
        ({"seed": 1.5}, "uncertainty.seed"),
        ({"include_corners": 1}, "uncertainty.include_corners"),
    ],
)
def test_bad_settings_are_refused(kwargs: dict, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field.replace(".", r"\.")):
        InertiaUncertainty(**kwargs)


def test_mismatched_grasps_are_refused(baxter: RobotModel, book_evaluations: list) -> None:
    with pytest.raises(InvalidInputError, match="grasps"):
        analyse_inertia_uncertainty(baxter, book_evaluations, GRASPS[:2], BOOK)
    with pytest.raises(InvalidInputError, match="metric"):
        analyse_inertia_uncertainty(baxter, book_evaluations, GRASPS, BOOK, metric="median")
