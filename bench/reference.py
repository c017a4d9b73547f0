"""The implementation before issue #5 (commit cbe368a), kept verbatim as a timing reference.

``reference_evaluate`` is the original per-sample loop: Pinocchio IK (np.linalg.solve,
computeFrameJacobian, one SE3 per sample) and computeMinverse + numpy per sample.

Its IK warm-starts each sample by extrapolating the two previous solutions (secant); the core
now uses a minimum-norm predictor instead (no drift along the self-motion manifold of
redundant arms), so on 7-DOF arms the joint paths, hence the effective masses and
iteration counts, differ from the reference's by design. What is still compared exactly is
the effective-mass half: ``reference_effective_masses`` (the original code, unchanged) on the
core's own joint path must give the core's effective masses to 1e-9 relative.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from grasp_safety_ros.core import ObjectInertia, ObjectTrajectory, RobotModel
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    effective_mass_along,
    translational_mobility_in_base,
    worst_direction,
)
from grasp_safety_ros.core.method.ik import IKConfig

STATIONARY_TANGENT_M = 1e-9


class ReferenceIK:
    """IKSolver as of commit cbe368a (reasons shortened: only feasibility is compared)."""

    def __init__(self, robot: RobotModel, config: IKConfig | None = None) -> None:
        self.robot = robot
        self.config = config or IKConfig()
        self.data = robot.model.createData()
        model = robot.model
        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        for joint in model.joints[1:]:
            if joint.nq != joint.nv:
                lower[joint.idx_q : joint.idx_q + joint.nq] = -np.inf
                upper[joint.idx_q : joint.idx_q + joint.nq] = np.inf
        self._lower_q, self._upper_q = lower, upper

    def solve(
        self, transform_tip_to_base: pin.SE3, q_init: np.ndarray
    ) -> tuple[np.ndarray, bool, int]:
        """Solve one tip pose from ``q_init``.

        Returns:
            The configuration, whether it converged to the tolerances, and the iterations.
        """
        model, data, config = self.robot.model, self.data, self.config
        frame_id = self.robot.tip_frame_id
        transform_target_to_world = self.robot.transform_base_to_world * transform_tip_to_base
        q = np.clip(np.array(q_init, dtype=float), self._lower_q, self._upper_q)
        n = model.nv
        for iteration in range(config.max_iterations + 1):
            pin.forwardKinematics(model, data, q)
            current = pin.updateFramePlacement(model, data, frame_id)
            error_transform = current.actInv(transform_target_to_world)
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
                step = np.linalg.solve(
                    jacobian.T @ jacobian + damping * np.eye(n), jacobian.T @ error
                )
            largest = float(np.abs(step).max())
            if largest > config.max_iteration_step:
                step *= config.max_iteration_step / largest
            q = np.clip(pin.integrate(model, q, step), self._lower_q, self._upper_q)
        return q, False, config.max_iterations

    def solve_first(
        self, transform_tip_to_base: pin.SE3, seed_q: np.ndarray
    ) -> tuple[np.ndarray, bool, int]:
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
    ) -> tuple[np.ndarray, np.ndarray, str]:
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
        check_velocity = (
            config.check_velocity_limits & np.isfinite(velocity_limits) & (velocity_limits > 0)
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
                reason = f"IK did not converge at sample {i}"
                return q_all[:i], iterations[:i], reason
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
                return q_all[:i], iterations[:i], reason
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
                    return q_all[:i], iterations[:i], reason
        return q_all, iterations, ""


def reference_evaluate(
    robot: RobotModel,
    ik: ReferenceIK,
    transform_tip_to_object: pin.SE3,
    object_inertia: ObjectInertia,
    trajectory: ObjectTrajectory,
    seed_q: np.ndarray,
) -> tuple[bool, np.ndarray, np.ndarray]:
    """Feasibility, per-sample effective masses [kg] and IK iterations, as before issue #5."""
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    poses, tangents = trajectory.tip_path(transform_tip_to_object, s_values)
    result = ik.solve_trajectory(poses, times, s_values, seed_q)
    if result[2]:
        return False, np.empty(0), np.empty(0, dtype=int)
    q_all, iterations = result[0], result[1]
    masses = reference_effective_masses(
        robot, transform_tip_to_object, object_inertia, q_all, tangents
    )
    return True, masses, iterations


def reference_effective_masses(
    robot: RobotModel,
    transform_tip_to_object: pin.SE3,
    object_inertia: ObjectInertia,
    q_all: np.ndarray,
    tangents: np.ndarray,
) -> np.ndarray:
    """Per-sample effective masses [kg] along the joint path q_all, given the tip path
    tangents (ObjectTrajectory.tip_path), as before issue #5 (the second half of
    ``reference_evaluate``)."""
    model = augmented_model(robot, object_inertia, transform_tip_to_object)
    data = model.createData()
    masses = np.empty(len(q_all))
    norms = np.linalg.norm(tangents, axis=1)
    for i in range(len(q_all)):
        mobility = translational_mobility_in_base(robot, model, data, q_all[i])
        if norms[i] < STATIONARY_TANGENT_M:
            masses[i] = worst_direction(mobility)[1]
        else:
            masses[i] = effective_mass_along(mobility, tangents[i] / norms[i])
    return masses
