"""The analyses ``safety_report.analyse`` runs, each an ``Analysis`` (``base``), registered in
``ANALYSES`` in the order they run: an analysis may read the parts of those before it
(redundancy's joint paths, the exposed points' metric point series).

Each class only adapts its module's functions to the protocol: the module computes (on the
backend's chain, or the Pinocchio reference without one), the class says when it runs, how
much progress it reports and which part it sets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..method.ranking import aggregate
from ..method.terms import SampleTerms
from .analysis_options import AnalysisOptions
from .base import Analysis, Parts, Shared, per_grasp
from .body_regions import BodyRegion, select_regions
from .effort import EffortEvaluation, evaluate_effort, evaluate_efforts
from .exposed_points import (
    ExposedPointsEvaluation,
    evaluate_exposed_points,
    evaluate_exposed_points_on_terms,
    metric_point_series,
)
from .iso15066 import PowerForceLimitAssessment, assess_grasp, assess_motions
from .redundancy import resolve_redundancy
from .uncertainty import analyse_inertia_uncertainty
from .whole_arm import (
    WHOLE_ARM_TERMS,
    ArmSites,
    WholeArmEvaluation,
    evaluate_whole_arm,
    evaluate_whole_arm_on_terms,
    resolve_arm_sites,
)


@dataclass(frozen=True)
class ExposedPoints:
    """Effective mass and speed at the object's exposed points (``exposed_points``)."""

    name: str = "exposed"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ("mobilities_tip_in_base",)

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.points_in_object_m is not None

    def units(self, grasps: int) -> int:
        return grasps

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

    def run(self, shared: Shared, parts: Parts) -> Parts:
        points = shared.options.points_in_object_m
        evaluations, grasps, motions = shared.evaluations, shared.grasps, shared.motions

        def on_chunk(c: int, chunk: Sequence[int]) -> list[tuple[int, ExposedPointsEvaluation]]:
            results = evaluate_exposed_points_on_terms(
                shared.robot,
                [evaluations[k] for k in chunk],
                [grasps[k] for k in chunk],
                [motions[k] for k in chunk],
                points,
                *shared.terms(c),
                shared.executor,
            )
            return list(zip(chunk, results, strict=True))

        def on_grasp(k: int) -> ExposedPointsEvaluation:
            return evaluate_exposed_points(
                shared.robot,
                evaluations[k],
                shared.object_inertia,
                grasps[k],
                motions[k],
                points,
                shared.model_of(k),
            )

        return replace(parts, exposed=per_grasp(shared, on_chunk, on_grasp))


@dataclass(frozen=True)
class Redundancy:
    """Null-space resolution of each grasp's path (``redundancy``), with the ranking's
    metric and the IK's joint step bound."""

    name: str = "redundancy"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.redundancy

    def units(self, grasps: int) -> int:
        return grasps

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

    def run(self, shared: Shared, parts: Parts) -> Parts:
        config = replace(
            shared.options.redundancy_settings,
            metric=shared.metric,
            max_joint_step=shared.evaluator.config.ik.max_joint_step,
        )
        resolutions = []
        for k, (e, g) in enumerate(zip(shared.evaluations, shared.grasps, strict=True)):
            resolutions.append(
                resolve_redundancy(
                    shared.robot,
                    e,
                    shared.object_inertia,
                    g,
                    shared.motions[k],
                    config,
                    shared.model_of(k),
                    shared.backend.chain,
                )
            )
            shared.step()
        return replace(parts, redundancy=tuple(resolutions))


@dataclass(frozen=True)
class SafetyScores:
    """Each feasible grasp's score on the metric point (the exposed points' leading or worst
    point, or the tip, redundancy-optimised when on) and the safety order; always runs."""

    name: str = "scores"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return True

    def units(self, grasps: int) -> int:
        return 0

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

    def run(self, shared: Shared, parts: Parts) -> Parts:
        evaluations, options = shared.evaluations, shared.options
        scores = np.full(len(evaluations), np.nan)
        series: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # the metric point's speeds, masses
        for k, evaluation in enumerate(evaluations):
            if not evaluation.feasible:
                continue
            masses, speeds = metric_point_series(
                evaluation, parts.exposed[k] if parts.exposed else None, options.metric_point
            )
            if parts.redundancy and options.metric_point == "tip":
                masses = parts.redundancy[k].effective_mass_kg
            scores[k] = aggregate(masses, evaluation.times_s, shared.metric)
            series[k] = (speeds, masses)
        feasible = np.flatnonzero(~np.isnan(scores))
        safety_order = tuple(int(k) for k in sorted(feasible, key=lambda k: (scores[k], k)))
        return replace(parts, scores=scores, series=series, safety_order=safety_order)


@dataclass(frozen=True)
class Iso15066:
    """ISO/TS 15066 power and force limiting of every grasp on its metric point's speeds
    and masses (``iso15066``), one array pass per motion duration."""

    name: str = "iso"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.iso_regions != ()

    def units(self, grasps: int) -> int:
        return 0

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

    def run(self, shared: Shared, parts: Parts) -> Parts:
        iso_regions, evaluations = shared.options.iso_regions, shared.evaluations
        regions = None if iso_regions is None else list(iso_regions)
        assessed: dict[int, PowerForceLimitAssessment] = {}
        by_duration: dict[float, list[int]] = {}
        for k in parts.series:
            by_duration.setdefault(shared.motions[k].duration_s, []).append(k)
        for duration, group in by_duration.items():
            results = assess_motions(
                [parts.series[k][0] for k in group],
                [parts.series[k][1] for k in group],
                duration,
                regions,
                [evaluations[k].index for k in group],
                [evaluations[k].name for k in group],
            )
            assessed.update(zip(group, results, strict=True))
        iso = tuple(
            assessed[k] if k in assessed else assess_grasp(evaluation, regions)
            for k, evaluation in enumerate(evaluations)
        )
        return replace(parts, iso=iso)


@dataclass(frozen=True)
class Uncertainty:
    """Scores over the object-inertia uncertainty set (``uncertainty``), compiled on the
    evaluator's worker pool when the request is large enough."""

    name: str = "uncertainty"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.uncertainty is not None

    def units(self, grasps: int) -> int:
        return 1

    def prepare(self, shared: Shared) -> None:
        """Nothing runs ahead."""

    def run(self, shared: Shared, parts: Parts) -> Parts:
        uncertainty = analyse_inertia_uncertainty(
            shared.robot,
            shared.evaluations,
            shared.grasps,
            shared.object_inertia,
            shared.options.uncertainty,
            shared.metric,
            shared.backend.chain,
            shared.executor,
        )
        shared.step()
        return replace(parts, uncertainty=uncertainty)


@dataclass(frozen=True)
class Effort:
    """Joint torques along each grasp's path (``effort``; redundancy's where it applied). On
    the compiled backend along the evaluated paths, when an analysis before it reads the
    shared terms: chunk by chunk on them, run ahead with that analysis; else all grasps in
    one kernel call that computes its own kinematics (cheaper than terms for it alone)."""

    name: str = "effort"
    keeps_terms: bool = False
    optional_terms: tuple[str, ...] = ()

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.effort

    def units(self, grasps: int) -> int:
        return grasps

    def prepare(self, shared: Shared) -> None:
        if shared.can_run_ahead:

            def on_chunk(c: int, chunk: Sequence[int]) -> list[tuple[int, EffortEvaluation]]:
                terms, _ = shared.terms(c)
                results = evaluate_efforts(
                    shared.robot,
                    [shared.evaluations[k] for k in chunk],
                    shared.object_inertia,
                    [shared.grasps[k] for k in chunk],
                    [shared.motions[k] for k in chunk],
                    terms=terms,
                    chain=shared.backend.chain,
                    executor=shared.executor,
                )
                return list(zip(chunk, results, strict=True))

            shared.run_ahead(self.name, on_chunk)

    def run(self, shared: Shared, parts: Parts) -> Parts:
        ahead = shared.take_ahead(self.name)
        if ahead is not None:

            def on_grasp(k: int) -> EffortEvaluation:  # infeasible: no samples
                args = (shared.evaluations[k], shared.object_inertia, shared.grasps[k])
                return evaluate_effort(shared.robot, *args, shared.motions[k])

            return replace(parts, effort=per_grasp(shared, ahead, on_grasp))
        effort = evaluate_efforts(
            shared.robot,
            shared.evaluations,
            shared.object_inertia,
            shared.grasps,
            shared.motions,
            parts.resolved_paths(),
            chain=shared.backend.chain,
            executor=shared.executor,
        )
        for _ in shared.grasps:
            shared.step()
        return replace(parts, effort=effort)


@dataclass(frozen=True)
class WholeArm:
    """Exposure of the arm's sites (``whole_arm``): on the shared terms along the evaluated
    paths (run ahead, with the first analysis that reads them), on terms of their own along
    redundancy's paths, the Pinocchio path without terms."""

    name: str = "whole_arm"
    keeps_terms: bool = True  # with redundancy, it reads the chunks the exposed points read
    optional_terms: tuple[str, ...] = WHOLE_ARM_TERMS

    def wanted(self, options: AnalysisOptions) -> bool:
        return options.whole_arm

    def units(self, grasps: int) -> int:
        return grasps

    def prepare(self, shared: Shared) -> None:
        if shared.can_run_ahead:
            sites, regions = _sites_and_regions(shared)

            def on_chunk(c: int, chunk: Sequence[int]) -> list[tuple[int, WholeArmEvaluation]]:
                return _whole_arm_chunk(shared, sites, regions, None, c, chunk)

            shared.run_ahead(self.name, on_chunk)

    def run(self, shared: Shared, parts: Parts) -> Parts:
        sites, regions = _sites_and_regions(shared)
        resolved = parts.resolved_paths()

        def on_grasp(k: int) -> WholeArmEvaluation:
            return evaluate_whole_arm(
                shared.robot,
                shared.evaluations[k],
                shared.object_inertia,
                shared.grasps[k],
                shared.motions[k],
                sites,
                shared.options.iso_regions,
                shared.model_of(k),
                None if resolved is None else resolved[k],
            )

        def on_chunk(c: int, chunk: Sequence[int]) -> list[tuple[int, WholeArmEvaluation]]:
            return _whole_arm_chunk(shared, sites, regions, resolved, c, chunk)

        whole_arm = per_grasp(shared, shared.take_ahead(self.name) or on_chunk, on_grasp)
        return replace(parts, whole_arm=whole_arm, arm_sites=sites)


def _sites_and_regions(shared: Shared) -> tuple[ArmSites, tuple[BodyRegion, ...]]:
    """The whole arm's sites and ISO/TS 15066 regions for the request's options."""
    iso_regions = shared.options.iso_regions
    sites = resolve_arm_sites(shared.robot, shared.options.arm_points_m)
    return sites, select_regions(None if iso_regions is None else list(iso_regions))


def _whole_arm_chunk(
    shared: Shared,
    sites: ArmSites,
    regions: tuple[BodyRegion, ...],
    resolved: Sequence[np.ndarray | None] | None,
    c: int,
    chunk: Sequence[int],
) -> list[tuple[int, WholeArmEvaluation]]:
    """The whole arm of the grasps of chunk ``c``: those on their evaluated paths on the
    chunk's shared terms, those with a path of their own (``resolved``) on its terms."""
    own = [k for k in chunk if resolved is not None and resolved[k] is not None]
    on_path = [k for k in chunk if k not in set(own)]
    groups: list[tuple[list[int], SampleTerms, np.ndarray, list[np.ndarray]]] = []
    if on_path:
        terms, counts = shared.terms(c)
        if own:
            rows = [list(chunk).index(k) for k in on_path]
            terms, counts = SampleTerms(*(array[rows] for array in terms)), counts[rows]
        groups.append(
            (on_path, terms, counts, [shared.evaluations[k].joint_positions for k in on_path])
        )
    if own and resolved is not None:
        paths = [path for k in own if (path := resolved[k]) is not None]
        groups.append((own, *shared.path_terms(own, paths), paths))
    pairs: list[tuple[int, WholeArmEvaluation]] = []
    for indices, terms, counts, paths in groups:
        assessed = evaluate_whole_arm_on_terms(
            shared.robot,
            [shared.evaluations[k] for k in indices],
            [shared.motions[k] for k in indices],
            [shared.grasps[k] for k in indices],
            sites,
            regions,
            terms,
            counts,
            paths,
        )
        pairs.extend(zip(indices, assessed, strict=True))
    return pairs


ANALYSES: tuple[Analysis, ...] = (
    ExposedPoints(),
    Redundancy(),
    SafetyScores(),
    Iso15066(),
    Uncertainty(),
    Effort(),
    WholeArm(),
)
"""The analyses of ``analyse``, in the order they run (register new ones here)."""
