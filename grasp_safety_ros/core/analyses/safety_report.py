"""One safety report per request: the paper's ranking plus the analyses beyond it.

Combines, on top of GraspSafetyEvaluator.rank: effective mass at exposed object points
(``metric_point``), ISO/TS 15066 power and force limiting, inertia uncertainty, grasp quality
(weighted sum + Pareto set), null-space redundancy resolution, joint effort and the whole
arm's exposure. ``analyse`` is the analyses stage of ``core.pipeline.run_pipeline`` (after the
ranking and posture selection), which every adapter calls: a loop over the registered
analyses (``registry.ANALYSES``, each an ``Analysis`` of ``base``) that the options want; the
adapters serialise the SafetyReport it returns.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..exceptions import InvalidInputError
from ..method.ranking import Grasp, GraspSafetyEvaluator, Ranking
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import Trajectory
from .analysis_options import RANK_BY as RANK_BY
from .analysis_options import AnalysisOptions as AnalysisOptions
from .base import Parts, Shared
from .effort import EffortEvaluation, order_by_effort
from .exposed_points import ExposedPointsEvaluation
from .iso15066 import PowerForceLimitAssessment
from .multi_objective import QualityRanking, rank_with_quality
from .redundancy import RedundancyResolution
from .registry import ANALYSES
from .retime import RetimedMotion
from .safe_duration import SafeDurationPostureCriterion, standard_mass_estimate_kg
from .uncertainty import ArmatureRangeAnalysis, UncertaintyAnalysis
from .whole_arm import (
    ArmSites,
    WholeArmEvaluation,
    WholeArmPostureCriterion,
    order_by_whole_arm,
    resolve_arm_sites,
)


def posture_criterion(
    robot: RobotModel, options: AnalysisOptions
) -> WholeArmPostureCriterion | SafeDurationPostureCriterion | None:
    """What posture selection (core.method.posture) minimises for ``options``: with
    ``rank_by: whole_arm`` the whole arm's worst force for ``whole_arm_region`` over its sites
    (the defaults and ``arm_points_m``), with ``safe_duration`` the retimed duration, the
    criterion that ranks; else None (the tip score)."""
    if options.rank_by == "whole_arm":
        sites = resolve_arm_sites(robot, options.arm_points_m)
        return WholeArmPostureCriterion(sites, options.whole_arm_region)
    if options.rank_by == "safe_duration" and options.retime is not None:  # (it must be set)
        return SafeDurationPostureCriterion(
            options.retime,
            resolve_arm_sites(robot, options.arm_points_m),
            options.points_in_object_m,
            None if options.iso_regions is None else tuple(options.iso_regions),
        )
    return None


@dataclass(frozen=True)
class SafetyReport:
    """Everything computed for one set of candidates; per-grasp tuples in candidate order.

    Attributes:
        ranking: The paper's tip ranking (nominal inertia, no redundancy).
        options: The options used.
        scores: Safety score per grasp with the chosen metric point (and redundancy, if on);
            NaN for infeasible grasps.
        safety_order: Feasible grasps by ``scores``, safest first.
        order: The final order (safety, the safety/quality combination, or effort).
        exposed: Exposed-point evaluations, when points were given.
        iso: ISO/TS 15066 assessment per grasp (on the metric point's mass and speed).
        uncertainty: Inertia-uncertainty analysis, when bounds were given.
        quality: Safety/quality combination and Pareto set (pure safety when no quality).
        redundancy: Null-space resolution per grasp, when on.
        effort: Joint effort per grasp, when on.
        whole_arm: Exposure of the arm's sites per grasp, when on.
        arm_sites: The sites assessed (resolved once per report), when on.
        armature_range: Effective masses and ranking at both ends of armature ranges, when
            the armature was given as ranges (uncertainty.analyse_armature_range).
        retimed: Each grasp's motion retimed to the site speed limits (None: infeasible or
            no timing found), when ``options.retime`` is set (core.pipeline's RetimeStage,
            which also sets ``order`` under ``rank_by: safe_duration``).
        retime_reasons: Why each grasp has no retimed motion ("" where it has one).
        standard_mass_estimate_kg: ISO/TS 15066's m_R = M/2 + m_L [kg] (safe_duration).
    """

    ranking: Ranking
    options: AnalysisOptions
    scores: np.ndarray
    safety_order: tuple[int, ...]
    order: tuple[int, ...]
    quality: QualityRanking
    iso: tuple[PowerForceLimitAssessment, ...] = ()
    exposed: tuple[ExposedPointsEvaluation, ...] = ()
    uncertainty: UncertaintyAnalysis | None = None
    redundancy: tuple[RedundancyResolution, ...] = ()
    effort: tuple[EffortEvaluation, ...] = ()
    whole_arm: tuple[WholeArmEvaluation, ...] = ()
    arm_sites: ArmSites | None = None
    armature_range: ArmatureRangeAnalysis | None = None
    retimed: tuple[RetimedMotion | None, ...] = ()
    retime_reasons: tuple[str, ...] = ()
    standard_mass_estimate_kg: float = float("nan")


def analyse(
    evaluator: GraspSafetyEvaluator,
    grasps: Sequence[Grasp],
    object_inertia: ObjectInertia,
    trajectory: Trajectory,
    options: AnalysisOptions | None = None,
    seed_positions: Sequence[float] | np.ndarray | None = None,
    metric: str | None = None,
    ranking: Ranking | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SafetyReport:
    """Rank the grasps (unless ``ranking`` is given) and run the analyses ``options`` ask for
    (``registry.ANALYSES``, in order, on values they share: ``base.Shared``).

    Args:
        progress: Called as ``progress(done, total)`` after each unit of work (one grasp of
            one analysis); it may raise to abandon the analysis.
    """
    options = options or AnalysisOptions()
    if options.grasp_quality is not None and len(options.grasp_quality) != len(grasps):
        raise InvalidInputError(
            "grasp_quality",
            f"must have one value per grasp ({len(grasps)}), got {len(options.grasp_quality)}",
        )
    if ranking is None:
        ranking = evaluator.rank(grasps, object_inertia, trajectory, seed_positions, metric)
    wanted = [analysis for analysis in ANALYSES if analysis.wanted(options)]
    total = sum(analysis.units(len(grasps)) for analysis in wanted)
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    shared = Shared(
        evaluator,
        grasps,
        object_inertia,
        [evaluator.trajectory_for(g, trajectory) for g in grasps],
        options,
        ranking.evaluations,
        ranking.metric,
        keepers=[analysis.name for analysis in wanted if analysis.keeps_terms],
        step=step,
        optional={name for analysis in wanted for name in analysis.optional_terms},
    )
    try:
        for analysis in wanted:
            analysis.prepare(shared)
        parts = Parts()
        for analysis in wanted:
            parts = analysis.run(shared, parts)
    finally:
        shared.release()  # at once: what ran ahead refers to shared
    quality = rank_with_quality(
        parts.scores,
        None if options.grasp_quality is None else np.array(options.grasp_quality),
        options.safety_weight if options.grasp_quality is not None else 1.0,
    )
    return SafetyReport(
        ranking=ranking,
        options=options,
        order=_final_order(options, parts, quality),
        quality=quality,
        standard_mass_estimate_kg=standard_mass_estimate_kg(
            evaluator.robot, object_inertia.mass_kg
        ),
        **parts.report_fields(),  # scores, safety_order and each analysis's result, by name
    )


def _final_order(
    options: AnalysisOptions, parts: Parts, quality: QualityRanking
) -> tuple[int, ...]:
    """The report's order: by effort or the whole arm when ranked by them, else by the
    safety/quality combination when qualities were given, else by safety."""
    if options.rank_by == "effort":
        return order_by_effort(parts.effort, options.effort_criterion)
    if options.rank_by == "whole_arm":
        return order_by_whole_arm(parts.whole_arm, options.whole_arm_region)
    if options.grasp_quality is not None:
        return quality.order
    return parts.safety_order
