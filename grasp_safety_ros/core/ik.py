"""Inverse kinematics of the tip frame along a trajectory (damped Gauss-Newton on SE(3))."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .exceptions import InvalidInputError
from .robot import RobotModel


@dataclass(frozen=True)
class IKConfig:
    """Settings of the IK solver.

    Attributes:
        position_tolerance_m: Converged when the tip position error is at most this [m].
        orientation_tolerance_rad: ... and the tip orientation error at most this [rad].
        max_iterations: Gauss-Newton iterations per sample.
        max_iteration_step: Largest joint change of one iteration (inf-norm) [rad or m].
        random_restarts: Random seeds tried for the first sample when the given seed fails.
        random_seed: Seed of those restarts (results are deterministic).
        max_joint_step: Largest joint change between consecutive samples before the
            trajectory counts as a jump (IK branch switch) [rad or m].
        check_velocity_limits: Refuse trajectories whose joint speeds exceed the URDF limits.
    """

    position_tolerance_m: float = 1e-6
    orientation_tolerance_rad: float = 1e-6
    max_iterations: int = 100
    max_iteration_step: float = 0.5
    random_restarts: int = 30
    random_seed: int = 0
    max_joint_step: float = 0.5
    check_velocity_limits: bool = True

    def __post_init__(self) -> None:
        positive = {
            "ik.position_tolerance_m": self.position_tolerance_m,
            "ik.orientation_tolerance_rad": self.orientation_tolerance_rad,
            "ik.max_iteration_step": self.max_iteration_step,
            "ik.max_joint_step": self.max_joint_step,
        }
        for name, value in positive.items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise InvalidInputError(name, f"must be a finite number > 0, got {value!r}")
        for name, value in {
            "ik.max_iterations": self.max_iterations,
            "ik.random_restarts": self.random_restarts,
        }.items():
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise InvalidInputError(name, f"must be an integer >= 0, got {value!r}")


@dataclass(frozen=True)
class IKTrajectoryResult:
    """Joint positions along a trajectory, or the reason it cannot be followed.

    Attributes:
        q: Pinocchio configurations, one row per solved sample.
        iterations: Gauss-Newton iterations per solved sample.
        reason: Empty when every sample was solved; otherwise why the trajectory fails.
    """

    q: np.ndarray
    iterations: np.ndarray
    reason: str

    @property
    def feasible(self) -> bool:
        """True when every sample was solved within tolerance and limits."""
        return not self.reason


class IKSolver:
    """Tip-pose IK for a RobotModel, warm-started along trajectories."""

    def __init__(self, robot: RobotModel, config: IKConfig | None = None) -> None:
        self.robot = robot
        self.config = config or IKConfig()
        self.data = robot.model.createData()
        model = robot.model
        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        for joint in model.joints[1:]:
            if joint.nq != joint.nv:  # continuous joint: (cos, sin), no limit
                lower[joint.idx_q : joint.idx_q + joint.nq] = -np.inf
                upper[joint.idx_q : joint.idx_q + joint.nq] = np.inf
        self._lower_q, self._upper_q = lower, upper

    def solve(self, transform_tip_to_base: pin.SE3, q_init: np.ndarray) -> tuple[np.ndarray, bool, int]:
        """Solve one tip pose from ``q_init``.

        Returns:
            The configuration, whether it converged to the tolerances, and the iterations.
        """
        model, data, config = self.robot.model, self.data, self.config
        frame_id = self.robot.tip_frame_id
        target_in_world = self.robot.transform_base_to_world * transform_tip_to_base
        q = np.clip(np.array(q_init, dtype=float), self._lower_q, self._upper_q)
        n = model.nv
        for iteration in range(config.max_iterations + 1):
            pin.forwardKinematics(model, data, q)
            current = pin.updateFramePlacement(model, data, frame_id)
            error_transform = current.actInv(target_in_world)
            error = pin.log6(error_transform).vector
            if (
                np.linalg.norm(error_transform.translation) <= config.position_tolerance_m
                and np.linalg.norm(error[3:]) <= config.orientation_tolerance_rad
            ):
                return q, True, iteration
            if iteration == config.max_iterations:
                break
            frame_jacobian = pin.computeFrameJacobian(
                model, data, q, frame_id, pin.ReferenceFrame.LOCAL
            ).reshape(6, n)  # eigenpy returns a 6x1 matrix as a vector
            jacobian = pin.Jlog6(error_transform.inverse()) @ frame_jacobian
            damping = 1e-12 + 1e-3 * float(error @ error)
            if n >= 6:
                step = jacobian.T @ np.linalg.solve(
                    jacobian @ jacobian.T + damping * np.eye(6), error
                )
            else:
                step = np.linalg.solve(jacobian.T @ jacobian + damping * np.eye(n), jacobian.T @ error)
            largest = float(np.abs(step).max())
            if largest > config.max_iteration_step:
                step *= config.max_iteration_step / largest
            q = np.clip(pin.integrate(model, q, step), self._lower_q, self._upper_q)
        return q, False, config.max_iterations

    def solve_first(self, transform_tip_to_base: pin.SE3, seed_q: np.ndarray) -> tuple[np.ndarray, bool, int]:
        """Solve from the seed, then from deterministic random restarts within the limits."""
        q, converged, iterations = self.solve(transform_tip_to_base, seed_q)
        if converged:
            return q, True, iterations
        rng = np.random.default_rng(self.config.random_seed)
        lower = np.where(np.isfinite(self.robot.lower_limits), self.robot.lower_limits, -np.pi)
        upper = np.where(np.isfinite(self.robot.upper_limits), self.robot.upper_limits, np.pi)
        total = iterations
        for _ in range(self.config.random_restarts):
            start = self.robot.q_from_positions(rng.uniform(lower, upper))
            q, converged, iterations = self.solve(transform_tip_to_base, start)
            total += iterations
            if converged:
                return q, True, total
        return q, False, total

    def solve_trajectory(
        self,
        transforms_tip_to_base: Sequence[pin.SE3],
        times_s: np.ndarray,
        s_values: np.ndarray,
        seed_q: np.ndarray,
    ) -> IKTrajectoryResult:
        """Solve every sample, each warm-started by extrapolating the two previous solutions.

        The result is infeasible (with a reason) when a sample does not converge, or joint
        positions jump by more than ``max_joint_step`` or exceed the velocity limits between
        consecutive samples.
        """
        model, robot, config = self.robot.model, self.robot, self.config
        count = len(transforms_tip_to_base)
        q_all = np.empty((count, model.nq))
        iterations = np.zeros(count, dtype=int)
        velocity_limits = robot.velocity_limits
        check_velocity = config.check_velocity_limits & np.isfinite(velocity_limits) & (
            velocity_limits > 0
        )
        for i, target in enumerate(transforms_tip_to_base):
            if i == 0:
                q, converged, iterations[i] = self.solve_first(target, seed_q)
            else:
                guess = q_all[i - 1]
                if i >= 2 and s_values[i - 1] > s_values[i - 2]:
                    ratio = (s_values[i] - s_values[i - 1]) / (s_values[i - 1] - s_values[i - 2])
                    velocity = pin.difference(model, q_all[i - 2], q_all[i - 1])
                    guess = pin.integrate(model, q_all[i - 1], ratio * velocity)
                q, converged, iterations[i] = self.solve(target, guess)
            if not converged:
                reason = (
                    f"IK did not converge at sample {i} (t={times_s[i]:.3f} s)"
                    + self._limit_note(q)
                    + (" from the seed or any restart" if i == 0 else "")
                )
                return IKTrajectoryResult(q_all[:i], iterations[:i], reason)
            q_all[i] = q
            if i == 0:
                continue
            delta = np.abs(pin.difference(model, q_all[i - 1], q))
            k = int(np.argmax(delta))
            if delta[k] > config.max_joint_step:
                reason = (
                    f"joint '{robot.joint_names[k]}' jumps by {delta[k]:.3f} between t="
                    f"{times_s[i - 1]:.3f} s and t={times_s[i]:.3f} s (max_joint_step="
                    f"{config.max_joint_step:g})"
                )
                return IKTrajectoryResult(q_all[:i], iterations[:i], reason)
            elapsed = times_s[i] - times_s[i - 1]
            if check_velocity.any() and elapsed > 0:
                speed = delta / elapsed
                over = check_velocity & (speed > velocity_limits * (1 + 1e-9))
                if over.any():
                    k = int(np.flatnonzero(over)[0])
                    reason = (
                        f"joint '{robot.joint_names[k]}' needs speed {speed[k]:.3f} > limit "
                        f"{velocity_limits[k]:g} at t={times_s[i]:.3f} s"
                    )
                    return IKTrajectoryResult(q_all[:i], iterations[:i], reason)
        return IKTrajectoryResult(q_all, iterations, "")

    def _limit_note(self, q: np.ndarray) -> str:
        positions = self.robot.positions_from_q(q)
        at_limit = (positions <= self.robot.lower_limits + 1e-9) | (
            positions >= self.robot.upper_limits - 1e-9
        )
        if not at_limit.any():
            return " (target out of reach or singular)"
        names = ", ".join(self.robot.joint_names[k] for k in np.flatnonzero(at_limit))
        return f" (joint limits reached: {names})"
