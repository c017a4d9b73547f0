"""The per-sample pieces of the null-space optimisation (``redundancy``): U(q) = M_eff(q) and
its gradient in the null space of the tip Jacobian, re-projection onto a tip pose, the motion
bounds a resolved trajectory must meet, and the Bernstein basis of the offset profile."""

from __future__ import annotations

from math import comb

import numpy as np
import pinocchio as pin

from ..method.effective_mass import translational_mobility_in_base
from ..model.robot import RobotModel
from .effort import effort_limits

PROJECTION_TOLERANCE = 1e-10
"""Re-projection onto the tip pose stops below this position [m] and orientation [rad] error."""


def bernstein_basis(degree: int, s_values: np.ndarray) -> np.ndarray:
    """(N, degree + 1) Bernstein polynomials B_k(s) = C(d, k) s^k (1 − s)^(d − k)."""
    s = np.clip(np.asarray(s_values, dtype=float), 0.0, 1.0)[:, None]
    k = np.arange(degree + 1)[None, :]
    binomials = np.array([comb(degree, j) for j in range(degree + 1)], dtype=float)
    basis: np.ndarray = binomials * s**k * (1.0 - s) ** (degree - k)
    return basis


def metric_weights(masses: np.ndarray, times_s: np.ndarray, metric: str) -> np.ndarray:
    """(N,) d aggregate / d M_i (for ``max``: 1 at the first largest sample, 0 elsewhere)."""
    weights = np.zeros(len(masses))
    if metric == "mean":
        weights[:] = 1.0 / len(masses)
    elif metric == "max":
        weights[int(np.argmax(masses))] = 1.0
    elif len(times_s) > 1:  # trapezoid integral
        spacing = np.diff(times_s)
        weights[:-1] += 0.5 * spacing
        weights[1:] += 0.5 * spacing
    return weights


class SampleProblem:
    """U(q), null-space gradients and pose re-projection for one grasp."""

    def __init__(
        self, robot: RobotModel, model: pin.Model, finite_difference_step_rad: float
    ) -> None:
        self.robot, self.model = robot, model
        self.finite_difference_step_rad = finite_difference_step_rad
        self.data = model.createData()
        self.kinematics = robot.model.createData()
        self.lower = robot.lower_limits
        self.upper = robot.upper_limits

    def objective(self, q: np.ndarray, direction: np.ndarray, worst: bool) -> float:
        mobility = translational_mobility_in_base(self.robot, self.model, self.data, q)
        if worst:
            return float(1.0 / np.linalg.eigvalsh(0.5 * (mobility + mobility.T))[0])
        return float(1.0 / (direction @ mobility @ direction))

    def pose_error(
        self, q: np.ndarray, transform_target_to_world: pin.SE3
    ) -> tuple[pin.SE3, float, float]:
        pin.forwardKinematics(self.robot.model, self.kinematics, q)
        current = pin.updateFramePlacement(
            self.robot.model, self.kinematics, self.robot.tip_frame_id
        )
        error = current.actInv(transform_target_to_world)
        position = float(np.linalg.norm(error.translation))
        angle = float(np.linalg.norm(pin.log3(error.rotation)))
        return error, position, angle

    def project(self, q: np.ndarray, transform_target_to_world: pin.SE3) -> np.ndarray | None:
        """Gauss-Newton (minimum-norm steps) onto the tip pose; None if it fails."""
        model = self.robot.model
        for _ in range(30):
            error_transform, position, angle = self.pose_error(q, transform_target_to_world)
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

    def null_space_gradient(self, q: np.ndarray, direction: np.ndarray, worst: bool) -> np.ndarray:
        """(n,) N ∇U: the gradient of U projected onto the null space of the tip Jacobian."""
        model = self.robot.model
        h = self.finite_difference_step_rad
        basis = self.null_space(q)
        derivatives = np.array(
            [
                self.objective(pin.integrate(model, q, h * z), direction, worst)
                - self.objective(pin.integrate(model, q, -h * z), direction, worst)
                for z in basis.T
            ]
        ) / (2.0 * h)
        return basis @ derivatives if basis.shape[1] else np.zeros(model.nv)

    def within_limits(self, q: np.ndarray) -> bool:
        positions = self.robot.positions_from_q(q)
        return bool(np.all(positions >= self.lower) and np.all(positions <= self.upper))


class MotionBounds:
    """Peak joint speed, acceleration and torque of a sampled q(s(t)), bounded by the original's.

    Rates come from differences over s with the chain rule, as core.effort computes the
    null-space part: q̇ = q'(s)·ṡ, q̈ = q''(s)·ṡ² + q'(s)·s̈; torques from RNEA of the augmented
    model (gravity on).
    """

    def __init__(
        self,
        robot: RobotModel,
        model: pin.Model,
        q_original: list[np.ndarray],
        s_values: np.ndarray,
        s_rate: np.ndarray,
        s_accel: np.ndarray,
        ratio: float,
        effort_fraction: float,
    ) -> None:
        self.kinematic_model, self.model = robot.model, model
        self.data = model.createData()
        self.q_original = q_original
        self.s_values, self.s_rate, self.s_accel = s_values, s_rate, s_accel
        self.moving = len(s_values) > 1 and bool(np.all(np.diff(s_values) > 0))
        # Unwrapped (continuous joints) tangent coordinates of the original samples.
        self.unwrapped = np.zeros((len(q_original), robot.model.nv))
        for i in range(1, len(q_original)):
            self.unwrapped[i] = self.unwrapped[i - 1] + pin.difference(
                robot.model, q_original[i - 1], q_original[i]
            )
        speed, acceleration, torque = self.peaks(q_original)
        self.max_speed, self.max_acceleration = ratio * speed, ratio * acceleration
        limits = effort_limits(robot)
        self.max_torque = np.where(
            np.isfinite(limits), np.maximum(effort_fraction * limits, torque), np.inf
        )

    def peaks(self, q: list[np.ndarray]) -> tuple[float, float, np.ndarray]:
        """Largest |q̇| [rad/s] and |q̈| [rad/s²] over joints and samples, per-joint peak |τ|."""
        velocity = acceleration = np.zeros_like(self.unwrapped)
        if self.moving:
            unwrapped = self.unwrapped + np.array(
                [
                    pin.difference(self.kinematic_model, a, b)
                    for a, b in zip(self.q_original, q, strict=True)
                ]
            )
            dq_ds = np.gradient(unwrapped, self.s_values, axis=0)
            d2q_ds2 = np.gradient(dq_ds, self.s_values, axis=0)
            velocity = dq_ds * self.s_rate[:, None]
            acceleration = d2q_ds2 * self.s_rate[:, None] ** 2 + dq_ds * self.s_accel[:, None]
        torque = np.array(
            [
                pin.rnea(self.model, self.data, qi, vi, ai)
                for qi, vi, ai in zip(q, velocity, acceleration, strict=True)
            ]
        )
        return (
            float(np.abs(velocity).max()),
            float(np.abs(acceleration).max()),
            np.abs(torque).max(axis=0),
        )

    def ok(self, q: list[np.ndarray]) -> bool:
        speed, acceleration, torque = self.peaks(q)
        return bool(
            speed <= self.max_speed
            and acceleration <= self.max_acceleration
            and np.all(torque <= self.max_torque)
        )
