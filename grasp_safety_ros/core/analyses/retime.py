"""Safe retiming: the time-optimal timing of a grasp's joint path under the ISO/TS 15066 site
speed limits and the joint velocity and acceleration limits (TOPP-RA, ``toppra``).

The joint path q(s) is the clamped cubic spline through the planned samples, with the path
parameter s the planned time [s] (so the planner's own timing is ṡ = 1, and the path is at
rest at both ends: q'(0) = q'(T) = 0). TOPP-RA (Pham & Pham 2018) finds, on a grid of path
points s_i (the planned samples), the largest path velocities ṡ_i with piecewise-constant path
acceleration s̈ between them, at rest at both ends, subject at every grid point to:

- joint velocities |q'(s_i)| ṡ ≤ v_lim (``toppra.constraint.JointVelocityConstraint``);
- joint accelerations |q''(s) ṡ² + q'(s) s̈| ≤ a_lim (``JointAccelerationConstraint``,
  ``DiscretizationType.Interpolation``: with the s̈ of segment i, at both its ends s_i and
  s_i+1, ṡ²_i+1 = ṡ²_i + 2 s̈ (s_i+1 - s_i));
- every site k (``site_speeds``: arm sites, tip, object points; armature and object in the
  effective mass): |J_k q'(s_i)| ṡ ≤ f · v_max,k(s_i), with f the safety factor and v_max,k the
  admissible transient-contact speed of the limiting permitted region for the site's effective
  mass along its direction of motion (which is that of J_k q', whatever ṡ > 0): a first-order
  constraint ṡ² ≤ (f v_max,k / |J_k q'|)² (``SiteSpeedConstraint``).

The constraints hold at the grid points; between them the path's q', q'' change and a site or
joint may exceed its limit by what the path changes over one grid interval. The result is
reported on the grid (``output_dt_s`` None, the default: the samples where every limit holds
to TOPP-RA's solver tolerance) or at a uniform ``output_dt_s`` (interpolated: s̈ constant per
segment; the per-sample binding ratio says by how much a limit is exceeded there, if at all).

Beside it: the planner's own timing's worst site ratio max_i,k |J_k q'(s_i)| / (f v_max,k)
(ṡ = 1) and the uniform ``T_min`` = T · that ratio (the whole motion slowed alike; equal to
the whole-arm analysis' T_min up to the joint velocities used: here the spline's, there the
tip-following ones). Where the uniformly slowed timing is itself within the joint limits it is
one feasible timing, so the retimed one is no longer (to the grid: see the tests).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import GraspSafetyError, InvalidInputError
from ..input_checks import finite_float, read_only
from ..model.robot import RobotModel, per_joint_values
from .site_speeds import SiteSpeedModel, SiteSpeeds, site_speeds

RETIME_FIELD = "retime"
"""Prefix of the retiming inputs in messages (the scenario's ``retime:`` section)."""

MIN_SAMPLES = 3
"""Fewest path samples a retiming accepts (two grid intervals)."""

MAX_OUTPUT_SAMPLES = 100_000
"""Most samples a uniform ``output_dt_s`` may produce."""


def check_output_dt(output_dt_s: float | None, planned_durations_s: Sequence[float]) -> None:
    """Refuse a uniform ``output_dt_s`` [s] that gives more than MAX_OUTPUT_SAMPLES samples
    over the longest planned duration [s] (a safe duration longer still fails that grasp)."""
    if output_dt_s is None or not len(planned_durations_s):
        return
    longest = max(planned_durations_s)
    if longest / output_dt_s > MAX_OUTPUT_SAMPLES:
        raise InvalidInputError(
            "retime.output_dt_s",
            f"must be >= {longest / MAX_OUTPUT_SAMPLES:.3g} s (at most {MAX_OUTPUT_SAMPLES} "
            f"samples over the longest planned duration {longest:.3g} s), got {output_dt_s:g}",
        )


AT_REST = "at rest"
"""The binding label of a sample where nothing moves."""

MAX_PATH_RATE = 1e3
"""Cap on ṡ (the planned timing is ṡ = 1): where the path is at rest (q' = q'' = 0, the
ends of a quintic) no limit bounds ṡ or s̈ and TOPP-RA's sets would be unbounded."""

MAX_PATH_ACCELERATION = 1e4
"""Cap on |s̈| [1/s] for the same reason (toppra's own MAXU)."""


def joint_limits_from_input(
    value: Any,
    robot: RobotModel,
    field: str,
    default: np.ndarray | None = None,
) -> np.ndarray:
    """Per-joint limits (n,), chain order, each finite and > 0 [rad/s or rad/s², m/s or m/s²
    prismatic]: a list in chain order or ``{joint: value}`` (joints not named keep
    ``default``; without a default every joint must be named)."""
    names = robot.joint_names
    base = np.full(len(names), np.nan) if default is None else default
    values = per_joint_values(value, names, field, _limit, base)
    missing = [n for n, v in zip(names, values, strict=True) if not np.isfinite(v)]
    if missing:  # a mapping without a default names every joint
        raise InvalidInputError(field, f"has no finite limit for {', '.join(missing)}")
    return values


def _limit(value: Any, field: str) -> float:
    """One limit: a finite number > 0."""
    if isinstance(value, bool):
        raise InvalidInputError(field, f"must be a number > 0, got {value!r}")
    return finite_float(value, field, 0.0, None, True)


@dataclass(frozen=True)
class RetimeLimits:
    """The limits a retiming obeys.

    Attributes:
        joint_velocity_limits: (n,) [rad/s, m/s prismatic], > 0 and finite.
        joint_acceleration_limits: (n,) [rad/s², m/s² prismatic], > 0 and finite.
        safety_factor: f in (0, 1]: each site's speed is kept under f · v_max.
    """

    joint_velocity_limits: np.ndarray
    joint_acceleration_limits: np.ndarray
    safety_factor: float = 1.0

    @classmethod
    def from_input(
        cls,
        robot: RobotModel,
        joint_acceleration_limits: Any,
        joint_velocity_limits: Any = None,
        safety_factor: Any = 1.0,
        field: str = RETIME_FIELD,
    ) -> RetimeLimits:
        """Checked limits: accelerations required (the URDF has none), velocities default to
        the URDF's (refused where it gives none: 0 or not finite), f in (0, 1]."""
        if joint_acceleration_limits is None:
            raise InvalidInputError(
                f"{field}.joint_acceleration_limits",
                "is required for a retiming (a list in chain order or {joint: value} "
                "[rad/s², m/s² prismatic]; the URDF has none)",
            )
        accelerations = joint_limits_from_input(
            joint_acceleration_limits, robot, f"{field}.joint_acceleration_limits"
        )
        urdf = np.where(robot.velocity_limits > 0.0, robot.velocity_limits, np.nan)
        if joint_velocity_limits is None:
            bad = [n for n, v in zip(robot.joint_names, urdf, strict=True) if not np.isfinite(v)]
            if bad:
                raise InvalidInputError(
                    f"{field}.joint_velocity_limits",
                    f"the URDF gives no velocity limit for {', '.join(bad)}; give them here",
                )
            velocities = read_only(urdf, copy=True)
        else:
            velocities = joint_limits_from_input(
                joint_velocity_limits, robot, f"{field}.joint_velocity_limits", urdf
            )
        factor = finite_float(safety_factor, f"{field}.safety_factor", 0.0, 1.0, True)
        return cls(velocities, accelerations, factor)


@dataclass(frozen=True)
class RetimedMotion:
    """A grasp's joint path retimed (M output samples, n joints, chain order).

    Attributes:
        safe_duration_s: Duration of the retimed motion [s].
        times_s: (M,) output times [s] from 0.
        positions, velocities, accelerations: (M, n) q [rad, m], q̇ [rad/s, m/s], q̈
            [rad/s², m/s²].
        binding: (M,) the constraint closest to its limit per sample: ``site <name> (<region>)``,
            ``joint <name> velocity`` or ``joint <name> acceleration`` (AT_REST where
            nothing moves).
        binding_ratio: (M,) its value over its limit (1 where it binds, site limits include
            the safety factor).
        planned_duration_s: The planner's duration T [s].
        planned_worst_ratio: max over grid points and sites of speed / (f · v_max) at the
            planner's timing (> 1: too fast somewhere).
        planned_worst_site: Where (``site <name> (<region>)``).
        uniform_min_duration_s: T · planned_worst_ratio [s] (uniform scaling, sites only).
        uniform_feasible_duration_s: The shortest uniformly scaled duration within every
            limit, sites and joints: T · max(planned_worst_ratio, max |q'|/v_lim,
            sqrt(max |q''|/a_lim)) over the grid [s] (what uniform scaling really costs).
        grid_times_s: (N,) the times the grid points are reached [s].
        planned_times_s: (N,) the grid points: the planned sample times from 0 [s].
        regions: The regions assessed against (R), for the per-region series.
        region_speed_m_s: (M, R) per output sample and region, the speed of the site
            closest to that region's limit [m/s]; region_limit_m_s: (M, R) its f · v_max.
        planned_region_speed_m_s, planned_region_limit_m_s: (N, R) the same at the
            planner's timing, at the planned samples (grid points, times from 0).
    """

    safe_duration_s: float
    times_s: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    binding: tuple[str, ...]
    binding_ratio: np.ndarray
    planned_duration_s: float
    planned_worst_ratio: float
    planned_worst_site: str
    uniform_min_duration_s: float
    uniform_feasible_duration_s: float
    grid_times_s: np.ndarray
    planned_times_s: np.ndarray
    regions: tuple[str, ...] = ()
    region_speed_m_s: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    region_limit_m_s: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    planned_region_speed_m_s: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    planned_region_limit_m_s: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))


def most_binding(motion: RetimedMotion) -> str:
    """What sets ``motion``'s safe duration: the constraint binding (ratio > 0.99) at most
    samples (a ``binding`` label; on a tie the one binding first), or ``none``."""
    counts = Counter(
        label
        for label, ratio in zip(motion.binding, motion.binding_ratio, strict=True)
        if label != AT_REST and ratio > 0.99
    )
    return counts.most_common(1)[0][0] if counts else "none"


def region_series(speeds: SiteSpeeds, factor: float) -> tuple[np.ndarray, ...]:
    """Per sample and region (N, R): the speed [m/s] (``speed_per_unit`` along q̇, or along
    q' at ṡ = 1) of the site closest to the region's limit, and that limit f · v_max [m/s]."""
    speed = speeds.speed_per_unit  # (N, K)
    limits = factor * speeds.region_max_speed_m_s  # (N, K, R)
    if not speed.shape[1]:
        empty = np.zeros((len(speed), limits.shape[2]))
        return empty, empty
    worst = np.argmax(speed[..., None] / limits, axis=1)[:, None]  # (N, 1, R)
    chosen = np.take_along_axis(np.broadcast_to(speed[..., None], limits.shape), worst, axis=1)
    return chosen[:, 0], np.take_along_axis(limits, worst, axis=1)[:, 0]


def joint_path(times_s: np.ndarray, joint_positions: np.ndarray, robot: RobotModel) -> Any:
    """The clamped cubic spline q(s) through the samples (s = t − t_0 [s]; continuous joints
    unwrapped), as a ``toppra.SplineInterpolator``."""
    import toppra

    positions = np.array(joint_positions, dtype=float)
    continuous = ~np.isfinite(robot.lower_limits)
    if continuous.any():
        positions[:, continuous] = np.unwrap(positions[:, continuous], axis=0)
    return toppra.SplineInterpolator(times_s - times_s[0], positions, bc_type="clamped")


def _site_label(speed_model: SiteSpeedModel, site: int, region: int) -> str:
    return f"site {speed_model.sites.names[site]} ({speed_model.regions[region].name})"


def site_ratios(
    speed_model: SiteSpeedModel,
    robot: RobotModel,
    positions: np.ndarray,
    rates: np.ndarray,
    safety_factor: float,
) -> tuple[np.ndarray, SiteSpeeds]:
    """Per (sample, site): |J_k ṙ| / (f · v_max,k) (N, K) for joint positions (N, n) and
    rates (N, n) (q' or q̇), and the ``SiteSpeeds`` they come from."""
    q_all = np.array([robot.q_from_positions(p) for p in positions]).reshape(len(positions), -1)
    speeds = site_speeds(speed_model, q_all, rates)
    return speeds.speed_per_unit / (safety_factor * speeds.max_speed_m_s), speeds


def _site_constraint(ratios: np.ndarray) -> Any:
    """The per-site limit as a toppra first-order constraint: ṡ² ≤ 1 / max_k ratio_ik²
    (and the caps ṡ ≤ MAX_PATH_RATE, |s̈| ≤ MAX_PATH_ACCELERATION; no sites: those alone)."""
    from toppra.constraint import LinearConstraint

    worst = ratios.max(axis=1) if ratios.shape[1] else np.zeros(len(ratios))
    with np.errstate(divide="ignore"):
        upper = np.minimum(1.0 / worst**2, MAX_PATH_RATE**2)

    class SiteSpeedConstraint(LinearConstraint):
        """ṡ² ≤ (f v_max,k / |J_k q'|)² for every site k, on the retiming's own grid."""

        def __init__(self) -> None:
            super().__init__()
            self.dof = -1

        def compute_constraint_params(self, path: Any, gridpoints: np.ndarray, *_: Any) -> Any:
            count = len(gridpoints)
            path_rate = np.stack([np.zeros(count), upper], axis=1)
            path_acceleration = np.tile(
                [-MAX_PATH_ACCELERATION, MAX_PATH_ACCELERATION], (count, 1)
            )
            return None, None, None, None, None, path_acceleration, path_rate

    return SiteSpeedConstraint()


def retime_path(
    robot: RobotModel,
    speed_model: SiteSpeedModel | None,
    limits: RetimeLimits,
    times_s: np.ndarray,
    joint_positions: np.ndarray,
    output_dt_s: float | None = None,
) -> RetimedMotion:
    """The time-optimal timing of the joint path through ``joint_positions`` (N, n) sampled
    at ``times_s`` (N,) [s] (module docstring). ``speed_model`` None: joint limits only
    (what a user has without this package). Raises GraspSafetyError where TOPP-RA finds no
    timing (a numerically uncontrollable path)."""
    times, positions = _checked_path(robot, times_s, joint_positions)
    path = joint_path(times, positions, robot)
    grid = times - times[0]
    tangents = path(grid, 1)
    if speed_model is None:
        ratios, speeds = np.zeros((len(grid), 0)), None
    else:
        ratios, speeds = site_ratios(
            speed_model, robot, path(grid), tangents, limits.safety_factor
        )
    vlim, alim = limits.joint_velocity_limits, limits.joint_acceleration_limits
    path_accelerations, path_velocities = _time_optimal_rates(path, grid, ratios, vlim, alim)
    rates = np.maximum(path_velocities, 0.0)
    steps = 2.0 * np.diff(grid) / (rates[:-1] + rates[1:])
    grid_times = np.concatenate([[0.0], np.cumsum(steps)])
    duration = float(grid_times[-1])
    samples = _output_samples(path, grid, grid_times, rates, path_accelerations, output_dt_s)
    binding, binding_ratio, output_speeds = _binding(robot, speed_model, limits, samples)
    planned = ratios.max() if ratios.size else 0.0
    planned_duration = float(grid[-1])
    joint_ratio = max(
        float(np.max(np.abs(tangents) / vlim)),
        float(np.sqrt(np.max(np.abs(path(grid, 2)) / alim))),
    )
    worst, series = "", {}
    if speed_model is not None and speeds is not None and output_speeds is not None:
        worst = _site_label(speed_model, *_worst_site(ratios, speeds))
        series = _region_series_fields(speed_model, speeds, output_speeds, limits.safety_factor)
    return RetimedMotion(
        safe_duration_s=duration,
        times_s=read_only(samples[0]),
        positions=read_only(samples[1]),
        velocities=read_only(samples[2]),
        accelerations=read_only(samples[3]),
        binding=binding,
        binding_ratio=read_only(binding_ratio),
        planned_duration_s=planned_duration,
        planned_worst_ratio=float(planned),
        planned_worst_site=worst,
        uniform_min_duration_s=planned_duration * float(planned),
        uniform_feasible_duration_s=planned_duration * max(float(planned), joint_ratio),
        grid_times_s=read_only(grid_times),
        planned_times_s=read_only(grid),
        **series,
    )


def _checked_path(
    robot: RobotModel, times_s: np.ndarray, joint_positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``times_s`` (N,) and ``joint_positions`` (N, n) as float arrays; InvalidInputError
    unless finite, with at least MIN_SAMPLES increasing times and n joints."""
    times = np.asarray(times_s, dtype=float)
    positions = np.asarray(joint_positions, dtype=float)
    n = robot.num_joints
    if len(times) < MIN_SAMPLES or positions.shape != (len(times), n):
        raise InvalidInputError(
            "retime.path", f"needs >= {MIN_SAMPLES} samples of {n} joint positions"
        )
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(positions))):
        raise InvalidInputError("retime.path", "samples must be finite")
    if not np.all(np.diff(times) > 0.0):
        raise InvalidInputError("retime.path", "sample times must increase")
    return times, positions


def _time_optimal_rates(
    path: Any, grid: np.ndarray, ratios: np.ndarray, vlim: np.ndarray, alim: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """TOPP-RA's (s̈, ṡ) at the ``grid`` points of ``path`` from rest to rest within the joint
    velocity and acceleration limits and the site speed ``ratios``; GraspSafetyError where it
    finds none."""
    import toppra
    import toppra.algorithm
    import toppra.constraint

    constraints = [
        toppra.constraint.JointVelocityConstraint(np.stack([-vlim, vlim], axis=1)),
        toppra.constraint.JointAccelerationConstraint(
            np.stack([-alim, alim], axis=1),
            discretization_scheme=toppra.constraint.DiscretizationType.Interpolation,
        ),
    ]
    constraints.append(_site_constraint(ratios))
    solver = toppra.algorithm.TOPPRA(
        constraints,
        path,
        gridpoints=grid,
        solver_wrapper="seidel",
        parametrizer="ParametrizeConstAccel",
    )
    path_accelerations, path_velocities, _ = solver.compute_parameterization(0.0, 0.0)
    if path_velocities is None or not np.all(np.isfinite(path_velocities)):
        raise GraspSafetyError(
            "retime: TOPP-RA found no timing of this path within the limits (uncontrollable "
            "or badly conditioned path)"
        )
    return np.asarray(path_accelerations), path_velocities


def _region_series_fields(
    speed_model: SiteSpeedModel, planned: SiteSpeeds, retimed: SiteSpeeds, factor: float
) -> dict[str, Any]:
    """RetimedMotion's per-region series: the planned timing's (ṡ = 1) and the retimed's."""
    planned_speed, planned_limit = region_series(planned, factor)
    speed, limit = region_series(retimed, factor)
    return {
        "regions": tuple(region.name for region in speed_model.regions),
        "region_speed_m_s": read_only(speed),
        "region_limit_m_s": read_only(limit),
        "planned_region_speed_m_s": read_only(planned_speed),
        "planned_region_limit_m_s": read_only(planned_limit),
    }


def _worst_site(ratios: np.ndarray, speeds: SiteSpeeds) -> tuple[int, int]:
    """(site, region index) of the largest ratio."""
    sample, site = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
    return int(site), int(speeds.region_index[sample, site])


def _output_samples(
    path: Any,
    grid: np.ndarray,
    grid_times: np.ndarray,
    rates: np.ndarray,
    path_accelerations: np.ndarray,
    output_dt_s: float | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, q̇, q̈) at the grid points (``output_dt_s`` None) or every ``output_dt_s`` and
    the end: s(t) = s_i + ṡ_i τ + ½ s̈_i τ² in the segment i holding t."""
    duration = grid_times[-1]
    if output_dt_s is None:
        times = grid_times
    else:
        dt = finite_float(output_dt_s, "retime.output_dt_s", 0.0, None, True)
        if duration / dt > MAX_OUTPUT_SAMPLES:  # a per-path condition: not the request's
            raise GraspSafetyError(
                f"retime.output_dt_s {dt:g} s gives more than {MAX_OUTPUT_SAMPLES} samples "
                f"over this grasp's safe duration {duration:.3g} s"
            )
        times = np.append(np.arange(0.0, duration, dt), duration)
        times = times[np.concatenate([np.diff(times) > 0.0, [True]])]
    if output_dt_s is None:
        path_s, rate = grid, rates
        accel = np.append(path_accelerations, path_accelerations[-1])
    else:
        segment = np.clip(np.searchsorted(grid_times, times, side="right") - 1, 0, len(grid) - 2)
        tau = times - grid_times[segment]
        accel = path_accelerations[segment]
        rate = np.maximum(rates[segment] + accel * tau, 0.0)
        path_s = np.clip(
            grid[segment] + rates[segment] * tau + 0.5 * accel * tau**2, grid[0], grid[-1]
        )
    tangent, curvature = path(path_s, 1), path(path_s, 2)
    velocities = tangent * rate[:, None]
    accelerations = curvature * (rate**2)[:, None] + tangent * accel[:, None]
    return times, path(path_s), velocities, accelerations


def _binding(
    robot: RobotModel,
    speed_model: SiteSpeedModel | None,
    limits: RetimeLimits,
    samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[tuple[str, ...], np.ndarray, SiteSpeeds | None]:
    """Per output sample, the constraint closest to its limit and its ratio (value/limit),
    re-evaluated from the output q, q̇, q̈ (the sites along their actual velocity), and the
    sites' SiteSpeeds there (None without sites)."""
    _, positions, velocities, accelerations = samples
    names = [f"joint {n} velocity" for n in robot.joint_names]
    names += [f"joint {n} acceleration" for n in robot.joint_names]
    speeds = None
    columns = [
        np.abs(velocities) / limits.joint_velocity_limits,
        np.abs(accelerations) / limits.joint_acceleration_limits,
    ]
    if speed_model is not None:
        ratios, speeds = site_ratios(
            speed_model, robot, positions, velocities, limits.safety_factor
        )
        columns.append(ratios)
        names += [f"site {name}" for name in speed_model.sites.names]
    table = np.concatenate(columns, axis=1)
    where = np.argmax(table, axis=1)
    ratio = table[np.arange(len(table)), where]
    labels = []
    for row, column in enumerate(where):
        label = names[column]
        if speed_model is not None and speeds is not None and column >= 2 * robot.num_joints:
            site = column - 2 * robot.num_joints
            label = _site_label(speed_model, site, int(speeds.region_index[row, site]))
        labels.append(label if ratio[row] > 0.0 else AT_REST)
    return tuple(labels), ratio, speeds
