"""The one entry point: a ranking request in, the full safety report out.

``run_pipeline(evaluator, request, progress)`` runs, in this order,

1. ``rank``: the paper's ranking (``GraspSafetyEvaluator.rank``: IK along each grasp's
   motion, effective mass, score);
2. ``postures``: posture selection (``core.method.posture.select_postures``; with
   ``rank_by: whole_arm`` by the whole arm's criterion);
3. ``analyses``: every analysis the options enable (``core.analyses.safety_report.analyse``:
   exposed points, ISO/TS 15066, uncertainty, quality, redundancy, effort, whole arm);
4. the report stages (``REPORT_STAGES``, a ``ReportStage`` each): ``armature_range``, the
   effective masses and order at both ends of the armature ranges, when the armature was
   given as ranges (``analyse_armature_range``); ``retime``, each grasp's path retimed to the
   ISO/TS 15066 site speed limits, when ``options.retime`` is set (``retime_grasps``).

Every adapter calls it: the CLI (``grasp-safety rank``), the ROS node's service and topics,
the dataset batch, the benchmarks; so does a new capability (safe retiming, a live monitor, a
MoveIt ``GraspPlanning`` server): build a ``PipelineRequest``, call ``run_pipeline``, read the
``SafetyReport``. Nothing else calls the stages in sequence.

``progress(stage, done, total)`` is the hook for progress and cancellation: it is called
after each unit of work of each stage (one grasp, or one batch of grasps, of rank, postures
and each analysis) and before and after each report stage (``done`` 0 then 1 of 1); it may raise
any exception to abandon the request, which then propagates unchanged (the node raises when
its client left, its compute time is spent or it shuts down: ``ros.service.ranking_job``).
``timings``, when given, receives each stage's wall time ``{stage}``, the calling thread's
CPU time ``{stage}_cpu`` and the process's (worker threads included) ``{stage}_process_cpu``
[s] (the benchmarks read them).
"""

from __future__ import annotations

import time
from collections.abc import Callable, MutableMapping
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from .analyses.arm_sites import resolve_arm_sites
from .analyses.safe_duration import order_by_safe_duration, retime_grasps
from .analyses.safety_report import AnalysisOptions, SafetyReport, analyse, posture_criterion
from .analyses.uncertainty import analyse_armature_range
from .method.posture import PostureConfig, select_postures
from .method.ranking import GraspSafetyEvaluator
from .method.results import Grasp
from .model.armature import ArmatureRange
from .model.inertia import ObjectInertia
from .model.trajectory import ObjectTrajectory
from .model.waypoint_trajectory import WaypointTrajectory

__all__ = [
    "REPORT_STAGES",
    "STAGES",
    "ArmatureRangeStage",
    "PipelineRequest",
    "Progress",
    "ReportStage",
    "RetimeStage",
    "run_pipeline",
]


class Progress(Protocol):
    """``progress(stage, done, total)``: ``done`` of ``total`` units of ``stage`` (one of
    STAGES, below) are done; raise to abandon the request."""

    def __call__(self, stage: str, done: int, total: int, /) -> None: ...


@dataclass(frozen=True)
class PipelineRequest:
    """One ranking request, in core types (the robot is the evaluator's).

    Attributes:
        grasps: The candidates (tip pose in the object frame; optionally a planned joint
            trajectory each, which replaces the IK).
        object_inertia: The grasped object's inertia.
        trajectory: The object's motion after the grasp (poses of the object frame in the
            base frame).
        metric: ``mean``, ``max`` or ``integral``; None: the evaluator's configured metric.
        options: The analyses beyond the paper (AnalysisOptions; ISO/TS 15066 and effort by
            default, the others off: core.options).
        posture: Posture selection (PostureConfig; 8 restarts by default, core.options;
            ``restarts`` 0: the paper's single IK).
        seed_positions: IK seed of the first sample [rad or m], chain joint order; None: the
            evaluator's (mid-range).
        armature_range: Armature bounds per chain joint; the analysis runs when some joint
            has a range (lower < upper); the evaluator's robot should carry the upper ends.
    """

    grasps: tuple[Grasp, ...]
    object_inertia: ObjectInertia
    trajectory: ObjectTrajectory | WaypointTrajectory
    metric: str | None = None
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    posture: PostureConfig = field(default_factory=PostureConfig)
    seed_positions: tuple[float, ...] | np.ndarray | None = None
    armature_range: ArmatureRange | None = None


def run_pipeline(
    evaluator: GraspSafetyEvaluator,
    request: PipelineRequest,
    progress: Progress | None = None,
    timings: MutableMapping[str, float] | None = None,
) -> SafetyReport:
    """Rank ``request``'s grasps with ``evaluator`` (built for the robot; it keeps the
    compiled chain and the worker pool between requests), select their postures, run the
    enabled analyses and the armature range: the full SafetyReport (module docstring).

    Args:
        progress: The progress and cancellation hook (module docstring).
        timings: Receives the times of the stages run (module docstring).

    Raises:
        GraspSafetyError: Bad input, naming the field; whatever ``progress`` raises.
    """
    grasps, inertia, trajectory = list(request.grasps), request.object_inertia, request.trajectory
    clock = _Clock(timings)
    ranking = evaluator.rank(
        grasps,
        inertia,
        trajectory,
        seed_positions=request.seed_positions,
        metric=request.metric,
        progress=_stage(progress, "rank"),
    )
    clock.lap("rank")
    ranking = select_postures(
        evaluator,
        grasps,
        inertia,
        trajectory,
        ranking,
        request.posture,
        progress=_stage(progress, "postures"),
        criterion=posture_criterion(evaluator.robot, request.options),
    )
    clock.lap("postures")
    report = analyse(
        evaluator,
        grasps,
        inertia,
        trajectory,
        request.options,
        ranking=ranking,
        progress=_stage(progress, "analyses"),
    )
    clock.lap("analyses")
    for stage in REPORT_STAGES:
        if not stage.wanted(request):
            continue
        if progress is not None:
            progress(stage.name, 0, 1)
        report = stage.run(evaluator, request, report)
        clock.lap(stage.name)
        if progress is not None:
            progress(stage.name, 1, 1)
    return report


class ReportStage(Protocol):
    """An analysis run on the report after the others (``REPORT_STAGES``): adding one is its
    module in core/analyses, a class like ArmatureRangeStage here and its registration
    (docs/development.md, "Adding an analysis")."""

    @property
    def name(self) -> str:
        """Its stage name: ``progress``'s ``stage`` and the ``timings`` key."""
        ...

    def wanted(self, request: PipelineRequest) -> bool:
        """Whether ``request`` asks for it."""
        ...

    def run(
        self, evaluator: GraspSafetyEvaluator, request: PipelineRequest, report: SafetyReport
    ) -> SafetyReport:
        """The report with its result set (``report.ranking``: the kept postures)."""
        ...


@dataclass(frozen=True)
class ArmatureRangeStage:
    """Effective masses and order at both ends of the armature ranges
    (core.analyses.uncertainty.analyse_armature_range) -> ``SafetyReport.armature_range``."""

    name: str = "armature_range"

    def wanted(self, request: PipelineRequest) -> bool:
        return request.armature_range is not None and request.armature_range.is_range

    def run(
        self, evaluator: GraspSafetyEvaluator, request: PipelineRequest, report: SafetyReport
    ) -> SafetyReport:
        bounds, ranking = request.armature_range, report.ranking
        if bounds is None:  # not wanted: nothing to add
            return report
        spread = analyse_armature_range(
            evaluator.robot,
            ranking.evaluations,
            request.grasps,
            request.object_inertia,
            bounds.lower_kgm2,
            bounds.upper_kgm2,
            ranking.metric,
            compiled=evaluator.backend.compiled,
        )
        return replace(report, armature_range=spread)


@dataclass(frozen=True)
class RetimeStage:
    """Each feasible grasp's kept path (the null-space resolution's where applied) retimed to
    the ISO/TS 15066 site speed limits of its whole-arm sites and object points and to the
    joint limits (core.analyses.safe_duration.retime_grasps) -> ``SafetyReport.retimed``, and
    the order under ``rank_by: safe_duration`` (``order_by_safe_duration``)."""

    name: str = "retime"

    def wanted(self, request: PipelineRequest) -> bool:
        return request.options.retime is not None

    def run(
        self, evaluator: GraspSafetyEvaluator, request: PipelineRequest, report: SafetyReport
    ) -> SafetyReport:
        options, robot = report.options, evaluator.robot
        if options.retime is None:  # not wanted: nothing to add
            return report
        evaluations, redundancy = report.ranking.evaluations, report.redundancy
        retimed, reasons = retime_grasps(
            robot,
            options.retime,
            report.arm_sites or resolve_arm_sites(robot, options.arm_points_m),
            request.object_inertia,
            request.grasps,
            evaluations,
            options.points_in_object_m,
            options.iso_regions,
            [r.joint_positions if r.applied else None for r in redundancy] if redundancy else None,
        )
        order = report.order
        if options.rank_by == "safe_duration":
            order = order_by_safe_duration(retimed, report.scores, [e.index for e in evaluations])
        return replace(report, retimed=retimed, retime_reasons=reasons, order=order)


REPORT_STAGES: tuple[ReportStage, ...] = (ArmatureRangeStage(), RetimeStage())
"""The analyses run on the report after ``analyses``, in this order (register new ones here)."""

STAGES = ("rank", "postures", "analyses", *(stage.name for stage in REPORT_STAGES))
"""The stages, in the order they run; the first argument of ``Progress``."""


class _Clock:
    """Each stage's wall, thread and process CPU times [s] into ``timings`` (when given)."""

    SUFFIXES = ("", "_cpu", "_process_cpu")

    def __init__(self, timings: MutableMapping[str, float] | None) -> None:
        self.timings = timings
        self.last = self._now()

    @staticmethod
    def _now() -> tuple[float, float, float]:
        return time.perf_counter(), time.thread_time(), time.process_time()

    def lap(self, stage: str) -> None:
        now = self._now()
        if self.timings is not None:
            for suffix, end, start in zip(self.SUFFIXES, now, self.last, strict=True):
                self.timings[stage + suffix] = end - start
        self.last = now


def _stage(progress: Progress | None, stage: str) -> Callable[[int, int], None] | None:
    """The stage's ``progress(done, total)`` callback, or None."""
    if progress is None:
        return None
    return lambda done, total: progress(stage, done, total)
