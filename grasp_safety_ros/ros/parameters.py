"""Node parameters: names, defaults, and validation as pure functions (no rclpy).

Every check raises InvalidInputError naming the parameter, so the node's on-set callback can
refuse a bad value with that reason, and the checks are unit-testable without ROS.
"""

from __future__ import annotations

import array
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.exceptions import FrameNotFoundError, GraspSafetyError, InvalidInputError
from ..core.inertia import ObjectInertia
from ..core.ranking import METRICS, EvaluationConfig, GraspSafetyEvaluator
from ..core.robot import RobotModel
from ..core.validation import finite_array, finite_float


@dataclass(frozen=True)
class ParameterSpec:
    """One node parameter: its default value and a one-line description (with units)."""

    default: Any
    description: str


PARAMETERS: Mapping[str, ParameterSpec] = {
    "robot_description": ParameterSpec(
        "", "URDF XML of the robot; takes precedence over urdf and the /robot_description topic"
    ),
    "urdf": ParameterSpec(
        "", "URDF file path or example-robot-data:<name>; used when robot_description is empty"
    ),
    "robot_description_timeout_s": ParameterSpec(
        10.0,
        "start-up wait for the /robot_description topic when both robot_description and urdf "
        "are empty [s]; 0 waits for ever",
    ),
    "base_frame": ParameterSpec("", "base frame of the arm chain (URDF link or frame)"),
    "tip_frame": ParameterSpec("", "tip (end-effector) frame of the arm chain"),
    "object_frame": ParameterSpec(
        "object", "frame_id that marks grasps (and inertia) given in the object frame"
    ),
    "ik_seed": ParameterSpec(
        [], "IK seed, one position per chain joint, base to tip [rad or m]; empty: see docs"
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
    "metric": ParameterSpec("mean", f"default score: {' | '.join(METRICS)}"),
    "max_grasps": ParameterSpec(1000, "most grasps accepted in one request or candidate set"),
    "max_samples": ParameterSpec(20000, "most samples accepted per trajectory"),
    "max_total_samples": ParameterSpec(
        500_000,
        "most grasps x samples accepted in one request (bounds time and the result's size)",
    ),
    "max_mass_kg": ParameterSpec(1000.0, "largest object mass accepted [kg]"),
    "max_compute_time_s": ParameterSpec(
        60.0, "a ranking still running after this long is abandoned (success=false) [s]"
    ),
    "service_busy_timeout_s": ParameterSpec(
        10.0, "how long a request waits for a ranking in progress before answering busy [s]"
    ),
    "diagnostics_period_s": ParameterSpec(1.0, "period of /diagnostics status messages [s]"),
}
"""Every parameter of the node, by name."""

ROBOT_PARAMETERS = ("robot_description", "urdf", "base_frame", "tip_frame")
"""Parameters whose change rebuilds the robot model."""

_STRINGS = ("robot_description", "urdf", "base_frame", "tip_frame", "object_frame", "metric")
_POSITIVE = ("trajectory.dt_s", "trajectory.duration_s", "max_mass_kg", "max_compute_time_s")
_POSITIVE += ("service_busy_timeout_s", "diagnostics_period_s")
_MAX_COUNT = 1_000_000_000


@dataclass(frozen=True)
class NodeSettings:
    """Validated parameter values (see PARAMETERS for their meaning).

    Attributes:
        object_inertia: The default object, or None when ``object.mass_kg`` is 0.
        ik_seed: The seed parameter, or None when empty (length checked against the robot
            in build_robot).
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

    @property
    def robot_source(self) -> str:
        """The robot given by parameters (XML, path or example-robot-data:<name>), or ''."""
        return self.robot_description or self.urdf


def _string(name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise InvalidInputError(name, f"must be a string, got {_show(value)}")
    return value


def _integer(name: str, value: Any, minimum: int, maximum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidInputError(name, f"must be an integer, got {_show(value)}")
    if not minimum <= value <= maximum:
        raise InvalidInputError(name, f"must be in [{minimum}, {maximum}], got {value}")
    return int(value)


def _numbers(name: str, value: Any, length: int | None) -> tuple[float, ...]:
    if value is None:  # an empty list in a params file arrives as NOT_SET
        value = []
    if not isinstance(value, (list, tuple, np.ndarray, array.array)):
        raise InvalidInputError(name, f"must be a list of numbers, got {_show(value)}")
    items = list(value)
    if any(isinstance(v, (bool, str, bytes)) for v in items):
        raise InvalidInputError(name, f"must be a list of numbers, got {_show(items)}")
    array_ = finite_array(items, name, None if length is None else (length,))
    if array_.ndim != 1:
        raise InvalidInputError(name, f"must be a flat list of numbers, got {_show(items)}")
    return tuple(float(v) for v in array_)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


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
        if name == "metric" and text not in METRICS:
            raise InvalidInputError(name, f"must be one of {', '.join(METRICS)}, got {text!r}")
        if name == "object_frame" and not text:
            raise InvalidInputError(name, "must be a non-empty frame name")
        return text
    if name == "use_joint_states_seed":
        if not isinstance(value, bool):
            raise InvalidInputError(name, f"must be true or false, got {_show(value)}")
        return value
    if name in ("max_grasps", "max_samples", "max_total_samples"):
        return _integer(name, value, 1, _MAX_COUNT)
    if name == "ik_seed":
        return _numbers(name, value, None)
    if name == "object.com_in_object_m":
        return _numbers(name, value, 3)
    if name == "object.inertia_about_com_kgm2":
        return _numbers(name, value, 6)
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidInputError(name, f"must be a number, got {_show(value)}")
    if name in _POSITIVE:
        return finite_float(value, name, minimum=0.0, strict_minimum=True)
    # object.mass_kg (0 = none) and robot_description_timeout_s (0 = for ever)
    return finite_float(value, name, minimum=0.0)


def inertia_tensor_from_components(components: Sequence[float], field: str) -> np.ndarray:
    """3x3 symmetric tensor of (ixx, ixy, ixz, iyy, iyz, izz), as in geometry_msgs/Inertia."""
    ixx, ixy, ixz, iyy, iyz, izz = finite_array(list(components), field, (6,))
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


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
            v["object.inertia_about_com_kgm2"], "object.inertia_about_com_kgm2"
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
    )


@dataclass(frozen=True)
class RobotBundle:
    """A loaded robot chain with its evaluator and the validated ``ik_seed`` (or None).

    Attributes:
        origin: Where the description came from: a parameter name or the topic.
    """

    robot: RobotModel
    evaluator: GraspSafetyEvaluator
    seed: tuple[float, ...] | None
    origin: str


_CORE_FIELDS = {
    "robot.urdf": None,  # replaced by the parameter (or topic) the description came from
    "robot.base_frame": "base_frame",
    "robot.tip_frame": "tip_frame",
    "robot.seed": "ik_seed",
}


def _renamed(error: GraspSafetyError, origin: str) -> GraspSafetyError:
    """The core's error with its field renamed to the node parameter to change."""
    field = getattr(error, "field", None)
    if field not in _CORE_FIELDS:
        return error
    new_field = _CORE_FIELDS[field] or origin
    if isinstance(error, FrameNotFoundError):
        return FrameNotFoundError(new_field, error.frame, error.available)
    message = str(error)[len(field) + 2 :] if str(error).startswith(f"{field}: ") else str(error)
    return InvalidInputError(new_field, message)


def build_robot(settings: NodeSettings, topic_description: str | None) -> RobotBundle | None:
    """Load the robot chain of ``settings`` (parameters first, then the topic's description).

    Returns:
        None when neither the parameters nor the topic gave a description yet.

    Raises:
        GraspSafetyError: the description, a frame or the seed is wrong (field renamed to the
            node parameter, or ``/robot_description`` for the topic).
    """
    if settings.robot_description:
        source, origin = settings.robot_description, "robot_description"
    elif settings.urdf:
        source, origin = settings.urdf, "urdf"
    elif topic_description:
        source, origin = topic_description, "/robot_description"
    else:
        return None
    try:
        robot = RobotModel.from_urdf(source, settings.base_frame, settings.tip_frame)
        seed = None
        if settings.ik_seed is not None:
            seed = tuple(float(x) for x in robot.check_positions(settings.ik_seed, "robot.seed"))
    except GraspSafetyError as error:
        raise _renamed(error, origin) from None
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric=settings.metric))
    return RobotBundle(robot=robot, evaluator=evaluator, seed=seed, origin=origin)
