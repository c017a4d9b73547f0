"""Planned arm joint trajectories given per grasp instead of IK.

A planner's joint trajectory (joint names in any order, points (t_k, q_k), optional joint
velocities) replaces the IK for its grasp. The evaluation samples it at its own point times
t_k: the joint positions there are the given ones, the tip pose follows by forward kinematics
and the object pose from the grasp, T_base_object = T_base_tip · T_object_tip⁻¹.

Between and at the points, q(t) is a piecewise cubic in time: Hermite with the given
velocities when the trajectory has them, else scipy's C2 cubic spline ("not-a-knot"). The
direction of motion is that of the tip velocity J(q) q̇(t_k); where the tip is at rest
(|J q̇|·T < 1e-9 m) the first non-vanishing derivative of the tip path, J q̈ then J q⃛ (the
right-hand one at a point, the left-hand one at the last point). The effective mass is computed
as for IK samples, with the object's inertia attached at the grasp.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array
from ..model.robot import RobotModel
from ..model.trajectory import TipMotion, quintic_time_scaling
from .effective_mass import STATIONARY_TANGENT_M

RATE_LIMIT_MULTIPLE = 10.0
"""Planned joint velocities beyond this multiple of the joint's URDF velocity limit are
refused: the ranking only reports a speed above the limit (the executable output carries the
planner's velocities), but ten times the limit is no robot's motion: degrees per second sent
as radians per second are 57 times the value, and 1e30 rad/s was handed back as executable
(1e200 overflowed in the ISO/TS 15066 check). Accelerations (the URDF has no limit) are bounded
alike over the point's shortest interval: beyond RATE_LIMIT_MULTIPLE x limit / interval, the
velocity would change by more than that multiple of its limit within the interval."""
UNLIMITED_JOINT_RATE = 100.0
"""The velocity limit taken for a joint whose URDF gives none (0 or not finite) [rad/s or
m/s]: above any arm's joint speed (a fast arm's joints turn at 3-6 rad/s)."""


@dataclass(frozen=True)
class PlannedJointTrajectory:
    """A planned joint trajectory of the arm, as a planner sends it.

    Attributes:
        joint_names: Names of the columns of ``positions``; any order, may include joints
            off the chain (ignored); every chain joint must be present.
        times_s: (N,) point times [s], finite and strictly increasing, N >= 2.
        positions: (N, K) joint positions [rad or m].
        velocities: (N, K) joint velocities [rad/s or m/s], or None (then a cubic spline).
        accelerations: (N, K) joint accelerations [rad/s² or m/s²] as the planner sent them,
            or None; checked (finite, bounded: ``check_rates``), not used.
        field: Name of this input in error messages (e.g. ``grasps[2].joint_trajectory``).
    """

    joint_names: tuple[str, ...]
    times_s: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    field: str = "joint_trajectory"
    accelerations: np.ndarray | None = None

    def __post_init__(self) -> None:
        f = self.field
        names = tuple(self.joint_names)
        if not names or not all(isinstance(n, str) and n for n in names):
            raise InvalidInputError(f"{f}.joint_names", "must be a non-empty list of names")
        if len(set(names)) != len(names):
            raise InvalidInputError(f"{f}.joint_names", f"has duplicates: {list(names)}")
        times = np.array(self.times_s, dtype=float).reshape(-1)
        if len(times) < 2:
            raise InvalidInputError(f"{f}.points", f"needs at least 2 points, got {len(times)}")
        for k, t in enumerate(times):
            if not np.isfinite(t):
                raise InvalidInputError(f"{f}.points[{k}].time_s", f"must be finite, got {t}")
            if k and t <= times[k - 1]:
                raise InvalidInputError(
                    f"{f}.points[{k}].time_s",
                    f"must be > points[{k - 1}].time_s={times[k - 1]:g} (strictly increasing), "
                    f"got {t:g}",
                )
        rows = self._rows(self.positions, "positions", len(times), len(names))
        for name in ("velocities", "accelerations"):
            if getattr(self, name) is not None:
                rates = self._rows(getattr(self, name), name, len(times), len(names))
                object.__setattr__(self, name, rates)
        times.setflags(write=False)
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "positions", rows)

    def _rows(self, values: Any, name: str, count: int, width: int) -> np.ndarray:
        if len(values) != count:
            raise InvalidInputError(
                f"{self.field}.points", f"every point needs {name}; got {len(values)} of {count}"
            )
        rows = np.empty((count, width))
        for k, row in enumerate(values):
            rows[k] = finite_array(row, f"{self.field}.points[{k}].{name}", (width,))
        rows.setflags(write=False)
        return rows

    def chain_columns(self, robot: RobotModel) -> np.ndarray:
        """Column of each chain joint in ``positions`` (chain order); refuses missing ones."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        missing = [name for name in robot.joint_names if name not in index]
        if missing:
            raise InvalidInputError(
                f"{self.field}.joint_names",
                f"missing chain joint(s) {', '.join(missing)}; "
                f"chain: {', '.join(robot.joint_names)}",
            )
        return np.array([index[name] for name in robot.joint_names])

    def check_rates(self, robot: RobotModel) -> None:
        """Refuse velocities beyond RATE_LIMIT_MULTIPLE x the joint's velocity limit and
        accelerations beyond RATE_LIMIT_MULTIPLE x limit / the point's shortest interval
        (UNLIMITED_JOINT_RATE where the URDF gives no limit), naming the point, the column
        and the joint."""
        columns = self.chain_columns(robot)
        limits = np.array(robot.velocity_limits, dtype=float)
        limits[~(np.isfinite(limits) & (limits > 0.0))] = UNLIMITED_JOINT_RATE
        steps = np.diff(self.times_s)
        shortest_s = np.minimum(np.append(steps, np.inf), np.insert(steps, 0, np.inf))
        for name in ("velocities", "accelerations"):
            values = None if getattr(self, name) is None else getattr(self, name)[:, columns]
            per_s = shortest_s[:, None] if name == "accelerations" else np.ones((1, 1))
            if values is None or not np.any(
                beyond := np.abs(values) > RATE_LIMIT_MULTIPLE * limits / per_s
            ):
                continue
            k, j = (int(v) for v in np.argwhere(beyond)[0])
            unit = (
                "m" if robot.model.joints[j + 1].shortname().startswith("JointModelP") else "rad"
            )
            bound = f"{RATE_LIMIT_MULTIPLE:g} x its velocity limit {limits[j]:g} {unit}/s"
            if name == "accelerations":
                bound += f" per {shortest_s[k]:g} s (the point's shortest interval)"
            raise InvalidInputError(
                f"{self.field}.points[{k}].{name}[{columns[j]}]",
                f"joint '{robot.joint_names[j]}' at {values[k, j]:g} {unit}/s"
                f"{'^2' if name == 'accelerations' else ''}: beyond {bound}",
            )

    def chain_positions(self, robot: RobotModel) -> np.ndarray:
        """(N, n) positions in chain order, checked against the joint limits (1e-9 slack)."""
        positions = self.positions[:, self.chain_columns(robot)]
        outside = (positions < robot.lower_limits - 1e-9) | (positions > robot.upper_limits + 1e-9)
        if outside.any():
            k, j = (int(v) for v in np.argwhere(outside)[0])
            name = robot.joint_names[j]
            raise InvalidInputError(
                f"{self.field}.points[{k}].positions",
                f"joint '{name}' = {positions[k, j]:g} is outside its limits "
                f"[{robot.lower_limits[j]:g}, {robot.upper_limits[j]:g}]",
            )
        return positions


@dataclass(frozen=True)
class JointSpaceTrajectory:
    """The object motion a planned joint trajectory and a grasp induce (module docstring).

    Offers the common trajectory interface (``trajectory.TipMotion``), so the analyses work on
    it unchanged; its samples are the trajectory's points.

    Attributes:
        robot: The arm.
        planned: The planned joint trajectory.
        transform_tip_to_object: The grasp (attaches the object to the tip).
    """

    robot: RobotModel
    planned: PlannedJointTrajectory
    transform_tip_to_object: pin.SE3
    joint_positions: np.ndarray = field(init=False, repr=False)
    _spline: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        from scipy.interpolate import CubicHermiteSpline, CubicSpline

        positions = self.planned.chain_positions(self.robot)
        self.planned.check_rates(self.robot)
        times = self.planned.times_s
        if self.planned.velocities is not None:
            velocities = self.planned.velocities[:, self.planned.chain_columns(self.robot)]
            spline = CubicHermiteSpline(times, positions, velocities)
        else:
            spline = CubicSpline(times, positions)
        positions.setflags(write=False)
        object.__setattr__(self, "joint_positions", positions)
        object.__setattr__(self, "transform_tip_to_object", pin.SE3(self.transform_tip_to_object))
        object.__setattr__(self, "_spline", spline)

    @property
    def duration_s(self) -> float:
        """t_{N-1} − t_0 [s]."""
        return float(self.planned.times_s[-1] - self.planned.times_s[0])

    def times_s(self) -> np.ndarray:
        """The point times [s]."""
        return np.array(self.planned.times_s)

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The analyses' monotone time coordinate: quintic s((t − t_0)/T) and its rates."""
        tau = np.clip(
            (np.asarray(times_s, dtype=float) - self.planned.times_s[0]) / self.duration_s,
            0.0,
            1.0,
        )
        s, ds, dds = quintic_time_scaling(tau)
        return s, ds / self.duration_s, dds / self.duration_s**2

    def joint_rates(self) -> tuple[np.ndarray, np.ndarray]:
        """The joint velocities [rad/s or m/s] and accelerations [rad/s² or m/s²] at the
        points, chain order, of the interpolation the analyses use: the planner's velocities
        and their Hermite interpolation's accelerations, or without velocities the
        derivatives of the (not-a-knot) cubic spline through the positions."""
        if self.planned.velocities is None:
            return self._spline(self.planned.times_s, 1), self._spline(self.planned.times_s, 2)
        velocities = self.planned.velocities[:, self.planned.chain_columns(self.robot)]
        return np.array(velocities), self._spline(self.planned.times_s, 2)

    def _joint_states(self, times_s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Chain positions (given ones at the points), velocities, 2nd and 3rd derivatives."""
        times = np.clip(
            np.asarray(times_s, dtype=float), self.planned.times_s[0], self.planned.times_s[-1]
        )
        positions = self._spline(times)
        exact = np.searchsorted(self.planned.times_s, times)
        exact = np.minimum(exact, len(self.planned.times_s) - 1)
        at_point = self.planned.times_s[exact] == times
        positions[at_point] = self.joint_positions[exact[at_point]]
        return positions, self._spline(times, 1), self._spline(times, 2), self._spline(times, 3)

    def _kinematics(self, times_s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Tip rotations, positions, twists, twist rates (base axes) and the rest limits
        T²·J q̈ (or T³·J q⃛ where that vanishes), 6-D, base axes."""
        robot = self.robot
        model, data = robot.model, robot.model.createData()
        base = robot.transform_base_to_world
        positions, rates, seconds, thirds = self._joint_states(times_s)
        count = len(positions)
        rotations, translations = np.empty((count, 3, 3)), np.empty((count, 3))
        twists, twist_rates = np.empty((count, 6)), np.empty((count, 6))
        rest = np.empty((count, 6))
        frame, frame_type = robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        for i in range(count):
            q = robot.q_from_positions(positions[i])
            pin.forwardKinematics(model, data, q, rates[i], seconds[i])
            pin.computeJointJacobians(model, data, q)
            pose = base.actInv(pin.updateFramePlacement(model, data, frame))
            rotations[i], translations[i] = pose.rotation, pose.translation
            jacobian = pin.getFrameJacobian(model, data, frame, frame_type).reshape(6, model.nv)
            twist = jacobian @ rates[i]
            accel = pin.getFrameClassicalAcceleration(model, data, frame, frame_type)
            twists[i] = np.concatenate([base.rotation.T @ twist[:3], base.rotation.T @ twist[3:]])
            twist_rates[i] = np.concatenate(
                [base.rotation.T @ accel.linear, base.rotation.T @ accel.angular]
            )
            t = self.duration_s
            second = jacobian @ seconds[i] * t**2
            third = jacobian @ thirds[i] * t**3
            limit = second if np.linalg.norm(second[:3]) >= STATIONARY_TANGENT_M else third
            rest[i] = np.concatenate([base.rotation.T @ limit[:3], base.rotation.T @ limit[3:]])
        return rotations, translations, twists, twist_rates, rest

    def object_poses(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object rotations (N, 3, 3) and positions (N, 3) [m] in the base frame."""
        rotations, positions, *_ = self._kinematics(times_s)
        inverse = self.transform_tip_to_object.inverse()
        object_rotations = rotations @ inverse.rotation
        return object_rotations, positions + rotations @ inverse.translation

    def tip_motion(self, transform_tip_to_object: pin.SE3, times_s: np.ndarray) -> TipMotion:
        """Motion of a frame attached to the object (``transform_tip_to_object`` in the object
        frame): poses, tangents T·v [m] (at rest: the limit direction, module docstring) and
        speeds [m/s]."""
        rotations, positions, twists, _, rest = self._kinematics(times_s)
        relative = self.transform_tip_to_object.inverse() * pin.SE3(transform_tip_to_object)
        lever = rotations @ relative.translation  # tip -> attached frame, base axes
        velocity = twists[:, :3] + np.cross(twists[:, 3:], lever)
        tangents = velocity * self.duration_s
        at_rest = np.linalg.norm(tangents, axis=1) < STATIONARY_TANGENT_M
        limit = rest[:, :3] + np.cross(rest[:, 3:], lever)  # J q̈ (or J q⃛) where q̇ = 0
        tangents[at_rest] = limit[at_rest]
        return TipMotion(
            rotations=rotations @ relative.rotation,
            positions=positions + lever,
            tangents=tangents,
            speeds=np.linalg.norm(velocity, axis=1),
        )

    def tip_twists(
        self, transform_tip_to_object: pin.SE3, times_s: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Twist (N, 6) [m/s, rad/s] and its time derivative of a frame attached to the object
        (base axes; linear part: classical acceleration)."""
        rotations, _, twists, rates, _ = self._kinematics(times_s)
        relative = self.transform_tip_to_object.inverse() * pin.SE3(transform_tip_to_object)
        lever = rotations @ relative.translation
        omega, alpha = twists[:, 3:], rates[:, 3:]
        out, out_rate = twists.copy(), rates.copy()
        out[:, :3] += np.cross(omega, lever)
        out_rate[:, :3] += np.cross(alpha, lever) + np.cross(omega, np.cross(omega, lever))
        return out, out_rate
