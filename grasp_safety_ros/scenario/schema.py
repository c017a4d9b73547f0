"""Scenario files (YAML): robot, object, trajectory, grasps, metric, the options; validated
per field (readers: scenario.fields), read by the CLI and the batch."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.analyses.exposed_points import (
    box_corners_in_object,
    check_metric_point_has_points,
    cylinder_rim_points_in_object,
)
from ..core.analyses.redundancy import RedundancyConfig
from ..core.analyses.safe_duration import RetimeOptions
from ..core.analyses.safety_report import RANK_BY, AnalysisOptions
from ..core.analyses.uncertainty import InertiaUncertainty
from ..core.analyses.whole_arm import check_exposed_points_m
from ..core.exceptions import InvalidInputError
from ..core.input_checks import finite_array, finite_float
from ..core.method.ik import IKConfig
from ..core.method.joint_trajectory import PlannedJointTrajectory
from ..core.method.posture import PostureConfig
from ..core.method.ranking import METRICS, Grasp, check_metric
from ..core.model.armature import (
    PUBLISHED,
    ArmatureRange,
    PublishedArmature,
    armature_range,
    published_for,
    published_values,
)
from ..core.model.inertia import ObjectInertia, solid_box, solid_cylinder, solid_sphere
from ..core.model.robot import RobotModel
from ..core.model.trajectory import ObjectTrajectory
from ..core.model.waypoint_trajectory import WaypointTrajectory
from ..core.options import (
    IK_OPTIONS,
    LIMITS,
    REDUNDANCY_OPTIONS,
    bounds,
    default,
    ik_config,
    redundancy_config,
)
from ..core.pipeline import PipelineRequest
from .fields import (
    check_keys,
    flag,
    mapping,
    read_pose,
    read_yaml_file,
    required,
    string,
)

MAX_GRASPS = int(LIMITS["grasps"].value)
"""Most grasps in a scenario (core.options.LIMITS, as every limit here but the file's)."""

MAX_GRASP_SAMPLES = int(LIMITS["grasp_samples"].value)
"""Most grasps x trajectory samples (IK solves) in a scenario."""

MAX_POINTS = int(LIMITS["points"].value)
"""Most exposed points (``object.points_m``)."""

MAX_UNCERTAINTY_SAMPLES = int(LIMITS["uncertainty_samples"].value)
"""Most random inertia samples (``uncertainty.samples``)."""

MAX_OBJECT_MASS_KG = 10_000.0
"""Heaviest object [kg]."""

MAX_OBJECT_SIZE_M = LIMITS["object_size_m"].value
"""Largest object dimension, CoM offset and radius of gyration [m] (far beyond any gripper;
much larger objects make the augmented mass matrix numerically singular)."""


@dataclass(frozen=True)
class RobotSpec:
    """Where the robot comes from and which chain to use.

    Attributes:
        urdf: URDF path (relative to the scenario file), URDF XML, or example-robot-data:<name>.
        base_frame, tip_frame: Chain ends.
        seed: IK seed for the first sample, chain joint order [rad or m]; None: mid-range.
        locked_joints: Positions of joints off the chain (default: neutral) [rad or m].
        armature_kgm2: Reflected rotor inertia (core.model.armature): a list in chain order or
            ``{joint_name: value}`` (the joints not named keep the description's own),
            values or ``[lo, hi]`` ranges [kg m^2, kg if prismatic],
            or ``published`` / ``published:<entry>``; None: the description's own (MJCF) or
            none.
    """

    urdf: str
    base_frame: str
    tip_frame: str
    seed: tuple[float, ...] | None = None
    locked_joints: Mapping[str, float] | None = None
    armature_kgm2: Any = None

    def load(self, relative_to: Path | None = None) -> RobotModel:
        """Build the chain model, with the upper ends of armature ranges."""
        robot = RobotModel.from_urdf(
            self.urdf, self.base_frame, self.tip_frame, self.locked_joints, relative_to
        )
        bounds = self.armature_range(robot)
        return robot if bounds is None else robot.with_armature(bounds.upper_kgm2)

    def armature_range(self, robot: RobotModel) -> ArmatureRange | None:
        """The armature bounds per chain joint of ``robot``; None when not given."""
        value = self.armature_kgm2
        if value is None:
            return None
        if isinstance(value, str):
            entry = published_for(value, self.urdf, robot.joint_names)
            value = published_values(entry, robot.joint_names)
        return armature_range(value, robot.joint_names, robot.armature_kgm2)

    def published_armature(self, robot: RobotModel) -> PublishedArmature | None:
        """The published entry the armature comes from, if any."""
        if not isinstance(self.armature_kgm2, str):
            return None
        return published_for(self.armature_kgm2, self.urdf, robot.joint_names)


@dataclass(frozen=True)
class Scenario:
    """Everything a ranking needs, as read from a scenario file.

    Attributes:
        options: The analyses beyond the paper (metric point, ISO/TS 15066, uncertainty,
            grasp quality, redundancy, effort), from the optional sections of the file.
        posture: Posture selection (section ``posture``; defaults: core.options).
        ik: The IK solver's settings (section ``ik``; defaults: core.options).
    """

    robot: RobotSpec
    object_inertia: ObjectInertia
    trajectory: ObjectTrajectory | WaypointTrajectory
    grasps: tuple[Grasp, ...]
    metric: str
    base_dir: Path
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    posture: PostureConfig = field(default_factory=PostureConfig)
    ik: IKConfig = field(default_factory=IKConfig)

    def request(self, robot: RobotModel) -> PipelineRequest:
        """The pipeline's request (core.pipeline) for ``robot``, the chain ``self.robot``
        loaded (its armature range, if any, from ``robot.armature_kgm2``); the metric is the
        evaluator's."""
        return PipelineRequest(
            grasps=self.grasps,
            object_inertia=self.object_inertia,
            trajectory=self.trajectory,
            options=self.options,
            posture=self.posture,
            seed_positions=self.robot.seed,
            armature_range=self.robot.armature_range(robot),
        )


def parse_robot(section: Any) -> RobotSpec:
    """Parse the ``robot`` section."""
    robot = mapping(section, "robot")
    check_keys(
        robot,
        {"urdf", "base_frame", "tip_frame", "seed", "locked_joints", "armature_kgm2"}
        | {"exposed_points_m"},  # exposed_points_m: an analysis option
        "robot",
    )
    armature = robot.get("armature_kgm2")
    if isinstance(armature, str) and armature.partition(":")[0] != PUBLISHED:
        raise InvalidInputError(
            "robot.armature_kgm2",
            f"must be a list, a mapping {{joint_name: value}}, '{PUBLISHED}' or "
            f"'{PUBLISHED}:<entry>', got {armature!r}",
        )
    seed = robot.get("seed")
    locked = robot.get("locked_joints")
    if locked is not None:
        locked = {
            string(k, "robot.locked_joints"): finite_float(v, f"robot.locked_joints.{k}")
            for k, v in mapping(locked, "robot.locked_joints").items()
        }
    if seed is not None:
        array = finite_array(seed, "robot.seed")
        if array.ndim != 1:
            raise InvalidInputError("robot.seed", "must be a list of joint positions")
        seed = tuple(float(x) for x in array)
    return RobotSpec(
        urdf=string(required(robot, "urdf", "robot"), "robot.urdf"),
        base_frame=string(required(robot, "base_frame", "robot"), "robot.base_frame"),
        tip_frame=string(required(robot, "tip_frame", "robot"), "robot.tip_frame"),
        seed=seed,
        locked_joints=locked,
        armature_kgm2=armature,
    )


def parse_object(section: Any) -> tuple[ObjectInertia, np.ndarray | None]:
    """Parse the ``object`` section: mass, optional CoM, a tensor or a primitive shape, points.

    Returns:
        The inertia, and the exposed points [m] (object frame): ``points_m`` when given, else
        the corners of a box or the rims of a cylinder, else None.
    """
    obj = mapping(section, "object")
    inertia = _parse_inertia(obj)
    if "points_m" in obj:
        if isinstance(obj["points_m"], list) and len(obj["points_m"]) > MAX_POINTS:
            raise InvalidInputError(
                "object.points_m",
                f"has {len(obj['points_m'])} points; at most {MAX_POINTS} are allowed",
            )
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
    check_keys(obj, {"mass_kg", "com_in_object_m", "points_m"} | shapes, "object")
    mass = finite_float(
        required(obj, "mass_kg", "object"),
        "object.mass_kg",
        minimum=0.0,
        maximum=MAX_OBJECT_MASS_KG,
        strict_minimum=True,
    )
    com = finite_array(obj.get("com_in_object_m", [0.0, 0.0, 0.0]), "object.com_in_object_m", (3,))
    _check_size(com, "object.com_in_object_m")
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
        inertia = ObjectInertia(mass, com, tensor)
        gyration_m = float(
            np.sqrt(np.max(np.linalg.eigvalsh(inertia.inertia_about_com_kgm2)) / mass)
        )
        if gyration_m > MAX_OBJECT_SIZE_M:
            raise InvalidInputError(
                "object.inertia_about_com_kgm2",
                f"radius of gyration sqrt(I_max / mass_kg) = {gyration_m:g} m; at most "
                f"{MAX_OBJECT_SIZE_M:g} m",
            )
        return inertia
    if "box_size_m" in obj:
        _check_size(obj["box_size_m"], "object.box_size_m")
        return solid_box(mass, obj["box_size_m"], com)
    if "cylinder" in obj:
        cylinder = mapping(obj["cylinder"], "object.cylinder")
        check_keys(cylinder, {"radius_m", "length_m"}, "object.cylinder")
        radius = required(cylinder, "radius_m", "object.cylinder")
        length = required(cylinder, "length_m", "object.cylinder")
        _check_size(radius, "object.cylinder.radius_m")
        _check_size(length, "object.cylinder.length_m")
        return solid_cylinder(mass, radius, length, com)
    sphere = mapping(obj["sphere"], "object.sphere")
    check_keys(sphere, {"radius_m"}, "object.sphere")
    radius = required(sphere, "radius_m", "object.sphere")
    _check_size(radius, "object.sphere.radius_m")
    return solid_sphere(mass, radius, com)


def _check_size(value: Any, field: str) -> None:
    """Refuse a length or vector [m] longer than MAX_OBJECT_SIZE_M; other checks (type, sign,
    shape) are the inertia constructors'."""
    array = finite_array(value, field)
    size = float(np.max(np.abs(array), initial=0.0))
    if size > MAX_OBJECT_SIZE_M:
        raise InvalidInputError(field, f"must be at most {MAX_OBJECT_SIZE_M:g} m, got {size:g} m")


def parse_trajectory(section: Any) -> ObjectTrajectory | WaypointTrajectory:
    """Parse the ``trajectory`` section (object-frame poses in the base frame): ``start``,
    ``goal``, ``duration_s``, ``dt_s``, or timed ``waypoints`` and ``dt_s``."""
    trajectory = mapping(section, "trajectory")
    if "waypoints" in trajectory:
        check_keys(trajectory, {"waypoints", "dt_s"}, "trajectory")
        waypoints = trajectory["waypoints"]
        if not isinstance(waypoints, list):
            raise InvalidInputError(
                "trajectory.waypoints", f"must be a list of timed poses, got {waypoints!r}"
            )
        times, poses = [], []
        for i, item in enumerate(waypoints):
            field = f"trajectory.waypoints[{i}]"
            poses.append(read_pose(item, field, frozenset({"time_s"})))
            times.append(finite_float(required(item, "time_s", field), f"{field}.time_s"))
        return WaypointTrajectory(
            tuple(times),
            tuple(poses),
            finite_float(required(trajectory, "dt_s", "trajectory"), "trajectory.dt_s"),
        )
    check_keys(trajectory, {"start", "goal", "duration_s", "dt_s"}, "trajectory")
    return ObjectTrajectory(
        read_pose(required(trajectory, "start", "trajectory"), "trajectory.start"),
        read_pose(required(trajectory, "goal", "trajectory"), "trajectory.goal"),
        finite_float(required(trajectory, "duration_s", "trajectory"), "trajectory.duration_s"),
        finite_float(required(trajectory, "dt_s", "trajectory"), "trajectory.dt_s"),
    )


def parse_grasps(section: Any) -> tuple[tuple[Grasp, ...], tuple[float, ...] | None]:
    """Parse the ``grasps`` list (tip-frame poses in the object frame) and their qualities.

    Returns:
        The grasps, and the ``quality`` of each (higher is better) when every grasp has one,
        None when none has.
    """
    if not isinstance(section, list) or not section:
        raise InvalidInputError("grasps", "must be a non-empty list of poses")
    if len(section) > MAX_GRASPS:
        raise InvalidInputError(
            "grasps", f"has {len(section)} grasps; at most {MAX_GRASPS} are allowed"
        )
    grasps = []
    qualities = []
    for i, item in enumerate(section):
        field = f"grasps[{i}]"
        tip_pose = read_pose(item, field, frozenset({"name", "quality", "joint_trajectory"}))
        entry = mapping(item, field)
        planned = None
        if "joint_trajectory" in entry:
            planned = parse_joint_trajectory(
                entry["joint_trajectory"], f"{field}.joint_trajectory"
            )
        grasps.append(Grasp(tip_pose, str(entry.get("name", f"grasp_{i}")), planned))
        if "quality" in entry:
            qualities.append(finite_float(entry["quality"], f"{field}.quality"))
    if qualities and len(qualities) != len(grasps):
        raise InvalidInputError("grasps", "give a quality for every grasp or for none")
    return tuple(grasps), tuple(qualities) if qualities else None


def parse_joint_trajectory(section: Any, field: str) -> PlannedJointTrajectory:
    """Parse ``grasps[i].joint_trajectory``: ``joint_names`` and ``points`` with ``time_s``,
    ``positions`` and optionally ``velocities`` (every point or none)."""
    trajectory = mapping(section, field)
    check_keys(trajectory, {"joint_names", "points"}, field)
    names = required(trajectory, "joint_names", field)
    if not isinstance(names, list):
        raise InvalidInputError(f"{field}.joint_names", f"must be a list of names, got {names!r}")
    points = required(trajectory, "points", field)
    if not isinstance(points, list):
        raise InvalidInputError(f"{field}.points", f"must be a list of points, got {points!r}")
    times, positions, velocities = [], [], []
    for k, item in enumerate(points):
        where = f"{field}.points[{k}]"
        point = mapping(item, where)
        check_keys(point, {"time_s", "positions", "velocities"}, where)
        times.append(finite_float(required(point, "time_s", where), f"{where}.time_s"))
        positions.append(required(point, "positions", where))
        if "velocities" in point:
            velocities.append(point["velocities"])
    if velocities and len(velocities) != len(points):
        raise InvalidInputError(f"{field}.points", "give velocities for every point or for none")
    return PlannedJointTrajectory(
        tuple(string(n, f"{field}.joint_names") for n in names),
        np.array(times),
        positions,  # type: ignore[arg-type]  # lists: rows checked, then converted, there
        velocities or None,  # type: ignore[arg-type]
        field,
    )


OPTIONAL_SECTIONS = {
    "metric_point",
    "iso_ts_15066",
    "uncertainty",
    "safety_weight",
    "redundancy",
    "effort",
    "rank_by",
    "posture",
    "ik",
    "whole_arm",
    "retime",
}


def parse_retime(section: Any, requested: bool = False) -> RetimeOptions | None:
    """The ``retime`` section (core.analyses.safe_duration.RetimeOptions): on when given
    (unless ``enabled: false``) or ``requested`` (``--retime``, ``rank_by: safe_duration``)."""
    if section is None and not requested:
        return None
    retime = mapping({} if section is None else section, "retime")
    keys = {"joint_acceleration_limits", "joint_velocity_limits", "safety_factor", "output_dt_s"}
    check_keys(retime, keys | {"enabled"}, "retime")
    if not (requested or flag(retime.get("enabled", True), "retime.enabled")):
        return None
    return RetimeOptions(
        retime.get("joint_acceleration_limits"),
        retime.get("joint_velocity_limits"),
        retime.get("safety_factor", default("retime.safety_factor")),
        retime.get("output_dt_s"),
    )


def parse_posture(section: Any) -> PostureConfig:
    """Parse the ``posture`` section: ``{restarts: N, seed: S}``."""
    posture = mapping(section, "posture")
    check_keys(posture, {"restarts", "seed"}, "posture")
    return PostureConfig(
        restarts=posture.get("restarts", default("posture.restarts")), seed=posture.get("seed", 0)
    )


def _dotted(
    section: Any, name: str, keys: tuple[str, ...], extra: frozenset[str]
) -> dict[str, Any]:
    """Section ``name``'s entries but ``extra`` as the table's dotted keys (core.options),
    refusing any but ``keys`` and ``extra``."""
    entries = mapping(section, name)
    check_keys(entries, {key.split(".", 1)[1] for key in keys} | extra, name)
    return {f"{name}.{key}": value for key, value in entries.items() if key not in extra}


def parse_ik(section: Any) -> IKConfig:
    """Parse the ``ik`` section: ``{max_iterations: N, position_tolerance_m: x, ...}``."""
    return ik_config(_dotted(section, "ik", IK_OPTIONS, frozenset()))


def parse_redundancy(section: Any) -> tuple[bool, RedundancyConfig]:
    """The ``redundancy`` entry: true or false, or a section ``{enabled: ..., iterations: ...,
    ...}`` (its settings: core.options.REDUNDANCY_OPTIONS); (on, RedundancyConfig)."""
    if not isinstance(section, Mapping):
        return flag(section, "redundancy"), redundancy_config({})
    values = _dotted(section, "redundancy", REDUNDANCY_OPTIONS, frozenset({"enabled"}))
    enabled = flag(section.get("enabled", default("redundancy.enabled")), "redundancy.enabled")
    return enabled, redundancy_config(values)


def parse_options(
    root: Mapping[str, Any], points: np.ndarray | None, quality: tuple[float, ...] | None
) -> AnalysisOptions:
    """Parse the optional sections beyond the paper into AnalysisOptions."""
    iso = mapping(root.get("iso_ts_15066", {}), "iso_ts_15066")
    check_keys(iso, {"regions"}, "iso_ts_15066")
    regions = iso.get("regions")
    if regions is not None and not (
        isinstance(regions, list) and all(isinstance(r, str) for r in regions)
    ):
        raise InvalidInputError(
            "iso_ts_15066.regions", f"must be a list of names, got {regions!r}"
        )
    uncertainty = None
    if "uncertainty" in root:
        section = mapping(root["uncertainty"], "uncertainty")
        allowed = {
            "mass_fraction",
            "com_offset_m",
            "inertia_fraction",
            "samples",
            "percentile",
            "seed",
        }
        check_keys(section, allowed, "uncertainty")
        samples = section.get("samples")
        if isinstance(samples, int) and samples > MAX_UNCERTAINTY_SAMPLES:
            raise InvalidInputError(
                "uncertainty.samples",
                f"must be at most {MAX_UNCERTAINTY_SAMPLES}, got {samples}",
            )
        renamed = {("num_random_samples" if k == "samples" else k): v for k, v in section.items()}
        uncertainty = InertiaUncertainty(**renamed)
    effort = mapping(root.get("effort", {}), "effort")
    check_keys(effort, {"enabled", "criterion"}, "effort")
    whole_arm = mapping(root.get("whole_arm", {}), "whole_arm")
    check_keys(whole_arm, {"enabled", "region"}, "whole_arm")
    arm_points = mapping(root.get("robot", {}), "robot").get("exposed_points_m")
    check_exposed_points_m(arm_points or {})  # early, naming the scenario key
    rank_by = root.get("rank_by", default("rank_by"))
    if rank_by not in RANK_BY:
        raise InvalidInputError("rank_by", f"must be one of {', '.join(RANK_BY)}, got {rank_by!r}")
    metric_point = root.get("metric_point", default("metric_point"))
    check_metric_point_has_points(metric_point, points, "object.points_m or a box or cylinder")
    redundancy, redundancy_settings = parse_redundancy(
        root.get("redundancy", default("redundancy.enabled"))
    )
    try:
        return AnalysisOptions(
            metric_point=metric_point,
            points_in_object_m=points,
            iso_regions=None if regions is None else tuple(regions),
            uncertainty=uncertainty,
            grasp_quality=quality,
            safety_weight=finite_float(
                root.get("safety_weight", default("safety_weight")),
                "safety_weight",
                *bounds("safety_weight"),
            ),
            redundancy=redundancy,
            effort=flag(effort.get("enabled", default("effort.enabled")), "effort.enabled"),
            rank_by=rank_by,
            effort_criterion=effort.get("criterion", default("effort.criterion")),
            whole_arm=flag(
                whole_arm.get("enabled", default("whole_arm.enabled")), "whole_arm.enabled"
            ),
            arm_points_m=arm_points,
            whole_arm_region=whole_arm.get("region", default("whole_arm.region")),
            retime=parse_retime(root.get("retime"), rank_by == "safe_duration"),
            redundancy_settings=redundancy_settings,
        )
    except InvalidInputError as error:  # the core says iso15066.<field>; the file iso_ts_15066
        if not error.field.startswith("iso15066."):
            raise
        field = "iso_ts_15066." + error.field[len("iso15066.") :]
        raise InvalidInputError(field, error.reason) from None


def parse_scenario(data: Any, base_dir: Path) -> Scenario:
    """Validate a scenario mapping (as loaded from YAML)."""
    root = mapping(data, "scenario")
    sections = {"robot", "object", "trajectory", "grasps", "metric"}
    check_keys(root, sections | OPTIONAL_SECTIONS, "")
    metric = root.get("metric", default("metric"))
    if not isinstance(metric, str):
        raise InvalidInputError("metric", f"must be one of {', '.join(METRICS)}, got {metric!r}")
    object_inertia, points = parse_object(required(root, "object", ""))
    grasps, quality = parse_grasps(required(root, "grasps", ""))
    trajectory = parse_trajectory(required(root, "trajectory", ""))
    samples = trajectory.num_samples
    if len(grasps) * samples > MAX_GRASP_SAMPLES:
        raise InvalidInputError(
            "grasps",
            f"{len(grasps)} grasps x {samples} trajectory samples = "
            f"{len(grasps) * samples} IK solves; at most {MAX_GRASP_SAMPLES} "
            "(fewer grasps or a larger trajectory.dt_s)",
        )
    return Scenario(
        robot=parse_robot(required(root, "robot", "")),
        object_inertia=object_inertia,
        trajectory=trajectory,
        grasps=grasps,
        metric=check_metric(metric),
        base_dir=base_dir,
        options=parse_options(root, points, quality),
        posture=parse_posture(root.get("posture", {})),
        ik=parse_ik(root.get("ik", {})),
    )


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file (at most MAX_SCENARIO_BYTES, UTF-8)."""
    return parse_scenario(read_yaml_file(path), Path(path).resolve().parent)
