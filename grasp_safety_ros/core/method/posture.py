"""Posture selection: search the arm's redundancy for the start posture with the lowest score.

For a redundant arm (or an arm with several IK branches) one tip pose has many joint
solutions, and the effective mass depends on which one the arm is in. The paper (and
``GraspSafetyEvaluator.rank``) follows one IK solution, from one seed. Here, per grasp:

1. the single IK of the paper: the evaluation from the configured seed (restart 0);
2. ``restarts`` more IK solutions of the tip pose at the first sample, from deterministic
   seeds: a scrambled Halton sequence (seeded by ``seed``) within the joint limits
   ([-pi, pi] for unlimited joints). A start posture within ``duplicate_tolerance_rad``
   (inf-norm) of one already found is not followed again;
3. each distinct start posture followed along the whole trajectory with the evaluator's own
   warm start (``GraspSafetyEvaluator.evaluate_batch`` seeded with it: sample 0 converges at
   once, in 0 iterations, to that posture), and scored;
4. the feasible one with the lowest score is kept (ties: the earliest, so the single IK).

A ``PostureCriterion`` may replace the score in step 4 (core.analyses.whole_arm's, with
``rank_by: whole_arm``: the worst predicted force over the arm's points); the single IK is
among the candidates and kept on ties, so the kept posture is never worse than the single IK
by the criterion used.

The null-space refinement (core.analyses.redundancy, when enabled) then starts from the kept
posture. A grasp is infeasible only when no start posture gives a feasible trajectory.
``restarts=0`` returns the ranking unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..model.inertia import ObjectInertia
from ..model.trajectory import ObjectTrajectory
from .pool import evaluate_jobs, executor_for
from .ranking import (
    BATCH_GRASPS,
    GraspSafetyEvaluator,
    SampledTrajectory,
    order_by_score,
    sample_trajectory,
)
from .results import SCORE_CRITERION, Grasp, GraspEvaluation, PostureSelection, Ranking

MAX_RESTARTS = 1000
"""Largest number of posture restarts accepted per grasp."""

DEFAULT_RESTARTS = 8
"""Default restarts of the CLI and the node (docs/analyses.md, "Posture selection")."""


@dataclass(frozen=True)
class PostureConfig:
    """Settings of posture selection.

    Attributes:
        restarts: Start postures tried besides the single IK's, in [0, MAX_RESTARTS];
            0: the paper's single IK only (the ranking is returned unchanged).
        seed: Seed of the scrambled Halton sequence of the IK seeds (repeatable results).
        duplicate_tolerance_rad: Start postures closer than this (largest joint difference)
            [rad or m] to one already found are not followed again.
    """

    restarts: int = 0
    seed: int = 0
    duplicate_tolerance_rad: float = 1e-3

    def __post_init__(self) -> None:
        for name, value, top in (
            ("posture.restarts", self.restarts, MAX_RESTARTS),
            ("posture.seed", self.seed, 2**32 - 1),
        ):
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= top:
                raise InvalidInputError(name, f"must be an integer in [0, {top}], got {value!r}")
        tolerance = self.duplicate_tolerance_rad
        if not (
            isinstance(tolerance, (int, float))
            and not isinstance(tolerance, bool)
            and np.isfinite(tolerance)
            and tolerance > 0
        ):
            raise InvalidInputError(
                "posture.duplicate_tolerance_rad",
                f"must be a finite number > 0, got {tolerance!r}",
            )


class PostureCriterion(Protocol):
    """What posture selection minimises instead of the tip score (lower is better).

    Picklable (a frozen dataclass of a module-level class) so a process pool can run it.
    """

    @property
    def name(self) -> str:
        """Short name recorded in PostureSelection.criterion, e.g. ``whole_arm:chest``."""
        ...

    def __call__(
        self,
        evaluator: Any,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        trajectory: ObjectTrajectory,
        evaluations: Sequence[GraspEvaluation],
    ) -> np.ndarray:
        """One finite value per (feasible) evaluation of ``grasp``, in their order."""
        ...


def restart_seeds(evaluator: GraspSafetyEvaluator, config: PostureConfig) -> np.ndarray:
    """The (restarts, n) IK seeds of posture selection [rad or m], chain order, deterministic."""
    robot = evaluator.robot
    if config.restarts == 0:
        return np.empty((0, robot.num_joints))
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    from scipy.stats import qmc  # scipy.stats takes ~0.5 s to import: only when restarting

    unit = qmc.Halton(d=robot.num_joints, scramble=True, seed=config.seed).random(config.restarts)
    return lower + unit * (upper - lower)


def single_posture(evaluation: GraspEvaluation, restarts: int = 0) -> PostureSelection:
    """The selection record of an evaluation from the single IK alone."""
    feasible = evaluation.feasible
    return PostureSelection(
        index=evaluation.index,
        restarts=restarts,
        score=evaluation.score,
        score_single_ik=evaluation.score,
        score_range=(evaluation.score, evaluation.score),
        start_positions=np.array(evaluation.joint_positions[0]) if feasible else np.empty(0),
        postures_tried=1,
        postures_feasible=int(feasible),
        selected=0 if feasible else -1,
        criterion_value=evaluation.score,
        criterion_single_ik=evaluation.score,
    )


def select_posture(
    evaluator: GraspSafetyEvaluator,
    grasp: Grasp,
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory,
    single_ik: GraspEvaluation,
    config: PostureConfig,
    metric: str,
    seeds: np.ndarray | None = None,
    sampled: SampledTrajectory | None = None,
    criterion: PostureCriterion | None = None,
) -> tuple[GraspEvaluation, PostureSelection]:
    """The lowest-score posture of one grasp (module docstring); a grasp with a planned joint
    trajectory keeps its posture (``single_ik``).

    Args:
        single_ik: The grasp's evaluation from the configured seed (the paper's single IK).
        metric: The score's aggregate (the single IK's).
        seeds: ``restart_seeds(evaluator, config)``, when already computed.
        sampled: ``sample_trajectory(trajectory)``, when already computed.
        criterion: What to minimise instead of the score; None: the score.

    Returns:
        The kept evaluation (``single_ik`` itself when nothing scores lower) and the record.
    """
    if grasp.joint_trajectory is not None:  # a planned motion: its posture is given
        return single_ik, single_posture(single_ik)
    if seeds is None:
        seeds = restart_seeds(evaluator, config)
    if sampled is None:
        sampled = sample_trajectory(trajectory)
    robot, solver = evaluator.robot, evaluator.ik
    start_tip_in_base = trajectory.transform_object_to_base_start * pin.SE3(
        grasp.transform_tip_to_object
    )
    tolerance = config.duplicate_tolerance_rad
    found: list[np.ndarray] = []
    if single_ik.feasible:
        found.append(np.asarray(single_ik.joint_positions[0], dtype=float))
    converged_any = single_ik.feasible
    for seed in seeds:
        q, converged, _ = solver.solve(start_tip_in_base, robot.q_from_positions(seed))
        if not converged:
            continue
        converged_any = True
        positions = robot.positions_from_q(q)
        if any(np.max(np.abs(positions - other)) < tolerance for other in found):
            continue
        found.append(positions)
    starts = found[1:] if single_ik.feasible else found  # the single IK's is evaluated
    candidates = [single_ik]
    for first in range(0, len(starts), BATCH_GRASPS):  # new start postures, in kernel batches
        batch = starts[first : first + BATCH_GRASPS]
        candidates += evaluator.evaluate_batch(
            [single_ik.index] * len(batch),
            [grasp] * len(batch),
            object_inertia,
            sampled,
            metric,
            np.array([robot.q_from_positions(positions) for positions in batch]),
        )
    feasible = [k for k, e in enumerate(candidates) if e.feasible]
    if not feasible:
        tried = len(seeds) + 1
        detail = "" if converged_any else ", none reached the start pose"
        reason = (
            f"no feasible posture from {tried} IK seeds{detail}; single IK: {single_ik.reason}"
        )
        return replace(single_ik, reason=reason), PostureSelection(
            index=single_ik.index,
            restarts=config.restarts,
            score=float("nan"),
            score_single_ik=float("nan"),
            score_range=(float("nan"), float("nan")),
            start_positions=np.empty(0),
            postures_tried=len(candidates),
            postures_feasible=0,
            selected=-1,
            criterion=SCORE_CRITERION if criterion is None else criterion.name,
        )
    scores = np.array([candidates[k].score for k in feasible])
    values = scores
    if criterion is not None:
        feasible_candidates = [candidates[k] for k in feasible]
        values = np.asarray(
            criterion(evaluator, grasp, object_inertia, trajectory, feasible_candidates),
            dtype=float,
        )
        if values.shape != scores.shape or not np.all(np.isfinite(values)):
            raise InvalidInputError(
                "posture.criterion",
                f"{criterion.name} must give one finite value per posture, got {values!r}",
            )
    chosen_k = int(np.argmin(values))  # argmin keeps the first of equal values
    best = feasible[chosen_k]
    chosen = candidates[best] if best == 0 else _detached(candidates[best])
    return chosen, PostureSelection(
        index=single_ik.index,
        restarts=config.restarts,
        score=chosen.score,
        score_single_ik=single_ik.score,
        score_range=(float(scores.min()), float(scores.max())),
        start_positions=np.array(chosen.joint_positions[0]),
        postures_tried=len(candidates),
        postures_feasible=len(feasible),
        selected=best,
        criterion=SCORE_CRITERION if criterion is None else criterion.name,
        criterion_value=float(values[chosen_k]),
        criterion_single_ik=float(values[0]) if single_ik.feasible else math.nan,
    )


def select_postures(
    evaluator: GraspSafetyEvaluator,
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory,
    ranking: Ranking,
    config: PostureConfig,
    progress: Callable[[int, int], None] | None = None,
    criterion: PostureCriterion | None = None,
) -> Ranking:
    """Posture selection on every grasp of ``ranking`` (from ``evaluator.rank`` on the same
    grasps, inertia and trajectory); re-ranked by the kept postures' scores.

    Returns:
        A Ranking whose ``postures`` holds one PostureSelection per grasp; with
        ``config.restarts == 0`` the same evaluations and order (the paper's single IK).

    Args:
        progress: Called as ``progress(done, total)`` after each grasp; it may raise.
        criterion: What each grasp's posture minimises; None: its score (select_posture).
    """
    grasps = list(grasps)
    if len(grasps) != len(ranking.evaluations):
        raise InvalidInputError(
            "grasps", f"must match the ranking's {len(ranking.evaluations)} evaluations"
        )
    if config.restarts == 0:
        postures = tuple(single_posture(e) for e in ranking.evaluations)
        return replace(ranking, postures=postures)
    seeds = restart_seeds(evaluator, config)
    sampled = sample_trajectory(trajectory)  # once for every grasp and posture
    jobs = [
        (
            grasp,
            object_inertia,
            trajectory,
            single_ik,
            config,
            ranking.metric,
            seeds,
            sampled,
            criterion,
        )
        for grasp, single_ik in zip(grasps, ranking.evaluations, strict=True)
    ]
    # Work estimate: every grasp followed from up to restarts + 1 postures.
    executor = executor_for(evaluator, len(grasps) * len(sampled.times_s) * (len(seeds) + 1))
    results = (
        (select_posture(evaluator, *job) for job in jobs)
        if executor is None
        else evaluate_jobs(evaluator, executor, jobs, select_posture)
    )
    evaluations: list[GraspEvaluation] = []
    selections: list[PostureSelection] = []
    try:
        for evaluation, selection in results:
            evaluations.append(evaluation)
            selections.append(selection)
            if progress is not None:
                progress(len(evaluations), len(grasps))
    finally:
        results.close()  # progress raised: stop the work still queued
    return replace(
        ranking,
        order=order_by_score(evaluations),
        evaluations=tuple(evaluations),
        postures=tuple(selections),
    )


def _detached(evaluation: GraspEvaluation) -> GraspEvaluation:
    """The evaluation with its per-sample arrays copied: a kept posture must not hold the
    kernel buffers of every candidate of its batch (the links-only masses are the masses
    themselves without armature: one copy for both then)."""
    masses = np.array(evaluation.effective_mass_kg)
    links_only = evaluation.links_only_effective_mass_kg
    return replace(
        evaluation,
        joint_positions=np.array(evaluation.joint_positions),
        directions_in_base=np.array(evaluation.directions_in_base),
        effective_mass_kg=masses,
        links_only_effective_mass_kg=(
            masses if links_only is evaluation.effective_mass_kg else np.array(links_only)
        ),
        direction_is_worst_case=np.array(evaluation.direction_is_worst_case),
        tip_speed_m_s=np.array(evaluation.tip_speed_m_s),
        ik_iterations=np.array(evaluation.ik_iterations),
    )
