"""Use the arm's redundancy to lower the effective mass along the trajectory.

For a chain with more joints than the 6 tip-pose coordinates, the tip pose leaves a self-motion
manifold free. At each sample, starting from the IK solution, gradient steps on U(q) = M_eff(q)
(the effective mass along the sample's fixed direction of motion u, or the largest one where
the evaluation used the worst direction) are taken in the null space of the tip's 6 x n
Jacobian, as the paper's commented-out section sketches:

    Δq = −h · N ∇U / |N ∇U|,  N ∇U from central differences of U along a null-space basis,

each followed by a Gauss-Newton re-projection onto the sample's tip pose (to 1e-10 m / rad).
A step is kept only if U decreases strictly and the configuration stays inside the joint
limits, within ``max_joint_step`` of the previous sample's configuration and (if asked) within
the joint velocity limits; otherwise h is halved, down to ``min_step_rad``. The optimised
posture is carried along the trajectory: sample i starts from the IK solution shifted by the
previous sample's null-space offset (then by half of it, then from the IK solution itself),
and the first start that ends at or below the IK solution's effective mass is kept; if none
does, the IK solution itself is kept. So M_eff never rises at any sample and the tip pose keeps
the IK tolerance. If even the IK solution is out of reach of the previous optimised sample, the
grasp is returned unchanged with a reason. Chains with at most 6 joints are returned unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .effective_mass import augmented_model
from .exceptions import InvalidInputError
from .exposed_points import point_mobility_in_base
from .inertia import ObjectInertia
from .ranking import Grasp, GraspEvaluation, aggregate, check_metric
from .robot import RobotModel
from .trajectory import ObjectTrajectory

TASK_DIMENSION = 6
"""Tip pose coordinates the trajectory fixes (position and orientation)."""

PROJECTION_TOLERANCE = 1e-10
"""Re-projection onto the tip pose stops below this position [m] and orientation [rad] error."""


@dataclass(frozen=True)
class RedundancyConfig:
    """Settings of the null-space optimisation.

    Attributes:
        enabled: False returns every evaluation unchanged (the parameter that switches it on).
        iterations_first_sample: Gradient steps at the first sample (sets the posture).
        iterations_per_sample: Gradient steps at each later sample.
        initial_step_rad: First null-space step length (joint-space 2-norm) [rad or m].
        min_step_rad: Smallest step tried before giving up at a sample [rad or m].
        finite_difference_step_rad: Step of the central differences of U [rad or m].
        max_joint_step: Largest joint change between consecutive samples [rad or m].
        check_velocity_limits: Also keep joint speeds between samples within the URDF limits.
        metric: Aggregate used for ``score`` and ``original_score`` (core.ranking.METRICS).
    """

    enabled: bool = True
    iterations_first_sample: int = 100
    iterations_per_sample: int = 10
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
        for name in ("iterations_first_sample", "iterations_per_sample"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise InvalidInputError(
                    f"redundancy.{name}", f"must be an integer >= 0, got {value!r}"
                )
        for name in (
            "initial_step_rad",
            "min_step_rad",
            "finite_difference_step_rad",
            "max_joint_step",
        ):
            value = getattr(self, name)
            if not (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and np.isfinite(value)
                and value > 0
            ):
                raise InvalidInputError(
                    f"redundancy.{name}", f"must be a finite number > 0, got {value!r}"
                )
        if self.min_step_rad > self.initial_step_rad:
            raise InvalidInputError(
                "redundancy.min_step_rad",
                f"must be in (0, initial_step_rad={self.initial_step_rad:g}], "
                f"got {self.min_step_rad:g}",
            )
        check_metric(self.metric, "redundancy.metric")


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
        """(N,) original minus optimised effective mass [kg] (>= 0)."""
        return self.original_effective_mass_kg - self.effective_mass_kg


def _read_only(array: np.ndarray) -> np.ndarray:
    array = np.array(array)
    array.setflags(write=False)
    return array


class _SampleProblem:
    """U(q), null-space directions and pose re-projection for one grasp."""

    def __init__(self, robot: RobotModel, model: pin.Model, config: RedundancyConfig) -> None:
        self.robot, self.model, self.config = robot, model, config
        self.data = model.createData()
        self.kinematics = robot.model.createData()
        self.lower = robot.lower_limits
        self.upper = robot.upper_limits
        self.origin = np.zeros((1, 3))

    def objective(self, q: np.ndarray, direction: np.ndarray, worst: bool) -> float:
        mobility = point_mobility_in_base(self.robot, self.model, self.data, q, self.origin)[0]
        if worst:
            return float(1.0 / np.linalg.eigvalsh(0.5 * (mobility + mobility.T))[0])
        return float(1.0 / (direction @ mobility @ direction))

    def pose_error(self, q: np.ndarray, target_in_world: pin.SE3) -> tuple[pin.SE3, float, float]:
        pin.forwardKinematics(self.robot.model, self.kinematics, q)
        current = pin.updateFramePlacement(
            self.robot.model, self.kinematics, self.robot.tip_frame_id
        )
        error = current.actInv(target_in_world)
        position = float(np.linalg.norm(error.translation))
        angle = float(np.linalg.norm(pin.log3(error.rotation)))
        return error, position, angle

    def project(self, q: np.ndarray, target_in_world: pin.SE3) -> np.ndarray | None:
        """Gauss-Newton (minimum-norm steps) onto the tip pose; None if it fails."""
        model = self.robot.model
        for _ in range(30):
            error_transform, position, angle = self.pose_error(q, target_in_world)
            if position <= PROJECTION_TOLERANCE and angle <= PROJECTION_TOLERANCE:
                return q
            error = pin.log6(error_transform).vector
            jacobian = pin.Jlog6(error_transform.inverse()) @ pin.computeFrameJacobian(
                model, self.kinematics, q, self.robot.tip_frame_id, pin.ReferenceFrame.LOCAL
            ).reshape(6, model.nv)
            step = np.linalg.lstsq(jacobian, error, rcond=1e-10)[0]
            if np.abs(step).max() > 0.5:
                return None
            q = pin.integrate(model, q, step)
        return None

    def null_space(self, q: np.ndarray) -> np.ndarray:
        """Orthonormal basis (n, n − rank) of the null space of the tip Jacobian."""
        model = self.robot.model
        jacobian = pin.computeFrameJacobian(
            model, self.kinematics, q, self.robot.tip_frame_id, pin.ReferenceFrame.LOCAL
        ).reshape(6, model.nv)
        _, singular_values, vt = np.linalg.svd(jacobian)
        rank = int(np.sum(singular_values > 1e-9 * max(singular_values[0], 1e-300)))
        return vt[rank:].T

    def within_limits(self, q: np.ndarray) -> bool:
        positions = self.robot.positions_from_q(q)
        return bool(np.all(positions >= self.lower) and np.all(positions <= self.upper))


def _step_bound(robot: RobotModel, config: RedundancyConfig, elapsed_s: float) -> np.ndarray:
    bound = np.full(robot.num_joints, config.max_joint_step)
    limits = robot.velocity_limits
    if config.check_velocity_limits and elapsed_s > 0:
        usable = np.isfinite(limits) & (limits > 0)
        bound = np.where(usable, np.minimum(bound, limits * elapsed_s), bound)
    return bound


def resolve_redundancy(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    trajectory: ObjectTrajectory,
    config: RedundancyConfig | None = None,
) -> RedundancyResolution:
    """Lower the effective mass of one evaluated grasp through its null-space motion.

    ``grasp`` and ``trajectory`` must be the ones the evaluation was computed with.
    """
    config = config or RedundancyConfig()
    original = np.asarray(evaluation.joint_positions, dtype=float)
    masses = np.asarray(evaluation.effective_mass_kg, dtype=float)
    if not evaluation.feasible:
        return _unchanged(evaluation, config, "grasp is infeasible")
    if not config.enabled:
        return _unchanged(evaluation, config, "redundancy resolution is switched off")
    if robot.model.nv <= TASK_DIMENSION:
        return _unchanged(
            evaluation,
            config,
            f"no redundancy: {robot.model.nv} joints for a {TASK_DIMENSION}-D tip pose",
        )
    model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    problem = _SampleProblem(robot, model, config)
    times = np.asarray(evaluation.times_s, dtype=float)
    s_values, _, _ = trajectory.path_parameter(times)
    poses, _ = trajectory.tip_path(grasp.transform_tip_to_object, s_values)
    directions = np.asarray(evaluation.directions_in_base, dtype=float)
    worst = np.asarray(evaluation.direction_is_worst_case, dtype=bool)
    q_original = [robot.q_from_positions(p) for p in original]
    q_result: list[np.ndarray] = []
    changed = np.zeros(len(times), dtype=bool)
    result_masses = masses.copy()
    for i, target in enumerate(poses):
        target_in_world = robot.transform_base_to_world * target
        reference = problem.objective(q_original[i], directions[i], bool(worst[i]))
        previous = q_result[i - 1] if i else None
        bound = _step_bound(robot, config, times[i] - times[i - 1]) if i else None
        starts: list[tuple[np.ndarray, float]] = []
        if previous is not None:
            offset = pin.difference(robot.model, q_original[i - 1], previous)
            for fraction in (1.0, 0.5) if np.any(offset) else ():
                start = problem.project(
                    pin.integrate(robot.model, q_original[i], fraction * offset), target_in_world
                )
                if (
                    start is not None
                    and problem.within_limits(start)
                    and _step_ok(robot, previous, start, bound)
                ):
                    starts.append((start, problem.objective(start, directions[i], bool(worst[i]))))
        starts.append((q_original[i], reference))
        best_q = q_original[i]
        iterations = config.iterations_per_sample if i else config.iterations_first_sample
        for start, start_u in starts:
            q_new, u_new = _descend(
                problem,
                start,
                start_u,
                target_in_world,
                directions[i],
                bool(worst[i]),
                previous,
                bound,
                iterations,
            )
            if u_new <= reference and q_new is not q_original[i]:
                best_q, changed[i], result_masses[i] = q_new, True, u_new
                break
            if q_new is q_original[i]:
                break  # the IK solution itself cannot be improved: keep it
        if previous is not None and not _step_ok(robot, previous, best_q, bound):
            # Even the IK solution is too far from the optimised previous sample: give up.
            return _unchanged(
                evaluation,
                config,
                f"optimised posture cannot rejoin the IK solution at t={times[i]:.3f} s "
                "within max_joint_step / velocity limits; kept the IK solution",
            )
        q_result.append(best_q)
    positions = np.array(
        [robot.positions_from_q(q) if changed[i] else original[i] for i, q in enumerate(q_result)]
    )
    errors = np.array(
        [
            problem.pose_error(q, robot.transform_base_to_world * p)[1:]
            for q, p in zip(q_result, poses, strict=True)
        ]
    )
    improved = changed & (result_masses < masses)
    return RedundancyResolution(
        index=evaluation.index,
        name=evaluation.name,
        feasible=True,
        applied=True,
        reason="",
        times_s=_read_only(times),
        joint_positions=_read_only(positions),
        effective_mass_kg=_read_only(result_masses),
        original_joint_positions=_read_only(original),
        original_effective_mass_kg=_read_only(masses),
        score=aggregate(result_masses, times, config.metric),
        original_score=aggregate(masses, times, config.metric),
        metric=config.metric,
        samples_improved=int(improved.sum()),
        max_position_error_m=float(errors[:, 0].max()),
        max_orientation_error_rad=float(errors[:, 1].max()),
    )


def _step_ok(
    robot: RobotModel, previous: np.ndarray, q: np.ndarray, bound: np.ndarray | None
) -> bool:
    if bound is None:
        return True
    return bool(np.all(np.abs(pin.difference(robot.model, previous, q)) <= bound))


def _descend(
    problem: _SampleProblem,
    q: np.ndarray,
    value: float,
    target_in_world: pin.SE3,
    direction: np.ndarray,
    worst: bool,
    previous: np.ndarray | None,
    bound: np.ndarray | None,
    iterations: int,
) -> tuple[np.ndarray, float]:
    """Null-space gradient descent with step halving; U never increases."""
    config, model = problem.config, problem.robot.model
    h = config.finite_difference_step_rad
    step = config.initial_step_rad
    for _ in range(iterations):
        basis = problem.null_space(q)
        if basis.shape[1] == 0:
            break
        gradient = np.array(
            [
                problem.objective(pin.integrate(model, q, h * z), direction, worst)
                - problem.objective(pin.integrate(model, q, -h * z), direction, worst)
                for z in basis.T
            ]
        ) / (2.0 * h)
        descent = -(basis @ gradient)
        norm = float(np.linalg.norm(descent))
        if norm < 1e-12:
            break
        descent /= norm
        while step >= config.min_step_rad:
            candidate = problem.project(pin.integrate(model, q, step * descent), target_in_world)
            if (
                candidate is not None
                and problem.within_limits(candidate)
                and (previous is None or _step_ok(problem.robot, previous, candidate, bound))
            ):
                candidate_value = problem.objective(candidate, direction, worst)
                if candidate_value < value:
                    q, value = candidate, candidate_value
                    step = min(2.0 * step, config.initial_step_rad)
                    break
            step *= 0.5
        else:
            break
    return q, value


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
        times_s=_read_only(times),
        joint_positions=_read_only(evaluation.joint_positions),
        effective_mass_kg=_read_only(masses),
        original_joint_positions=_read_only(evaluation.joint_positions),
        original_effective_mass_kg=_read_only(masses),
        score=score,
        original_score=score,
        metric=config.metric,
        samples_improved=0,
        max_position_error_m=float("nan"),
        max_orientation_error_rad=float("nan"),
    )
