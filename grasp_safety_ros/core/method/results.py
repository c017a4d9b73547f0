"""The records of a ranking: a candidate grasp, its evaluation, the posture chosen for it and
the ranking of them all (below ``ranking`` and ``posture``, which fill them, and the analyses,
which read them)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
import pinocchio as pin

from .joint_trajectory import PlannedJointTrajectory


@dataclass(frozen=True)
class Grasp:
    """A candidate grasp.

    Attributes:
        transform_tip_to_object: Pose of the tip frame in the object frame.
        name: Optional label.
        joint_trajectory: A planned arm joint trajectory to evaluate instead of following
            the object trajectory by IK (see ``joint_trajectory``); None: IK.
    """

    transform_tip_to_object: pin.SE3
    name: str = ""
    joint_trajectory: PlannedJointTrajectory | None = None


@dataclass(frozen=True)
class GraspEvaluation:
    """Effective mass of one grasp along the trajectory.

    Per-sample arrays have one row per sample when feasible, none when infeasible.

    Attributes:
        index: Position in the candidate list.
        name: Label of the grasp.
        feasible: Whether the tip trajectory can be followed.
        reason: Why not, when infeasible; empty otherwise.
        score: Aggregate of the effective mass (kg, or kg s for ``integral``); NaN if infeasible.
        times_s: Sample times [s].
        joint_positions: Chain joint positions [rad or m], chain order; continuous joints
            unwrapped (continuous along the motion from the IK seed, or the planner's own).
        directions_in_base: Unit direction of tip motion, base axes.
        effective_mass_kg: Effective mass along that direction [kg].
        direction_is_worst_case: True where the tip does not translate and the direction of
            largest effective mass was used instead.
        tip_speed_m_s: Tip speed along the trajectory [m/s].
        ik_iterations: Gauss-Newton iterations per sample.
        links_only_effective_mass_kg: Effective mass of the links alone (armature left out, a
            lower bound) [kg]; the same array as ``effective_mass_kg`` when the chain has no
            armature (None given: that array).
        planned_joint_rates: A planned trajectory's joint velocities [rad/s or m/s] and
            accelerations at the samples, of the interpolation the analysis used (its own
            velocities, else the cubic spline through its positions); None (IK): rates are
            fitted for execution (method.executable).
    """

    index: int
    name: str
    feasible: bool
    reason: str
    score: float
    times_s: np.ndarray
    joint_positions: np.ndarray
    directions_in_base: np.ndarray
    effective_mass_kg: np.ndarray
    direction_is_worst_case: np.ndarray
    tip_speed_m_s: np.ndarray
    ik_iterations: np.ndarray
    # None given: __post_init__ puts effective_mass_kg there (the attribute is always an array)
    links_only_effective_mass_kg: np.ndarray = None  # type: ignore[assignment]
    planned_joint_rates: tuple[np.ndarray, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.links_only_effective_mass_kg is None:
            object.__setattr__(self, "links_only_effective_mass_kg", self.effective_mass_kg)

    @property
    def peak_effective_mass_kg(self) -> float:
        """Largest per-sample effective mass [kg]; NaN if infeasible."""
        return float(self.effective_mass_kg.max()) if self.feasible else float("nan")

    @property
    def mean_effective_mass_kg(self) -> float:
        """Mean per-sample effective mass [kg]; NaN if infeasible."""
        return float(self.effective_mass_kg.mean()) if self.feasible else float("nan")


@dataclass(frozen=True)
class FollowedPosture:
    """A start posture followed along the whole trajectory (GraspSafetyEvaluator's
    ``follow_postures``): whether it is feasible and its score, and its GraspEvaluation built
    on demand, as posture selection needs it for the kept posture only (``score`` and
    ``feasible`` are the evaluation's, bit for bit).

    Attributes:
        feasible: Whether the whole trajectory is feasible.
        score: The score (as GraspEvaluation.score); NaN if infeasible.
        build: Makes the GraspEvaluation (call ``evaluation()``).
    """

    feasible: bool
    score: float
    build: Callable[[], GraspEvaluation]

    @classmethod
    def of(cls, evaluation: GraspEvaluation) -> FollowedPosture:
        """An evaluation already built."""
        return cls(evaluation.feasible, evaluation.score, partial(_given, evaluation))

    def evaluation(self) -> GraspEvaluation:
        """The posture's GraspEvaluation (built at each call)."""
        return self.build()


def _given(evaluation: GraspEvaluation) -> GraspEvaluation:
    return evaluation


SAMPLE_ARRAYS = (
    "times_s",
    "joint_positions",
    "directions_in_base",
    "effective_mass_kg",
    "direction_is_worst_case",
    "tip_speed_m_s",
    "ik_iterations",
)
"""The GraspEvaluation fields that are arrays over the samples (axis 0), as the ranking
gives them (links_only_effective_mass_kg defaults to effective_mass_kg)."""


@dataclass(frozen=True)
class Ranking:
    """Grasps ranked by score, safest (lowest) first.

    Attributes:
        joint_names: Chain joint names, the column order of ``joint_positions``.
        metric: The aggregate used.
        order: Indices of the feasible grasps, safest first (ties keep input order).
        evaluations: One per candidate, in candidate order.
        postures: How each candidate's posture was chosen (core.method.posture), in candidate
            order; empty when posture selection was not run.
        backend: What ran: ``compiled`` or ``python``, with the reason when ``auto`` fell
            back, e.g. ``python (numba not installed)``; empty when not recorded.
        armature_given: Whether the chain's armature (reflected rotor inertia) was given,
            zeros included (RobotModel.armature_given); False: not given, the effective masses
            are the links' only (a lower bound, robot.NO_ARMATURE_NOTE).
    """

    joint_names: tuple[str, ...]
    metric: str
    order: tuple[int, ...]
    evaluations: tuple[GraspEvaluation, ...]
    postures: tuple[PostureSelection, ...] = ()
    backend: str = ""
    armature_given: bool = False


SCORE_CRITERION = "score"
"""PostureSelection.criterion of selection by the tip score (the default)."""


@dataclass(frozen=True)
class PostureSelection:
    """How one grasp's posture was chosen.

    Attributes:
        index: Position in the candidate list.
        restarts: Restarts asked for (besides the single IK).
        score: Score of the kept posture (the evaluation's score); NaN if infeasible.
        score_single_ik: Score of the paper's single IK from the configured seed; NaN when
            that one is infeasible.
        score_range: (lowest, highest) score over the feasible postures found (with
            ``PostureConfig.early_stop``, the default: those followed to the end); NaN if
            none.
        start_positions: (n,) joint positions at t = 0 of the kept posture [rad or m], chain
            order; empty if infeasible.
        postures_tried: Distinct start postures followed along the trajectory (the single
            IK's counts as one, also when it fails).
        postures_feasible: Of those, the ones whose whole trajectory is feasible (with
            ``PostureConfig.early_stop``: not counting those stopped early).
        postures_stopped: Of those, the ones stopped early (``PostureConfig.early_stop``):
            their score's lower bound already exceeded that of a feasible posture found, so
            they could only lose; neither feasible nor infeasible.
        selected: Which of the tried postures was kept (0: the single IK's); -1 if none.
        criterion: What chose the posture: SCORE_CRITERION or a posture criterion's name
            (core.method.posture.PostureCriterion).
        criterion_value: The kept posture's value of it (its score for SCORE_CRITERION; the
            criterion's unit, e.g. N); NaN if infeasible.
        criterion_single_ik: The single IK's value of it; NaN when that one is infeasible.
    """

    index: int
    restarts: int
    score: float
    score_single_ik: float
    score_range: tuple[float, float]
    start_positions: np.ndarray
    postures_tried: int
    postures_feasible: int
    selected: int
    criterion: str = SCORE_CRITERION
    criterion_value: float = math.nan
    criterion_single_ik: float = math.nan
    postures_stopped: int = 0
