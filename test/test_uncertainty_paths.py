"""Inertia uncertainty on the compiled path (``method.perturbed``) equals the Pinocchio reference
(``effective_mass_for_inertias``) to rounding, on 6- and 7-joint revolute, prismatic,
continuous and geared arms and Baxter, infeasible grasps and worst-direction samples mixed in;
its nominal inertia gives the ranking's own effective masses. Equality only, never timing."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions
from tolerances import (
    ROUNDINGS_PER_JOINT,
    assert_close_to_scale,
    condition_number,
    mass_matrices,
    rounding_tolerance,
)

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.uncertainty import (
    InertiaUncertainty,
    _aggregate_rows,
    analyse_armature_range,
    analyse_inertia_uncertainty,
    effective_mass_for_inertias,
    sample_inertia_perturbations,
)
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.core.method.metrics import aggregate
from grasp_safety_ros.core.method.perturbed import (
    GRASP_CHUNK,
    perturbed_effective_masses,
    spatial_inertias_in_tip,
)

needs_numba = pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
BOX = solid_box(0.8, [0.08, 0.12, 0.2], [0.0, 0.01, -0.02])
UNCERTAINTY = InertiaUncertainty(0.3, 0.03, 0.4, num_random_samples=6, seed=2)
"""1 nominal + 2^7 corners + 6 random inertias."""
ARMS = ("arm6", "arm7", "baxter", "prismatic_arm", "continuous_arm", "geared_arm")


def mass_tolerance(robot: RobotModel, evaluations: list, grasps: list[Grasp]) -> float:
    """k · cond · eps of the perturbed masses (compiled vs Pinocchio) of the feasible grasps:
    cond the worse of the arm's M (the reference factorises it) and M with the nominal object
    (the compiled path folds the object in), along each path; k = ROUNDINGS_PER_JOINT · n,
    doubled: the object's inertia enters through a second solve, (I + Y A)⁻¹."""
    conditions = [1.0]
    for evaluation, grasp in zip(evaluations, grasps, strict=True):
        if evaluation.feasible:
            carried = augmented_model(robot, BOX, grasp.transform_tip_to_object)
            for model in (robot.model, carried):
                matrices = mass_matrices(robot, model, evaluation.joint_positions)
                conditions.append(condition_number(matrices))
    return rounding_tolerance(max(conditions), 2 * ROUNDINGS_PER_JOINT * robot.num_joints)


def ranked_case(robot: RobotModel, seed: int) -> tuple[list[Grasp], list]:
    """Three grasps near the identity along a short reach of ``robot`` (at least two
    feasible) and one 30 m off (infeasible), ranked by the default (compiled) evaluator."""
    rng = np.random.default_rng(seed)
    grasps = [
        Grasp(pin.SE3(pin.exp3(rng.uniform(-0.2, 0.2, 3)), rng.uniform(-0.03, 0.03, 3)), f"g{k}")
        for k in range(3)
    ]
    grasps.insert(2, Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 30.0])), "far"))
    evaluator = GraspSafetyEvaluator(robot)
    assert evaluator.ik.compiled
    for _ in range(30):  # the first random posture whose reach keeps two grasps feasible
        positions = random_positions(robot, rng)
        start = robot.transform_tip_to_base(positions)
        goal = pin.SE3(
            start.rotation @ pin.exp3(np.array([0.1, -0.05, 0.15])),
            start.translation + np.array([0.03, -0.04, 0.05]),
        )
        trajectory = ObjectTrajectory(start, goal, 1.0, 0.02)
        ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=positions)
        feasible = [e.feasible for e in ranking.evaluations]
        if sum(feasible) >= 2:
            break
    assert sum(feasible) >= 2 and not feasible[2]
    return grasps, list(ranking.evaluations)


def with_worst_samples(evaluations: list) -> list:
    """The evaluations with every 7th sample (and the first) flagged worst-direction."""
    flagged = []
    for evaluation in evaluations:
        if evaluation.feasible:
            worst = evaluation.direction_is_worst_case.copy()
            worst[::7] = True
            evaluation = replace(evaluation, direction_is_worst_case=worst)
        flagged.append(evaluation)
    return flagged


@needs_numba
@pytest.mark.parametrize("name", ARMS)
def test_compiled_masses_equal_pinocchio(name: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    grasps, evaluations = ranked_case(robot, 21)
    evaluations = with_worst_samples(evaluations)
    inertias = sample_inertia_perturbations(BOX, UNCERTAINTY).inertias
    feasible = [k for k, e in enumerate(evaluations) if e.feasible]
    chain = GraspSafetyEvaluator(robot).ik.chain
    tolerance = mass_tolerance(robot, evaluations, grasps)
    compiled = perturbed_effective_masses(
        robot,
        chain,
        inertias,
        [grasps[k].transform_tip_to_object for k in feasible],
        [evaluations[k].joint_positions for k in feasible],
        [evaluations[k].directions_in_base for k in feasible],
        [evaluations[k].direction_is_worst_case for k in feasible],
    )
    for k, masses in zip(feasible, compiled, strict=True):
        reference = effective_mass_for_inertias(robot, evaluations[k], grasps[k], inertias)
        assert_close_to_scale(masses, reference, f"grasp {k}", tolerance)
        worst = evaluations[k].direction_is_worst_case
        assert worst.any() and np.all(masses[:, worst] > 0)


@needs_numba
@pytest.mark.parametrize("name", ARMS)
def test_compiled_analysis_equals_pinocchio(name: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    grasps, evaluations = ranked_case(robot, 22)
    evaluations = with_worst_samples(evaluations)
    chain = GraspSafetyEvaluator(robot).ik.chain
    tolerance = mass_tolerance(robot, evaluations, grasps)  # scores: sums of positive masses
    for metric in ("mean", "max", "integral"):
        reference = analyse_inertia_uncertainty(
            robot, evaluations, grasps, BOX, UNCERTAINTY, metric
        )
        compiled = analyse_inertia_uncertainty(
            robot, evaluations, grasps, BOX, UNCERTAINTY, metric, chain
        )
        for ours, theirs in zip(compiled.grasps, reference.grasps, strict=True):
            assert ours.feasible == theirs.feasible
            if ours.feasible:
                assert_close_to_scale(ours.scores, theirs.scores, f"{metric} scores", tolerance)
            else:
                assert len(ours.scores) == 0
        assert compiled.worst_case_order == reference.worst_case_order
        assert compiled.nominal_safest == reference.nominal_safest


@needs_numba
@pytest.mark.parametrize("name", ARMS)
def test_nominal_inertia_gives_the_rankings_masses(
    name: str, request: pytest.FixtureRequest
) -> None:
    """Oracle: the ranking's own effective mass per sample, on both paths; at a sample
    flagged worst-direction, 1 / the smallest eigenvalue of the ranking's mobility."""
    robot: RobotModel = request.getfixturevalue(name)
    grasps, evaluations = ranked_case(robot, 23)
    chain = GraspSafetyEvaluator(robot).ik.chain
    feasible = [k for k, e in enumerate(evaluations) if e.feasible]
    tolerance = mass_tolerance(robot, evaluations, grasps)
    nominal = [BOX, BOX]
    for k in feasible:
        evaluation, grasp = evaluations[k], grasps[k]
        (masses,) = perturbed_effective_masses(
            robot,
            chain,
            nominal,
            [grasp.transform_tip_to_object],
            [evaluation.joint_positions],
            [evaluation.directions_in_base],
            [evaluation.direction_is_worst_case],
        )
        reference = effective_mass_for_inertias(robot, evaluation, grasp, nominal)
        for rows in (masses, reference):
            assert_close_to_scale(rows[0], evaluation.effective_mass_kg, "nominal", tolerance)
            np.testing.assert_array_equal(rows[0], rows[1])
        worst = np.ones(len(evaluation.times_s), dtype=bool)
        (masses,) = perturbed_effective_masses(
            robot,
            chain,
            [BOX],
            [grasp.transform_tip_to_object],
            [evaluation.joint_positions],
            [evaluation.directions_in_base],
            [worst],
        )
        model = augmented_model(robot, BOX, grasp.transform_tip_to_object)
        data = model.createData()
        largest = [
            1.0
            / np.linalg.eigvalsh(
                translational_mobility_in_base(robot, model, data, robot.q_from_positions(q))
            )[0]
            for q in evaluation.joint_positions
        ]
        assert_close_to_scale(masses[0], np.array(largest), "worst direction", tolerance)
        assert np.all(masses[0] >= evaluation.effective_mass_kg * (1 - tolerance))


@needs_numba
def test_more_grasps_than_a_chunk_and_uneven_lengths(arm7: RobotModel) -> None:
    """Grasps beyond GRASP_CHUNK, and grasps with different sample counts in one chunk."""
    grasps, evaluations = ranked_case(arm7, 24)
    feasible = [k for k, e in enumerate(evaluations) if e.feasible]
    picks = [feasible[j % len(feasible)] for j in range(GRASP_CHUNK + 3)]
    lengths = [len(evaluations[k].times_s) - (j % 4) * 5 for j, k in enumerate(picks)]
    chain = GraspSafetyEvaluator(arm7).ik.chain
    inertias = sample_inertia_perturbations(BOX, InertiaUncertainty(0.2)).inertias
    tolerance = mass_tolerance(arm7, evaluations, grasps)
    compiled = perturbed_effective_masses(
        arm7,
        chain,
        inertias,
        [grasps[k].transform_tip_to_object for k in picks],
        [evaluations[k].joint_positions[:n] for k, n in zip(picks, lengths, strict=True)],
        [evaluations[k].directions_in_base[:n] for k, n in zip(picks, lengths, strict=True)],
        [evaluations[k].direction_is_worst_case[:n] for k, n in zip(picks, lengths, strict=True)],
    )
    for k, n, masses in zip(picks, lengths, compiled, strict=True):
        reference = effective_mass_for_inertias(arm7, evaluations[k], grasps[k], inertias)
        assert_close_to_scale(masses, reference[:, :n], f"grasp {k}, {n} samples", tolerance)


@needs_numba
def test_compiled_armature_range_equals_pinocchio(geared_arm: RobotModel) -> None:
    grasps, evaluations = ranked_case(geared_arm, 25)
    lower = 0.5 * geared_arm.armature_kgm2
    upper = 2.0 * geared_arm.armature_kgm2
    reference = analyse_armature_range(geared_arm, evaluations, grasps, BOX, lower, upper)
    compiled = analyse_armature_range(
        geared_arm, evaluations, grasps, BOX, lower, upper, compiled=True
    )
    feasible = [e.feasible for e in evaluations]
    tolerance = mass_tolerance(geared_arm, evaluations, grasps)  # armatures x2 at most
    for field in ("effective_mass_range_kg", "scores_lower", "scores_upper"):
        ours, theirs = getattr(compiled, field), getattr(reference, field)
        np.testing.assert_array_equal(np.isnan(ours), np.isnan(theirs))
        assert_close_to_scale(ours[feasible], theirs[feasible], field, tolerance)
    assert (compiled.order_lower, compiled.order_upper) == (
        reference.order_lower,
        reference.order_upper,
    )


def test_row_aggregates_are_the_per_row_aggregates() -> None:
    """Bit for bit: numpy reduces each row as it reduces the row alone."""
    rng = np.random.default_rng(5)
    masses = rng.uniform(0.5, 30.0, (37, 201))
    times = np.cumsum(rng.uniform(0.005, 0.02, 201))
    for metric in ("mean", "max", "integral"):
        expected = [aggregate(row, times, metric) for row in masses]
        np.testing.assert_array_equal(_aggregate_rows(masses, times, metric), expected)
    np.testing.assert_array_equal(_aggregate_rows(masses[:, :1], times[:1], "integral"), 0.0)


def test_spatial_inertias_in_tip_are_pinocchios() -> None:
    """Y in the tip frame: Pinocchio's SE3.act of the object's spatial inertia, as a matrix."""
    rng = np.random.default_rng(6)
    inertias = sample_inertia_perturbations(BOX, UNCERTAINTY).inertias[:5]
    grasps = [pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.1) for _ in range(3)]
    ours = spatial_inertias_in_tip(
        inertias,
        np.array([g.rotation for g in grasps]),
        np.array([g.translation for g in grasps]),
    )
    for p, inertia in enumerate(inertias):
        for g, grasp in enumerate(grasps):
            expected = grasp.inverse().act(inertia.spatial_inertia_in_object()).matrix()
            # A rigid motion of a spatial inertia (condition 1): k = 16 roundings of the 3x3
            # products and the parallel-axis sums.
            tolerance = rounding_tolerance(1.0, 16)
            assert_close_to_scale(ours[p, g], expected, f"inertia {p}, grasp {g}", tolerance)


@needs_numba
def test_thread_pool_gives_the_serial_masses_bit_for_bit(arm7: RobotModel) -> None:
    from concurrent.futures import ThreadPoolExecutor

    grasps, evaluations = ranked_case(arm7, 26)
    feasible = [k for k, e in enumerate(evaluations) if e.feasible]
    picks = [feasible[j % len(feasible)] for j in range(3 * GRASP_CHUNK + 1)]
    inertias = sample_inertia_perturbations(BOX, UNCERTAINTY).inertias
    args = (
        arm7,
        GraspSafetyEvaluator(arm7).ik.chain,
        inertias,
        [grasps[k].transform_tip_to_object for k in picks],
        [evaluations[k].joint_positions for k in picks],
        [evaluations[k].directions_in_base for k in picks],
        [evaluations[k].direction_is_worst_case for k in picks],
    )
    serial = perturbed_effective_masses(*args)
    with ThreadPoolExecutor(max_workers=3) as pool:
        pooled = perturbed_effective_masses(*args, executor=pool)
    assert len(pooled) == len(picks)
    for ours, theirs in zip(pooled, serial, strict=True):
        np.testing.assert_array_equal(ours, theirs)


def test_six_by_six_solve_pivots_and_equals_numpy() -> None:
    """The kernel's LU of I + Y A (row swaps included) solves as numpy does, for spatial
    inertias Y and mobilities A from light to heavy (Y A up to ~1e3, where rows must swap)."""
    from grasp_safety_ros.core.kernels import uncertainty as kernels

    factor = getattr(kernels._factor_system, "py_func", kernels._factor_system)
    solve = getattr(kernels._solve_factored, "py_func", kernels._solve_factored)
    rng = np.random.default_rng(7)
    swapped = 0
    for trial in range(200):
        root = rng.normal(size=(6, 6))
        mobility = root @ root.T * 10.0 ** rng.uniform(-2, 2)
        inertia = pin.Inertia(
            10.0 ** rng.uniform(-1, 1.5),
            rng.normal(size=3) * 0.2,
            np.diag(rng.uniform(0.01, 1, 3)),
        ).matrix()
        system, pivots = np.empty((6, 6)), np.empty(6, dtype=np.int64)
        factor(mobility, inertia, system, pivots)
        swapped += int(np.any(pivots != np.arange(6)))
        rhs = rng.normal(size=6)
        expected = np.linalg.solve(np.eye(6) + inertia @ mobility, rhs)
        solve(system, pivots, rhs)
        # LU with partial pivoting vs LAPACK's: both backward stable, so within
        # cond · eps; k = 2 · 6 (the rows' eliminations and substitutions).
        tolerance = rounding_tolerance(np.linalg.cond(np.eye(6) + inertia @ mobility), 12)
        assert_close_to_scale(rhs, expected, f"trial {trial}", tolerance)
    assert swapped > 20
