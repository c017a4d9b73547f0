"""Checks of one node parameter on its own (type and range), by family, and the constraints
``ros2 param describe`` shows (pure functions, no rclpy).

Every check raises InvalidInputError naming the parameter, so the node's on-set callback can
refuse a bad value with that reason, and the checks are unit-testable without ROS.
"""

from __future__ import annotations

import array
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core.analyses.body_regions import BODY_REGIONS
from ...core.analyses.effort import EFFORT_CRITERIA
from ...core.analyses.exposed_points import METRIC_POINTS
from ...core.analyses.safety_report import RANK_BY
from ...core.analyses.whole_arm import MAX_SITES
from ...core.exceptions import InvalidInputError
from ...core.input_checks import (
    MAX_ABS_POSITION_M,
    check_within_reach,
    finite_array,
    finite_float,
)
from ...core.method.ranking import METRICS
from ...core.model.armature import PUBLISHED, published_armatures
from ...core.options import IK_OPTIONS, LIMITS, OPTIONS, REDUNDANCY_OPTIONS, bounds
from ..service.response import MAX_COUNT
from .arm_points import check_point_links
from .table import INFEASIBLE_CHOICES, PARAMETERS, PUBLISHED_PARAMETER
from .values import show, string_list

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
MAX_WAITING = 1_000
"""Top of ``moveit.max_waiting``: each request waiting for the planner costs the node CPU at
each executor wake-up (21 % of a core with 40 waiting, docs/ros/moveit.md); a thousand would
take the node's cores."""
_COUNT_LIMITS: Mapping[str, tuple[int, int]] = {
    **{limit.node: (1, int(limit.value)) for limit in LIMITS.values() if limit.node},
    **{k: (0, MAX_COUNT) for k in IK_OPTIONS + REDUNDANCY_OPTIONS if OPTIONS[k].type is int},
    **{
        key: (int(bounds(key)[0]), int(bounds(key)[1]))
        for key in ("uncertainty.samples", "posture.restarts", "redundancy.profile_degree")
    },
    "uncertainty.seed": (0, MAX_COUNT),  # a seed, not a count
    "response.joint_trajectories": (0, MAX_COUNT),  # clipped to the number of grasps
    "moveit.max_waiting": (1, MAX_WAITING),
}
"""Bounds of the node's count parameters; the request budgets' tops are the scenario's limits
(core.options.LIMITS): beyond them a request cannot finish in useful time or memory."""
_LISTS = frozenset(
    {
        "ik_seed",
        "robot.armature_kgm2",
        "robot.armature_lower_kgm2",
        "robot.armature_joint_names",
        "object.com_in_object_m",
        "object.inertia_about_com_kgm2",
        "object.points_in_object_m",
        "object.box_size_m",
        "moveit.object_goal",
        "iso_ts_15066.regions",
        "whole_arm.point_links",
        "whole_arm.points_m",
        "retime.joint_acceleration_limits",
        "retime.joint_velocity_limits",
    }
)
"""The array-valued parameters check_parameter hands to _check_list."""


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
        return _check_string(name, value)
    if name in _FLAGS:
        if not isinstance(value, bool):
            raise InvalidInputError(name, f"must be true or false, got {show(value)}")
        return value
    if name in _COUNT_LIMITS:
        return _integer(name, value, *_COUNT_LIMITS[name])
    if name in _LISTS:
        return _check_list(name, value)
    return _check_number(name, value)


def _check_string(name: str, value: Any) -> str:
    """A string parameter (one of _STRINGS): its type, its choices and its own format."""
    text = _string(name, value)
    if name == "robot_description" and text.strip() and not text.lstrip().startswith("<"):
        raise InvalidInputError(
            name, "must be URDF XML; give a file path or example-robot-data:<name> in urdf"
        )
    if name in _CHOICES and text not in _CHOICES[name]:
        raise InvalidInputError(name, f"must be one of {', '.join(_CHOICES[name])}, got {text!r}")
    if name == "object_frame" and not text:
        raise InvalidInputError(name, "must be a non-empty frame name")
    if name == PUBLISHED_PARAMETER and text:
        _check_published(text)
    return text


def _check_list(name: str, value: Any) -> Any:
    """An array parameter (one of _LISTS): its element type, length and range."""
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
    # ik_seed; retime.joint_*_limits: > 0 and one per joint are checked with the robot
    return _numbers(name, value, None)


def _check_number(name: str, value: Any) -> float:
    """A scalar float parameter: finite, in its range."""
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
