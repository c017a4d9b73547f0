"""Posture selection: search the arm's redundancy for the start posture with the lowest score.

For a redundant arm (or an arm with several IK branches) one tip pose has many joint
solutions, and the effective mass depends on which one the arm is in. The paper (and
``GraspSafetyEvaluator.rank``) follows one IK solution, from one seed. Here, per grasp:

1. the single IK of the paper: the evaluation from the configured seed (restart 0);
2. ``restarts`` more IK solutions of the tip pose at the first sample, from deterministic
   seeds: a scrambled Halton sequence (seeded by ``seed``; ``scrambled_halton``, the points
   of scipy's ``qmc.Halton``) within the joint limits ([-pi, pi] for unlimited joints), all
   grasps and seeds of a batch in one kernel call. A start posture within
   ``duplicate_tolerance_rad`` (inf-norm) of one already found is not followed again;
3. each distinct start posture followed along the whole trajectory with the evaluator's own
   warm start (seeded with it: sample 0 converges at once, in 0 iterations, to that
   posture), and scored; the postures of all grasps of a batch in one kernel call
   (``GraspSafetyEvaluator.follow_postures``). With ``early_stop`` (the default; selecting
   by the score), the first FIRST_WAVE new postures of all grasps are followed together,
   then the rest, and a posture is stopped as soon as a lower bound of its score (the
   running max, or the running weighted sum, of its effective masses, all > 0, widened by
   the sums' rounding) exceeds the lowest score of its grasp's feasible postures so far (the
   single IK's and the first wave's): it could only lose;
4. the feasible one with the lowest score is kept (ties: the earliest, so the single IK).

Never worse than the single IK, with or without the early stop: when the single IK is
feasible it is candidate 0, so the minimum over the candidates is at most its score, and on
equal scores argmin keeps the earliest, the single IK itself. The early stop changes no
choice: a stopped posture scores strictly above a feasible posture already found, so it is
neither the minimum nor the first of equal minima, and a posture that is not stopped is the
one the full evaluation gives, bit for bit (property tests: of ``_choose`` over arbitrary
candidates, ``test_posture_choice.py``; over random arms, grasps and metrics with the stop on
and off, ``test_posture.py``). It changes the record only: a stopped posture counts as tried and as
stopped (``PostureSelection.postures_stopped``, in every output that shows the counts), not
as feasible, and is not in the score range (the range of the postures followed to the end).

A ``PostureCriterion`` may replace the score in step 4 (core.analyses.whole_arm's, with
``rank_by: whole_arm``: the worst predicted force over the arm's points); the single IK is
among the candidates and kept on ties, so the kept posture is never worse than the single IK
by the criterion used.

The null-space refinement (core.analyses.redundancy, when enabled) then starts from the kept
posture. A grasp is infeasible only when no start posture gives a feasible trajectory.
``restarts=0`` returns the ranking unchanged.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectTrajectory
from ..model.waypoint_trajectory import WaypointTrajectory
from .halton import scrambled_halton
from .pool import evaluate_jobs, executor_for, job_ranges
from .ranking import (
    BATCH_GRASPS,
    GraspSafetyEvaluator,
    SampledTrajectory,
    order_by_score,
    sample_trajectory,
)
from .results import (
    SCORE_CRITERION,
    FollowedPosture,
    Grasp,
    GraspEvaluation,
    PostureSelection,
    Ranking,
)

MAX_RESTARTS = 1000
"""Largest number of posture restarts accepted per grasp."""

DEFAULT_RESTARTS = 8
"""Default restarts everywhere (core.options; docs/analyses.md, "Posture selection")."""

MAX_RESTART_ITERATIONS = 10_000
"""Largest ``PostureConfig.restart_iterations``."""

FOLLOW_ROWS = 64
"""Start postures per kernel call in ``select_posture_batch`` (bounds its buffers: ~45 floats
per posture and sample)."""

FIRST_WAVE = 2
"""With the early stop, each grasp's first FIRST_WAVE new postures are followed first (against
the single IK's score), then the rest together (against the best so far): two kernel calls
per batch whatever the restarts. One wave per posture rank (up to ``restarts`` kernel calls)
would follow 0.15 % fewer samples (simulated from every posture's per-sample masses on
bench/postures.py's Panda and Baxter workloads, 20 grasps, 8 restarts), less than the
calls cost."""


@dataclass(frozen=True)
class PostureConfig:
    """Settings of posture selection.

    Attributes:
        restarts: Start postures tried besides the single IK's, in [0, MAX_RESTARTS];
            0: the paper's single IK only (the ranking is returned unchanged); default
            DEFAULT_RESTARTS.
        seed: Seed of the scrambled Halton sequence of the IK seeds (repeatable results).
        duplicate_tolerance_rad: Start postures closer than this (largest joint difference)
            [rad or m] to one already found are not followed again.
        early_stop: Stop following a start posture as soon as its score certainly exceeds
            that of a posture of the same grasp already found (module docstring): the same
            kept posture bit for bit, a record that counts it as stopped
            (``PostureSelection.postures_stopped``) instead of feasible or not. On by
            default; off: every posture followed to the end (the full ``score_range``, as
            the MuJoCo validation's study of the range uses). It saves little (a few % of
            posture selection's time, docs/performance_pipeline.md), as the postures' scores
            differ by a few percent, so a lower bound of a worse one exceeds the best only
            near the end.
        restart_iterations: Largest Gauss-Newton iterations of each restart's IK at the
            start pose, in [1, MAX_RESTART_ITERATIONS]; None (default): the IK's own
            ``ik.max_iterations`` (100), the selection as before. Fewer drop the seeds that
            converge slowly, which changes the selection of some grasps: measured in
            docs/performance_pipeline.md ("Posture selection"), a product decision.
        restart_stall_iterations: k in [1, MAX_RESTART_ITERATIONS]: each restart's IK gives
            up when k iterations cut its error by less than ``packed.STALL_RATIO`` (10 %)
            (IKSettings.stall_iterations); None (default): never, the selection as before.
            Drops fewer slowly converging seeds than ``restart_iterations`` for the same IK
            time (measured as it), also a product decision.
    """

    restarts: int = DEFAULT_RESTARTS
    seed: int = 0
    duplicate_tolerance_rad: float = 1e-3
    early_stop: bool = True
    restart_iterations: int | None = None
    restart_stall_iterations: int | None = None

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
        for name, iterations in (
            ("posture.restart_iterations", self.restart_iterations),
            ("posture.restart_stall_iterations", self.restart_stall_iterations),
        ):
            if iterations is not None and (
                not isinstance(iterations, int)
                or isinstance(iterations, bool)
                or not 1 <= iterations <= MAX_RESTART_ITERATIONS
            ):
                raise InvalidInputError(
                    name,
                    f"must be null or an integer in [1, {MAX_RESTART_ITERATIONS}], "
                    f"got {iterations!r}",
                )
        if not isinstance(self.early_stop, bool):
            raise InvalidInputError(
                "posture.early_stop", f"must be true or false, got {self.early_stop!r}"
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
        evaluator: GraspSafetyEvaluator,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        trajectory: ObjectTrajectory | WaypointTrajectory,
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
    unit = scrambled_halton(robot.num_joints, config.restarts, config.seed)
    seeds: np.ndarray = lower + unit * (upper - lower)
    return seeds


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
    trajectory: ObjectTrajectory | WaypointTrajectory,
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
    if seeds is None:
        seeds = restart_seeds(evaluator, config)
    if sampled is None:
        sampled = sample_trajectory(trajectory)
    (result,) = select_posture_batch(
        evaluator,
        [grasp],
        object_inertia,
        trajectory,
        [single_ik],
        config,
        metric,
        seeds,
        sampled,
        criterion,
    )
    return result


def select_posture_batch(
    evaluator: GraspSafetyEvaluator,
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory | WaypointTrajectory,
    single_iks: Sequence[GraspEvaluation],
    config: PostureConfig,
    metric: str,
    seeds: np.ndarray,
    sampled: SampledTrajectory,
    criterion: PostureCriterion | None = None,
) -> list[tuple[GraspEvaluation, PostureSelection]]:
    """``select_posture`` of several grasps (one job of the worker pool): the restart IK of
    all of them in one kernel call, their new start postures followed in one more."""
    robot = evaluator.robot
    searched = [k for k, grasp in enumerate(grasps) if grasp.joint_trajectory is None]
    starts: dict[int, list[np.ndarray]] = {}
    reached = dict.fromkeys(searched, False)  # a restart converged at the start pose
    nq = robot.model.nq
    q, converged = evaluator.ik.solve_poses(
        [
            trajectory.transform_object_to_base_start * pin.SE3(grasps[k].transform_tip_to_object)
            for k in searched
        ],
        np.array([robot.q_from_positions(seed) for seed in seeds]).reshape(len(seeds), nq),
        config.restart_iterations,
        config.restart_stall_iterations or 0,
    )
    new_starts = _new_start_postures(
        robot, [single_iks[k] for k in searched], q, converged, config.duplicate_tolerance_rad
    )
    for row, k in enumerate(searched):
        reached[k] = bool(converged[row].any())
        starts[k] = new_starts[row]
    followed = _follow(
        evaluator,
        grasps,
        object_inertia,
        sampled,
        single_iks,
        config,
        metric,
        [(k, starts[k]) for k in searched],
        criterion is None,
    )
    results = []
    for k, (grasp, single_ik) in enumerate(zip(grasps, single_iks, strict=True)):
        if k not in starts:  # a planned motion: its posture is given
            results.append((single_ik, single_posture(single_ik)))
            continue
        results.append(
            _choose(
                evaluator,
                (grasp, object_inertia, trajectory),
                single_ik,
                followed[k],
                (config, len(seeds) + 1, single_ik.feasible or reached[k]),
                criterion,
            )
        )
    return results


def _new_start_postures(
    robot: RobotModel,
    single_iks: Sequence[GraspEvaluation],
    q: np.ndarray,
    converged: np.ndarray,
    tolerance: float,
) -> list[list[np.ndarray]]:
    """Each grasp's start postures (chain order) to follow: those of its converged restarts
    (q (G, R, nq), converged (G, R)), in restart order, but each within ``tolerance``
    (largest joint difference) of the single IK's (when feasible) or of one kept before it.

    The differences of all pairs of a grasp's postures come from one array operation for
    every grasp; a posture is a duplicate when the smallest of its differences to the
    postures kept so far is below ``tolerance`` (NaN: it is not, as numpy's min would have
    it), the same test on the same numbers as one posture at a time.
    """
    count, restarts = converged.shape
    n = robot.num_joints
    candidates = np.zeros((count, restarts + 1, n))  # row 0: the single IK's start posture
    if robot.model.nq == n:  # no continuous joint: the positions are q itself
        candidates[:, 1:] = q
    else:
        for g, r in zip(*np.nonzero(converged), strict=True):
            candidates[g, r + 1] = robot.positions_from_q(q[g, r])
    candidates[:, 1:][~converged] = 0.0  # not followed; keeps the differences finite
    for g, single_ik in enumerate(single_iks):
        if single_ik.feasible:
            candidates[g, 0] = single_ik.joint_positions[0]
    # joints first: the max over them is elementwise, 5x faster than over a short last axis
    by_joint = np.ascontiguousarray(candidates.transpose(2, 0, 1))  # (n, G, R + 1)
    pairs = np.abs(by_joint[:, :, :, None] - by_joint[:, :, None, :])  # (n, G, R + 1, R + 1)
    differences = np.max(pairs, axis=0).tolist()  # largest joint difference [rad or m]
    starts = []
    for g, (single_ik, row) in enumerate(zip(single_iks, converged.tolist(), strict=True)):
        kept = [0] if single_ik.feasible else []
        for i in (r + 1 for r, ok in enumerate(row) if ok):
            to_kept = [differences[g][i][j] for j in kept]
            if to_kept and all(d == d for d in to_kept) and min(to_kept) < tolerance:
                continue  # within the tolerance of a start posture already found
            kept.append(i)
        starts.append([candidates[g, i] for i in kept if i > 0])  # the single IK's is evaluated
    return starts


def _follow(
    evaluator: GraspSafetyEvaluator,
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    sampled: SampledTrajectory,
    single_iks: Sequence[GraspEvaluation],
    config: PostureConfig,
    metric: str,
    starts: list[tuple[int, list[np.ndarray]]],
    by_score: bool,
) -> dict[int, list[FollowedPosture | None]]:
    """Each grasp k's new start postures followed (None: stopped early; each one's
    GraspEvaluation is built on demand), in kernel calls of up to FOLLOW_ROWS postures.

    With the early stop (selecting by the score) the first FIRST_WAVE postures of all grasps
    go in one wave, the rest in a second, and a posture is stopped once its score certainly
    exceeds the lowest score of its grasp's feasible postures so far (the single IK's and the
    first wave's), not just the single IK's: a stopped posture scores above one already
    found, so it is never the argmin (nor the first of equal ones), and the kept posture is
    the one without the stop.
    """
    robot = evaluator.robot
    nq = robot.model.nq
    stopping = config.early_stop and by_score
    best = {
        k: single_iks[k].score if stopping and single_iks[k].feasible else math.inf
        for k, _ in starts
    }
    cuts = (0, FIRST_WAVE, None) if stopping else (0, None)
    rows = [
        [(k, positions) for k, found in starts for positions in found[first:last]]
        for first, last in itertools.pairwise(cuts)
    ]
    followed: dict[int, list[FollowedPosture | None]] = {k: [] for k, _ in starts}
    for wave in rows:
        for first in range(0, len(wave), FOLLOW_ROWS):
            batch = wave[first : first + FOLLOW_ROWS]
            results = evaluator.follow_postures(
                [single_iks[k].index for k, _ in batch],
                [grasps[k] for k, _ in batch],
                object_inertia,
                sampled,
                metric,
                np.array([robot.q_from_positions(p) for _, p in batch]).reshape(len(batch), nq),
                np.array([best[k] for k, _ in batch]),
            )
            for (k, _), result in zip(batch, results, strict=True):
                followed[k].append(result)
                if stopping and result is not None and result.feasible:
                    best[k] = min(best[k], result.score)
    return followed


def _choose(
    evaluator: GraspSafetyEvaluator,
    case: tuple[Grasp, ObjectInertia, ObjectTrajectory | WaypointTrajectory],
    single_ik: GraspEvaluation,
    followed: list[FollowedPosture | None],
    config_tried_reached: tuple[PostureConfig, int, bool],
    criterion: PostureCriterion | None,
) -> tuple[GraspEvaluation, PostureSelection]:
    """The kept posture of one grasp among the single IK's and its ``followed`` start
    postures (None: stopped early) and its record; ``config_tried_reached``: the config, the
    IK seeds tried (restarts + 1) and whether any of them converged at the start pose. Only
    the kept one's GraspEvaluation is built (all the feasible ones' for a criterion)."""
    config, tried, converged_any = config_tried_reached
    candidates = [FollowedPosture.of(single_ik), *followed]
    feasible = [k for k, e in enumerate(candidates) if e is not None and e.feasible]
    if not feasible:
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
            postures_stopped=followed.count(None),
            selected=-1,
            criterion=SCORE_CRITERION if criterion is None else criterion.name,
        )
    kept = [e for e in candidates if e is not None and e.feasible]
    scores = np.array([e.score for e in kept])
    values = scores
    evaluations = None  # built for a criterion only; else the kept one alone
    if criterion is not None:
        evaluations = [e.evaluation() for e in kept]
        values = np.asarray(criterion(evaluator, *case, evaluations), dtype=float)
        if values.shape != scores.shape or not np.all(np.isfinite(values)):
            raise InvalidInputError(
                "posture.criterion",
                f"{criterion.name} must give one finite value per posture, got {values!r}",
            )
    chosen_k = int(np.argmin(values))  # argmin keeps the first of equal values
    best = feasible[chosen_k]
    chosen = single_ik
    if best != 0:
        chosen = _detached(
            kept[chosen_k].evaluation() if evaluations is None else evaluations[chosen_k]
        )
    return chosen, PostureSelection(
        index=single_ik.index,
        restarts=config.restarts,
        score=chosen.score,
        score_single_ik=single_ik.score,
        score_range=(float(scores.min()), float(scores.max())),
        start_positions=np.array(chosen.joint_positions[0]),
        postures_tried=len(candidates),
        postures_feasible=len(feasible),
        postures_stopped=followed.count(None),
        selected=best,
        criterion=SCORE_CRITERION if criterion is None else criterion.name,
        criterion_value=float(values[chosen_k]),
        criterion_single_ik=float(values[0]) if single_ik.feasible else math.nan,
    )


def select_postures(
    evaluator: GraspSafetyEvaluator,
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory | WaypointTrajectory,
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
        progress: Called as ``progress(done, total)`` after each grasp (the grasps of a
            batch, up to BATCH_GRASPS, come together); it may raise.
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
    # Work estimate: every grasp followed from up to restarts + 1 postures.
    executor = executor_for(evaluator, len(grasps) * len(sampled.times_s) * (len(seeds) + 1))
    jobs = [
        (
            grasps[first:stop],
            object_inertia,
            trajectory,
            ranking.evaluations[first:stop],
            config,
            ranking.metric,
            seeds,
            sampled,
            criterion,
        )
        for first, stop in job_ranges(executor, len(grasps), BATCH_GRASPS)
    ]
    batches = (
        (select_posture_batch(evaluator, *job) for job in jobs)
        if executor is None or len(jobs) == 1  # one job: no hand-off to a worker
        else evaluate_jobs(evaluator, executor, jobs, select_posture_batch)
    )
    evaluations: list[GraspEvaluation] = []
    selections: list[PostureSelection] = []
    try:
        for batch in batches:
            for evaluation, selection in batch:
                evaluations.append(evaluation)
                selections.append(selection)
                if progress is not None:
                    progress(len(evaluations), len(grasps))
    finally:
        batches.close()  # progress raised: stop the work still queued
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
