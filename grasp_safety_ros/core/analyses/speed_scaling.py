"""Live speed scaling: the factor by which a robot's current motion must slow down so that
every assessed site stays under its body region's ISO/TS 15066 transient-contact speed.

For one joint state (q, q̇) of a robot carrying a payload (inertia in the tip frame, or
nothing), every site k (the whole-arm sites of ``arm_sites``, the tip among them, plus the
payload's points) has a speed |v_k| = |J_k q̇|, an effective mass along its own velocity and,
per body region, an admissible speed v_max (``site_speeds``: the shared math of the retiming).
Scaling q̇ by f scales every |v_k| by f and leaves the effective masses unchanged (they depend
on q and the direction of q̇ only), so the largest admissible factor is

    f = min(1, min_k margin · v_max,k / |v_k|)

over the sites that move (a site at rest, slower than ``rest_speed_m_s``, does not limit:
encoder noise never stops the robot), v_max,k the smallest admissible
speed of site k over the assessed regions (those where the TS permits transient contact) and
``margin`` in (0, 1] the fraction of it aimed at. ``IncreaseLimiter`` bounds how fast the
published factor may rise (never how fast it falls). Everything here is ROS-free; the node
``ros/monitor`` is the adapter.

In closed loop (``closed_loop_factor``) the measured state is the motion a controller has
already slowed by the published factor f_a: the unscaled motion's sites move 1/f_a times
faster, so its factor is min(1, f_a · min_k margin · v_max,k / |v_k|). Taking the state's own
factor instead would alternate between c/f and f (c the unscaled motion's factor) and, at its
fixed point sqrt(c), let every site run sqrt(1/c) times faster than admitted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .arm_sites import ArmSites
from .body_regions import BodyRegion
from .iso15066 import max_permissible_speed_m_s
from .site_speeds import SiteSpeedModel, permitted_regions, site_speeds


def check_margin(margin: float, field_name: str = "speed_scaling.margin") -> float:
    """The margin as a float in (0, 1], else InvalidInputError naming ``field_name``."""
    value = finite_float(margin, field_name, minimum=0.0, strict_minimum=True)
    if value > 1.0:
        raise InvalidInputError(field_name, f"must be in (0, 1], got {value:g}")
    return value


MAX_REST_SPEED_M_S = 0.01
"""Largest rest speed [m/s]: far below every region's v_max, so a site ignored as at rest at
factor f (f·|v| <= rest) would be admitted at that f anyway (rest <= v_max)."""


def check_rest_speed(value: float, field_name: str = "speed_scaling.rest_speed_m_s") -> float:
    """The rest speed as a float in [0, MAX_REST_SPEED_M_S] [m/s], else InvalidInputError."""
    return finite_float(value, field_name, minimum=0.0, maximum=MAX_REST_SPEED_M_S)


def headroom(
    speed_m_s: np.ndarray,
    max_speed_m_s: np.ndarray,
    margin: float = 1.0,
    rest_speed_m_s: float = 0.0,
) -> float:
    """min over moving sites (|v| > ``rest_speed_m_s``) of margin · v_max / |v| for (K,)
    speeds and limits [m/s]: how many times faster the motion could be; inf when no site moves
    (sites at rest do not limit)."""
    speeds = np.asarray(speed_m_s, dtype=float)
    moving = speeds > rest_speed_m_s
    if not moving.any():
        return math.inf
    return float(np.min(margin * np.asarray(max_speed_m_s, dtype=float)[moving] / speeds[moving]))


def scaling_factor(
    speed_m_s: np.ndarray,
    max_speed_m_s: np.ndarray,
    margin: float = 1.0,
    rest_speed_m_s: float = 0.0,
) -> float:
    """f = min(1, headroom): 1 when no site moves."""
    return min(1.0, headroom(speed_m_s, max_speed_m_s, margin, rest_speed_m_s))


def closed_loop_factor(applied: float, state_headroom: float) -> float:
    """The factor for the unscaled motion when the measured state already moves at
    ``applied`` times it (a controller applying the published factor): its sites' speeds are
    those of the state divided by ``applied``, so f = min(1, applied · headroom); 1 when no
    site moves (the factor cannot be inferred from a motion at rest, and rest is safe; never
    0 · inf)."""
    if math.isinf(state_headroom):
        return 1.0
    return min(1.0, applied * state_headroom)


@dataclass(frozen=True)
class RegionSpeed:
    """One body region at one joint state: its worst site (largest |v| / v_max).

    Attributes:
        region: Region name.
        site: Name of the worst site; "" when no site moves.
        effective_mass_kg: That site's effective mass along its velocity [kg] (NaN: none).
        speed_m_s: That site's speed [m/s] (0 when none moves).
        max_speed_m_s: The region's v_max for that mass [m/s], margin not applied (NaN: none).
        factor: min(1, margin · v_max / |v|) of this region alone (1 when none moves).
    """

    region: str
    site: str
    effective_mass_kg: float
    speed_m_s: float
    max_speed_m_s: float
    factor: float


def region_speeds(
    site_names: Sequence[str],
    speed_m_s: np.ndarray,
    effective_mass_kg: np.ndarray,
    regions: Sequence[BodyRegion],
    margin: float = 1.0,
    rest_speed_m_s: float = 0.0,
) -> tuple[RegionSpeed, ...]:
    """Per region (transient contact permitted), the worst of K sites with (K,) speeds [m/s]
    and effective masses [kg] (first on ties); sites at or below ``rest_speed_m_s`` are at
    rest."""
    speeds = np.asarray(speed_m_s, dtype=float)
    masses = np.asarray(effective_mass_kg, dtype=float)
    moving = np.flatnonzero(speeds > rest_speed_m_s)
    result = []
    for region in regions:
        if not len(moving):
            result.append(RegionSpeed(region.name, "", math.nan, 0.0, math.nan, 1.0))
            continue
        limits = max_permissible_speed_m_s(masses[moving], region)
        worst = int(np.argmax(speeds[moving] / limits))
        k = int(moving[worst])
        limit = float(limits[worst])
        result.append(
            RegionSpeed(
                region=region.name,
                site=site_names[k],
                effective_mass_kg=float(masses[k]),
                speed_m_s=float(speeds[k]),
                max_speed_m_s=limit,
                factor=min(1.0, margin * limit / float(speeds[k])),
            )
        )
    return tuple(result)


@dataclass(frozen=True)
class StateScaling:
    """The speed scaling of one joint state.

    Attributes:
        factor: f = min(1, headroom) (module docstring).
        headroom: min_k margin · v_max,k / |v_k| over the moving sites; inf when none moves.
        limiting_site, limiting_region: The site and region that set f; "" when f is 1.
        regions: One RegionSpeed per assessed region, in the model's region order.
    """

    factor: float
    headroom: float
    limiting_site: str
    limiting_region: str
    regions: tuple[RegionSpeed, ...]


def payload_speed_model(
    robot: RobotModel,
    sites: ArmSites,
    payload: ObjectInertia | None,
    points_in_tip_m: np.ndarray | None,
    regions: Sequence[str | BodyRegion] | None,
) -> SiteSpeedModel:
    """The SiteSpeedModel of ``robot`` carrying ``payload`` (inertia in the tip frame; None:
    nothing carried, and then no payload points) with ``sites`` plus the payload's points
    (P, 3) [m, tip frame], against the permitted ``regions`` (None: all permitted)."""
    if payload is None:
        model = robot.model.copy()
        return SiteSpeedModel(
            robot=robot,
            model=model,
            data=model.createData(),
            sites=sites,
            regions=permitted_regions(regions),
        )
    return SiteSpeedModel.build(
        robot, payload, pin.SE3.Identity(), sites, points_in_tip_m, regions
    )


@dataclass
class SpeedScaling:
    """The per-state analysis for one robot, payload and site set (built once, then called
    per joint state; not thread-safe: it reuses the model's Pinocchio data).

    Attributes:
        speed_model: The robot, payload, sites and regions (``payload_speed_model``).
        margin: Fraction of v_max aimed at, in (0, 1].
        rest_speed_m_s: Sites at or below this speed are at rest (do not limit) [m/s].
    """

    speed_model: SiteSpeedModel
    margin: float = 1.0
    rest_speed_m_s: float = 0.0

    def __post_init__(self) -> None:
        self.margin = check_margin(self.margin)
        self.rest_speed_m_s = check_rest_speed(self.rest_speed_m_s)

    def assess(self, positions: np.ndarray, velocities: np.ndarray) -> StateScaling:
        """The scaling of the chain state: joint positions [rad or m] and velocities [rad/s
        or m/s], chain order (continuous joints as angles)."""
        robot = self.speed_model.robot
        n = robot.num_joints
        q = finite_array(positions, "joint_states.position", (n,))
        qd = finite_array(velocities, "joint_states.velocity", (n,))
        speeds = site_speeds(self.speed_model, robot.q_from_positions(q)[None], qd[None])
        speed, mass = speeds.speed_per_unit[0], speeds.effective_mass_kg[0]
        limit = speeds.max_speed_m_s[0]
        rest = self.rest_speed_m_s
        room = headroom(speed, limit, self.margin, rest)
        factor = min(1.0, room)
        site = region = ""
        if factor < 1.0:
            moving = speed > rest
            ratios = np.where(moving, speed / np.where(moving, limit, 1.0), 0.0)
            k = int(np.argmax(ratios))
            site = self.speed_model.sites.names[k]
            region = self.speed_model.regions[int(speeds.region_index[0, k])].name
        return StateScaling(
            factor=factor,
            headroom=room,
            limiting_site=site,
            limiting_region=region,
            regions=region_speeds(
                self.speed_model.sites.names,
                speed,
                mass,
                self.speed_model.regions,
                self.margin,
                rest,
            ),
        )


@dataclass
class IncreaseLimiter:
    """Bounds the rise of a factor to ``max_increase_per_s`` per second; a fall passes at once.

    Starts at ``factor`` 0 at time ``time_s``; each call gives the factor to publish at
    ``time_s`` [s, monotonic] for the ``target`` in [0, 1].
    """

    max_increase_per_s: float
    factor: float = 0.0
    time_s: float | None = field(default=None)

    def __call__(self, target: float, time_s: float) -> float:
        if self.time_s is None or target <= self.factor:
            self.factor = target
        else:
            elapsed = max(0.0, time_s - self.time_s)
            self.factor = min(target, self.factor + self.max_increase_per_s * elapsed)
        self.time_s = time_s
        return self.factor
