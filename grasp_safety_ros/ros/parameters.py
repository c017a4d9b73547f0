"""Node parameters: names, defaults, and validation as pure functions (no rclpy).

Every check raises InvalidInputError naming the parameter, so the node's on-set callback can
refuse a bad value with that reason, and the checks are unit-testable without ROS.
"""

from __future__ import annotations

import array
import dataclasses
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.analyses.effort import EFFORT_CRITERIA
from ..core.analyses.exposed_points import (
    METRIC_POINTS,
    box_corners_in_object,
    check_metric_point_has_points,
    cylinder_rim_points_in_object,
)
from ..core.analyses.iso15066 import BODY_REGIONS
from ..core.analyses.safe_duration import RetimeOptions
from ..core.analyses.safety_report import RANK_BY, AnalysisOptions
from ..core.analyses.uncertainty import InertiaUncertainty
from ..core.analyses.whole_arm import MAX_SITES
from ..core.exceptions import InvalidInputError
from ..core.input_checks import (
    MAX_ABS_POSITION_M,
    check_within_reach,
    finite_array,
    finite_float,
)
from ..core.method.ik import IKConfig
from ..core.method.posture import PostureConfig
from ..core.method.ranking import METRICS
from ..core.model.armature import PUBLISHED, published_armatures
from ..core.model.inertia import ObjectInertia
from ..core.options import (
    IK_OPTIONS,
    LIMITS,
    OPTIONS,
    REDUNDANCY_OPTIONS,
    bounds,
    help_text,
    ik_config,
    redundancy_config,
)
from .arm_points import arm_points, check_point_links
from .conversions.geometry import inertia_tensor_from_components
from .response import MAX_COUNT, ResponseContent
from .values import show, string_list

INFEASIBLE_CHOICES = ("append", "drop")
"""What ``~/plan_grasps`` does with grasps outside the node's order (``moveit.infeasible``):
last, with quality 0, or left out."""


@dataclass(frozen=True)
class ParameterSpec:
    """One node parameter: its default value and a one-line description (with units).

    Attributes:
        item_type: For list parameters, the type of their items (float or str); needed when
            the default list is empty. The node declares every parameter with the type of its
            default (``bool``, ``int``, ``float``, ``str`` or a list of ``item_type``).
        read_only: Only read at start-up: the node refuses to change it at run time.
    """

    default: Any
    description: str
    item_type: type | None = None
    read_only: bool = False


def _option(key: str) -> ParameterSpec:
    """The parameter of option ``key`` of the one table (core.options): default and help."""
    return ParameterSpec(OPTIONS[key].default, help_text(key))


PARAMETERS: Mapping[str, ParameterSpec] = {
    "robot_description": ParameterSpec(
        "",
        "URDF or MJCF XML of the robot; takes precedence over urdf and the /robot_description "
        "topic",
    ),
    "urdf": ParameterSpec(
        "",
        "URDF or MJCF file path or example-robot-data:<name>; used when robot_description is "
        "empty",
    ),
    "robot.armature_kgm2": ParameterSpec(
        [],
        "armature (reflected rotor inertia) per chain joint, base to tip, or per joint of "
        "robot.armature_joint_names [kg m^2; kg for prismatic joints], >= 0; empty: the "
        "description's own (an MJCF's) or none",
        item_type=float,
    ),
    "robot.armature_joint_names": ParameterSpec(
        [],
        "chain joints the values of robot.armature_kgm2 are for (the others keep the "
        "description's own: an MJCF's, else 0); empty: all chain joints in order",
        item_type=str,
    ),
    "robot.armature_lower_kgm2": ParameterSpec(
        [],
        "lower ends of armature ranges, for the joints of robot.armature_kgm2 (then the upper "
        "ends, which the chain carries) [kg m^2; kg for prismatic joints], 0 <= lower <= "
        "upper; the response gives the order at both ends; empty: no ranges",
        item_type=float,
    ),
    "robot.armature_published": ParameterSpec(
        "",
        "published | published:<entry>: the armature of data/armature_published.yaml (see "
        "docs/arms.md); takes precedence over robot.armature_kgm2; empty: not used",
    ),
    "robot_description_timeout_s": ParameterSpec(
        10.0,
        "start-up wait for the /robot_description topic when both robot_description and urdf "
        "are empty [s]; 0 waits for ever",
        read_only=True,
    ),
    "base_frame": ParameterSpec("", "base frame of the arm chain (URDF link or frame)"),
    "tip_frame": ParameterSpec("", "tip (end-effector) frame of the arm chain"),
    "object_frame": ParameterSpec(
        "object", "frame_id that marks grasps (and inertia) given in the object frame"
    ),
    "ik_seed": ParameterSpec(
        [],
        "IK seed, one position per chain joint, base to tip [rad or m]; empty: see docs",
        item_type=float,
    ),
    "use_joint_states_seed": ParameterSpec(
        True, "seed IK with the chain joints of /joint_states when ik_seed is empty"
    ),
    "object.mass_kg": ParameterSpec(
        0.0, "default object mass [kg]; 0: no default object (requests must give one)"
    ),
    "object.com_in_object_m": ParameterSpec(
        [0.0, 0.0, 0.0], "default object centre of mass in the object frame [m]"
    ),
    "object.inertia_about_com_kgm2": ParameterSpec(
        [0.0] * 6,
        "default object inertia about the CoM, object axes: ixx ixy ixz iyy iyz izz [kg m^2]",
    ),
    "trajectory.dt_s": ParameterSpec(0.02, "sampling period of the object trajectory [s]"),
    "trajectory.duration_s": ParameterSpec(
        2.0, "trajectory duration when the two Path stamps are equal [s]"
    ),
    "metric": _option("metric"),
    "max_grasps": ParameterSpec(
        LIMITS["grasps"].budget, "most grasps accepted in one request or candidate set"
    ),
    "max_samples": ParameterSpec(
        LIMITS["trajectory_samples"].budget, "most samples accepted per trajectory"
    ),
    "max_total_samples": ParameterSpec(
        LIMITS["grasp_samples"].budget,
        "most grasps x samples accepted in one request (bounds time and the result's size)",
    ),
    "max_mass_kg": ParameterSpec(1000.0, "largest object mass accepted [kg]"),
    "max_compute_time_s": ParameterSpec(
        60.0,
        "a ranking that has computed this long is abandoned (success=false); time queued "
        "behind other rankings does not count [s]",
    ),
    "service_busy_timeout_s": ParameterSpec(
        10.0, "how long a request waits for a ranking in progress before answering busy [s]"
    ),
    "diagnostics_period_s": ParameterSpec(1.0, "period of /diagnostics status messages [s]"),
    # --- Analyses beyond the paper (core.analyses.safety_report.AnalysisOptions) ---
    "metric_point": _option("metric_point"),
    "object.points_in_object_m": ParameterSpec(
        [],
        "exposed object points, object frame, flat x y z x y z ... [m]; empty: from "
        "object.box_size_m or object.cylinder_*, else none",
        item_type=float,
    ),
    "object.box_size_m": ParameterSpec(
        [],
        "box edges along the object axes [m] (points: its 8 corners about the CoM); []: none",
        item_type=float,
    ),
    "object.cylinder_radius_m": ParameterSpec(
        0.0, "cylinder radius [m], axis = object z (points: 8 per rim about the CoM); 0: none"
    ),
    "object.cylinder_length_m": ParameterSpec(0.0, "cylinder length [m]; 0: no cylinder"),
    "iso_ts_15066.regions": ParameterSpec(
        [], "ISO/TS 15066 body regions to assess; empty: all of them", item_type=str
    ),
    "uncertainty.mass_fraction": _option("uncertainty.mass_fraction"),
    "uncertainty.com_offset_m": _option("uncertainty.com_offset_m"),
    "uncertainty.inertia_fraction": _option("uncertainty.inertia_fraction"),
    "uncertainty.samples": _option("uncertainty.samples"),
    "uncertainty.percentile": _option("uncertainty.percentile"),
    "uncertainty.seed": _option("uncertainty.seed"),
    "safety_weight": _option("safety_weight"),
    "redundancy.enabled": _option("redundancy.enabled"),
    "effort.enabled": _option("effort.enabled"),
    "effort.criterion": _option("effort.criterion"),
    "rank_by": _option("rank_by"),
    "posture.restarts": _option("posture.restarts"),
    **{key: _option(key) for key in REDUNDANCY_OPTIONS},
    # the evaluator's, built with the robot: read at start-up
    **{key: dataclasses.replace(_option(key), read_only=True) for key in IK_OPTIONS},
    # --- What the result messages carry (the service's response and ~/ranking) ---
    "response.joint_trajectories": ParameterSpec(
        1,
        "how many grasps carry their joint_trajectory: the first of the final order, then the "
        "grasps outside it; 0: none; the number of grasps or more: all",
    ),
    "response.per_sample": ParameterSpec(
        True,
        "fill the per-sample arrays of every evaluation (time_from_start_s, effective_mass_kg, "
        "direction_xyz, ...); false: leave them empty (the scores and aggregates stay)",
    ),
    # --- ~/plan_grasps, the MoveIt GraspPlanning service (docs/ros/moveit.md) ---
    "moveit.grasp_planner_service": ParameterSpec(
        "",
        "the upstream planner's moveit_msgs/srv/GraspPlanning service whose grasps "
        "~/plan_grasps ranks; empty: none (it ranks the request's candidate_grasps)",
    ),
    "moveit.planner_timeout_s": ParameterSpec(
        10.0, "how long ~/plan_grasps waits for the planner's service and answer [s]"
    ),
    "moveit.infeasible": ParameterSpec(
        "append",
        f"{' | '.join(INFEASIBLE_CHOICES)}: grasps outside the order come last (quality 0) or "
        "are left out of the answer",
    ),
    "moveit.planner_quality": ParameterSpec(
        False, "weigh the planner's grasp_quality into the order (safety_weight)"
    ),
    "moveit.object_goal": ParameterSpec(
        [],
        "the object's goal pose for ~/plan_grasps: x y z [m] qx qy qz qw, base frame; empty: "
        "the last pose of the latest ~/object_trajectory",
        item_type=float,
    ),
    # --- The whole arm's exposure (core.analyses.whole_arm, docs/whole_arm.md) ---
    "whole_arm.enabled": _option("whole_arm.enabled"),
    "whole_arm.region": _option("whole_arm.region"),
    "whole_arm.point_links": ParameterSpec(
        [],
        "link of each extra point on the arm, one per x y z of whole_arm.points_m (a link may "
        "repeat); empty: the default points only",
        item_type=str,
    ),
    "whole_arm.points_m": ParameterSpec(
        [],
        "extra points on the arm, each in the frame of its whole_arm.point_links entry, flat "
        "x y z x y z ... [m]",
        item_type=float,
    ),
    # --- Safe retiming (core.analyses.retime, docs/safe_speed.md) ---
    "retime.joint_acceleration_limits": ParameterSpec(
        [],
        "joint acceleration limits, chain order [rad/s^2, m/s^2 prismatic]; set: each grasp "
        "is retimed to the ISO/TS 15066 site speed limits (needed by rank_by safe_duration)",
        item_type=float,
    ),
    "retime.joint_velocity_limits": ParameterSpec(
        [],
        "joint velocity limits of the retiming, chain order [rad/s, m/s prismatic]; empty: "
        "the URDF's",
        item_type=float,
    ),
    "retime.safety_factor": _option("retime.safety_factor"),
}
"""Every parameter of the node, by name."""

PUBLISHED_PARAMETER = "robot.armature_published"

ROBOT_PARAMETERS: tuple[str, ...] = ("robot_description", "urdf", "base_frame", "tip_frame")
ROBOT_PARAMETERS += ("robot.armature_kgm2", "robot.armature_joint_names")
ROBOT_PARAMETERS += ("robot.armature_published", "robot.armature_lower_kgm2")
"""Parameters whose change rebuilds the robot model."""

_STRINGS: tuple[str, ...] = (
    "robot_description",
    "urdf",
    "base_frame",
    "tip_frame",
    "object_frame",
    "metric",
)
_STRINGS += ("metric_point", "effort.criterion", "rank_by", "robot.armature_published")
_STRINGS += ("whole_arm.region", "moveit.grasp_planner_service", "moveit.infeasible")
_CHOICES: Mapping[str, Collection[str]] = {
    "metric": METRICS,
    "metric_point": METRIC_POINTS,
    "effort.criterion": EFFORT_CRITERIA,
    "rank_by": RANK_BY,
    "whole_arm.region": BODY_REGIONS,
    "moveit.infeasible": INFEASIBLE_CHOICES,
}
_FLAGS: tuple[str, ...] = (
    "use_joint_states_seed",
    "redundancy.enabled",
    "effort.enabled",
    "response.per_sample",
)
_FLAGS += ("whole_arm.enabled", "moveit.planner_quality")
_POSITIVE: tuple[str, ...] = (
    "trajectory.dt_s",
    "trajectory.duration_s",
    "max_mass_kg",
    "max_compute_time_s",
)
_POSITIVE += ("service_busy_timeout_s", "diagnostics_period_s", "moveit.planner_timeout_s")
_FRACTIONS = ("uncertainty.mass_fraction", "uncertainty.inertia_fraction")
_POSITIVE += tuple(k for k in IK_OPTIONS + REDUNDANCY_OPTIONS if OPTIONS[k].type is float)
_RANGES: Mapping[str, tuple[float, float]] = {
    key: bounds(key) for key in ("uncertainty.percentile", "safety_weight")
}
_MAX_POINTS = int(LIMITS["points"].value)
_COUNT_LIMITS: Mapping[str, tuple[int, int]] = {
    **{limit.node: (1, int(limit.value)) for limit in LIMITS.values() if limit.node},
    **{k: (0, MAX_COUNT) for k in IK_OPTIONS + REDUNDANCY_OPTIONS if OPTIONS[k].type is int},
    **{
        key: (int(bounds(key)[0]), int(bounds(key)[1]))
        for key in ("uncertainty.samples", "posture.restarts", "redundancy.profile_degree")
    },
    "uncertainty.seed": (0, MAX_COUNT),  # a seed, not a count
    "response.joint_trajectories": (0, MAX_COUNT),  # clipped to the number of grasps
}
"""Bounds of the node's count parameters; the request budgets' tops are the scenario's limits
(core.options.LIMITS): beyond them a request cannot finish in useful time or memory."""


@dataclass(frozen=True)
class NodeSettings:
    """Validated parameter values (see PARAMETERS for their meaning).

    Attributes:
        object_inertia: The default object, or None when ``object.mass_kg`` is 0.
        analysis: Options of core.analyses.safety_report.analyse from the analysis parameters
            (metric_point, object points, iso_ts_15066.*, uncertainty.*, safety_weight,
            redundancy.*, effort.*, rank_by); a request may change metric_point and add grasp
            quality.
        posture: Posture selection (``posture.restarts``).
        response: What the result messages carry (``response.*``).
        ik_seed: The seed parameter, or None when empty (length checked against the robot
            in build_robot).
        armature_kgm2, armature_joint_names, armature_published, armature_lower_kgm2: The
            ``robot.armature_*`` parameters (checked against the chain in build_robot).
    """

    robot_description: str
    urdf: str
    robot_description_timeout_s: float
    base_frame: str
    tip_frame: str
    object_frame: str
    ik_seed: tuple[float, ...] | None
    use_joint_states_seed: bool
    object_inertia: ObjectInertia | None
    trajectory_dt_s: float
    trajectory_duration_s: float
    metric: str
    max_grasps: int
    max_samples: int
    max_total_samples: int
    max_mass_kg: float
    max_compute_time_s: float
    service_busy_timeout_s: float
    diagnostics_period_s: float
    analysis: AnalysisOptions = dataclasses.field(default_factory=AnalysisOptions)
    posture: PostureConfig = dataclasses.field(default_factory=PostureConfig)
    ik: IKConfig = dataclasses.field(default_factory=IKConfig)
    response: ResponseContent = dataclasses.field(
        default_factory=lambda: ResponseContent(joint_trajectories=1)
    )
    armature_kgm2: tuple[float, ...] = ()
    armature_joint_names: tuple[str, ...] = ()
    armature_published: str = ""
    armature_lower_kgm2: tuple[float, ...] = ()

    @property
    def robot_source(self) -> str:
        """The robot given by parameters (XML, path or example-robot-data:<name>), or ''."""
        return self.robot_description or self.urdf


def _string(name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise InvalidInputError(name, f"must be a string, got {show(value)}")
    return value


def _integer(name: str, value: Any, minimum: int, maximum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidInputError(name, f"must be an integer, got {show(value)}")
    if not minimum <= value <= maximum:
        raise InvalidInputError(name, f"must be in [{minimum}, {maximum}], got {value}")
    return int(value)


def _numbers(name: str, value: Any, length: int | None) -> tuple[float, ...]:
    if value is None:  # an empty list in a params file arrives as NOT_SET
        value = []
    if not isinstance(value, (list, tuple, np.ndarray, array.array)):
        raise InvalidInputError(name, f"must be a list of numbers, got {show(value)}")
    items = list(value)
    if any(isinstance(v, (bool, str, bytes)) for v in items):
        raise InvalidInputError(name, f"must be a list of numbers, got {show(items)}")
    array_ = finite_array(items, name, None if length is None else (length,))
    if array_.ndim != 1:
        raise InvalidInputError(name, f"must be a flat list of numbers, got {show(items)}")
    return tuple(float(v) for v in array_)


def check_parameter(name: str, value: Any) -> Any:
    """Check one parameter on its own (type and range) and return its normalised value.

    Names not in PARAMETERS (e.g. ``use_sim_time``) are returned unchanged.
    """
    if name not in PARAMETERS:
        return value
    if name in _STRINGS:
        text = _string(name, value)
        if name == "robot_description" and text.strip() and not text.lstrip().startswith("<"):
            raise InvalidInputError(
                name, "must be URDF XML; give a file path or example-robot-data:<name> in urdf"
            )
        if name in _CHOICES and text not in _CHOICES[name]:
            raise InvalidInputError(
                name, f"must be one of {', '.join(_CHOICES[name])}, got {text!r}"
            )
        if name == "object_frame" and not text:
            raise InvalidInputError(name, "must be a non-empty frame name")
        if name == PUBLISHED_PARAMETER and text:
            _check_published(text)
        return text
    if name in _FLAGS:
        if not isinstance(value, bool):
            raise InvalidInputError(name, f"must be true or false, got {show(value)}")
        return value
    if name in _COUNT_LIMITS:
        return _integer(name, value, *_COUNT_LIMITS[name])
    if name == "ik_seed":
        return _numbers(name, value, None)
    if name in ("robot.armature_kgm2", "robot.armature_lower_kgm2"):
        values = _numbers(name, value, None)
        negative = [k for k, x in enumerate(values) if x < 0.0]
        if negative:
            raise InvalidInputError(
                f"{name}[{negative[0]}]", f"must be >= 0, got {values[negative[0]]:g}"
            )
        return values
    if name == "robot.armature_joint_names":
        return _names(name, value)
    if name == "object.com_in_object_m":
        return _numbers(name, value, 3)
    if name == "object.inertia_about_com_kgm2":
        return _numbers(name, value, 6)
    if name == "object.points_in_object_m":
        return _points(name, value)
    if name == "object.box_size_m":
        size = _numbers(name, value, None)
        if size and (len(size) != 3 or min(size) <= 0.0):
            raise InvalidInputError(
                name, f"must be empty or 3 edge lengths > 0 [m], got {show(list(size))}"
            )
        return size
    if name == "moveit.object_goal":
        goal = _numbers(name, value, None)
        if goal and len(goal) != 7:
            raise InvalidInputError(
                name, f"must be empty or x y z qx qy qz qw (7 numbers), got {len(goal)}"
            )
        return goal
    if name == "iso_ts_15066.regions":
        return _regions(name, value)
    if name == "whole_arm.point_links":
        return check_point_links(value)
    if name == "whole_arm.points_m":  # 1e300 m: every later ranking failed (LinAlgError)
        points = _points(name, value, MAX_SITES)
        check_within_reach(points, name)
        return points
    if name in ("retime.joint_acceleration_limits", "retime.joint_velocity_limits"):
        return _numbers(name, value, None)  # > 0 and one per joint: checked with the robot
    if name == "retime.safety_factor":
        return finite_float(value, name, 0.0, 1.0, strict_minimum=True)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidInputError(name, f"must be a number, got {show(value)}")
    if name in _POSITIVE:
        return finite_float(value, name, minimum=0.0, strict_minimum=True)
    if name in _FRACTIONS:
        fraction = finite_float(value, name, minimum=0.0)
        if fraction >= 1.0:
            raise InvalidInputError(name, f"must be in [0, 1), got {fraction:g}")
        return fraction
    if name in _RANGES:
        return finite_float(value, name, *_RANGES[name])
    # object.mass_kg (0 = none), robot_description_timeout_s (0 = for ever),
    # object.cylinder_* (0 = none), uncertainty.com_offset_m (0 = exact)
    return finite_float(value, name, minimum=0.0)


def _check_published(text: str) -> None:
    """``robot.armature_published`` on its own: ``published`` or a table entry."""
    prefix, _, entry = text.partition(":")
    if prefix != PUBLISHED:
        raise InvalidInputError(
            PUBLISHED_PARAMETER,
            f"must be empty, '{PUBLISHED}' or '{PUBLISHED}:<entry>', got {text!r}",
        )
    if entry and entry not in published_armatures():
        raise InvalidInputError(
            PUBLISHED_PARAMETER,
            f"no published entry '{entry}'; entries: {', '.join(published_armatures())}",
        )


def _points(name: str, value: Any, maximum: int = _MAX_POINTS) -> tuple[float, ...]:
    numbers = _numbers(name, value, None)
    if len(numbers) % 3:
        raise InvalidInputError(
            name, f"must hold x y z per point (a multiple of 3 numbers), got {len(numbers)}"
        )
    if len(numbers) > 3 * maximum:
        raise InvalidInputError(
            name, f"must hold at most {maximum} points, got {len(numbers) // 3}"
        )
    return numbers


def _names(name: str, value: Any) -> tuple[str, ...]:
    """A list of distinct non-empty names."""
    names = string_list(name, value, "joint names")
    if not names:
        return ()
    if not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
        raise InvalidInputError(name, f"must be distinct joint names, got {show(names)}")
    return tuple(names)


def _regions(name: str, value: Any) -> tuple[str, ...]:
    names = string_list(name, value, "region names")
    if not names:
        return ()
    for region in names:
        if not isinstance(region, str):
            raise InvalidInputError(name, f"must be a list of region names, got {show(names)}")
        if region not in BODY_REGIONS:
            raise InvalidInputError(
                name, f"unknown body region {region!r}; regions: {', '.join(BODY_REGIONS)}"
            )
    if len(set(names)) != len(names):
        raise InvalidInputError(name, f"regions repeat: {show(names)}")
    return tuple(names)


@dataclass(frozen=True)
class ParameterConstraints:
    """What check_parameter accepts, for ``ros2 param describe``.

    Attributes:
        value_range: Closed range (minimum, maximum) of a number, or None where the accepted
            set is not a closed interval (ROS ranges are closed).
        text: The constraint in words (empty when the type says it all).
    """

    value_range: tuple[float, float] | None
    text: str


def parameter_constraints(name: str) -> ParameterConstraints:
    """The constraints check_parameter applies to ``name`` on its own (not cross-parameter)."""
    closed: tuple[float, float] | None = None
    text = ""
    if name in _CHOICES:
        text = f"one of: {', '.join(_CHOICES[name])}"
    elif name in _COUNT_LIMITS:
        closed = _COUNT_LIMITS[name]
    elif name in _RANGES:
        closed = _RANGES[name]
    elif name in _POSITIVE:
        text = "> 0"
    elif name in _FRACTIONS:
        text = "in [0, 1)"
    elif name == "object_frame":
        text = "non-empty"
    elif name in ("base_frame", "tip_frame"):
        text = "required: a frame of the robot description"
    elif name == "robot_description":
        text = "empty or URDF XML"
    elif name == "ik_seed":
        text = "empty or one finite value per chain joint"
    elif name == "object.com_in_object_m":
        text = "3 finite values"
    elif name == "object.inertia_about_com_kgm2":
        text = "6 finite values"
    elif name == "object.points_in_object_m":
        text = f"x y z per point (a multiple of 3 finite values), at most {_MAX_POINTS} points"
    elif name == "object.box_size_m":
        text = "empty or 3 edge lengths > 0"
    elif name == "iso_ts_15066.regions":
        text = f"distinct names from: {', '.join(BODY_REGIONS)}"
    elif name == "whole_arm.point_links":
        text = f"links of the robot, one per point of whole_arm.points_m, at most {MAX_SITES}"
    elif name == "whole_arm.points_m":
        text = (
            f"x y z (3 finite values, within +/-{MAX_ABS_POSITION_M:g} m) per entry of "
            "whole_arm.point_links"
        )
    elif name.startswith("retime.joint_"):
        text = "empty or one value > 0 per chain joint"
    elif name == "retime.safety_factor":
        text = "in (0, 1]"
    elif name in PARAMETERS and isinstance(PARAMETERS[name].default, float):
        text = ">= 0"
    return ParameterConstraints(closed, text)


def points_from_parameters(values: Mapping[str, Any]) -> np.ndarray | None:
    """Exposed object points (K, 3) [m] from checked parameter values, or None.

    ``object.points_in_object_m`` when set; else the corners of ``object.box_size_m``; else the
    rims of the ``object.cylinder_*`` cylinder; both shapes centred on ``object.com_in_object_m``
    as the CLI's scenario files do.
    """
    points = values["object.points_in_object_m"]
    box = values["object.box_size_m"]
    radius, length = values["object.cylinder_radius_m"], values["object.cylinder_length_m"]
    if (radius > 0.0) != (length > 0.0):
        which = "object.cylinder_length_m" if radius > 0.0 else "object.cylinder_radius_m"
        raise InvalidInputError(which, "must be > 0 too: a cylinder needs a radius and a length")
    if box and radius > 0.0:
        raise InvalidInputError(
            "object.box_size_m",
            "give a box or a cylinder (object.cylinder_radius_m, object.cylinder_length_m), "
            "not both",
        )
    com = np.array(values["object.com_in_object_m"])
    if points:
        return np.array(points).reshape(-1, 3)
    if box:
        return np.array(box_corners_in_object(box, com))
    if radius > 0.0:
        return np.array(cylinder_rim_points_in_object(radius, length, com))
    return None


def analysis_from_parameters(values: Mapping[str, Any]) -> AnalysisOptions:
    """The AnalysisOptions of checked parameter values (no grasp quality).

    Raises:
        InvalidInputError: naming the parameter (e.g. metric_point without object points).
    """
    points = points_from_parameters(values)
    metric_point = values["metric_point"]
    check_metric_point_has_points(
        metric_point,
        points,
        "set object.points_in_object_m, object.box_size_m or object.cylinder_radius_m and "
        "object.cylinder_length_m",
    )
    bounds = [values[f"uncertainty.{n}"] for n in ("mass_fraction", "com_offset_m")]
    bounds.append(values["uncertainty.inertia_fraction"])
    uncertainty = None
    if any(bound > 0.0 for bound in bounds):
        uncertainty = InertiaUncertainty(
            mass_fraction=values["uncertainty.mass_fraction"],
            com_offset_m=values["uncertainty.com_offset_m"],
            inertia_fraction=values["uncertainty.inertia_fraction"],
            num_random_samples=values["uncertainty.samples"],
            seed=values["uncertainty.seed"],
            percentile=values["uncertainty.percentile"],
        )
    regions = values["iso_ts_15066.regions"]
    return AnalysisOptions(
        metric_point=metric_point,
        points_in_object_m=points,
        iso_regions=regions or None,
        uncertainty=uncertainty,
        safety_weight=values["safety_weight"],
        redundancy=values["redundancy.enabled"],
        effort=values["effort.enabled"],
        rank_by=values["rank_by"],
        effort_criterion=values["effort.criterion"],
        whole_arm=values["whole_arm.enabled"],
        arm_points_m=arm_points(values["whole_arm.point_links"], values["whole_arm.points_m"]),
        whole_arm_region=values["whole_arm.region"],
        retime=RetimeOptions(
            values["retime.joint_acceleration_limits"],
            values["retime.joint_velocity_limits"] or None,
            values["retime.safety_factor"],
        )
        if values["retime.joint_acceleration_limits"]
        else None,
        redundancy_settings=redundancy_config(values),
    )


def settings_from_parameters(values: Mapping[str, Any]) -> NodeSettings:
    """Validate a full set of parameter values (missing ones take their defaults).

    Raises:
        InvalidInputError: naming the first bad parameter; cross-parameter checks name the
            parameter to change.
    """
    merged = {name: spec.default for name, spec in PARAMETERS.items()}
    merged.update({k: v for k, v in values.items() if k in PARAMETERS})
    v = {name: check_parameter(name, value) for name, value in merged.items()}
    for name in ("base_frame", "tip_frame"):
        if not v[name]:
            raise InvalidInputError(name, "must be set to a frame of the robot description")
    if v["object_frame"] == v["base_frame"]:
        raise InvalidInputError(
            "object_frame", f"must differ from base_frame ('{v['base_frame']}')"
        )
    if v["trajectory.dt_s"] > v["trajectory.duration_s"]:
        raise InvalidInputError(
            "trajectory.dt_s",
            f"must be at most trajectory.duration_s={v['trajectory.duration_s']:g}, "
            f"got {v['trajectory.dt_s']:g}",
        )
    samples = math.ceil(v["trajectory.duration_s"] / v["trajectory.dt_s"] - 1e-9) + 1
    if samples > v["max_samples"]:
        raise InvalidInputError(
            "trajectory.dt_s",
            f"gives {samples} samples over trajectory.duration_s="
            f"{v['trajectory.duration_s']:g}; at most max_samples={v['max_samples']} are allowed",
        )
    mass = v["object.mass_kg"]
    if mass > v["max_mass_kg"]:
        raise InvalidInputError(
            "object.mass_kg", f"must be at most max_mass_kg={v['max_mass_kg']:g}, got {mass:g}"
        )
    inertia = None
    if mass > 0.0:
        tensor = inertia_tensor_from_components(
            v["object.inertia_about_com_kgm2"], "object.inertia_about_com_kgm2", mass
        )
        inertia = ObjectInertia(mass, np.array(v["object.com_in_object_m"]), tensor)
    return NodeSettings(
        robot_description=v["robot_description"].strip(),
        urdf=v["urdf"].strip(),
        robot_description_timeout_s=v["robot_description_timeout_s"],
        base_frame=v["base_frame"],
        tip_frame=v["tip_frame"],
        object_frame=v["object_frame"],
        ik_seed=v["ik_seed"] or None,
        use_joint_states_seed=v["use_joint_states_seed"],
        object_inertia=inertia,
        trajectory_dt_s=v["trajectory.dt_s"],
        trajectory_duration_s=v["trajectory.duration_s"],
        metric=v["metric"],
        max_grasps=v["max_grasps"],
        max_samples=v["max_samples"],
        max_total_samples=v["max_total_samples"],
        max_mass_kg=v["max_mass_kg"],
        max_compute_time_s=v["max_compute_time_s"],
        service_busy_timeout_s=v["service_busy_timeout_s"],
        diagnostics_period_s=v["diagnostics_period_s"],
        analysis=analysis_from_parameters(v),
        posture=PostureConfig(restarts=v["posture.restarts"]),
        ik=ik_config(v),
        response=ResponseContent(
            joint_trajectories=v["response.joint_trajectories"],
            per_sample=v["response.per_sample"],
        ),
        armature_kgm2=v["robot.armature_kgm2"],
        armature_joint_names=v["robot.armature_joint_names"],
        armature_published=v["robot.armature_published"],
        armature_lower_kgm2=v["robot.armature_lower_kgm2"],
    )
