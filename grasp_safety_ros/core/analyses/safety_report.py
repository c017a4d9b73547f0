"""One safety report per request: the paper's ranking plus the analyses beyond it.

Combines, on top of GraspSafetyEvaluator.rank: effective mass at exposed object points
(``metric_point``), ISO/TS 15066 power and force limiting, inertia uncertainty, grasp quality
(weighted sum + Pareto set), null-space redundancy resolution, joint effort and the whole
arm's exposure. ``analyse`` is the analyses stage of ``core.pipeline.run_pipeline`` (after the
ranking and posture selection), which every adapter calls; the adapters serialise the
SafetyReport it returns.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..method.effective_mass import augmented_model
from ..method.pool import executor_for
from ..method.ranking import Grasp, GraspEvaluation, GraspSafetyEvaluator, Ranking, aggregate
from ..method.terms import SampleTerms, grasps_terms
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import Trajectory
from .effort import EffortEvaluation, check_effort_criterion, evaluate_efforts, order_by_effort
from .exposed_points import (
    ExposedPointsEvaluation,
    check_metric_point,
    check_metric_point_has_points,
    check_points_in_object,
    evaluate_exposed_points,
    evaluate_exposed_points_on_terms,
    metric_point_series,
)
from .iso15066 import (
    BODY_REGIONS,
    PowerForceLimitAssessment,
    assess_grasp,
    assess_motions,
    select_regions,
)
from .multi_objective import QualityRanking, rank_with_quality
from .redundancy import RedundancyConfig, RedundancyResolution, resolve_redundancy
from .retime import RetimedMotion
from .safe_duration import RetimeOptions, SafeDurationPostureCriterion, standard_mass_estimate_kg
from .uncertainty import (
    ArmatureRangeAnalysis,
    InertiaUncertainty,
    UncertaintyAnalysis,
    analyse_inertia_uncertainty,
)
from .whole_arm import (
    DEFAULT_RANK_REGION,
    ArmSites,
    WholeArmEvaluation,
    WholeArmPostureCriterion,
    check_exposed_points_m,
    evaluate_whole_arm,
    evaluate_whole_arm_on_terms,
    order_by_whole_arm,
    resolve_arm_sites,
)

TERMS_CHUNK_SAMPLES = 25_000
"""The shared terms are computed for consecutive chunks of feasible grasps of at most this
many samples in all (about 50 MB for a 7-joint arm), so that a request's progress is reported
(and it can be abandoned) chunk by chunk."""

TERMS_CACHE_SAMPLES = 250_000
"""Chunks of terms are kept for the next analysis while those kept hold at most this many
samples (about 500 MB for a 7-joint arm); beyond it the oldest is dropped (then computed
again if an analysis needs it)."""

RANK_BY = ("safety", "effort", "whole_arm", "safe_duration")
"""What orders the final ranking: the safety score (with quality, when given), the effort,
the whole arm's worst predicted force for ``whole_arm_region``, or the retimed duration."""


@dataclass(frozen=True)
class AnalysisOptions:
    """What to compute beyond the tip effective mass (ISO/TS 15066 and effort by default; the
    defaults are core.options.OPTIONS', checked by test/test_options.py).

    Attributes:
        metric_point: ``tip`` (the paper), ``leading_point`` or ``worst_point`` of the object.
        points_in_object_m: (K, 3) exposed points of the object [m], object frame; needed for
            the point metrics (the CLI derives them from the object's primitive shape).
        iso_regions: ISO/TS 15066 body regions to assess; None: all; empty: no assessment.
        uncertainty: Bounds on the object-inertia error; None: no uncertainty analysis.
        grasp_quality: Quality per candidate (higher is better); None: pure safety ranking.
        safety_weight: w of the weighted sum w·safety + (1 − w)·quality, in [0, 1].
        redundancy: Null-space optimisation of the effective mass (arms with > 6 joints);
            when on, the tip score uses the optimised effective mass.
        effort: Compute joint torques along the trajectory.
        rank_by: ``safety``, ``effort`` (then ``effort_criterion`` orders the grasps) or
            ``whole_arm`` (the worst predicted force over the arm's sites for
            ``whole_arm_region``; turns ``whole_arm`` on).
        effort_criterion: ``peak_fraction`` or ``rms_fraction`` of the torque limits.
        whole_arm: Assess the arm's own sites (core.analyses.whole_arm).
        arm_points_m: Extra sites ``{link_name: (P, 3) points [m], link frame}``; giving any
            turns ``whole_arm`` on.
        whole_arm_region: Body region ``rank_by: whole_arm`` uses (DEFAULT_RANK_REGION).
        retime: Retime each feasible grasp to the site speed limits (core.analyses.
            safe_duration); required by ``rank_by: safe_duration``.
        redundancy_settings: The null-space optimisation's settings when ``redundancy`` is on
            (its ``metric`` and ``max_joint_step`` are the evaluator's).
    """

    metric_point: str = "tip"
    points_in_object_m: np.ndarray | None = None
    iso_regions: tuple[str, ...] | None = None
    uncertainty: InertiaUncertainty | None = None
    grasp_quality: tuple[float, ...] | None = None
    safety_weight: float = 0.5
    redundancy: bool = False
    effort: bool = True
    rank_by: str = "safety"
    effort_criterion: str = "peak_fraction"
    whole_arm: bool = False
    arm_points_m: Mapping[str, Any] | None = None
    whole_arm_region: str = DEFAULT_RANK_REGION
    retime: RetimeOptions | None = None
    redundancy_settings: RedundancyConfig = field(default_factory=RedundancyConfig)

    def __post_init__(self) -> None:
        check_metric_point(self.metric_point)
        if self.points_in_object_m is not None:
            object.__setattr__(
                self,
                "points_in_object_m",
                check_points_in_object(self.points_in_object_m, "object.points_m"),
            )
        check_metric_point_has_points(
            self.metric_point,
            self.points_in_object_m,
            "a box or cylinder shape, or object.points_m",
        )
        if self.iso_regions:
            select_regions(list(self.iso_regions))  # raises on unknown names
        if self.rank_by not in RANK_BY:
            raise InvalidInputError(
                "rank_by", f"must be one of {', '.join(RANK_BY)}, got {self.rank_by!r}"
            )
        check_effort_criterion(self.effort_criterion, "effort.criterion")
        if self.rank_by == "effort" and not self.effort:
            object.__setattr__(self, "effort", True)
        if self.arm_points_m is not None:
            points = check_exposed_points_m(self.arm_points_m)
            object.__setattr__(self, "arm_points_m", MappingProxyType(points))
        if not isinstance(self.whole_arm_region, str):
            raise InvalidInputError(
                "whole_arm.region",
                f"must be one body region name, got {self.whole_arm_region!r}; regions: "
                f"{', '.join(BODY_REGIONS)}",
            )
        if self.whole_arm_region not in BODY_REGIONS:
            raise InvalidInputError(
                "whole_arm.region",
                f"unknown body region {self.whole_arm_region!r}; regions: "
                f"{', '.join(BODY_REGIONS)}",
            )
        assessed = self.iso_regions
        if self.rank_by == "whole_arm" and assessed and self.whole_arm_region not in assessed:
            raise InvalidInputError(
                "whole_arm.region",
                f"rank_by whole_arm ranks by {self.whole_arm_region!r}, which is not among the "
                f"assessed iso_ts_15066.regions ({', '.join(assessed)}); add it there or set "
                "whole_arm.region to one of them",
            )
        if self.rank_by == "whole_arm" or self.arm_points_m:
            object.__setattr__(self, "whole_arm", True)
        if self.retime is None and self.rank_by == "safe_duration":
            raise InvalidInputError(
                "retime.joint_acceleration_limits",
                "rank_by safe_duration needs a retime section with the joint acceleration limits",
            )
        if self.retime is not None and self.iso_regions == ():
            raise InvalidInputError(
                "iso_ts_15066.regions", "a retiming needs at least one region (none: all)"
            )


def posture_criterion(
    robot: RobotModel, options: AnalysisOptions
) -> WholeArmPostureCriterion | SafeDurationPostureCriterion | None:
    """What posture selection (core.method.posture) minimises for ``options``: with
    ``rank_by: whole_arm`` the whole arm's worst force for ``whole_arm_region`` over its sites
    (the defaults and ``arm_points_m``), with ``safe_duration`` the retimed duration, the
    criterion that ranks; else None (the tip score)."""
    if options.rank_by not in ("whole_arm", "safe_duration"):
        return None
    sites = resolve_arm_sites(robot, options.arm_points_m)
    if options.rank_by == "safe_duration":
        regions = None if options.iso_regions is None else tuple(options.iso_regions)
        return SafeDurationPostureCriterion(
            options.retime,
            sites,
            options.points_in_object_m,
            regions,  # type: ignore[arg-type]
        )
    return WholeArmPostureCriterion(sites, options.whole_arm_region)


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
    """Rank the grasps (unless ``ranking`` is given) and run the analyses ``options`` ask for.

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
    robot = evaluator.robot
    evaluations = ranking.evaluations
    metric = ranking.metric
    per_grasp = (
        (options.points_in_object_m is not None)
        + options.redundancy
        + options.effort
        + options.whole_arm
    ) * len(grasps) + (options.uncertainty is not None)
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, per_grasp)

    # Shared by every analysis: each grasp's motion, and for the feasible grasps the terms
    # along their joint paths, all in one kernel call (compiled chains), or else each one's
    # augmented model (an infeasible grasp's analyses need neither).
    motions = [evaluator.trajectory_for(g, trajectory) for g in grasps]
    models: dict[int, pin.Model] = {}
    chain = evaluator.ik.chain if evaluator.ik.compiled else None
    feasible_grasps = [k for k, e in enumerate(evaluations) if e.feasible]
    chunks = _chunks(feasible_grasps, [len(evaluations[k].times_s) for k in feasible_grasps])
    cached: dict[int, tuple[SampleTerms, np.ndarray]] = {}
    reread = options.whole_arm  # the whole arm reads the exposed points' chunks again

    def chunk_terms(c: int) -> tuple[SampleTerms, np.ndarray]:
        """The terms of the grasps of ``chunks[c]`` (axis 0 in its order) and their counts,
        kept while the kept chunks stay within TERMS_CACHE_SAMPLES samples when a later
        analysis reads them again (else the last chunk's buffers are reused)."""
        if c not in cached:
            recycled = None
            while cached and (
                not reread
                or sum(int(n.sum()) for _, n in cached.values())
                + sum(len(evaluations[k].times_s) for k in chunks[c])
                > TERMS_CACHE_SAMPLES
            ):
                recycled = cached.pop(next(iter(cached)))[0]  # the oldest
            cached[c] = grasps_terms(
                robot,
                chain,
                object_inertia,
                [grasps[k].transform_tip_to_object for k in chunks[c]],
                [evaluations[k].joint_positions for k in chunks[c]],
                None if reread else recycled,
            )
        return cached[c]

    def model_of(k: int) -> pin.Model | None:
        if not evaluations[k].feasible:
            return None
        if k not in models:
            models[k] = augmented_model(robot, object_inertia, grasps[k].transform_tip_to_object)
        return models[k]

    exposed: tuple[ExposedPointsEvaluation, ...] = ()
    if options.points_in_object_m is not None:
        points = options.points_in_object_m
        exposed_list: list[ExposedPointsEvaluation | None] = [None] * len(grasps)
        for c, chunk in enumerate(chunks if chain is not None else []):
            on_terms = evaluate_exposed_points_on_terms(
                robot,
                [evaluations[k] for k in chunk],
                [grasps[k] for k in chunk],
                [motions[k] for k in chunk],
                points,
                *chunk_terms(c),
            )
            for k, result in zip(chunk, on_terms, strict=True):
                exposed_list[k] = result
                step()
        for k, (e, g) in enumerate(zip(evaluations, grasps, strict=True)):
            if exposed_list[k] is None:  # infeasible, or no compiled chain
                exposed_list[k] = evaluate_exposed_points(
                    robot, e, object_inertia, g, motions[k], points, model_of(k)
                )
                step()
        exposed = tuple(exposed_list)  # type: ignore[arg-type]
    redundancy: tuple[RedundancyResolution, ...] = ()
    if options.redundancy:
        config = replace(
            options.redundancy_settings,
            metric=metric,
            max_joint_step=evaluator.config.ik.max_joint_step,
        )
        resolutions = []
        for k, (e, g) in enumerate(zip(evaluations, grasps, strict=True)):
            resolutions.append(
                resolve_redundancy(
                    robot, e, object_inertia, g, motions[k], config, model_of(k), chain
                )
            )
            step()
        redundancy = tuple(resolutions)

    scores = np.full(len(evaluations), np.nan)
    series: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # the metric point's speeds, masses
    for k, evaluation in enumerate(evaluations):
        if not evaluation.feasible:
            continue
        masses, speeds = metric_point_series(
            evaluation, exposed[k] if exposed else None, options.metric_point
        )
        if redundancy and options.metric_point == "tip":
            masses = redundancy[k].effective_mass_kg
        scores[k] = aggregate(masses, evaluation.times_s, metric)
        series[k] = (speeds, masses)
    iso = (
        _assess_iso(options.iso_regions, evaluations, series, motions)
        if options.iso_regions != ()
        else []
    )
    feasible = np.flatnonzero(~np.isnan(scores))
    safety_order = tuple(int(k) for k in sorted(feasible, key=lambda k: (scores[k], k)))
    quality = rank_with_quality(
        scores,
        None if options.grasp_quality is None else np.array(options.grasp_quality),
        options.safety_weight if options.grasp_quality is not None else 1.0,
    )
    uncertainty = None
    if options.uncertainty is not None:
        samples = sum(len(e.times_s) for e in evaluations if e.feasible)
        uncertainty = analyse_inertia_uncertainty(
            robot,
            evaluations,
            grasps,
            object_inertia,
            options.uncertainty,
            metric,
            chain,
            executor_for(evaluator, samples) if chain is not None else None,
        )
        step()
    effort: tuple[EffortEvaluation, ...] = ()
    if options.effort:
        resolved = [r.joint_positions if r.applied else None for r in redundancy] or None
        effort = evaluate_efforts(
            robot, evaluations, object_inertia, grasps, motions, resolved, chain=chain
        )
        for _ in grasps:
            step()
    whole_arm: tuple[WholeArmEvaluation, ...] = ()
    arm_sites = None
    if options.whole_arm:
        arm_sites = resolve_arm_sites(robot, options.arm_points_m)
        whole_arm = _assess_whole_arm(
            evaluator,
            evaluations,
            grasps,
            motions,
            object_inertia,
            arm_sites,
            options.iso_regions,
            [r.joint_positions if r.applied else None for r in redundancy] if redundancy else None,
            (chunks, chunk_terms) if chain is not None else None,
            model_of,
            step,
        )
    if options.rank_by == "effort":
        order = order_by_effort(effort, options.effort_criterion)
    elif options.rank_by == "whole_arm":
        order = order_by_whole_arm(whole_arm, options.whole_arm_region)
    elif options.grasp_quality is not None:
        order = quality.order
    else:
        order = safety_order
    return SafetyReport(
        ranking=ranking,
        options=options,
        scores=scores,
        safety_order=safety_order,
        order=order,
        quality=quality,
        iso=tuple(iso),
        exposed=exposed,
        uncertainty=uncertainty,
        redundancy=redundancy,
        effort=effort,
        whole_arm=whole_arm,
        arm_sites=arm_sites,
        standard_mass_estimate_kg=standard_mass_estimate_kg(robot, object_inertia.mass_kg),
    )


def _assess_iso(
    iso_regions: Sequence[str] | None,
    evaluations: Sequence[GraspEvaluation],
    series: dict[int, tuple[np.ndarray, np.ndarray]],
    motions: Sequence[Trajectory],
) -> list[PowerForceLimitAssessment]:
    """ISO/TS 15066 assessment of every grasp: the feasible ones on their metric point's speeds
    and masses (``series``), in one array pass per motion duration."""
    regions = None if iso_regions is None else list(iso_regions)
    assessed: dict[int, PowerForceLimitAssessment] = {}
    by_duration: dict[float, list[int]] = {}
    for k in series:
        by_duration.setdefault(motions[k].duration_s, []).append(k)
    for duration, group in by_duration.items():
        results = assess_motions(
            [series[k][0] for k in group],
            [series[k][1] for k in group],
            duration,
            regions,
            [evaluations[k].index for k in group],
            [evaluations[k].name for k in group],
        )
        assessed.update(zip(group, results, strict=True))
    return [
        assessed[k] if k in assessed else assess_grasp(evaluation, regions)
        for k, evaluation in enumerate(evaluations)
    ]


def _chunks(grasps: Sequence[int], samples: Sequence[int]) -> list[list[int]]:
    """``grasps`` in consecutive chunks of at most TERMS_CHUNK_SAMPLES samples (``samples``
    per grasp; a longer grasp alone)."""
    chunks: list[list[int]] = []
    total = 0
    for k, count in zip(grasps, samples, strict=True):
        if not chunks or total + count > TERMS_CHUNK_SAMPLES:
            chunks.append([])
            total = 0
        chunks[-1].append(k)
        total += count
    return chunks


def _assess_whole_arm(
    evaluator: GraspSafetyEvaluator,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    motions: Sequence[Trajectory],
    object_inertia: ObjectInertia,
    sites: ArmSites,
    iso_regions: Sequence[str] | None,
    resolved: Sequence[np.ndarray | None] | None,
    shared: tuple[list[list[int]], Callable[[int], tuple[SampleTerms, np.ndarray]]] | None,
    model_of: Callable[[int], pin.Model | None],
    step: Callable[[], None],
) -> tuple[WholeArmEvaluation, ...]:
    """The whole-arm evaluation of every grasp, ``step()`` after each: with ``shared`` (the
    chunks of feasible grasps and their terms, compiled chains) the feasible ones along their
    evaluated joint paths on those terms, and those with a joint path of their own
    (``resolved``: the redundancy resolution's) on terms along it, chunk by chunk; the
    Pinocchio path when there are no terms."""
    robot = evaluator.robot
    regions = select_regions(None if iso_regions is None else list(iso_regions))
    results: list[WholeArmEvaluation | None] = [None] * len(grasps)
    chunks, chunk_terms = shared if shared is not None else ([], None)
    for c, chunk in enumerate(chunks):
        own = [k for k in chunk if resolved is not None and resolved[k] is not None]
        on_path = [k for k in chunk if k not in set(own)]
        groups = []
        if on_path:
            terms, counts = chunk_terms(c)  # type: ignore[misc]
            if own:
                rows = [chunk.index(k) for k in on_path]
                terms, counts = SampleTerms(*(array[rows] for array in terms)), counts[rows]
            paths = [evaluations[k].joint_positions for k in on_path]
            groups.append((on_path, terms, counts, paths))
        if own:
            paths = [resolved[k] for k in own]  # type: ignore[index]
            transforms = [grasps[k].transform_tip_to_object for k in own]
            terms = grasps_terms(robot, evaluator.ik.chain, object_inertia, transforms, paths)
            groups.append((own, *terms, paths))
        for indices, terms, counts, paths in groups:
            assessed = evaluate_whole_arm_on_terms(
                robot,
                [evaluations[k] for k in indices],
                [motions[k] for k in indices],
                [grasps[k] for k in indices],
                sites,
                regions,
                terms,
                counts,
                paths,
            )
            for k, result in zip(indices, assessed, strict=True):
                results[k] = result
                step()
    for k, (e, g) in enumerate(zip(evaluations, grasps, strict=True)):
        if results[k] is None:
            results[k] = evaluate_whole_arm(
                robot,
                e,
                object_inertia,
                g,
                motions[k],
                sites,
                iso_regions,
                model_of(k),
                None if resolved is None else resolved[k],
            )
            step()
    return tuple(results)  # type: ignore[arg-type]
