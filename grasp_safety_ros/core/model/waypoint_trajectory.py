"""Timed waypoint trajectories of the object: C2 through every waypoint, at rest at both ends.

Interpolation (object frame in the base frame, waypoints (t_i, R_i, p_i), i = 0..N-1):

- Position: the quintic spline p(t) (degree 5, knots at the waypoint times, C4) through every
  p_i at t_i with zero velocity and zero acceleration at t_0 and t_{N-1}. Its 6(N-1)
  coefficients are fixed by 2(N-1) interpolation conditions, 4(N-2) continuity conditions
  (derivatives 1..4) at the interior waypoints and the 4 end conditions.
- Rotation: R(t) = R_0 exp(φ(t)), with φ the same kind of quintic spline through the rotation
  vectors φ_i = log(R_0ᵀ R_i) (each unwrapped by a multiple of 2π along its axis to the one
  nearest φ_{i-1}, so a path turning by more than π stays continuous). exp is smooth, so R is
  C4 like φ; the body angular velocity ω = J_r(φ) φ̇ (J_r: right Jacobian of SO(3)) and its
  derivative are continuous, and zero at both ends (φ̇ = φ̈ = 0 there). R(t_i) = R_i.
- Two waypoints: exactly the quintic ``ObjectTrajectory`` from the first to the second pose
  (the code delegates to it), whose position is linear and rotation geodesic in s(τ).

Samples: t_0 + k·dt (the last clipped to t_{N-1}) and every waypoint time; a regular sample
closer than 1e-6·dt to a waypoint time is replaced by it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_float
from .trajectory import (
    MAX_SAMPLES,
    ObjectMotion,
    ObjectTrajectory,
    TipMotion,
    exp3_batch,
    quintic_time_scaling,
)

_MERGE_FRACTION = 1e-6
"""Regular samples within this fraction of dt of a waypoint time are replaced by it."""

_REST_SCALE = 1.0 / 60.0
"""p''' T³/60 at a rest end equals d p/ds of a quintic segment (s ≈ 10τ³)."""


def right_jacobian_so3(rotation_vectors: np.ndarray) -> np.ndarray:
    """Right Jacobian J_r(φ) of exp on SO(3) (Pinocchio's Jexp3), (N, 3) -> (N, 3, 3).

    J_r = I − (1 − cos θ)/θ² φ̂ + (θ − sin θ)/θ³ φ̂², θ = |φ| (series below 1e-4 rad).
    """
    phi = np.asarray(rotation_vectors, dtype=float).reshape(-1, 3)
    theta2 = np.einsum("ij,ij->i", phi, phi)
    theta = np.sqrt(theta2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (safe - np.sin(safe)) / safe**3)
    hat = _hat(phi)
    jacobians: np.ndarray = np.eye(3) - a[:, None, None] * hat + b[:, None, None] * (hat @ hat)
    return jacobians


def _hat(vectors: np.ndarray) -> np.ndarray:
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    zero = np.zeros_like(x)
    return np.stack(
        [np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)],
        axis=1,
    )


def _rest_spline(times: np.ndarray, values: np.ndarray) -> Any:
    """Quintic spline through ``values`` at ``times`` with zero 1st and 2nd end derivatives."""
    from scipy.interpolate import make_interp_spline

    zero = np.zeros(values.shape[1])
    ends = [(1, zero), (2, zero)]
    return make_interp_spline(times, values, k=5, bc_type=(ends, ends))


def _unwrapped_logs(rotations: Sequence[np.ndarray]) -> np.ndarray:
    """φ_i = log(R_0ᵀ R_i), each shifted by 2πk along its axis to lie nearest φ_{i-1}."""
    logs = np.zeros((len(rotations), 3))
    for i in range(1, len(rotations)):
        phi = np.asarray(pin.log3(rotations[0].T @ rotations[i]), dtype=float)
        angle = float(np.linalg.norm(phi))
        if angle > 1e-12:
            axis = phi / angle
            candidates = [phi + 2.0 * math.pi * k * axis for k in range(-3, 4)]
            phi = min(candidates, key=lambda c: float(np.linalg.norm(c - logs[i - 1])))
        logs[i] = phi
    return logs


@dataclass(frozen=True)
class WaypointTrajectory:
    """Object-frame poses in the base frame through timed waypoints (module docstring).

    Attributes:
        waypoint_times_s: t_i [s] from the start of the motion: t_0 = 0, strictly increasing,
            at least two.
        transforms_object_to_base: Object pose in the base frame at each t_i.
        dt_s: Sampling period [s], in (0, t_{N-1} − t_0].
    """

    waypoint_times_s: tuple[float, ...]
    transforms_object_to_base: tuple[pin.SE3, ...]
    dt_s: float
    _quintic: ObjectTrajectory | None = field(init=False, repr=False, compare=False)
    _position_spline: Any = field(init=False, repr=False, compare=False)
    _rotation_spline: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        times = tuple(float(t) for t in self.waypoint_times_s)
        poses = tuple(pin.SE3(pose) for pose in self.transforms_object_to_base)
        if len(times) != len(poses):
            raise InvalidInputError(
                "trajectory.waypoints",
                f"needs one time per pose, got {len(times)} times and {len(poses)} poses",
            )
        if len(times) < 2:
            raise InvalidInputError(
                "trajectory.waypoints", f"needs at least 2 waypoints, got {len(times)}"
            )
        for i, t in enumerate(times):
            finite_float(t, f"trajectory.waypoints[{i}].time_s")
            if i == 0 and t != 0.0:
                raise InvalidInputError(
                    "trajectory.waypoints[0].time_s",
                    f"must be 0 (times count from the start of the motion), got {t:g}",
                )
            if i and t <= times[i - 1]:
                raise InvalidInputError(
                    f"trajectory.waypoints[{i}].time_s",
                    f"must be > waypoints[{i - 1}].time_s={times[i - 1]:g} (strictly "
                    f"increasing), got {t:g}",
                )
        for i, pose in enumerate(poses):
            if not (np.all(np.isfinite(pose.rotation)) and np.all(np.isfinite(pose.translation))):
                raise InvalidInputError(
                    f"trajectory.waypoints[{i}]", "pose must be finite, got non-finite values"
                )
        duration = times[-1] - times[0]
        dt = finite_float(self.dt_s, "trajectory.dt_s", minimum=0.0, strict_minimum=True)
        if dt > duration:
            raise InvalidInputError(
                "trajectory.dt_s", f"must be in (0, duration={duration:g}], got {dt:g}"
            )
        if duration / dt + len(times) > MAX_SAMPLES:
            raise InvalidInputError(
                "trajectory.dt_s",
                f"gives {duration / dt + len(times):.0f} samples; at most {MAX_SAMPLES} are "
                "allowed",
            )
        object.__setattr__(self, "waypoint_times_s", times)
        object.__setattr__(self, "transforms_object_to_base", poses)
        object.__setattr__(self, "dt_s", dt)
        if len(times) == 2:
            quintic = ObjectTrajectory(poses[0], poses[1], duration, dt)
            object.__setattr__(self, "_quintic", quintic)
            object.__setattr__(self, "_position_spline", None)
            object.__setattr__(self, "_rotation_spline", None)
            return
        knots = np.array(times)
        positions = np.array([pose.translation for pose in poses])
        logs = _unwrapped_logs([pose.rotation for pose in poses])
        object.__setattr__(self, "_quintic", None)
        object.__setattr__(self, "_position_spline", _rest_spline(knots, positions))
        object.__setattr__(self, "_rotation_spline", _rest_spline(knots, logs))

    @property
    def quintic(self) -> ObjectTrajectory | None:
        """For two waypoints, the identical quintic ``ObjectTrajectory``; else None."""
        return self._quintic

    # ------------------------------------------------------------------ common interface
    @property
    def duration_s(self) -> float:
        """t_{N-1} − t_0 [s]."""
        return self.waypoint_times_s[-1] - self.waypoint_times_s[0]

    @property
    def transform_object_to_base_start(self) -> pin.SE3:
        """Object pose at the first waypoint."""
        return self.transforms_object_to_base[0]

    @property
    def num_samples(self) -> int:
        """Number of sample times (``len(times_s())``)."""
        return len(self.times_s())

    def times_s(self) -> np.ndarray:
        """Sample times [s]: every dt from t_0 and every waypoint time, sorted."""
        start = self.waypoint_times_s[0]
        if self._quintic is not None:
            return start + self._quintic.times_s()
        count = math.ceil(self.duration_s / self.dt_s - 1e-9) + 1
        regular = np.minimum(start + np.arange(count) * self.dt_s, self.waypoint_times_s[-1])
        waypoints = np.array(self.waypoint_times_s)
        distance = np.abs(regular[:, None] - waypoints[None, :]).min(axis=1)
        kept = regular[distance > _MERGE_FRACTION * self.dt_s]
        return np.sort(np.concatenate([kept, waypoints]))

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A monotone time coordinate for the analyses: the quintic s((t − t_0)/T), ds/dt
        [1/s], d²s/dt² [1/s²] (for two waypoints, the quintic's own path parameter)."""
        relative = np.asarray(times_s, dtype=float) - self.waypoint_times_s[0]
        tau = np.clip(relative / self.duration_s, 0.0, 1.0)
        s, ds, dds = quintic_time_scaling(tau)
        return s, ds / self.duration_s, dds / self.duration_s**2

    def object_poses(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object rotations (N, 3, 3) and positions (N, 3) [m] in the base frame."""
        if self._quintic is not None:
            return self._quintic.object_poses(self._relative(times_s))
        times = self._clipped(times_s)
        rotations = np.matmul(
            self.transforms_object_to_base[0].rotation, exp3_batch(self._rotation_spline(times))
        )
        return rotations, np.asarray(self._position_spline(times))

    def tip_motion(self, transform_tip_to_object: pin.SE3, times_s: np.ndarray) -> TipMotion:
        """Tip poses, path tangents and speeds of a grasp (see ``trajectory.TipMotion``).

        Tangents: T·v_tip [m]; at the rest ends (first and last waypoint), where v = 0, the
        limit direction T³/60 · d³p_tip/dt³ (with the quintic's scaling, = d p/ds there).
        """
        return self.object_motion(times_s).tip_motion(transform_tip_to_object)

    def object_motion(self, times_s: np.ndarray) -> ObjectMotion:
        """The object's motion at the times (see ``trajectory.ObjectMotion``): tangents T·v
        (linear [m], angular [rad]); at the rest ends the limit T³/60 · (d³/dt³), speed 0."""
        if self._quintic is not None:
            return self._quintic.object_motion(self._relative(times_s))
        times = self._clipped(times_s)
        rotations, positions = self.object_poses(times)
        jr = right_jacobian_so3(self._rotation_spline(times))
        omega = np.einsum(
            "nij,nj->ni", rotations, np.einsum("nij,nj->ni", jr, self._rotation_spline(times, 1))
        )
        linear = self._position_spline(times, 1) * self.duration_s
        angular = omega * self.duration_s
        speed_per_tangent = np.full(len(times), 1.0 / self.duration_s)
        rest = (times <= self.waypoint_times_s[0]) | (times >= self.waypoint_times_s[-1])
        if rest.any():
            scale = self.duration_s**3 * _REST_SCALE
            third_angular = np.einsum(
                "nij,nj->ni",
                rotations[rest],
                np.einsum("nij,nj->ni", jr[rest], self._rotation_spline(times[rest], 3)),
            )
            linear[rest] = self._position_spline(times[rest], 3) * scale
            angular[rest] = third_angular * scale
            speed_per_tangent[rest] = 0.0  # exactly at rest
        return ObjectMotion(rotations, positions, linear, angular, speed_per_tangent)

    def tip_twists(
        self, transform_tip_to_object: pin.SE3, times_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Tip twist (N, 6) [m/s, rad/s] and its time derivative (N, 6), base axes.

        Linear part: velocity / classical acceleration of the tip origin; angular part:
        angular velocity / acceleration of the object. dJ_r/dt comes from a central difference
        over ±1e-5·T (it multiplies φ̇, which is zero at the ends).
        """
        if self._quintic is not None:
            return self._quintic.tip_twists(transform_tip_to_object, self._relative(times_s))
        grasp = pin.SE3(transform_tip_to_object)
        times = self._clipped(times_s)
        rotations, _ = self.object_poses(times)
        lever = rotations @ grasp.translation
        spline = self._rotation_spline
        rate, second = spline(times, 1), spline(times, 2)
        jr = right_jacobian_so3(spline(times))
        h = 1e-5 * self.duration_s
        jr_rate = (
            right_jacobian_so3(spline(times + h)) - right_jacobian_so3(spline(times - h))
        ) / (2.0 * h)
        omega_body = np.einsum("nij,nj->ni", jr, rate)
        alpha_body = np.einsum("nij,nj->ni", jr, second) + np.einsum("nij,nj->ni", jr_rate, rate)
        omega = np.einsum("nij,nj->ni", rotations, omega_body)
        alpha = np.einsum("nij,nj->ni", rotations, alpha_body)
        twist = np.empty((len(times), 6))
        twist_rate = np.empty((len(times), 6))
        twist[:, :3] = self._position_spline(times, 1) + np.cross(omega, lever)
        twist[:, 3:] = omega
        twist_rate[:, :3] = (
            self._position_spline(times, 2)
            + np.cross(alpha, lever)
            + np.cross(omega, np.cross(omega, lever))
        )
        twist_rate[:, 3:] = alpha
        return twist, twist_rate

    def _relative(self, times_s: np.ndarray) -> np.ndarray:
        relative: np.ndarray = np.asarray(times_s, dtype=float) - self.waypoint_times_s[0]
        return relative

    def _clipped(self, times_s: np.ndarray) -> np.ndarray:
        clipped: np.ndarray = np.clip(
            np.asarray(times_s, dtype=float), self.waypoint_times_s[0], self.waypoint_times_s[-1]
        )
        return clipped
