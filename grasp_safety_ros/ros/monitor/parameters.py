"""The monitor's parameters: those it shares with the ranking node (same names, specs and
checks: ros/parameters/) and its own, validated as pure functions (no rclpy)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from ...core.analyses.exposed_points import box_corners_in_object
from ...core.analyses.speed_scaling import MAX_REST_SPEED_M_S, check_margin, check_rest_speed
from ...core.exceptions import InvalidInputError
from ...core.input_checks import finite_array, finite_float
from ...core.model.inertia import ObjectInertia
from ..conversions.geometry import inertia_tensor_from_components
from ..parameters import (
    PARAMETERS,
    NodeSettings,
    ParameterConstraints,
    ParameterSpec,
    check_parameter,
    parameter_constraints,
    settings_from_parameters,
)
from ..parameters.declaration import ParameterTable
from ..parameters.values import show

SHARED: tuple[str, ...] = (
    "robot_description",
    "urdf",
    "base_frame",
    "tip_frame",
    "robot.armature_kgm2",
)
SHARED += ("robot.armature_joint_names", "robot.armature_published", "iso_ts_15066.regions")
SHARED += ("whole_arm.point_links", "whole_arm.points_m", "max_mass_kg", "diagnostics_period_s")
"""Parameters of the ranking node the monitor has too (same spec and check)."""

MAX_PAYLOAD_POINTS = 1000

_OWN: dict[str, ParameterSpec] = {
    "joint_states_timeout_s": ParameterSpec(
        0.1, "no valid /joint_states for longer than this makes the factor 0 [s], > 0"
    ),
    "speed_scaling.margin": ParameterSpec(
        1.0,
        "fraction of each site's admissible speed v_max the factor aims at, in (0, 1]: every "
        "moving site is kept at or below margin * v_max",
    ),
    "speed_scaling.closed_loop": ParameterSpec(
        True,
        "the /joint_states motion is the one the controller slows by this factor: the factor "
        "for the unscaled motion is the last published one times the state's margin * v_max / "
        "speed; false: the state's own factor (a motion this factor does not slow)",
    ),
    "speed_scaling.rest_speed_m_s": ParameterSpec(
        0.001,
        "sites at or below this speed are at rest and do not limit the factor (encoder noise) "
        f"[m/s], in [0, {MAX_REST_SPEED_M_S:g}]",
    ),
    "speed_scaling.controller_latency_s": ParameterSpec(
        0.05,
        "the controller's command-to-state latency [s], >= 0: in closed loop the factor "
        "assumed applied is the lowest published within this window",
    ),
    "speed_scaling.max_increase_per_s": ParameterSpec(
        2.0, "largest rise of the published factor per second [1/s], > 0; falls are immediate"
    ),
    "payload.mass_kg": ParameterSpec(
        0.0, "mass of the carried object [kg]; 0: nothing carried (until ~/payload says)"
    ),
    "payload.com_in_tip_m": ParameterSpec(
        [0.0, 0.0, 0.0], "centre of mass of the carried object in the tip frame [m]"
    ),
    "payload.inertia_about_com_kgm2": ParameterSpec(
        [0.0] * 6,
        "inertia of the carried object about its CoM, tip axes: ixx ixy ixz iyy iyz izz [kg m^2]",
    ),
    "payload.points_in_tip_m": ParameterSpec(
        [],
        "points of the carried object assessed as sites, tip frame, flat x y z x y z ... [m]; "
        "empty: the corners of payload.box_size_m, else none",
        item_type=float,
    ),
    "payload.box_size_m": ParameterSpec(
        [],
        "box edges along the tip axes [m], centred on the payload's CoM (sites: its 8 "
        "corners); []: none",
        item_type=float,
    ),
}

MONITOR_PARAMETERS: Mapping[str, ParameterSpec] = MappingProxyType(
    {**{name: PARAMETERS[name] for name in SHARED}, **_OWN}
)
"""Every parameter of the monitor, by name."""

RUNTIME: tuple[str, ...] = (
    "joint_states_timeout_s",
    "speed_scaling.margin",
    "speed_scaling.max_increase_per_s",
)
RUNTIME += ("speed_scaling.closed_loop", "speed_scaling.controller_latency_s")
"""Parameters the monitor takes at run time; the others are read at start-up only."""

_POSITIVE = ("joint_states_timeout_s", "speed_scaling.max_increase_per_s")


def _numbers(name: str, value: Any, length: int | None = None) -> tuple[float, ...]:
    if value is None:  # an empty list in a params file arrives as NOT_SET
        value = []
    if isinstance(value, (str, bytes, bool)) or any(isinstance(v, (bool, str)) for v in value):
        raise InvalidInputError(name, f"must be a list of numbers, got {show(value)}")
    array = finite_array(list(value), name, None if length is None else (length,))
    if array.ndim != 1:
        raise InvalidInputError(name, f"must be a flat list of numbers, got {show(value)}")
    return tuple(float(v) for v in array)


def check_monitor_parameter(name: str, value: Any) -> Any:
    """Check one monitor parameter on its own and return its normalised value (names of
    neither table are returned unchanged)."""
    if name not in _OWN:
        return check_parameter(name, value) if name in MONITOR_PARAMETERS else value
    if name.startswith("payload.") and name != "payload.mass_kg":
        numbers = _numbers(name, value, {"payload.com_in_tip_m": 3}.get(name))
        if name == "payload.inertia_about_com_kgm2" and len(numbers) != 6:
            raise InvalidInputError(name, f"must hold 6 numbers, got {len(numbers)}")
        if name == "payload.box_size_m" and numbers and (len(numbers) != 3 or min(numbers) <= 0):
            raise InvalidInputError(
                name, f"must be empty or 3 edge lengths > 0 [m], got {show(list(numbers))}"
            )
        if name == "payload.points_in_tip_m" and (
            len(numbers) % 3 or len(numbers) > 3 * MAX_PAYLOAD_POINTS
        ):
            raise InvalidInputError(
                name,
                f"must hold x y z per point, at most {MAX_PAYLOAD_POINTS} points, got "
                f"{len(numbers)} numbers",
            )
        return numbers
    if name == "speed_scaling.closed_loop":
        if not isinstance(value, bool):
            raise InvalidInputError(name, f"must be true or false, got {show(value)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidInputError(name, f"must be a number, got {show(value)}")
    if name == "speed_scaling.margin":
        return check_margin(float(value), name)
    if name == "speed_scaling.rest_speed_m_s":
        return check_rest_speed(float(value), name)
    return finite_float(value, name, minimum=0.0, strict_minimum=name in _POSITIVE)


def monitor_constraints(name: str) -> ParameterConstraints:
    """What check_monitor_parameter accepts of ``name``, for ``ros2 param describe``."""
    texts = {
        "joint_states_timeout_s": "> 0",
        "speed_scaling.margin": "in (0, 1]",
        "speed_scaling.closed_loop": "",
        "speed_scaling.max_increase_per_s": "> 0",
        "speed_scaling.rest_speed_m_s": f"in [0, {MAX_REST_SPEED_M_S:g}]",
        "speed_scaling.controller_latency_s": ">= 0",
        "payload.mass_kg": ">= 0, at most max_mass_kg",
        "payload.com_in_tip_m": "3 finite values",
        "payload.inertia_about_com_kgm2": "6 finite values",
        "payload.points_in_tip_m": f"x y z per point, at most {MAX_PAYLOAD_POINTS} points",
        "payload.box_size_m": "empty or 3 edge lengths > 0",
    }
    if name in texts:
        return ParameterConstraints(None, texts[name])
    return parameter_constraints(name)


MONITOR_TABLE = ParameterTable(MONITOR_PARAMETERS, check_monitor_parameter, monitor_constraints)


@dataclass(frozen=True)
class Payload:
    """The carried object: inertia in the tip frame (None: nothing) and its points (P, 3)
    [m, tip frame] assessed as sites (None: none)."""

    inertia: ObjectInertia | None
    points_in_tip_m: np.ndarray | None


def payload_points(
    inertia: ObjectInertia | None, points: tuple[float, ...], box_size_m: tuple[float, ...]
) -> np.ndarray | None:
    """The payload's sites (P, 3) [m, tip frame]: the given points, else the corners of the
    box about the CoM; none when nothing is carried."""
    if inertia is None:
        return None
    if points:
        return np.reshape(points, (-1, 3))
    if box_size_m:
        return np.array(box_corners_in_object(box_size_m, inertia.com_in_object_m))
    return None


@dataclass(frozen=True)
class MonitorSettings:
    """Validated monitor parameters (see MONITOR_PARAMETERS for their meaning).

    Attributes:
        node: The shared parameters as the ranking node's settings (robot, armature, regions,
            whole-arm points), for ``build_robot``.
        payload: The payload of the ``payload.*`` parameters.
        points_in_tip_m, box_size_m: ``payload.points_in_tip_m``, ``payload.box_size_m``
            (also for a payload from ~/payload).
    """

    node: NodeSettings
    joint_states_timeout_s: float
    margin: float
    closed_loop: bool
    rest_speed_m_s: float
    controller_latency_s: float
    max_increase_per_s: float
    payload: Payload
    points_in_tip_m: tuple[float, ...]
    box_size_m: tuple[float, ...]


def monitor_settings(values: Mapping[str, Any]) -> MonitorSettings:
    """Validate a full set of monitor parameter values (missing ones take their defaults).

    Raises:
        InvalidInputError: naming the first bad parameter.
    """
    merged = {name: spec.default for name, spec in MONITOR_PARAMETERS.items()}
    merged.update({k: v for k, v in values.items() if k in MONITOR_PARAMETERS})
    v = {name: check_monitor_parameter(name, value) for name, value in merged.items()}
    node = settings_from_parameters({name: v[name] for name in SHARED})
    mass = v["payload.mass_kg"]
    if mass > v["max_mass_kg"]:
        raise InvalidInputError(
            "payload.mass_kg", f"must be at most max_mass_kg={v['max_mass_kg']:g}, got {mass:g}"
        )
    if v["payload.points_in_tip_m"] and v["payload.box_size_m"]:
        raise InvalidInputError(
            "payload.box_size_m", "give payload.points_in_tip_m or a box, not both"
        )
    inertia = None
    if mass > 0.0:
        field = "payload.inertia_about_com_kgm2"
        tensor = inertia_tensor_from_components(v[field], field, mass)
        try:
            inertia = ObjectInertia(mass, np.array(v["payload.com_in_tip_m"]), tensor)
        except InvalidInputError as error:
            raise InvalidInputError(field, error.reason) from None
    points, box = v["payload.points_in_tip_m"], v["payload.box_size_m"]
    return MonitorSettings(
        node=node,
        joint_states_timeout_s=v["joint_states_timeout_s"],
        margin=v["speed_scaling.margin"],
        closed_loop=v["speed_scaling.closed_loop"],
        rest_speed_m_s=v["speed_scaling.rest_speed_m_s"],
        controller_latency_s=v["speed_scaling.controller_latency_s"],
        max_increase_per_s=v["speed_scaling.max_increase_per_s"],
        payload=Payload(inertia, payload_points(inertia, points, box)),
        points_in_tip_m=points,
        box_size_m=box,
    )
