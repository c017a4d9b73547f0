"""Quintic object trajectories and the tip trajectories that grasps induce."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_float

_EPS = float(np.finfo(float).eps)
_PREC3 = _EPS ** (1.0 / 4.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<3>()

MAX_SAMPLES = 1_000_000
"""Upper bound on the number of samples of one trajectory."""


class TipMotion(NamedTuple):
    """The tip path a grasp induces, sampled (the common interface of object trajectories).

    Every trajectory type (``ObjectTrajectory``, ``WaypointTrajectory``,
    ``JointSpaceTrajectory``) offers ``times_s()``, ``duration_s``, ``path_parameter(times)``,
    ``object_poses(times)``, ``tip_motion(grasp, times)`` and ``tip_twists(grasp, times)``;
    the evaluator (compiled or not) and the analyses use only these.
    """

    rotations: np.ndarray  # (N, 3, 3) tip frame in the base frame
    positions: np.ndarray  # (N, 3) [m] tip origin in the base frame
    tangents: np.ndarray  # (N, 3) [m] direction of tip motion, base axes (see each type)
    speeds: np.ndarray  # (N,) [m/s] tip speed


class ObjectMotion(NamedTuple):
    """An object trajectory sampled once, from which the tip motion of any grasp follows.

    A point at ``lever`` from the object origin (base axes) moves along the tangent
    ``linear_tangents + angular_tangents x lever``; its speed is |tangent| ``speed_per_tangent``.
    Each trajectory type chooses the tangent's scale (``ObjectTrajectory``: d/ds;
    ``WaypointTrajectory``: T d/dt, and the limit direction at its rest ends).
    """

    rotations: np.ndarray  # (N, 3, 3) object frame in the base frame
    positions: np.ndarray  # (N, 3) [m] object origin in the base frame
    linear_tangents: np.ndarray  # (N, 3) [m] tangent of the object origin, base axes
    angular_tangents: np.ndarray  # (N, 3) [rad] angular tangent of the object, base axes
    speed_per_tangent: np.ndarray  # (N,) [1/s] speed / |tangent|; 0 where at rest

    def tip_motion(self, transform_tip_to_object: pin.SE3) -> TipMotion:
        """The motion of the tip frame at ``transform_tip_to_object`` (object frame)."""
        grasp = pin.SE3(transform_tip_to_object)
        count = len(self.positions)
        stacked = self.rotations.reshape(3 * count, 3)  # one matrix product per quantity
        lever, tangents = self._lever_and_tangents(grasp.translation)
        norms = np.sqrt(np.einsum("ij,ij->i", tangents, tangents))
        return TipMotion(
            rotations=(stacked @ grasp.rotation).reshape(count, 3, 3),
            positions=self.positions + lever,
            tangents=tangents,
            speeds=norms * self.speed_per_tangent,
        )

    def tip_tangents(self, transform_tip_to_object: pin.SE3) -> np.ndarray:
        """``tip_motion(transform_tip_to_object).tangents`` (N, 3) [m] alone."""
        return self._lever_and_tangents(pin.SE3(transform_tip_to_object).translation)[1]

    def _lever_and_tangents(self, tip_in_object_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) the object origin -> tip lever [m] and the tip's tangents [m], base axes, of
        the tip origin at ``tip_in_object_m`` (object frame)."""
        count = len(self.positions)
        stacked = self.rotations.reshape(3 * count, 3)
        lever = (stacked @ tip_in_object_m).reshape(count, 3)
        w, r = self.angular_tangents, lever
        tangents = np.empty_like(r)  # w x r (np.cross is slower on short rows)
        tangents[:, 0] = w[:, 1] * r[:, 2] - w[:, 2] * r[:, 1]
        tangents[:, 1] = w[:, 2] * r[:, 0] - w[:, 0] * r[:, 2]
        tangents[:, 2] = w[:, 0] * r[:, 1] - w[:, 1] * r[:, 0]
        tangents += self.linear_tangents
        return lever, tangents


class Trajectory(Protocol):
    """What the evaluator and the analyses need of an object trajectory (see TipMotion)."""

    @property
    def duration_s(self) -> float: ...

    def times_s(self) -> np.ndarray: ...

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def object_poses(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def tip_motion(self, transform_tip_to_object: pin.SE3, times_s: np.ndarray) -> TipMotion: ...

    def tip_twists(
        self, transform_tip_to_object: pin.SE3, times_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]: ...


@runtime_checkable
class ObjectPath(Trajectory, Protocol):
    """An object trajectory that can be sampled once for every grasp (``ObjectTrajectory``,
    ``WaypointTrajectory``): ``tip_motion(grasp, t)`` is ``object_motion(t).tip_motion(grasp)``."""

    def object_motion(self, times_s: np.ndarray) -> ObjectMotion: ...


def quintic_time_scaling(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and its derivatives ds/dτ, d²s/dτ² (τ in [0, 1])."""
    tau = np.asarray(tau, dtype=float)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


@dataclass(frozen=True)
class ObjectTrajectory:
    """Object-frame poses in the base frame, quintic in time from ``start`` to ``goal``.

    Position is linear in s, orientation geodesic: R(s) = R0 exp(s log(R0ᵀ Rf)).
    Samples are at t = i·dt, i = 0..N with N = ceil(T/dt) (= round(T/dt) when T/dt is an
    integer); the last sample is clipped to t = T, so the goal is always sampled.

    Attributes:
        transform_object_to_base_start: Object pose in the base frame at t = 0.
        transform_object_to_base_goal: Object pose in the base frame at t = T.
        duration_s: T [s], > 0.
        dt_s: Sampling period [s], in (0, T].
    """

    transform_object_to_base_start: pin.SE3
    transform_object_to_base_goal: pin.SE3
    duration_s: float
    dt_s: float
    rotation_log_in_object: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        duration = finite_float(
            self.duration_s, "trajectory.duration_s", minimum=0.0, strict_minimum=True
        )
        dt = finite_float(self.dt_s, "trajectory.dt_s", minimum=0.0, strict_minimum=True)
        if dt > duration:
            raise InvalidInputError(
                "trajectory.dt_s", f"must be in (0, duration_s={duration:g}], got {dt:g}"
            )
        if duration / dt > MAX_SAMPLES:
            raise InvalidInputError(
                "trajectory.dt_s",
                f"gives {duration / dt:.0f} samples; at most {MAX_SAMPLES} are allowed",
            )
        start = pin.SE3(self.transform_object_to_base_start)
        goal = pin.SE3(self.transform_object_to_base_goal)
        log = pin.log3(start.rotation.T @ goal.rotation)
        log.setflags(write=False)
        object.__setattr__(self, "duration_s", duration)
        object.__setattr__(self, "dt_s", dt)
        object.__setattr__(self, "transform_object_to_base_start", start)
        object.__setattr__(self, "transform_object_to_base_goal", goal)
        object.__setattr__(self, "rotation_log_in_object", log)

    @property
    def num_samples(self) -> int:
        """N + 1 samples, N = ceil(T/dt) up to a 1e-9 rounding tolerance."""
        return math.ceil(self.duration_s / self.dt_s - 1e-9) + 1

    def times_s(self) -> np.ndarray:
        """Sample times t_i = min(i·dt, T) [s]."""
        return np.minimum(np.arange(self.num_samples) * self.dt_s, self.duration_s)

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s(t), ds/dt [1/s] and d²s/dt² [1/s²] at the given times."""
        tau = np.clip(np.asarray(times_s, dtype=float) / self.duration_s, 0.0, 1.0)
        s, ds, dds = quintic_time_scaling(tau)
        return s, ds / self.duration_s, dds / self.duration_s**2

    def transform_object_to_base(self, s: float) -> pin.SE3:
        """Object pose in the base frame at path parameter s in [0, 1]."""
        start = self.transform_object_to_base_start
        goal = self.transform_object_to_base_goal
        rotation = start.rotation @ pin.exp3(s * self.rotation_log_in_object)
        translation = (1.0 - s) * start.translation + s * goal.translation
        return pin.SE3(rotation, translation)

    def tip_path(
        self, transform_tip_to_object: pin.SE3, s_values: np.ndarray
    ) -> tuple[list[pin.SE3], np.ndarray]:
        """Tip poses in base and path tangents d p_tip/ds [m] (base axes) for a grasp.

        Args:
            transform_tip_to_object: The grasp: pose of the tip frame in the object frame.
            s_values: Path parameters in [0, 1].

        Returns:
            The tip poses T_base_tip(s) = T_base_object(s)·T_object_tip and, per sample, the
            derivative of the tip position with respect to s, in base axes.
        """
        grasp = pin.SE3(transform_tip_to_object)
        poses: list[pin.SE3] = []
        tangents = np.empty((len(s_values), 3))
        linear = self.transform_object_to_base_goal.translation - (
            self.transform_object_to_base_start.translation
        )
        angular_in_object = self.rotation_log_in_object
        lever_in_object = np.cross(angular_in_object, grasp.translation)
        for i, s in enumerate(s_values):
            object_pose = self.transform_object_to_base(float(s))
            poses.append(object_pose * grasp)
            tangents[i] = linear + object_pose.rotation @ lever_in_object
        return poses, tangents

    def object_poses(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object rotations (N, 3, 3) and positions (N, 3) [m] in the base frame at the times."""
        motion = self.tip_motion(pin.SE3.Identity(), times_s)
        return motion.rotations, motion.positions

    def tip_motion(self, transform_tip_to_object: pin.SE3, times_s: np.ndarray) -> TipMotion:
        """Tip poses, path tangents d p_tip/ds [m] and speeds |d p_tip/ds|·ds/dt [m/s]; equal
        to ``tip_path`` at s(t) up to rounding."""
        return self.object_motion(times_s).tip_motion(transform_tip_to_object)

    def object_motion(self, times_s: np.ndarray) -> ObjectMotion:
        """The object's motion at the times: tangents d/ds (linear p_f − p_0 [m], angular
        R(s) log(R0ᵀ Rf) [rad]), speed per tangent ds/dt [1/s]."""
        s_values, s_rate, _ = self.path_parameter(times_s)
        start = self.transform_object_to_base_start
        goal = self.transform_object_to_base_goal
        log = np.asarray(self.rotation_log_in_object, dtype=float)
        rotations = np.matmul(start.rotation, exp3_batch(s_values[:, None] * log))
        translations = (1.0 - s_values)[:, None] * start.translation + s_values[
            :, None
        ] * goal.translation
        linear = np.tile(goal.translation - start.translation, (len(s_values), 1))
        return ObjectMotion(rotations, translations, linear, rotations @ log, s_rate)

    def tip_twists(
        self, transform_tip_to_object: pin.SE3, times_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Tip twist (N, 6) [m/s, rad/s] and its time derivative (N, 6), base axes.

        Linear part: velocity / classical acceleration of the tip origin; angular part: angular
        velocity / acceleration of the object (= of the tip).
        """
        grasp = pin.SE3(transform_tip_to_object)
        times = np.asarray(times_s, dtype=float)
        s_values, s_rate, s_accel = self.path_parameter(times)
        omega = self.rotation_log_in_object  # object angular velocity per unit s, object axes
        start = self.transform_object_to_base_start
        linear = self.transform_object_to_base_goal.translation - start.translation
        rotations = np.matmul(start.rotation, exp3_batch(s_values[:, None] * omega))
        # d p_tip / ds (as tip_path), the angular tangent and d² p_tip / ds², base axes.
        tangents = linear + rotations @ np.cross(omega, grasp.translation)
        angular = rotations @ omega
        second = rotations @ np.cross(omega, np.cross(omega, grasp.translation))
        rate, accel = s_rate[:, None], s_accel[:, None]
        twist = np.concatenate([tangents * rate, angular * rate], axis=1)
        twist_rate = np.concatenate([second * rate**2 + tangents * accel, angular * accel], axis=1)
        return twist, twist_rate


def exp3_batch(rotation_vectors: np.ndarray) -> np.ndarray:
    """Pinocchio's exp3 (same formula and Taylor branch) for an (N, 3) array of vectors."""
    v = np.asarray(rotation_vectors, dtype=float)
    t2 = np.einsum("ij,ij->i", v, v) + _EPS * _EPS
    t = np.sqrt(t2)
    ct, st = np.cos(t), np.sin(t)
    large = t > _PREC3
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha_vxvx = np.where(large, (1.0 - ct) / t2, 0.5 - t2 / 24.0)
        alpha_vx = np.where(large, st / t, 1.0 - t2 / 6.0)
    ct = np.where(large, ct, 1.0 - t2 / 2.0)
    result = alpha_vxvx[:, None, None] * v[:, :, None] * v[:, None, :]
    result[:, 0, 1] -= alpha_vx * v[:, 2]
    result[:, 1, 0] += alpha_vx * v[:, 2]
    result[:, 0, 2] += alpha_vx * v[:, 1]
    result[:, 2, 0] -= alpha_vx * v[:, 1]
    result[:, 1, 2] -= alpha_vx * v[:, 0]
    result[:, 2, 1] += alpha_vx * v[:, 0]
    for k in range(3):
        result[:, k, k] += ct
    return result
