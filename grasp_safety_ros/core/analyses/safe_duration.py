"""The retiming analysis of a ranking: each feasible grasp's path retimed to the ISO/TS 15066
site speed limits (``retime``), ``rank_by: safe_duration``, its posture criterion, and the
standard's own effective-mass estimate beside the exact one.

Per feasible grasp the joint path retimed is the kept posture's (or the null-space
resolution's, when applied); the sites are the whole arm's (``arm_sites``: joint origins from
the third, the tip, ``robot.exposed_points_m``) plus the object's points, against the assessed
ISO/TS 15066 regions that permit transient contact.

ISO/TS 15066 (A.3) and ISO 10218-2:2025 (Annex A) let an integrator estimate the robot's
effective mass as m_R = M/2 + m_L, M the mass of the moving parts and m_L the payload
(``standard_mass_estimate_kg``: M = every link the chain joints move, m_L = the object).
``compare_with_standard`` puts it beside the exact effective mass of each site (its largest
along the motion): where the estimate is smaller, the shortcut is *optimistic* (it would admit
a speed the exact mass does not).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..exceptions import GraspSafetyError, InvalidInputError
from ..input_checks import finite_float
from ..method.ranking import Grasp, GraspEvaluation, GraspSafetyEvaluator
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectTrajectory
from ..model.waypoint_trajectory import WaypointTrajectory
from .arm_sites import ArmSites
from .retime import RETIME_FIELD, RetimedMotion, RetimeLimits, check_output_dt, retime_path
from .site_speeds import SiteSpeedModel

UNRETIMABLE_S = float(np.finfo(float).max)
"""The posture criterion's value for a posture TOPP-RA cannot retime (finite, ranks last)."""


@dataclass(frozen=True)
class RetimeOptions:
    """The scenario's ``retime:`` section, checked against the robot when used.

    Attributes:
        joint_acceleration_limits: Required: a list in chain order or ``{joint: value}``
            [rad/s², m/s² prismatic].
        joint_velocity_limits: None: the URDF's; else as above (a mapping overrides the
            URDF's for the joints it names) [rad/s, m/s].
        safety_factor: f in (0, 1]: sites are kept under f · v_max.
        output_dt_s: None: the retimed trajectory at its grid points (the planned samples,
            where every limit holds); else a uniform step [s].
    """

    joint_acceleration_limits: Any
    joint_velocity_limits: Any = None
    safety_factor: float = 1.0
    output_dt_s: float | None = None

    def __post_init__(self) -> None:
        if self.joint_acceleration_limits is None:
            raise InvalidInputError(
                f"{RETIME_FIELD}.joint_acceleration_limits",
                "is required for a retiming (a list in chain order or {joint: value} "
                "[rad/s², m/s² prismatic]; the URDF has none)",
            )
        for name in ("joint_acceleration_limits", "joint_velocity_limits"):
            value = getattr(self, name)
            if isinstance(value, Mapping):
                object.__setattr__(self, name, dict(value))
            elif isinstance(value, (list, np.ndarray)):
                object.__setattr__(self, name, tuple(value))
        factor = finite_float(self.safety_factor, f"{RETIME_FIELD}.safety_factor", 0.0, 1.0, True)
        object.__setattr__(self, "safety_factor", factor)
        if self.output_dt_s is not None:
            dt = finite_float(self.output_dt_s, f"{RETIME_FIELD}.output_dt_s", 0.0, None, True)
            object.__setattr__(self, "output_dt_s", dt)

    def limits(self, robot: RobotModel) -> RetimeLimits:
        """The checked limits for ``robot`` (errors name the ``retime.*`` field)."""
        return RetimeLimits.from_input(
            robot, self.joint_acceleration_limits, self.joint_velocity_limits, self.safety_factor
        )


def retime_evaluation(
    robot: RobotModel,
    options: RetimeOptions,
    sites: ArmSites,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    evaluation: GraspEvaluation,
    points_in_object_m: np.ndarray | None,
    regions: Sequence[str] | None,
    joint_positions: np.ndarray | None = None,
) -> RetimedMotion:
    """One feasible evaluation's path (or ``joint_positions``, same samples) retimed."""
    speed_model = SiteSpeedModel.build(
        robot, object_inertia, grasp.transform_tip_to_object, sites, points_in_object_m, regions
    )
    path = evaluation.joint_positions if joint_positions is None else joint_positions
    return retime_path(
        robot, speed_model, options.limits(robot), evaluation.times_s, path, options.output_dt_s
    )


def retime_grasps(
    robot: RobotModel,
    options: RetimeOptions,
    sites: ArmSites,
    object_inertia: ObjectInertia,
    grasps: Sequence[Grasp],
    evaluations: Sequence[GraspEvaluation],
    points_in_object_m: np.ndarray | None,
    regions: Sequence[str] | None,
    resolved: Sequence[np.ndarray | None] | None = None,
    step: Callable[[], None] | None = None,
) -> tuple[tuple[RetimedMotion | None, ...], tuple[str, ...]]:
    """Every grasp's retimed motion (None: infeasible, or no timing found) and why it has
    none ("" where it has one), in candidate order; ``step()`` after each grasp. Bad limits
    or ``output_dt_s`` raise once, naming the field; one grasp's failure is that grasp's."""
    options.limits(robot)  # refuse bad input before any work
    planned = [e.times_s[-1] - e.times_s[0] for e in evaluations if e.feasible]
    check_output_dt(options.output_dt_s, planned)
    results: list[RetimedMotion | None] = []
    reasons: list[str] = []
    for k, (grasp, evaluation) in enumerate(zip(grasps, evaluations, strict=True)):
        motion, reason = None, "infeasible"
        if evaluation.feasible:
            try:
                motion = retime_evaluation(
                    robot,
                    options,
                    sites,
                    object_inertia,
                    grasp,
                    evaluation,
                    points_in_object_m,
                    regions,
                    None if resolved is None else resolved[k],
                )
                reason = ""
            except InvalidInputError:
                raise
            except GraspSafetyError as error:
                reason = " ".join(str(error).split())
        results.append(motion)
        reasons.append(reason)
        if step is not None:
            step()
    return tuple(results), tuple(reasons)


def order_by_safe_duration(
    retimed: Sequence[RetimedMotion | None], scores: np.ndarray, indices: Sequence[int]
) -> tuple[int, ...]:
    """Grasps with a retimed motion by safe duration, shortest first; ties by the effective-
    mass score, then candidate order; grasps without one are left out (``indices``: each
    grasp's candidate index)."""
    keyed = [
        (motion.safe_duration_s, scores[k], k)
        for k, motion in enumerate(retimed)
        if motion is not None
    ]
    return tuple(int(indices[k]) for *_, k in sorted(keyed))


@dataclass(frozen=True)
class SafeDurationPostureCriterion:
    """Posture selection by the safe duration (a core.method.posture.PostureCriterion): each
    candidate posture's retimed duration [s] (UNRETIMABLE_S where TOPP-RA finds none).

    Attributes:
        options: The retiming inputs.
        sites: The arm's sites (``resolve_arm_sites``).
        points_in_object_m: The object's points (object frame [m]); None: none.
        regions: The assessed regions; None: all.
    """

    options: RetimeOptions
    sites: ArmSites
    points_in_object_m: np.ndarray | None = None
    regions: tuple[str, ...] | None = None

    @property
    def name(self) -> str:
        """``safe_duration``."""
        return "safe_duration"

    def __call__(
        self,
        evaluator: GraspSafetyEvaluator,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        trajectory: ObjectTrajectory | WaypointTrajectory,
        evaluations: Sequence[GraspEvaluation],
    ) -> np.ndarray:
        """The safe duration [s] of each feasible evaluation of ``grasp``."""
        robot = evaluator.robot
        options = replace(self.options, output_dt_s=None)  # the duration only: the grid's
        values = []
        for evaluation in evaluations:
            try:
                motion = retime_evaluation(
                    robot,
                    options,
                    self.sites,
                    object_inertia,
                    grasp,
                    evaluation,
                    self.points_in_object_m,
                    self.regions,
                )
                values.append(motion.safe_duration_s)
            except InvalidInputError:
                raise
            except GraspSafetyError:
                values.append(UNRETIMABLE_S)
        return np.array(values)


def standard_mass_estimate_kg(robot: RobotModel, object_mass_kg: float) -> float:
    """ISO/TS 15066's m_R = M/2 + m_L [kg]: M the mass of every link the chain moves."""
    moving = sum(robot.model.inertias[j].mass for j in range(1, robot.model.njoints))
    return 0.5 * float(moving) + float(object_mass_kg)


@dataclass(frozen=True)
class StandardMassComparison:
    """The standard's estimate beside the exact effective mass, per site (K sites).

    Attributes:
        estimate_kg: m_R = M/2 + m_L [kg] (one value for the robot and payload).
        exact_kg: (K,) each site's largest effective mass along the motion [kg].
        optimistic: (K,) estimate < exact: the shortcut would admit too high a speed there.
    """

    estimate_kg: float
    exact_kg: np.ndarray
    optimistic: np.ndarray


def compare_with_standard(
    estimate_kg: float, effective_mass_kg: np.ndarray, stationary: np.ndarray
) -> StandardMassComparison:
    """Per site, the largest effective mass over the samples where it moves (N, K) (NaN for
    a site that never moves) against the standard's ``estimate_kg``."""
    masses = np.where(np.asarray(stationary, bool), np.nan, np.asarray(effective_mass_kg, float))
    moving = ~np.all(np.isnan(masses), axis=0)
    exact = np.full(masses.shape[1], math.nan)
    exact[moving] = np.nanmax(masses[:, moving], axis=0)
    return StandardMassComparison(
        estimate_kg=estimate_kg,
        exact_kg=exact,
        optimistic=np.where(moving, estimate_kg < exact, False),
    )
