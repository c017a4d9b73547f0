"""Use the arm's redundancy to lower the effective mass along the trajectory, smoothly.

For a chain with more joints than the 6 tip-pose coordinates, the tip pose leaves a self-motion
manifold free, and U(q) = M_eff(q) (the effective mass along the sample's fixed direction of
motion u, or the largest one where the evaluation used the worst direction) varies along it;
the paper's commented-out section sketches a gradient of U in the null space of the tip's
6 x n Jacobian J. Descending it sample by sample gives the lowest U at each sample but not a
motion a robot can execute: the posture keeps drifting along the manifold at the first samples,
where the quintic barely moves (ds/dt ≈ 0), and a drift of a few 0.01 rad per 0.02 s sample
means joint accelerations of hundreds of rad/s² (Baxter, book grasp at −0.1 m: 743 rad/s² and
a 432 N m peak torque against 2.2 rad/s² and 46 N m without it). So the null-space motion is
optimised here as one smooth profile of the path parameter s:

    q(s_i) = Π_i(q_IK(s_i) ⊕ δ(s_i)),    δ(s) = Σ_k B_k(s) D_k,

B_k the Bernstein polynomials of degree d = ``profile_degree`` on s in [0, 1] (a partition of
unity, |δ'| <= d·max|ΔD|, |δ''| <= d(d−1)·max|Δ²D|), D_k in R^n joint-space control offsets,
Π_i the minimum-norm Gauss-Newton re-projection onto sample i's tip pose (to 1e-10 m / rad; it
removes the part of δ that would move the tip). Why this form:

- The start posture is free (the arm is at rest before the motion), so δ(0) = D_0 is any
  offset: the first control offset sets the posture, the others how it evolves.
- δ is a function of s, not of t: the null-space velocity is δ'(s)·ṡ and its acceleration
  δ''(s)·ṡ² + δ'(s)·s̈. Both vanish where the task motion does (the arm still starts and stops
  at rest, with zero acceleration) and are bounded everywhere by the profile's derivatives.
- A trial profile is accepted only if the resolved q(t) is as executable as the original:
  its peak joint speed and peak joint acceleration (over joints and samples, from differences
  over s with the chain rule, as core.effort computes the null-space part) at most
  ``max_rate_ratio`` times the original (IK) trajectory's, and its peak joint torques (RNEA of
  robot + object, gravity on) within ``max_effort_fraction`` of the URDF effort limits, or not
  above the original's peak at a joint whose original peak is already higher. The posture
  change alters gravity torques, so this matters even for slow motions.

Optimisation: D starts at 0 (the IK trajectory) and follows steepest descent on the score (the
``metric`` aggregate of U): d score / d D_k = Σ_i w_i B_k(s_i) g_i, w_i = d score / d U_i and
g_i = N_i ∇U_i the null-space gradient at sample i (central differences of U along an
orthonormal basis of ker J; to first order the re-projection's derivative is the projector onto
ker J). Each trial shifts every sample by its offset change from the current trajectory and
re-projects. The step (largest joint-space 2-norm of the offset change over the samples) is
halved on refusal and doubled back after an accepted trial. A trial is accepted only if every
sample re-projects, stays inside the joint limits, within ``max_joint_step`` of the previous
sample (and, if asked, within the joint velocity limits between samples), meets the bounds
above, has U_i <= (1 + ``max_sample_increase``)·U_i,original, and the score decreases strictly.
Refusals steer the next trial: samples whose U rose get extra weight in the descent (up to
MAX_REWEIGHTINGS times per iteration), a rate or torque violation lowers the degree of the
descent direction (a smoother change of the profile), anything else halves the step. It stops
after ``iterations`` steps, when no trial is accepted, or when an iteration lowers the score by
less than ``relative_tolerance`` of it.

Guarantees: the tip pose of every sample is kept (to the re-projection tolerance), joint
limits, steps, rate and torque bounds hold, the score is strictly lower or, if no trial is
accepted, the IK trajectory is returned as it is. The per-sample bound is relaxed by
``max_sample_increase`` (default 1e-5, relative) on purpose: where the IK posture happens to be
a sample's own optimum (the null-space gradient changes sign along the path), a strict bound
forces the smooth profile through zero offset exactly at that sample, and the descent then
finds almost nothing (no gain at all for the Baxter book grasp at −0.1 m sampled at 0.02 s).
0 restores the strict bound. Chains with at most 6 joints are returned unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import read_only
from ..method.effective_mass import augmented_model, translational_mobilities_in_base
from ..method.packed import ChainArrays
from ..method.ranking import Grasp, GraspEvaluation, aggregate, check_metric, positions_along
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import Trajectory
from .null_space import MotionBounds, SampleProblem, bernstein_basis, metric_weights

TASK_DIMENSION = 6
"""Tip pose coordinates the trajectory fixes (position and orientation)."""


MAX_REWEIGHTINGS = 24
"""Trials per iteration that raise the weight of samples whose U rose, before halving."""

MAX_PROFILE_DEGREE = 12
"""Highest Bernstein degree accepted for the null-space profile (conditioning)."""


@dataclass(frozen=True)
class RedundancyConfig:
    """Settings of the null-space optimisation.

    Attributes:
        enabled: False returns every evaluation unchanged (the parameter that switches it on).
        iterations: Largest number of descent steps on the null-space profile.
        profile_degree: Degree of the Bernstein polynomial in s of the joint offset profile
            (degree + 1 control offsets; 0 is one constant offset: a new start posture only).
        max_rate_ratio: Largest ratio of the resolved to the original trajectory's peak joint
            speed, and of its peak joint acceleration (>= 1).
        max_effort_fraction: Largest peak joint torque as a fraction of the URDF effort limit
            (a joint whose original peak is higher may keep that peak; unknown limits: free).
        max_sample_increase: Largest relative rise of the effective mass allowed at any one
            sample (>= 0; the score itself always decreases strictly).
        relative_tolerance: Stop when an iteration lowers the score by less than this fraction.
        initial_step_rad: Largest step (joint-space 2-norm of the offset change at the sample
            that moves most) [rad or m].
        min_step_rad: Smallest step tried before stopping [rad or m].
        finite_difference_step_rad: Step of the central differences of U [rad or m].
        max_joint_step: Largest joint change between consecutive samples [rad or m].
        check_velocity_limits: Also keep joint speeds between samples within the URDF limits.
        metric: Aggregate used for ``score`` and ``original_score`` (core.ranking.METRICS).
    """

    enabled: bool = True
    iterations: int = 60
    profile_degree: int = 5
    max_rate_ratio: float = 1.5
    max_effort_fraction: float = 1.0
    max_sample_increase: float = 1e-5
    relative_tolerance: float = 1e-5
    initial_step_rad: float = 0.05
    min_step_rad: float = 1e-4
    finite_difference_step_rad: float = 1e-6
    max_joint_step: float = 0.5
    check_velocity_limits: bool = True
    metric: str = "mean"

    def __post_init__(self) -> None:
        for name in ("enabled", "check_velocity_limits"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidInputError(
                    f"redundancy.{name}", f"must be true or false, got {getattr(self, name)!r}"
                )
        if not _is_int(self.iterations) or self.iterations < 0:
            raise InvalidInputError(
                "redundancy.iterations", f"must be an integer >= 0, got {self.iterations!r}"
            )
        if not _is_int(self.profile_degree) or not 0 <= self.profile_degree <= MAX_PROFILE_DEGREE:
            raise InvalidInputError(
                "redundancy.profile_degree",
                f"must be an integer in [0, {MAX_PROFILE_DEGREE}], got {self.profile_degree!r}",
            )
        for name, minimum, strict in (
            ("initial_step_rad", 0.0, True),
            ("min_step_rad", 0.0, True),
            ("finite_difference_step_rad", 0.0, True),
            ("max_joint_step", 0.0, True),
            ("max_effort_fraction", 0.0, True),
            ("max_rate_ratio", 1.0, False),
            ("max_sample_increase", 0.0, False),
            ("relative_tolerance", 0.0, False),
        ):
            value = getattr(self, name)
            if not (_is_number(value) and (value > minimum if strict else value >= minimum)):
                raise InvalidInputError(
                    f"redundancy.{name}",
                    f"must be a finite number {'>' if strict else '>='} {minimum:g}, "
                    f"got {value!r}",
                )
        if self.min_step_rad > self.initial_step_rad:
            raise InvalidInputError(
                "redundancy.min_step_rad",
                f"must be in (0, initial_step_rad={self.initial_step_rad:g}], "
                f"got {self.min_step_rad:g}",
            )
        check_metric(self.metric, "redundancy.metric")


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and bool(np.isfinite(value))
    )


@dataclass(frozen=True)
class RedundancyResolution:
    """Effective mass of one grasp with and without the null-space optimisation (N samples).

    Attributes:
        index, name, feasible: As in the grasp's GraspEvaluation.
        applied: True when the optimisation ran (redundant chain, feasible grasp, enabled).
        reason: Why it did not run; empty when it ran.
        times_s: (N,) sample times [s].
        joint_positions: (N, n) optimised chain joint positions [rad or m], chain order.
        effective_mass_kg: (N,) effective mass with the optimised positions [kg].
        original_joint_positions: (N, n) the evaluation's (IK) joint positions.
        original_effective_mass_kg: (N,) the evaluation's effective mass [kg].
        score: Aggregate (``metric``) of effective_mass_kg; NaN if infeasible.
        original_score: Aggregate of original_effective_mass_kg; NaN if infeasible.
        metric: The aggregate used.
        samples_improved: Samples where the effective mass decreased.
        max_position_error_m: Largest tip position error of the returned positions [m]
            (NaN when not applied: then they are the IK's, within its tolerance).
        max_orientation_error_rad: Largest tip orientation error of them [rad] (likewise).
    """

    index: int
    name: str
    feasible: bool
    applied: bool
    reason: str
    times_s: np.ndarray
    joint_positions: np.ndarray
    effective_mass_kg: np.ndarray
    original_joint_positions: np.ndarray
    original_effective_mass_kg: np.ndarray
    score: float
    original_score: float
    metric: str
    samples_improved: int
    max_position_error_m: float
    max_orientation_error_rad: float

    @property
    def reduction_kg(self) -> np.ndarray:
        """(N,) original minus optimised effective mass [kg] (>= −max_sample_increase·original).

        Negative entries (at most the configured relative rise) can occur; the score is lower.
        """
        return self.original_effective_mass_kg - self.effective_mass_kg


def _step_bound(robot: RobotModel, config: RedundancyConfig, elapsed_s: float) -> np.ndarray:
    bound = np.full(robot.num_joints, config.max_joint_step)
    limits = robot.velocity_limits
    if config.check_velocity_limits and elapsed_s > 0:
        usable = np.isfinite(limits) & (limits > 0)
        bound = np.where(usable, np.minimum(bound, limits * elapsed_s), bound)
    return bound


@dataclass(frozen=True)
class _Rejection:
    """Why a trial trajectory was refused: ``path`` (re-projection, joint limits, steps),
    ``motion`` (speed, acceleration, torque), ``mass`` (U above the original at ``samples``)
    or ``score`` (not lower)."""

    reason: str
    samples: np.ndarray | None = None


@dataclass
class _Trajectory:
    """One candidate resolved trajectory: configurations, U per sample and the score."""

    q: list[np.ndarray]
    masses: np.ndarray
    score: float


def resolve_redundancy(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    trajectory: Trajectory,
    config: RedundancyConfig | None = None,
    model: pin.Model | None = None,
    chain: ChainArrays | None = None,
) -> RedundancyResolution:
    """Lower the effective mass of one evaluated grasp through a smooth null-space motion.

    ``grasp`` and ``trajectory`` must be the ones the evaluation was computed with;
    ``model``: their ``augmented_model``, when already built (shared across analyses);
    ``chain``: ``compiled.chain_arrays(robot)`` to take each trial's effective masses from the
    compiled mobility kernel, all samples in one call (numba; equal to Pinocchio's to rounding).
    The null-space gradients stay on Pinocchio: their central differences divide rounding by
    2 h (h = ``finite_difference_step_rad``), so a change of summation order in U would move
    them, and every later trial, by far more than rounding.
    """
    config = config or RedundancyConfig()
    original = np.asarray(evaluation.joint_positions, dtype=float)
    masses = np.asarray(evaluation.effective_mass_kg, dtype=float)
    reason = _skip_reason(robot, evaluation, config)
    if reason:
        return _unchanged(evaluation, config, reason)
    if model is None:
        model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    problem = SampleProblem(robot, model, config.finite_difference_step_rad)
    times = np.asarray(evaluation.times_s, dtype=float)
    s_values, s_rate, s_accel = trajectory.path_parameter(times)
    tip = trajectory.tip_motion(grasp.transform_tip_to_object, times)
    targets = [
        robot.transform_base_to_world * pin.SE3(rotation, position)
        for rotation, position in zip(tip.rotations, tip.positions, strict=True)
    ]
    q_original = [robot.q_from_positions(p) for p in original]
    checks = _TrialChecks(
        robot=robot,
        problem=problem,
        targets=targets,
        bounds=[_step_bound(robot, config, times[i] - times[i - 1]) for i in range(1, len(times))],
        motion=MotionBounds(
            robot,
            model,
            q_original,
            s_values,
            s_rate,
            s_accel,
            config.max_rate_ratio,
            config.max_effort_fraction,
        ),
        object_inertia=object_inertia,
        transform_tip_to_object=grasp.transform_tip_to_object,
        chain=chain,
        directions=np.asarray(evaluation.directions_in_base, dtype=float),
        worst=np.asarray(evaluation.direction_is_worst_case, dtype=bool),
        ceiling=masses * (1.0 + config.max_sample_increase),
        times=times,
        metric=config.metric,
    )
    initial = _Trajectory(q_original, masses, aggregate(masses, times, config.metric))
    best = _descend(checks, initial, s_values, config)
    return _resolution(checks, evaluation, initial, best, config.metric)


def _skip_reason(robot: RobotModel, evaluation: GraspEvaluation, config: RedundancyConfig) -> str:
    """Why the optimisation does not run for this grasp; empty when it runs."""
    if not evaluation.feasible:
        return "grasp is infeasible"
    if not config.enabled:
        return "redundancy resolution is switched off"
    if robot.model.nv <= TASK_DIMENSION:
        return f"no redundancy: {robot.model.nv} joints for a {TASK_DIMENSION}-D tip pose"
    return ""


@dataclass(frozen=True)
class _TrialChecks:
    """One grasp's fixed data a trial trajectory is built from and checked against.

    ``targets``: each sample's tip pose in the world; ``bounds``: the largest joint step into
    each sample after the first; ``ceiling``: the largest U allowed per sample [kg];
    ``chain``: compiled chain arrays for the effective masses (None: Pinocchio's).
    """

    robot: RobotModel
    problem: SampleProblem
    targets: list[pin.SE3]
    bounds: list[np.ndarray]
    motion: MotionBounds
    object_inertia: ObjectInertia
    transform_tip_to_object: pin.SE3
    chain: ChainArrays | None
    directions: np.ndarray
    worst: np.ndarray
    ceiling: np.ndarray
    times: np.ndarray
    metric: str

    def candidate(self, current: _Trajectory, offsets: np.ndarray) -> _Trajectory | _Rejection:
        """Shift every sample by its offset and re-project; the trajectory if all checks pass."""
        q_new: list[np.ndarray] = []
        for i, (q, offset) in enumerate(zip(current.q, offsets, strict=True)):
            projected = self.problem.project(
                pin.integrate(self.robot.model, q, offset), self.targets[i]
            )
            if (
                projected is None
                or not self.problem.within_limits(projected)
                or (i and not _step_ok(self.robot, q_new[-1], projected, self.bounds[i - 1]))
            ):
                return _Rejection("path")
            q_new.append(projected)
        if not self.motion.ok(q_new):
            return _Rejection("motion")
        u = self.objectives(q_new)
        above = u > self.ceiling
        if np.any(above):
            return _Rejection("mass", above)
        trial = _Trajectory(q_new, u, aggregate(u, self.times, self.metric))
        return trial if trial.score < current.score else _Rejection("score")

    def objectives(self, q: list[np.ndarray]) -> np.ndarray:
        """(N,) U of configurations ``q`` [kg]: compiled kernel if ``chain``, else Pinocchio."""
        if self.chain is not None:
            return _objectives(
                translational_mobilities_in_base(
                    self.robot,
                    self.object_inertia,
                    self.transform_tip_to_object,
                    np.array(q),
                    self.chain,
                ),
                self.directions,
                self.worst,
            )
        return np.array(
            [
                self.problem.objective(qi, d, bool(w))
                for qi, d, w in zip(q, self.directions, self.worst, strict=True)
            ]
        )

    def gradients(self, q: list[np.ndarray]) -> np.ndarray:
        """(N, n) null-space gradients of U at configurations ``q``."""
        return np.array(
            [
                self.problem.null_space_gradient(qi, d, bool(w))
                for qi, d, w in zip(q, self.directions, self.worst, strict=True)
            ]
        )


def _descend(
    checks: _TrialChecks, best: _Trajectory, s_values: np.ndarray, config: RedundancyConfig
) -> _Trajectory:
    """Steepest descent on the profile's control offsets from ``best``; the best trajectory."""
    times = checks.times
    bases = [bernstein_basis(degree, s_values) for degree in range(config.profile_degree + 1)]
    degree, step = config.profile_degree, config.initial_step_rad
    penalty = np.zeros(len(times))  # extra weight of samples whose U rose in a trial
    for _ in range(config.iterations):
        gradients = checks.gradients(best.q)
        weights = metric_weights(best.masses, times, config.metric)
        previous_score, reweightings = best.score, 0
        while step >= config.min_step_rad:
            basis = bases[degree]
            total = weights + penalty
            descent = -(basis @ (basis.T @ (total[:, None] * gradients)))  # (N, n)
            norm = float(np.linalg.norm(descent, axis=1).max())
            if norm < 1e-12:
                break
            trial = checks.candidate(best, step / norm * descent)
            if isinstance(trial, _Trajectory):
                best = trial
                step = min(2.0 * step, config.initial_step_rad)
                degree = min(degree + 1, config.profile_degree)
                break
            if trial.reason == "mass" and reweightings < MAX_REWEIGHTINGS:
                reweightings += 1
                penalty[trial.samples] = 2.0 * penalty[trial.samples] + weights.max()
            elif trial.reason == "motion" and degree > 0:
                degree -= 1
            else:
                step *= 0.5
        if best.score >= previous_score * (1.0 - config.relative_tolerance):
            break
    return best


def _resolution(
    checks: _TrialChecks,
    evaluation: GraspEvaluation,
    initial: _Trajectory,
    best: _Trajectory,
    metric: str,
) -> RedundancyResolution:
    """The applied resolution of ``best`` against the evaluation's ``initial`` trajectory."""
    times = checks.times
    original = np.asarray(evaluation.joint_positions, dtype=float)
    masses = initial.masses
    if best.q is initial.q:
        positions, result_masses = original, masses
    else:
        positions = positions_along(checks.robot, np.asarray(best.q), original[0])  # unwrapped
        result_masses = best.masses
    errors = np.array(
        [
            checks.problem.pose_error(q, target)[1:]
            for q, target in zip(best.q, checks.targets, strict=True)
        ]
    )
    return RedundancyResolution(
        index=evaluation.index,
        name=evaluation.name,
        feasible=True,
        applied=True,
        reason="",
        times_s=read_only(times, copy=True),
        joint_positions=read_only(positions, copy=True),
        effective_mass_kg=read_only(result_masses, copy=True),
        original_joint_positions=read_only(original, copy=True),
        original_effective_mass_kg=read_only(masses, copy=True),
        score=aggregate(result_masses, times, metric),
        original_score=aggregate(masses, times, metric),
        metric=metric,
        samples_improved=int(np.sum(result_masses < masses)),
        max_position_error_m=float(errors[:, 0].max()),
        max_orientation_error_rad=float(errors[:, 1].max()),
    )


def _objectives(mobilities: np.ndarray, directions: np.ndarray, worst: np.ndarray) -> np.ndarray:
    """``SampleProblem.objective`` of (N, 3, 3) mobilities [1/kg] at once: 1 / (dᵀ A d), or
    1 / the smallest eigenvalue of A where ``worst`` [kg]."""
    masses = 1.0 / np.einsum("ni,nij,nj->n", directions, mobilities, directions)
    if worst.any():
        flagged = mobilities[worst]
        masses[worst] = (
            1.0 / np.linalg.eigvalsh(0.5 * (flagged + flagged.transpose(0, 2, 1)))[:, 0]
        )
    return masses


def _step_ok(robot: RobotModel, previous: np.ndarray, q: np.ndarray, bound: np.ndarray) -> bool:
    return bool(np.all(np.abs(pin.difference(robot.model, previous, q)) <= bound))


def _unchanged(
    evaluation: GraspEvaluation, config: RedundancyConfig, reason: str
) -> RedundancyResolution:
    times = np.asarray(evaluation.times_s, dtype=float)
    masses = np.asarray(evaluation.effective_mass_kg, dtype=float)
    score = aggregate(masses, times, config.metric) if evaluation.feasible else float("nan")
    return RedundancyResolution(
        index=evaluation.index,
        name=evaluation.name,
        feasible=evaluation.feasible,
        applied=False,
        reason=reason,
        times_s=read_only(times, copy=True),
        joint_positions=read_only(evaluation.joint_positions, copy=True),
        effective_mass_kg=read_only(masses, copy=True),
        original_joint_positions=read_only(evaluation.joint_positions, copy=True),
        original_effective_mass_kg=read_only(masses, copy=True),
        score=score,
        original_score=score,
        metric=config.metric,
        samples_improved=0,
        max_position_error_m=float("nan"),
        max_orientation_error_rad=float("nan"),
    )
