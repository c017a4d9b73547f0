"""Scenario files (YAML): robot, object, trajectory, grasps, metric; validated per field."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from .core.exceptions import InvalidInputError
from .core.inertia import ObjectInertia, solid_box, solid_cylinder, solid_sphere
from .core.ranking import METRICS, Grasp, check_metric
from .core.robot import RobotModel
from .core.trajectory import ObjectTrajectory
from .core.validation import finite_array, finite_float, pose_from_position_quat


@dataclass(frozen=True)
class RobotSpec:
    """Where the robot comes from and which chain to use.

    Attributes:
        urdf: URDF path (relative to the scenario file), URDF XML, or example-robot-data:<name>.
        base_frame, tip_frame: Chain ends.
        seed: IK seed for the first sample, chain joint order [rad or m]; None: mid-range.
        locked_joints: Positions of joints off the chain (default: neutral) [rad or m].
    """

    urdf: str
    base_frame: str
    tip_frame: str
    seed: tuple[float, ...] | None = None
    locked_joints: Mapping[str, float] | None = None

    def load(self, relative_to: Path | None = None) -> RobotModel:
        """Build the chain model."""
        return RobotModel.from_urdf(
            self.urdf, self.base_frame, self.tip_frame, self.locked_joints, relative_to
        )


@dataclass(frozen=True)
class Scenario:
    """Everything a ranking needs, as read from a scenario file."""

    robot: RobotSpec
    object_inertia: ObjectInertia
    trajectory: ObjectTrajectory
    grasps: tuple[Grasp, ...]
    metric: str
    base_dir: Path


def _mapping(value: Any, field: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise InvalidInputError(field, f"must be a mapping, got {type(value).__name__}")
    return value


def _required(section: Mapping[str, Any], key: str, prefix: str) -> Any:
    if key not in section:
        raise InvalidInputError(f"{prefix}.{key}" if prefix else key, "is required")
    return section[key]


def _string(value: Any, field: str) -> str:
    if not isinstance(value, str) or not value:
        raise InvalidInputError(field, f"must be a non-empty string, got {value!r}")
    return value


def _check_keys(section: Mapping[str, Any], allowed: set[str], prefix: str) -> None:
    unknown = sorted(set(section) - allowed)
    if unknown:
        where = f"{prefix}.{unknown[0]}" if prefix else str(unknown[0])
        raise InvalidInputError(where, f"unknown field; allowed: {', '.join(sorted(allowed))}")


def parse_robot(section: Any) -> RobotSpec:
    """Parse the ``robot`` section."""
    robot = _mapping(section, "robot")
    _check_keys(robot, {"urdf", "base_frame", "tip_frame", "seed", "locked_joints"}, "robot")
    seed = robot.get("seed")
    locked = robot.get("locked_joints")
    if locked is not None:
        locked = {
            _string(k, "robot.locked_joints"): finite_float(v, f"robot.locked_joints.{k}")
            for k, v in _mapping(locked, "robot.locked_joints").items()
        }
    if seed is not None:
        array = finite_array(seed, "robot.seed")
        if array.ndim != 1:
            raise InvalidInputError("robot.seed", "must be a list of joint positions")
        seed = tuple(float(x) for x in array)
    return RobotSpec(
        urdf=_string(_required(robot, "urdf", "robot"), "robot.urdf"),
        base_frame=_string(_required(robot, "base_frame", "robot"), "robot.base_frame"),
        tip_frame=_string(_required(robot, "tip_frame", "robot"), "robot.tip_frame"),
        seed=seed,
        locked_joints=locked,
    )


def parse_object(section: Any) -> ObjectInertia:
    """Parse the ``object`` section: mass, optional CoM, and a tensor or a primitive shape."""
    obj = _mapping(section, "object")
    shapes = {"inertia_about_com_kgm2", "box_size_m", "cylinder", "sphere"}
    _check_keys(obj, {"mass_kg", "com_in_object_m"} | shapes, "object")
    mass = finite_float(
        _required(obj, "mass_kg", "object"), "object.mass_kg", minimum=0.0, strict_minimum=True
    )
    com = finite_array(obj.get("com_in_object_m", [0.0, 0.0, 0.0]), "object.com_in_object_m", (3,))
    given = sorted(shapes & set(obj))
    if len(given) != 1:
        raise InvalidInputError(
            "object",
            "give exactly one of inertia_about_com_kgm2, box_size_m, cylinder, sphere; got "
            f"{given or 'none'}",
        )
    if "inertia_about_com_kgm2" in obj:
        tensor = finite_array(
            obj["inertia_about_com_kgm2"], "object.inertia_about_com_kgm2", (3, 3)
        )
        return ObjectInertia(mass, com, tensor)
    if "box_size_m" in obj:
        return solid_box(mass, obj["box_size_m"], com)
    if "cylinder" in obj:
        cylinder = _mapping(obj["cylinder"], "object.cylinder")
        _check_keys(cylinder, {"radius_m", "length_m"}, "object.cylinder")
        return solid_cylinder(
            mass,
            _required(cylinder, "radius_m", "object.cylinder"),
            _required(cylinder, "length_m", "object.cylinder"),
            com,
        )
    sphere = _mapping(obj["sphere"], "object.sphere")
    _check_keys(sphere, {"radius_m"}, "object.sphere")
    return solid_sphere(mass, _required(sphere, "radius_m", "object.sphere"), com)


def _pose(section: Any, field: str):
    pose = _mapping(section, field)
    _check_keys(pose, {"position_m", "quat_xyzw", "name"}, field)
    return pose_from_position_quat(
        _required(pose, "position_m", field), _required(pose, "quat_xyzw", field), field
    )


def parse_trajectory(section: Any) -> ObjectTrajectory:
    """Parse the ``trajectory`` section (object-frame poses in the base frame)."""
    trajectory = _mapping(section, "trajectory")
    _check_keys(trajectory, {"start", "goal", "duration_s", "dt_s"}, "trajectory")
    return ObjectTrajectory(
        _pose(_required(trajectory, "start", "trajectory"), "trajectory.start"),
        _pose(_required(trajectory, "goal", "trajectory"), "trajectory.goal"),
        finite_float(_required(trajectory, "duration_s", "trajectory"), "trajectory.duration_s"),
        finite_float(_required(trajectory, "dt_s", "trajectory"), "trajectory.dt_s"),
    )


def parse_grasps(section: Any) -> tuple[Grasp, ...]:
    """Parse the ``grasps`` list (tip-frame poses in the object frame)."""
    if not isinstance(section, list) or not section:
        raise InvalidInputError("grasps", "must be a non-empty list of poses")
    grasps = []
    for i, item in enumerate(section):
        field = f"grasps[{i}]"
        pose = _pose(item, field)
        name = _mapping(item, field).get("name", f"grasp_{i}")
        grasps.append(Grasp(pose, str(name)))
    return tuple(grasps)


def parse_scenario(data: Any, base_dir: Path) -> Scenario:
    """Validate a scenario mapping (as loaded from YAML)."""
    root = _mapping(data, "scenario")
    _check_keys(root, {"robot", "object", "trajectory", "grasps", "metric"}, "")
    metric = root.get("metric", "mean")
    if not isinstance(metric, str):
        raise InvalidInputError("metric", f"must be one of {', '.join(METRICS)}, got {metric!r}")
    return Scenario(
        robot=parse_robot(_required(root, "robot", "")),
        object_inertia=parse_object(_required(root, "object", "")),
        trajectory=parse_trajectory(_required(root, "trajectory", "")),
        grasps=parse_grasps(_required(root, "grasps", "")),
        metric=check_metric(metric),
        base_dir=base_dir,
    )


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InvalidInputError("scenario", f"cannot read '{path}': {error.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise InvalidInputError("scenario", f"'{path}' is not valid YAML: {error}") from None
    return parse_scenario(data, path.resolve().parent)
