"""The node's settings: a full set of checked parameter values, cross-checked, as the frozen
NodeSettings the node ranks with (pure functions, no rclpy)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core.analyses.exposed_points import (
    box_corners_in_object,
    check_metric_point_has_points,
    cylinder_rim_points_in_object,
)
from ...core.analyses.safe_duration import RetimeOptions
from ...core.analyses.safety_report import AnalysisOptions
from ...core.analyses.uncertainty import InertiaUncertainty
from ...core.exceptions import InvalidInputError
from ...core.method.ik import IKConfig
from ...core.method.posture import PostureConfig
from ...core.model.inertia import ObjectInertia
from ...core.options import ik_config, redundancy_config
from ..conversions.geometry import inertia_tensor_from_components
from ..service.response import ResponseContent
from .arm_points import arm_points
from .checks import check_parameter
from .table import PARAMETERS


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
