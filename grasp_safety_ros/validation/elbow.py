"""A free impact at an elbow point in MuJoCo, predicted by the whole-arm effective mass.

The site is the origin of the fourth chain joint (Baxter: ``right_e1``, the elbow), as
core.analyses.whole_arm assesses it by default. At one sample of a grasp's trajectory the
site's direction of motion u and effective mass M_eff (robot + object, armature included, as
the core's model has it) come from ``evaluate_whole_arm``; the ImpulseChecker then puts its
colliding sphere on the site's link, centred on the joint origin, with the arm unactuated and
the sphere moving at v along u against a frictionless wall: the normal impulse is
P = (1 + e)·M_eff·v (e measured). The tip's effective mass at the same sample, used in its place,
shows how wrong a tip-only assessment is for this contact.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.analyses.whole_arm import evaluate_whole_arm, resolve_arm_sites
from ..core.method.ranking import Grasp, GraspEvaluation
from ..core.model.inertia import ObjectInertia
from ..core.model.robot import RobotModel
from ..core.model.trajectory import Trajectory
from .simulation import ImpulseChecker, ImpulseSetup

ELBOW_JOINT_INDEX = 3
"""Chain index (0-based) of the joint whose origin is the elbow site."""


def elbow_impact(
    robot: RobotModel,
    urdf_source: str,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    evaluation: GraspEvaluation,
    trajectory: Trajectory,
    setup: ImpulseSetup | None = None,
    time_s: float = 1.0,
) -> dict[str, Any]:
    """One free impact at the elbow site at the sample nearest ``time_s`` (module docstring)."""
    sites = resolve_arm_sites(robot)
    site = sites.names.index(robot.joint_names[ELBOW_JOINT_INDEX])
    whole = evaluate_whole_arm(robot, evaluation, object_inertia, grasp, trajectory, sites)
    sample = int(np.argmin(np.abs(whole.times_s - time_s)))
    mass = float(whole.effective_mass_kg[sample, site])
    checker = ImpulseChecker(
        robot,
        urdf_source,
        object_inertia,
        grasp.transform_tip_to_object,
        setup,
        body_name=sites.links[site],
    )
    case = checker.run(
        evaluation.joint_positions[sample], whole.directions_in_base[sample, site], mass
    )
    tip_mass = float(evaluation.effective_mass_kg[sample])
    tip_predicted = (1.0 + case.restitution) * tip_mass * case.speed_before_m_s
    return {
        "grasp": evaluation.name,
        "site": sites.names[site],
        "link": sites.links[site],
        "time_s": float(whole.times_s[sample]),
        "stationary": bool(whole.stationary[sample, site]),
        "effective_mass_kg": mass,
        "engine_effective_mass_kg": case.engine_effective_mass_kg,
        "impulse_n_s": case.impulse_n_s,
        "predicted_impulse_n_s": case.predicted_impulse_n_s,
        "restitution": case.restitution,
        "rel_error": case.rel_error,
        "tip_effective_mass_kg": tip_mass,
        "rel_error_with_tip_mass": abs(case.impulse_n_s - tip_predicted) / tip_predicted,
        "speed_m_s": case.speed_before_m_s,
        "contact_duration_s": case.duration_s,
        "joint_limit_active": case.limit_active,
    }


def format_elbow(result: dict[str, Any]) -> str:
    """One summary line."""
    return (
        f"  elbow impact ({result['site']} on {result['link']}, {result['grasp']}, "
        f"t = {result['time_s']:.2f} s): |P - (1+e) M_eff v| / P_pred = "
        f"{result['rel_error']:.2e} with the whole-arm M_eff {result['effective_mass_kg']:.3f} kg;"
        f" {result['rel_error_with_tip_mass']:.2f} with the tip's "
        f"{result['tip_effective_mass_kg']:.3f} kg"
    )
