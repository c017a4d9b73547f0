"""Scenario files (YAML): robot, object, trajectory, grasps, metric; validated per field."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..core.analyses.exposed_points import box_corners_in_object, cylinder_rim_points_in_object
from ..core.analyses.safety_report import RANK_BY, AnalysisOptions
from ..core.analyses.uncertainty import InertiaUncertainty
from ..core.exceptions import InvalidInputError
from ..core.input_checks import finite_array, finite_float, pose_from_position_quat
from ..core.method.posture import DEFAULT_RESTARTS, PostureConfig
from ..core.method.ranking import METRICS, Grasp, check_metric
from ..core.model.inertia import ObjectInertia, solid_box, solid_cylinder, solid_sphere
from ..core.model.robot import RobotModel
from ..core.model.trajectory import ObjectTrajectory


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
    """Everything a ranking needs, as read from a scenario file.

    Attributes:
        options: The analyses beyond the paper (metric point, ISO/TS 15066, uncertainty,
            grasp quality, redundancy, effort), from the optional sections of the file.
        posture: Posture selection (section ``posture``; default DEFAULT_RESTARTS restarts).
    """

    robot: RobotSpec
    object_inertia: ObjectInertia
    trajectory: ObjectTrajectory
    grasps: tuple[Grasp, ...]
    metric: str
    base_dir: Path
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    posture: PostureConfig = field(default_factory=lambda: PostureConfig(DEFAULT_RESTARTS))


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


def parse_object(section: Any) -> tuple[ObjectInertia, np.ndarray | None]:
    """Parse the ``object`` section: mass, optional CoM, a tensor or a primitive shape, points.

    Returns:
        The inertia, and the exposed points [m] (object frame): ``points_m`` when given, else
        the corners of a box or the rims of a cylinder, else None.
    """
    obj = _mapping(section, "object")
    inertia = _parse_inertia(obj)
    if "points_m" in obj:
        points = finite_array(obj["points_m"], "object.points_m")
        if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
            raise InvalidInputError(
                "object.points_m", f"must be a list of [x, y, z], got shape {list(points.shape)}"
            )
        return inertia, points
    com = inertia.com_in_object_m
    if "box_size_m" in obj:
        return inertia, box_corners_in_object(obj["box_size_m"], com)
    if "cylinder" in obj:
        cylinder = obj["cylinder"]
        return inertia, cylinder_rim_points_in_object(
            cylinder["radius_m"], cylinder["length_m"], com
        )
    return inertia, None


def _parse_inertia(obj: Mapping[str, Any]) -> ObjectInertia:
    shapes = {"inertia_about_com_kgm2", "box_size_m", "cylinder", "sphere"}
    _check_keys(obj, {"mass_kg", "com_in_object_m", "points_m"} | shapes, "object")
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
    _check_keys(pose, {"position_m", "quat_xyzw", "name", "quality"}, field)
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


def parse_grasps(section: Any) -> tuple[tuple[Grasp, ...], tuple[float, ...] | None]:
    """Parse the ``grasps`` list (tip-frame poses in the object frame) and their qualities.

    Returns:
        The grasps, and the ``quality`` of each (higher is better) when every grasp has one,
        None when none has.
    """
    if not isinstance(section, list) or not section:
        raise InvalidInputError("grasps", "must be a non-empty list of poses")
    grasps = []
    qualities = []
    for i, item in enumerate(section):
        field = f"grasps[{i}]"
        pose = _pose(item, field)
        entry = _mapping(item, field)
        grasps.append(Grasp(pose, str(entry.get("name", f"grasp_{i}"))))
        if "quality" in entry:
            qualities.append(finite_float(entry["quality"], f"{field}.quality"))
    if qualities and len(qualities) != len(grasps):
        raise InvalidInputError("grasps", "give a quality for every grasp or for none")
    return tuple(grasps), tuple(qualities) if qualities else None


OPTIONAL_SECTIONS = {
    "metric_point",
    "iso_ts_15066",
    "uncertainty",
    "safety_weight",
    "redundancy",
    "effort",
    "rank_by",
    "posture",
}


def parse_posture(section: Any) -> PostureConfig:
    """Parse the ``posture`` section: ``{restarts: N, seed: S}``."""
    posture = _mapping(section, "posture")
    _check_keys(posture, {"restarts", "seed"}, "posture")
    return PostureConfig(
        restarts=posture.get("restarts", DEFAULT_RESTARTS), seed=posture.get("seed", 0)
    )


def _flag(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise InvalidInputError(field, f"must be true or false, got {value!r}")
    return value


def parse_options(
    root: Mapping[str, Any], points: np.ndarray | None, quality: tuple[float, ...] | None
) -> AnalysisOptions:
    """Parse the optional sections beyond the paper into AnalysisOptions."""
    iso = _mapping(root.get("iso_ts_15066", {}), "iso_ts_15066")
    _check_keys(iso, {"regions"}, "iso_ts_15066")
    regions = iso.get("regions")
    if regions is not None and not (
        isinstance(regions, list) and all(isinstance(r, str) for r in regions)
    ):
        raise InvalidInputError(
            "iso_ts_15066.regions", f"must be a list of names, got {regions!r}"
        )
    uncertainty = None
    if "uncertainty" in root:
        section = _mapping(root["uncertainty"], "uncertainty")
        allowed = {
            "mass_fraction",
            "com_offset_m",
            "inertia_fraction",
            "samples",
            "percentile",
            "seed",
        }
        _check_keys(section, allowed, "uncertainty")
        renamed = {("num_random_samples" if k == "samples" else k): v for k, v in section.items()}
        uncertainty = InertiaUncertainty(**renamed)
    effort = _mapping(root.get("effort", {}), "effort")
    _check_keys(effort, {"enabled", "criterion"}, "effort")
    rank_by = root.get("rank_by", "safety")
    if rank_by not in RANK_BY:
        raise InvalidInputError("rank_by", f"must be one of {', '.join(RANK_BY)}, got {rank_by!r}")
    metric_point = root.get("metric_point", "tip")
    if metric_point != "tip" and points is None:
        raise InvalidInputError(
            "metric_point",
            f"{metric_point!r} needs object.points_m or a box or cylinder object",
        )
    return AnalysisOptions(
        metric_point=metric_point,
        points_in_object_m=points,
        iso_regions=None if regions is None else tuple(regions),
        uncertainty=uncertainty,
        grasp_quality=quality,
        safety_weight=finite_float(root.get("safety_weight", 0.5), "safety_weight", 0.0, 1.0),
        redundancy=_flag(root.get("redundancy", False), "redundancy"),
        effort=_flag(effort.get("enabled", True), "effort.enabled"),
        rank_by=rank_by,
        effort_criterion=effort.get("criterion", "peak_fraction"),
    )


def parse_scenario(data: Any, base_dir: Path) -> Scenario:
    """Validate a scenario mapping (as loaded from YAML)."""
    root = _mapping(data, "scenario")
    required = {"robot", "object", "trajectory", "grasps", "metric"}
    _check_keys(root, required | OPTIONAL_SECTIONS, "")
    metric = root.get("metric", "mean")
    if not isinstance(metric, str):
        raise InvalidInputError("metric", f"must be one of {', '.join(METRICS)}, got {metric!r}")
    object_inertia, points = parse_object(_required(root, "object", ""))
    grasps, quality = parse_grasps(_required(root, "grasps", ""))
    return Scenario(
        robot=parse_robot(_required(root, "robot", "")),
        object_inertia=object_inertia,
        trajectory=parse_trajectory(_required(root, "trajectory", "")),
        grasps=grasps,
        metric=check_metric(metric),
        base_dir=base_dir,
        options=parse_options(root, points, quality),
        posture=parse_posture(root.get("posture", {})),
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
