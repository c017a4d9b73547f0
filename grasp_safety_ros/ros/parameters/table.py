"""The node's parameters: their names, defaults and one-line descriptions (no rclpy).

PARAMETERS is the one table the node declares (declaration.py), checks (checks.py) and reads
into its settings (settings.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ...core.options import IK_OPTIONS, LIMITS, OPTIONS, REDUNDANCY_OPTIONS, help_text

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
    "moveit.max_waiting": ParameterSpec(
        32,
        "most requests ~/plan_grasps keeps waiting for the planner at once; one more is "
        "answered FAILURE at once (each waiting request costs the node CPU at every wake-up)",
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
