"""The fused per-grasp kernel: tip path, IK and effective mass of one grasp in one call."""

import math

import numpy as np

from ._jit import _jit
from .effective_mass import _mobility_from_frames
from .ik import _solve_pose_into, _trajectory_step, _workspace
from .kinematics import _forward_kinematics
from .lie_group import _exp3


@_jit
def evaluate_grasp(
    placement_rotations,
    placement_translations,
    axes,
    prismatic,
    tip_rotation,
    tip_translation,
    base_rotation,
    lower_q,
    upper_q,
    base_translation,
    start_rotation,
    start_translation,
    goal_translation,
    rotation_log,
    grasp_rotation,
    grasp_translation,
    times,
    s_values,
    seed_q,
    q0_given,
    position_tolerance,
    orientation_tolerance,
    max_iterations,
    max_iteration_step,
    max_joint_step,
    check_velocity,
    velocity_limits,
    masses,
    levers,
    rotational_inertias,
    stationary_tangent,
    target_rotations,
    target_translations,
    tangents,
    tangent_norms,
    q_all,
    iterations,
    q_fail,
    mobilities,
    effective_masses,
    directions,
    worst,
):
    """One grasp along an object trajectory: tip path, IK, effective mass; one call.

    The same computation as ObjectTrajectory.tip_path + IKSolver.solve_trajectory +
    translational_mobility_in_base + effective_mass_along, sample by sample. The tip poses
    (world frame) and path tangents (base axes) are written first. Sample 0 is solved from
    seed_q unless q0_given (then seed_q is its solution, found by the caller's restarts).

    Returns:
        (status, sample, joint, value): status 0 OK, 1 IK not converged, 2 joint jump,
        3 joint speed over its limit, 4 sample 0 not converged from the seed (q_fail holds
        the last iterate); for worst[i] samples (tip not translating) the caller fills
        directions and effective masses from mobilities[i].
    """
    count = s_values.shape[0]
    n = axes.shape[0]
    ws = _workspace(n)
    rot = ws[20]
    linear0 = goal_translation[0] - start_translation[0]
    linear1 = goal_translation[1] - start_translation[1]
    linear2 = goal_translation[2] - start_translation[2]
    g0, g1, g2 = grasp_translation[0], grasp_translation[1], grasp_translation[2]
    lever0 = rotation_log[1] * g2 - rotation_log[2] * g1
    lever1 = rotation_log[2] * g0 - rotation_log[0] * g2
    lever2 = rotation_log[0] * g1 - rotation_log[1] * g0
    ro = np.empty((3, 3))
    rt = np.empty((3, 3))
    po = np.empty(3)
    pt = np.empty(3)
    for i in range(count):
        s = s_values[i]
        _exp3(s * rotation_log[0], s * rotation_log[1], s * rotation_log[2], rot)
        for a in range(3):
            for b in range(3):
                ro[a, b] = (
                    start_rotation[a, 0] * rot[0, b]
                    + start_rotation[a, 1] * rot[1, b]
                    + start_rotation[a, 2] * rot[2, b]
                )
            po[a] = (1.0 - s) * start_translation[a] + s * goal_translation[a]
        for a in range(3):
            for b in range(3):
                rt[a, b] = (
                    ro[a, 0] * grasp_rotation[0, b]
                    + ro[a, 1] * grasp_rotation[1, b]
                    + ro[a, 2] * grasp_rotation[2, b]
                )
            pt[a] = ro[a, 0] * g0 + ro[a, 1] * g1 + ro[a, 2] * g2 + po[a]
        tangents[i, 0] = linear0 + ro[0, 0] * lever0 + ro[0, 1] * lever1 + ro[0, 2] * lever2
        tangents[i, 1] = linear1 + ro[1, 0] * lever0 + ro[1, 1] * lever1 + ro[1, 2] * lever2
        tangents[i, 2] = linear2 + ro[2, 0] * lever0 + ro[2, 1] * lever1 + ro[2, 2] * lever2
        tangent_norms[i] = math.sqrt(
            tangents[i, 0] * tangents[i, 0]
            + tangents[i, 1] * tangents[i, 1]
            + tangents[i, 2] * tangents[i, 2]
        )
        for a in range(3):
            target_translations[i, a] = base_translation[a] + (
                base_rotation[a, 0] * pt[0]
                + base_rotation[a, 1] * pt[1]
                + base_rotation[a, 2] * pt[2]
            )
            for b in range(3):
                target_rotations[i, a, b] = (
                    base_rotation[a, 0] * rt[0, b]
                    + base_rotation[a, 1] * rt[1, b]
                    + base_rotation[a, 2] * rt[2, b]
                )
    guess = np.empty(n)
    q = np.empty(n)
    if q0_given:
        for k in range(n):
            q[k] = seed_q[k]
        _forward_kinematics(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            q,
            ws[0],
            ws[1],
            ws[2],
            ws[3],
        )
    else:
        converged, iterations[0] = _solve_pose_into(
            placement_rotations,
            placement_translations,
            axes,
            prismatic,
            tip_rotation,
            tip_translation,
            lower_q,
            upper_q,
            target_rotations[0],
            target_translations[0],
            seed_q,
            position_tolerance,
            orientation_tolerance,
            max_iterations,
            max_iteration_step,
            q,
            ws,
        )
        if not converged:
            for k in range(n):
                q_fail[k] = q[k]
            return 4, 0, 0, 0.0
    any_velocity_check = False
    for k in range(n):
        q_all[0, k] = q[k]
        if check_velocity[k]:
            any_velocity_check = True
    for i in range(count):
        if i > 0:
            status, joint, value = _trajectory_step(
                placement_rotations,
                placement_translations,
                axes,
                prismatic,
                tip_rotation,
                tip_translation,
                lower_q,
                upper_q,
                target_rotations,
                target_translations,
                times,
                i,
                position_tolerance,
                orientation_tolerance,
                max_iterations,
                max_iteration_step,
                max_joint_step,
                check_velocity,
                any_velocity_check,
                velocity_limits,
                q_all,
                iterations,
                q_fail,
                guess,
                q,
                ws,
            )
            if status != 0:
                return status, i, joint, value
        # ws holds the joint poses at q_all[i] (the IK's last forward kinematics).
        mobility = mobilities[i]
        _mobility_from_frames(
            axes, prismatic, base_rotation, masses, levers, rotational_inertias, ws, mobility
        )
        norm = tangent_norms[i]
        if norm < stationary_tangent:
            worst[i] = True
            continue
        worst[i] = False
        d0, d1, d2 = tangents[i, 0] / norm, tangents[i, 1] / norm, tangents[i, 2] / norm
        directions[i, 0], directions[i, 1], directions[i, 2] = d0, d1, d2
        unit_norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u0, u1, u2 = d0 / unit_norm, d1 / unit_norm, d2 / unit_norm
        quadratic = 0.0
        for a in range(3):
            ua = u0 if a == 0 else (u1 if a == 1 else u2)
            quadratic += ua * (mobility[a, 0] * u0 + mobility[a, 1] * u1 + mobility[a, 2] * u2)
        effective_masses[i] = 1.0 / quadratic
    return 0, count, 0, 0.0
