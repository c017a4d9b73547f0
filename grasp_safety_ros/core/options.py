"""The one table of options: each option's key, type, unit, default, bounds and help.

Every interface takes its defaults and bounds from here: the scenario file's parser
(``scenario.schema``), the node's parameters (``ros.parameters``: defaults, help, ranges; their
typed declaration and ``docs/ros/parameters.md`` follow from those), the batch SPEC (the
scenario's parser) and the core's own dataclasses (``AnalysisOptions``, ``PostureConfig``,
``InertiaUncertainty``: checked equal by ``test/test_options.py``). The few values an
interface must set differently are LIMITS' node budgets, with their reason.

Keys are the node's parameter names; ``scenario`` is the scenario file's key where it differs
(None: the node only).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from .analyses.effort import EFFORT_CRITERIA
from .analyses.exposed_points import METRIC_POINTS
from .analyses.redundancy import MAX_PROFILE_DEGREE, RedundancyConfig
from .analyses.safety_report import RANK_BY
from .analyses.whole_arm import DEFAULT_RANK_REGION
from .method.ik import IKConfig
from .method.metrics import METRICS
from .method.posture import DEFAULT_RESTARTS, MAX_RESTARTS

__all__ = [
    "IK_OPTIONS",
    "LIMITS",
    "OPTIONS",
    "REDUNDANCY_OPTIONS",
    "Limit",
    "Option",
    "bounds",
    "default",
    "help_text",
    "ik_config",
    "redundancy_config",
]

MAX_UNCERTAINTY_SAMPLES = 10_000
"""Most random inertias per request (``uncertainty.samples`` = 10^9 asked for 52 GiB)."""


@dataclass(frozen=True)
class Option:
    """One option of a ranking.

    Attributes:
        key: The node parameter's name (dotted sections).
        type: ``bool``, ``int``, ``float`` or ``str``.
        default: Its value when not given, in every interface.
        help: One line on what it does.
        unit: Its unit (``s``, ``m``, ``%``, ...); empty: none.
        bounds: Closed [low, high] of a number; None: unbounded, half-open (the fractions'
            [0, 1), stated in the help) or not a number.
        choices: The allowed strings; empty: any.
        scenario: The scenario file's key when it differs from ``key``; None: same.
    """

    key: str
    type: type
    default: bool | int | float | str
    help: str
    unit: str = ""
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    scenario: str | None = None

    @property
    def scenario_key(self) -> str:
        """The key in a scenario file (and a batch SPEC)."""
        return self.scenario or self.key


def _bar(values: tuple[str, ...]) -> str:
    return " | ".join(values)


OPTIONS: Mapping[str, Option] = MappingProxyType(
    {
        option.key: option
        for option in (
            Option("metric", str, "mean", f"score: {_bar(METRICS)}", choices=METRICS),
            Option(
                "metric_point",
                str,
                "tip",
                f"point whose effective mass the safety score uses: {_bar(METRIC_POINTS)} "
                "(the last two need object points)",
                choices=METRIC_POINTS,
            ),
            Option(
                "safety_weight",
                float,
                0.5,
                "w in [0, 1] of w*safety + (1 - w)*quality when a grasp quality is given",
                bounds=(0.0, 1.0),
            ),
            Option(
                "redundancy.enabled",
                bool,
                False,
                "lower the tip effective mass in the null space (chains with > 6 joints)",
                scenario="redundancy",
            ),
            Option(
                "redundancy.iterations",
                int,
                60,
                "largest number of descent steps of the null-space optimisation",
            ),
            Option(
                "redundancy.profile_degree",
                int,
                5,
                "degree of the joint offset profile's Bernstein polynomial in time (0: one "
                "constant offset, a new start posture only)",
                bounds=(0, MAX_PROFILE_DEGREE),
            ),
            Option(
                "redundancy.max_rate_ratio",
                float,
                1.5,
                "largest ratio of the optimised to the original trajectory's peak joint speed "
                "and acceleration, >= 1",
            ),
            Option(
                "redundancy.max_effort_fraction",
                float,
                1.0,
                "largest peak joint torque of the optimised trajectory as a fraction of the "
                "URDF effort limit, > 0",
            ),
            Option(
                "ik.max_iterations",
                int,
                100,
                "Gauss-Newton iterations of the IK per trajectory sample",
            ),
            Option(
                "ik.position_tolerance_m",
                float,
                1e-6,
                "the IK converges when the tip position error is at most this, > 0",
                unit="m",
            ),
            Option(
                "ik.orientation_tolerance_rad",
                float,
                1e-6,
                "... and the tip orientation error at most this, > 0",
                unit="rad",
            ),
            Option(
                "ik.random_restarts",
                int,
                30,
                "random IK seeds tried for the first sample when the given seed fails",
            ),
            Option("effort.enabled", bool, True, "compute joint torques along the trajectory"),
            Option(
                "effort.criterion",
                str,
                "peak_fraction",
                f"effort score: {_bar(EFFORT_CRITERIA)} of the URDF effort limits",
                choices=EFFORT_CRITERIA,
            ),
            Option(
                "rank_by",
                str,
                "safety",
                f"final order: {_bar(RANK_BY)} (effort turns effort.enabled on)",
                choices=RANK_BY,
            ),
            Option(
                "whole_arm.enabled",
                bool,
                False,
                "assess points on the arm's links (every chain joint origin from the third on, "
                "the tip, and whole_arm.points_m); rank_by whole_arm or extra points turn it on",
            ),
            Option(
                "whole_arm.region",
                str,
                DEFAULT_RANK_REGION,
                "body region whose worst predicted transient force over the arm's points "
                "orders rank_by whole_arm; must be among iso_ts_15066.regions (when not empty)",
            ),
            Option(
                "retime.safety_factor",
                float,
                1.0,
                "safe retiming (retime.joint_acceleration_limits set): every site is kept under "
                "this fraction of its ISO/TS 15066 admissible speed, in (0, 1]",
            ),
            Option(
                "posture.restarts",
                int,
                DEFAULT_RESTARTS,
                "IK restarts at the start pose per grasp besides the seed's; the lowest-score "
                "posture is kept; 0: the paper's single IK",
                bounds=(0, MAX_RESTARTS),
            ),
            Option(
                "uncertainty.mass_fraction",
                float,
                0.0,
                "relative object mass error bound, in [0, 1); all three bounds 0: no analysis",
            ),
            Option(
                "uncertainty.com_offset_m",
                float,
                0.0,
                "object CoM error bound per object axis",
                unit="m",
            ),
            Option(
                "uncertainty.inertia_fraction",
                float,
                0.0,
                "relative error bound of the principal moments of inertia, in [0, 1)",
            ),
            Option(
                "uncertainty.samples",
                int,
                64,
                "random inertias drawn in the error box (besides the nominal one and the corners)",
                bounds=(0, MAX_UNCERTAINTY_SAMPLES),
            ),
            Option(
                "uncertainty.percentile",
                float,
                95.0,
                "percentile of the score reported per grasp, in [0, 100]",
                bounds=(0.0, 100.0),
            ),
            Option(
                "uncertainty.seed",
                int,
                0,
                "seed of the random inertias (results are repeatable)",
            ),
        )
    }
)
"""Every option, by node parameter name."""

IK_OPTIONS = tuple(key for key in OPTIONS if key.startswith("ik."))
"""The IK solver's options (core.method.ik.IKConfig fields, ``ik.`` prefixed)."""

REDUNDANCY_OPTIONS = tuple(
    key for key in OPTIONS if key.startswith("redundancy.") and key != "redundancy.enabled"
)
"""The null-space optimisation's settings (core.analyses.redundancy.RedundancyConfig fields,
``redundancy.`` prefixed); ``redundancy.enabled`` is AnalysisOptions.redundancy."""


def _fields(keys: tuple[str, ...], values: Mapping[str, Any]) -> dict[str, Any]:
    """``keys``' values (their defaults where absent) as fields: the section prefix dropped."""
    return {key.split(".", 1)[1]: values.get(key, default(key)) for key in keys}


def ik_config(values: Mapping[str, Any]) -> IKConfig:
    """The IKConfig of IK_OPTIONS' values by dotted key (absent: the table's default); the
    config checks them (InvalidInputError naming ``ik.<field>``)."""
    return IKConfig(**_fields(IK_OPTIONS, values))


def redundancy_config(values: Mapping[str, Any]) -> RedundancyConfig:
    """The RedundancyConfig of REDUNDANCY_OPTIONS' values by dotted key (absent: the table's
    default); the config checks them (InvalidInputError naming ``redundancy.<field>``)."""
    return RedundancyConfig(**_fields(REDUNDANCY_OPTIONS, values))


@dataclass(frozen=True)
class Limit:
    """A bound on a request's size: the largest a scenario (or batch chunk) accepts, which is
    also the top of the node's parameter that bounds its requests.

    Attributes:
        name: What is bounded.
        value: The limit (the scenario's, and the node parameter's upper bound).
        unit: Its unit; empty: a count.
        node: The node parameter bounded by it; empty: none.
        budget: That parameter's default: the per-request budget of a service shared by
            clients, lower than what a file may ask.
    """

    name: str
    value: float
    unit: str = ""
    node: str = ""
    budget: int = 0


LIMITS: Mapping[str, Limit] = MappingProxyType(
    {
        limit.name: limit
        for limit in (
            Limit("grasps", 10_000, node="max_grasps", budget=1000),
            Limit("grasp_samples", 10_000_000, node="max_total_samples", budget=500_000),
            Limit("trajectory_samples", 10_000_000, node="max_samples", budget=20_000),
            Limit("points", 1_000),
            Limit("uncertainty_samples", MAX_UNCERTAINTY_SAMPLES),
            Limit("object_size_m", 100.0, "m"),
        )
    }
)
"""Request-size limits (Limit), by name."""


def default(key: str) -> bool | int | float | str:
    """The default of option ``key`` (OPTIONS)."""
    return OPTIONS[key].default


def bounds(key: str) -> tuple[float, float]:
    """The bounds of numeric option ``key``; ValueError if it has none."""
    option = OPTIONS[key]
    if option.bounds is None:
        raise ValueError(f"option {key} has no bounds")
    return option.bounds


def help_text(key: str) -> str:
    """The option's help with its unit, as the node's parameter description shows it."""
    option = OPTIONS[key]
    return f"{option.help} [{option.unit}]" if option.unit else option.help
