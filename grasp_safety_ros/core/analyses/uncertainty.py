"""Robustness of the grasp ranking to errors in the object's inertia.

The IK does not depend on the object's inertia, so each GraspEvaluation's joint positions are
reused and only the effective mass is recomputed per perturbed inertia. With the object's
spatial inertia Y (6x6, tip frame, Pinocchio's [linear; angular] order) attached to the tip,
the joint-space inertia is M_aug(q) = M(q) + J(q)ᵀ Y J(q) (J: the tip's LOCAL Jacobian), exactly
what core.effective_mass.augmented_model builds, so every perturbation costs one batched
n x n solve per sample. On chains the compiled kernels support (``chain`` given), every
(grasp, sample, perturbation) runs compiled instead (``method.perturbed``: the ranking's own
mass matrix and Cholesky factor once per sample, then one 6 x 6 solve per perturbation, by
J M_aug⁻¹ Jᵀ = A (I + Y A)⁻¹ with A = J M⁻¹ Jᵀ; equal to this reference to rounding).

Uncertainty set (deterministic): the nominal inertia, then the corners of the parameter box
(over the parameters with a non-zero bound), then ``num_random_samples`` points drawn uniformly
in the box with a fixed seed. Parameters, each within ± its bound:
- mass: m' = m (1 + δ_m);
- centre of mass: c' = c + δ_c, per object axis [m];
- inertia: about the nominal principal axes (no rotation), the principal second moments of
  the mass distribution Σ_j = ∫ x_j² dm = (I_k + I_l − I_j)/2 are scaled by (1 + δ_j), j = 1..3,
  and the moments rebuilt as I_j = Σ_k + Σ_l. Every principal moment then stays within
  ± inertia_fraction of its nominal value and the tensor always satisfies the triangle
  inequality (scaling the moments themselves would not: a thin plate has I_3 = I_1 + I_2).
  Any sample that still fails ObjectInertia's checks is skipped and counted (``num_invalid``).
Mass and inertia errors are independent parameters (scaling the mass does not scale the
tensor). Every sample has the same weight; "probability" means fraction of the set.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float
from ..method.backend import Backend
from ..method.packed import ChainArrays
from ..method.perturbed import perturbed_effective_masses
from ..method.ranking import Grasp, GraspEvaluation, aggregate, check_metric
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel

PERTURBATION_CHUNK = 32
"""Perturbations processed per batch (bounds memory to chunk x samples x n x n floats)."""


@dataclass(frozen=True)
class InertiaUncertainty:
    """Bounds of the inertia error and how the uncertainty set is built.

    Attributes:
        mass_fraction: Relative mass error bound, in [0, 1).
        com_offset_m: CoM error bound per object axis [m], >= 0.
        inertia_fraction: Relative error bound of each principal second moment (so of each
            principal moment of inertia), in [0, 1).
        num_random_samples: Uniform samples in the box, >= 0.
        include_corners: Include the 2^d corners of the box (d = parameters with a bound > 0).
        seed: Seed of the random samples.
        percentile: Percentile of the score reported per grasp, in [0, 100].
    """

    mass_fraction: float = 0.0
    com_offset_m: float = 0.0
    inertia_fraction: float = 0.0
    num_random_samples: int = 64
    include_corners: bool = True
    seed: int = 0
    percentile: float = 95.0

    def __post_init__(self) -> None:
        mass = finite_float(self.mass_fraction, "uncertainty.mass_fraction", 0.0)
        if mass >= 1.0:
            raise InvalidInputError(
                "uncertainty.mass_fraction", f"must be in [0, 1), got {mass:g}"
            )
        inertia = finite_float(self.inertia_fraction, "uncertainty.inertia_fraction", 0.0)
        if inertia >= 1.0:
            raise InvalidInputError(
                "uncertainty.inertia_fraction", f"must be in [0, 1), got {inertia:g}"
            )
        com = finite_float(self.com_offset_m, "uncertainty.com_offset_m", 0.0)
        percentile = finite_float(self.percentile, "uncertainty.percentile", 0.0, 100.0)
        for name in ("num_random_samples", "seed"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise InvalidInputError(
                    f"uncertainty.{name}", f"must be an integer >= 0, got {value!r}"
                )
        if not isinstance(self.include_corners, bool):
            raise InvalidInputError(
                "uncertainty.include_corners",
                f"must be true or false, got {self.include_corners!r}",
            )
        object.__setattr__(self, "mass_fraction", mass)
        object.__setattr__(self, "inertia_fraction", inertia)
        object.__setattr__(self, "com_offset_m", com)
        object.__setattr__(self, "percentile", percentile)

    @property
    def bounds(self) -> np.ndarray:
        """Half-widths (7,) of the box: [δ_m, δ_cx, δ_cy, δ_cz [m], δ_Σ1, δ_Σ2, δ_Σ3]."""
        return np.array(
            [self.mass_fraction] + [self.com_offset_m] * 3 + [self.inertia_fraction] * 3
        )


@dataclass(frozen=True)
class PerturbationSet:
    """The perturbed inertias; entry 0 is always the nominal one.

    Attributes:
        inertias: The valid perturbed inertias (nominal first).
        parameters: (P, 7) [δ_m, δ_c (3) [m], δ_Σ (3)] of each inertia.
        kinds: Per inertia "nominal", "corner" or "random".
        num_invalid: Samples skipped because the perturbed tensor was not physically valid.
    """

    inertias: tuple[ObjectInertia, ...]
    parameters: np.ndarray
    kinds: tuple[str, ...]
    num_invalid: int

    def __len__(self) -> int:
        return len(self.inertias)


def perturb_inertia(nominal: ObjectInertia, parameters: Any) -> ObjectInertia:
    """The inertia with parameters [δ_m, δ_c (3) [m], δ_Σ (3)] applied (see the module doc).

    Raises InvalidInputError if the result is not a valid ObjectInertia.
    """
    parameters = finite_array(parameters, "uncertainty.parameters", (7,))
    moments, axes = np.linalg.eigh(nominal.inertia_about_com_kgm2)
    second_moments = (0.5 * moments.sum() - moments) * (1.0 + parameters[4:7])
    perturbed = second_moments.sum() - second_moments
    tensor = axes @ np.diag(perturbed) @ axes.T
    return ObjectInertia(
        nominal.mass_kg * (1.0 + parameters[0]),
        nominal.com_in_object_m + parameters[1:4],
        0.5 * (tensor + tensor.T),
    )


def sample_inertia_perturbations(
    nominal: ObjectInertia, uncertainty: InertiaUncertainty
) -> PerturbationSet:
    """Build the deterministic uncertainty set (nominal, corners, seeded uniform samples)."""
    bounds = uncertainty.bounds
    active = np.flatnonzero(bounds > 0.0)
    candidates: list[tuple[str, np.ndarray]] = [("nominal", np.zeros(7))]
    if len(active):
        if uncertainty.include_corners:
            for signs in itertools.product((-1.0, 1.0), repeat=len(active)):
                parameters = np.zeros(7)
                parameters[active] = np.array(signs) * bounds[active]
                candidates.append(("corner", parameters))
        rng = np.random.default_rng(uncertainty.seed)
        draws = rng.uniform(-1.0, 1.0, (uncertainty.num_random_samples, 7)) * bounds
        candidates.extend(("random", row) for row in draws)
    inertias: list[ObjectInertia] = []
    kept: list[np.ndarray] = []
    kinds: list[str] = []
    invalid = 0
    for kind, parameters in candidates:
        try:
            inertia = nominal if kind == "nominal" else perturb_inertia(nominal, parameters)
        except InvalidInputError:
            invalid += 1
            continue
        inertias.append(inertia)
        kept.append(parameters)
        kinds.append(kind)
    array = np.array(kept)
    array.setflags(write=False)
    return PerturbationSet(tuple(inertias), array, tuple(kinds), invalid)


def effective_mass_for_inertias(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    grasp: Grasp,
    inertias: Sequence[ObjectInertia],
) -> np.ndarray:
    """Effective mass (P, N) [kg] along the evaluation's directions, one row per inertia.

    Uses the evaluation's joint positions and directions; at samples flagged
    direction_is_worst_case the largest effective mass over directions is used instead.
    """
    if not evaluation.feasible:
        raise InvalidInputError("evaluation", f"grasp {evaluation.index} is infeasible")
    model = robot.model
    data = model.createData()
    count, nv = len(evaluation.times_s), model.nv
    mass_matrices = np.empty((count, nv, nv))
    jacobians_tip_local = np.empty((count, 6, nv))
    jacobians_tip_in_base = np.empty((count, 3, nv))
    rotation_base_to_world = robot.transform_base_to_world.rotation
    for i, positions in enumerate(evaluation.joint_positions):
        q = robot.q_from_positions(positions)
        upper = np.triu(pin.crba(model, data, q))
        mass_matrices[i] = upper + np.triu(upper, 1).T
        pin.computeJointJacobians(model, data, q)
        rotation_tip_to_world = pin.updateFramePlacement(model, data, robot.tip_frame_id).rotation
        local = pin.getFrameJacobian(
            model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL
        ).reshape(6, nv)
        jacobians_tip_local[i] = local
        jacobians_tip_in_base[i] = rotation_base_to_world.T @ rotation_tip_to_world @ local[:3]
    transform_object_to_tip = pin.SE3(grasp.transform_tip_to_object).inverse()
    spatial = np.array(
        [transform_object_to_tip.act(i.spatial_inertia_in_object()).matrix() for i in inertias]
    )
    directions = np.asarray(evaluation.directions_in_base, dtype=float)
    worst = np.asarray(evaluation.direction_is_worst_case, dtype=bool)
    result = np.empty((len(inertias), count))
    for start in range(0, len(inertias), PERTURBATION_CHUNK):
        chunk = spatial[start : start + PERTURBATION_CHUNK]
        augmented = mass_matrices[None] + np.einsum(
            "nai,pab,nbj->pnij", jacobians_tip_local, chunk, jacobians_tip_local
        )
        rhs = np.broadcast_to(
            np.swapaxes(jacobians_tip_in_base, 1, 2), (*augmented.shape[:2], nv, 3)
        )
        solved = np.linalg.solve(augmented, rhs)
        mobility = np.einsum("nai,pnib->pnab", jacobians_tip_in_base, solved)
        masses = 1.0 / np.einsum("na,pnab,nb->pn", directions, mobility, directions)
        if worst.any():
            eigenvalues = np.linalg.eigvalsh(
                0.5 * (mobility[:, worst] + np.swapaxes(mobility[:, worst], -1, -2))
            )
            masses[:, worst] = 1.0 / eigenvalues[..., 0]
        result[start : start + len(chunk)] = masses
    return result


def _masses_for_inertias(
    robot: RobotModel,
    chain: ChainArrays | None,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    inertias: Sequence[ObjectInertia],
    executor: Executor | None = None,
) -> list[np.ndarray]:
    """``effective_mass_for_inertias`` of each (feasible) evaluation: compiled for all at once
    when ``chain`` is given (on ``executor``'s threads if given), else the Pinocchio reference
    per grasp."""
    if chain is None:
        return [
            effective_mass_for_inertias(robot, evaluation, grasp, inertias)
            for evaluation, grasp in zip(evaluations, grasps, strict=True)
        ]
    return perturbed_effective_masses(
        robot,
        chain,
        inertias,
        [grasp.transform_tip_to_object for grasp in grasps],
        [evaluation.joint_positions for evaluation in evaluations],
        [evaluation.directions_in_base for evaluation in evaluations],
        [evaluation.direction_is_worst_case for evaluation in evaluations],
        executor,
    )


def _aggregate_rows(masses: np.ndarray, times_s: np.ndarray, metric: str) -> np.ndarray:
    """``aggregate`` of each row of masses (P, N) [kg], as numpy reduces a row on its own."""
    if metric == "mean":
        return masses.sum(axis=1) / masses.shape[1]
    if metric == "max":
        return masses.max(axis=1)
    if masses.shape[1] < 2:
        return np.zeros(len(masses))
    return np.trapezoid(masses, times_s, axis=1)


@dataclass(frozen=True)
class GraspUncertainty:
    """Score of one grasp over the uncertainty set.

    Attributes:
        index, name, feasible: As in the grasp's GraspEvaluation.
        scores: (P,) score per perturbed inertia (entry 0: nominal); empty if infeasible.
        nominal_score: Score with the nominal inertia (NaN if infeasible).
        worst_case_score: Largest score over the set.
        percentile_score: The set's ``percentile`` of the score (numpy's linear interpolation).
        probability_safest: Fraction of the set where this grasp has the lowest score.
        worst_case_sample: Index into the set of the worst case (-1 if infeasible).
    """

    index: int
    name: str
    feasible: bool
    scores: np.ndarray
    nominal_score: float
    worst_case_score: float
    percentile_score: float
    probability_safest: float
    worst_case_sample: int


@dataclass(frozen=True)
class UncertaintyAnalysis:
    """How the ranking holds up over the inertia uncertainty set.

    Attributes:
        metric: Aggregate of the per-sample effective mass (core.ranking.METRICS).
        uncertainty: The bounds and settings used.
        perturbations: The uncertainty set (P inertias).
        grasps: One GraspUncertainty per candidate, in candidate order.
        nominal_safest: Index of the safest grasp with the nominal inertia (-1 if none).
        safest_per_sample: (P,) index of the safest grasp per inertia (ties: lowest index).
        ranking_flips: True when the nominal safest grasp is not the safest for some inertia.
        order_stability: Fraction of the set whose full order equals the nominal order.
        worst_case_order: Feasible grasps sorted by worst-case score (a robust ranking).
        message: One sentence saying whether, and how much, the ranking flips.
    """

    metric: str
    uncertainty: InertiaUncertainty
    perturbations: PerturbationSet
    grasps: tuple[GraspUncertainty, ...]
    nominal_safest: int
    safest_per_sample: np.ndarray
    ranking_flips: bool
    order_stability: float
    worst_case_order: tuple[int, ...]
    message: str


def analyse_inertia_uncertainty(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    uncertainty: InertiaUncertainty | None = None,
    metric: str = "mean",
    chain: ChainArrays | None = None,
    executor: Executor | None = None,
) -> UncertaintyAnalysis:
    """Scores of every grasp over the uncertainty set, worst case, percentile and P(safest).

    ``grasps[i]`` is the grasp of ``evaluations[i]``; ``metric`` should be the one the
    evaluations were ranked with. ``chain``: ``compiled.chain_arrays(robot)`` to run the
    compiled kernel (numba), on the thread pool ``executor`` if given; None: the Pinocchio
    reference.
    """
    check_metric(metric)
    uncertainty = uncertainty or InertiaUncertainty()
    if len(grasps) != len(evaluations):
        raise InvalidInputError(
            "grasps", f"must have one entry per evaluation ({len(evaluations)}), got {len(grasps)}"
        )
    perturbations = sample_inertia_perturbations(object_inertia, uncertainty)
    count = len(perturbations)
    scores = _scores(robot, evaluations, grasps, perturbations, metric, chain, executor)
    feasible = np.array([e.feasible for e in evaluations], dtype=bool)
    safest, order_stability = _safest_per_sample(scores, feasible)
    results = [
        _grasp_uncertainty(evaluation, scores[g], safest == g, uncertainty.percentile)
        for g, evaluation in enumerate(evaluations)
    ]
    nominal_safest = int(safest[0]) if count and feasible.any() else -1
    flips = bool(feasible.any() and np.any(safest != nominal_safest))
    feasible_results = [r for r in results if r.feasible]
    worst_case_order = tuple(
        r.index for r in sorted(feasible_results, key=lambda r: r.worst_case_score)
    )
    safest_array = np.array([evaluations[k].index if k >= 0 else -1 for k in safest])
    safest_array.setflags(write=False)
    nominal_index = evaluations[nominal_safest].index if nominal_safest >= 0 else -1
    return UncertaintyAnalysis(
        metric=metric,
        uncertainty=uncertainty,
        perturbations=perturbations,
        grasps=tuple(results),
        nominal_safest=nominal_index,
        safest_per_sample=safest_array,
        ranking_flips=flips,
        order_stability=order_stability,
        worst_case_order=worst_case_order,
        message=_message(results, nominal_safest, flips, count, perturbations.num_invalid),
    )


def _scores(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    perturbations: PerturbationSet,
    metric: str,
    chain: ChainArrays | None,
    executor: Executor | None,
) -> np.ndarray:
    """(G, S) score of every grasp for every inertia sample; NaN rows for infeasible grasps."""
    scores = np.full((len(evaluations), len(perturbations)), np.nan)
    feasible_indices = [g for g, evaluation in enumerate(evaluations) if evaluation.feasible]
    masses = _masses_for_inertias(
        robot,
        chain,
        [evaluations[g] for g in feasible_indices],
        [grasps[g] for g in feasible_indices],
        perturbations.inertias,
        executor,
    )
    for g, rows in zip(feasible_indices, masses, strict=True):
        scores[g] = _aggregate_rows(rows, evaluations[g].times_s, metric)
    return scores


def _safest_per_sample(scores: np.ndarray, feasible: np.ndarray) -> tuple[np.ndarray, float]:
    """(S,) index of the lowest-scoring feasible grasp per sample (ties: lowest index; -1
    when none is feasible) and the fraction of samples ranking the feasible grasps as the
    nominal sample does (NaN when none is feasible)."""
    if not feasible.any():
        return np.full(scores.shape[1], -1), float("nan")
    masked = np.where(feasible[:, None], scores, np.inf)
    safest = np.argmin(masked, axis=0)  # ties: lowest index
    nominal_order = np.argsort(masked[:, 0], kind="stable")[: int(feasible.sum())]
    orders = np.argsort(masked, axis=0, kind="stable")[: int(feasible.sum())]
    return safest, float(np.mean(np.all(orders == nominal_order[:, None], axis=0)))


def _grasp_uncertainty(
    evaluation: GraspEvaluation, scores: np.ndarray, is_safest: np.ndarray, percentile: float
) -> GraspUncertainty:
    """One grasp's summary over its (S,) ``scores``; ``is_safest``: (S,) where it is safest."""
    if not evaluation.feasible:
        return GraspUncertainty(
            index=evaluation.index,
            name=evaluation.name,
            feasible=False,
            scores=np.empty(0),
            nominal_score=float("nan"),
            worst_case_score=float("nan"),
            percentile_score=float("nan"),
            probability_safest=0.0,
            worst_case_sample=-1,
        )
    row = scores.copy()
    row.setflags(write=False)
    return GraspUncertainty(
        index=evaluation.index,
        name=evaluation.name,
        feasible=True,
        scores=row,
        nominal_score=float(row[0]),
        worst_case_score=float(row.max()),
        percentile_score=float(np.percentile(row, percentile)),
        probability_safest=float(np.mean(is_safest)),
        worst_case_sample=int(np.argmax(row)),
    )


def _message(
    results: Sequence[GraspUncertainty], nominal: int, flips: bool, count: int, invalid: int
) -> str:
    skipped = f" ({invalid} physically invalid samples skipped)" if invalid else ""
    if nominal < 0:
        return "no feasible grasp: nothing to rank"
    best = results[nominal]
    label = f"grasp {best.index}" + (f" '{best.name}'" if best.name else "")
    if not flips:
        return f"ranking stable: {label} is the safest for all {count} inertia samples{skipped}"
    rivals = sorted(
        (r for r in results if r.feasible and r.probability_safest > 0 and r is not best),
        key=lambda r: -r.probability_safest,
    )
    others = ", ".join(
        f"grasp {r.index}" + (f" '{r.name}'" if r.name else "") + f" {r.probability_safest:.0%}"
        for r in rivals
    )
    return (
        f"ranking flips: the nominal safest {label} is the safest for only "
        f"{best.probability_safest:.1%} of {count} inertia samples (also safest: {others})"
        f"{skipped}"
    )


# --- Armature (reflected rotor inertia) ranges ----------------------------------------------


@dataclass(frozen=True)
class ArmatureRangeAnalysis:
    """How the ranking holds up over per-joint armature ranges.

    The joint-space inertia M + diag(a) grows with every armature a_k, so J M⁻¹ Jᵀ shrinks and
    every effective mass grows: over the box of ranges the effective masses (and the mean,
    max or integral scores) are smallest at the lower ends and largest at the upper ends, and
    those two corners bound them exactly.

    Attributes:
        lower_kgm2, upper_kgm2: (n,) the ranges' ends per chain joint [kg m^2, kg prismatic].
        effective_mass_range_kg: (G, 2) per grasp, the smallest (lower ends) and largest
            (upper ends) per-sample effective mass [kg]; NaN if infeasible.
        scores_lower, scores_upper: (G,) scores at the lower and upper ends (NaN infeasible).
        order_lower, order_upper: Feasible grasps by score at each end, safest first.
        ranking_flips: Whether the two orders differ.
        message: One sentence saying so.
    """

    lower_kgm2: np.ndarray
    upper_kgm2: np.ndarray
    effective_mass_range_kg: np.ndarray
    scores_lower: np.ndarray
    scores_upper: np.ndarray
    order_lower: tuple[int, ...]
    order_upper: tuple[int, ...]
    ranking_flips: bool
    message: str


def analyse_armature_range(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    lower_kgm2: np.ndarray,
    upper_kgm2: np.ndarray,
    metric: str = "mean",
    compiled: bool = False,
) -> ArmatureRangeAnalysis:
    """Effective masses and scores at both ends of the armature ranges (the IK does not
    depend on the armature: the evaluations' joint positions are reused). ``compiled``: run
    the compiled kernel where it supports the chain (numba); False: the Pinocchio reference."""
    check_metric(metric)
    ends = (robot.with_armature(lower_kgm2), robot.with_armature(upper_kgm2))
    count = len(evaluations)
    scores = np.full((2, count), np.nan)
    ranges = np.full((count, 2), np.nan)
    feasible_indices = [g for g, evaluation in enumerate(evaluations) if evaluation.feasible]
    for end, chain_robot in enumerate(ends):
        masses = _masses_for_inertias(
            chain_robot,
            Backend.for_robot(chain_robot).chain if compiled else None,
            [evaluations[g] for g in feasible_indices],
            [grasps[g] for g in feasible_indices],
            [object_inertia],
        )
        for g, (row,) in zip(feasible_indices, masses, strict=True):
            scores[end, g] = aggregate(row, evaluations[g].times_s, metric)
            ranges[g, end] = row.min() if end == 0 else row.max()
    orders = []
    for end in range(2):
        feasible = [g for g in range(count) if evaluations[g].feasible]
        orders.append(
            tuple(evaluations[g].index for g in sorted(feasible, key=lambda g: scores[end, g]))
        )
    flips = orders[0] != orders[1]
    message = (
        f"ranking flips over the armature ranges: {list(orders[0])} at the lower ends, "
        f"{list(orders[1])} at the upper ends"
        if flips
        else f"ranking stable over the armature ranges: {list(orders[1])}"
    )
    for array in (scores, ranges):
        array.setflags(write=False)
    return ArmatureRangeAnalysis(
        lower_kgm2=ends[0].armature_kgm2,
        upper_kgm2=ends[1].armature_kgm2,
        effective_mass_range_kg=ranges,
        scores_lower=scores[0],
        scores_upper=scores[1],
        order_lower=orders[0],
        order_upper=orders[1],
        ranking_flips=flips,
        message=message,
    )
