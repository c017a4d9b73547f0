"""The batch SPEC file (YAML): robot, gripper convention, object motion, defaults, analyses and
the dataset sources; validated like scenario files, one-line errors naming the field.

Grasp seen by the method: T_object_tip = T_object_gripper · T_gripper_tip, with
T_gripper_tip = ``gripper_to_tip``. Object motion: T_base_object(t) = T_base_object_start ·
M(t), M the ``motion`` waypoints in the object's start frame (the first the identity at 0 s).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..core.analyses.safety_report import AnalysisOptions
from ..core.exceptions import InvalidInputError
from ..core.input_checks import finite_float
from ..core.method.ik import IKConfig
from ..core.method.posture import PostureConfig
from ..core.method.ranking import check_metric
from ..core.model.inertia import ObjectInertia
from ..core.model.waypoint_trajectory import WaypointTrajectory
from ..core.options import default
from ..scenario.fields import check_keys, mapping, read_pose, required, string
from ..scenario.schema import (
    OPTIONAL_SECTIONS,
    RobotSpec,
    parse_ik,
    parse_object,
    parse_options,
    parse_posture,
    parse_robot,
)

FORMATS = ("acronym", "graspgen", "scenarios")
"""Source formats: ACRONYM HDF5, GraspGen ``isaac_grasp`` YAML, scenario files."""

PER_GRASP_ANALYSES = frozenset({"metric_point", "iso_ts_15066", "redundancy", "effort", "retime"})
"""Analysis sections a SPEC may have: each grasp's result depends on that grasp alone."""

SET_ANALYSES = OPTIONAL_SECTIONS - PER_GRASP_ANALYSES - {"posture", "ik"}
"""Analyses over the whole candidate set (uncertainty, quality weighting, rank_by): refused,
a chunk is not the candidate set."""

DEFAULT_CHUNK_GRASPS = 64
"""Grasps per chunk (one task, one Parquet part) unless the SPEC says ``chunk_grasps``."""

MAX_CHUNK_GRASPS = 10_000
"""Largest ``chunk_grasps`` (bounds a task's memory)."""

IDENTITY_TOLERANCE = 1e-9
"""Largest deviation of the first motion waypoint from the identity [m, rad]."""


@dataclass(frozen=True)
class SourceSpec:
    """One ``sources`` entry: a format and a glob relative to the SPEC file."""

    format: str
    pattern: str


@dataclass(frozen=True)
class BatchSpec:
    """A validated SPEC.

    Attributes:
        robot: The arm (None when every source is a scenario file: they carry their own).
        transform_tip_to_gripper: T_gripper_tip, pose of the robot's tip frame in the
            dataset's gripper frame.
        trajectory: The object's motion in the base frame, T_base_object_start · M(t).
        object_defaults: Inertia used where a source has none; None: not given.
        metric, posture, ik, options: As in a scenario (options: the per-grasp analyses).
        sources: Where the grasps come from.
        chunk_grasps: Grasps per chunk.
        base_dir: Folder of the SPEC file (globs and relative URDF paths start there).
        content_hash: SHA-256 of everything above that changes the results (the SPEC's data
            and the URDF file's bytes), for ``--resume``.
    """

    robot: RobotSpec | None
    transform_tip_to_gripper: pin.SE3 | None
    trajectory: WaypointTrajectory | None
    object_defaults: ObjectInertia | None
    metric: str
    posture: PostureConfig
    ik: IKConfig
    options: AnalysisOptions
    sources: tuple[SourceSpec, ...]
    chunk_grasps: int
    base_dir: Path
    content_hash: str


def parse_motion(section: Any, start: pin.SE3) -> WaypointTrajectory:
    """The ``motion`` section (waypoints in the object's start frame, first the identity at
    0 s, and ``dt_s``) as a trajectory in the base frame: T_base_object_start · M(t_i)."""
    motion = mapping(section, "motion")
    check_keys(motion, {"waypoints", "dt_s"}, "motion")
    waypoints = required(motion, "waypoints", "motion")
    if not isinstance(waypoints, list) or len(waypoints) < 2:
        raise InvalidInputError(
            "motion.waypoints", f"must be a list of at least 2 timed poses, got {waypoints!r}"
        )
    times, poses = [], []
    for i, item in enumerate(waypoints):
        field = f"motion.waypoints[{i}]"
        pose = read_pose(item, field, frozenset({"time_s"}))
        times.append(finite_float(required(item, "time_s", field), f"{field}.time_s"))
        poses.append(start * pose)
        if i == 0:
            angle = float(np.linalg.norm(pin.log3(pose.rotation)))
            offset = float(np.linalg.norm(pose.translation))
            if max(abs(times[0]), angle, offset) > IDENTITY_TOLERANCE:
                raise InvalidInputError(
                    field,
                    "must be the identity at time_s 0 (the object's start frame), got time_s "
                    f"{times[0]:g}, offset {offset:g} m, angle {angle:g} rad",
                )
    dt_s = finite_float(required(motion, "dt_s", "motion"), "motion.dt_s")
    return WaypointTrajectory(tuple(times), tuple(poses), dt_s)


def parse_sources(section: Any) -> tuple[SourceSpec, ...]:
    """The ``sources`` list: ``{format: acronym | graspgen | scenarios, path: GLOB}``."""
    if not isinstance(section, list) or not section:
        raise InvalidInputError("sources", "must be a non-empty list of {format, path}")
    sources = []
    for i, item in enumerate(section):
        field = f"sources[{i}]"
        entry = mapping(item, field)
        check_keys(entry, {"format", "path"}, field)
        fmt = required(entry, "format", field)
        if fmt not in FORMATS:
            raise InvalidInputError(
                f"{field}.format", f"must be one of {', '.join(FORMATS)}, got {fmt!r}"
            )
        sources.append(SourceSpec(fmt, string(required(entry, "path", field), f"{field}.path")))
    return tuple(sources)


def _chunk_grasps(value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= MAX_CHUNK_GRASPS:
        raise InvalidInputError(
            "chunk_grasps", f"must be an integer in [1, {MAX_CHUNK_GRASPS}], got {value!r}"
        )
    return value


def _content_hash(data: Any, robot: RobotSpec | None, base_dir: Path) -> str:
    digest = hashlib.sha256()
    digest.update(json.dumps(data, sort_keys=True, default=str).encode())
    if robot is not None and "<" not in robot.urdf and ":" not in robot.urdf:
        path = base_dir / robot.urdf
        if path.is_file():
            digest.update(path.read_bytes())
    return digest.hexdigest()


def parse_spec(data: Any, base_dir: Path) -> BatchSpec:
    """Validate a SPEC mapping (as loaded from YAML)."""
    root = mapping(data, "spec")
    dataset_keys = {"robot", "gripper_to_tip", "object_start_in_base", "motion"}
    allowed = dataset_keys | {"object", "metric", "posture", "ik", "sources", "chunk_grasps"}
    for name in sorted(SET_ANALYSES & set(root)):
        raise InvalidInputError(
            name, "depends on the whole candidate set; not available in a batch (chunks)"
        )
    check_keys(root, allowed | PER_GRASP_ANALYSES, "")
    sources = parse_sources(required(root, "sources", ""))
    needs_arm = any(s.format != "scenarios" for s in sources)
    robot = tip_to_gripper = trajectory = None
    if needs_arm or "robot" in root:
        robot = parse_robot(required(root, "robot", ""))
    if needs_arm:
        tip_to_gripper = read_pose(required(root, "gripper_to_tip", ""), "gripper_to_tip")
        start = read_pose(required(root, "object_start_in_base", ""), "object_start_in_base")
        trajectory = parse_motion(required(root, "motion", ""), start)
    defaults, points = (None, None)
    if "object" in root:
        defaults, points = parse_object(root["object"])
    if any(s.format == "graspgen" for s in sources) and defaults is None:
        raise InvalidInputError("object", "is required for graspgen sources (they carry no mass)")
    metric = root.get("metric", default("metric"))
    if not isinstance(metric, str):
        raise InvalidInputError("metric", f"must be a string, got {metric!r}")
    return BatchSpec(
        robot=robot,
        transform_tip_to_gripper=tip_to_gripper,
        trajectory=trajectory,
        object_defaults=defaults,
        metric=check_metric(metric),
        posture=parse_posture(root.get("posture", {})),
        ik=parse_ik(root.get("ik", {})),
        options=parse_options(root, points, None),
        sources=sources,
        chunk_grasps=_chunk_grasps(root.get("chunk_grasps", DEFAULT_CHUNK_GRASPS)),
        base_dir=base_dir,
        content_hash=_content_hash(
            {k: v for k, v in root.items() if k != "sources"}, robot, base_dir
        ),
    )
