"""The fused kernel: IK and effective mass of a batch of grasps along their tip paths, in one
call. The object's motion (poses and tangents in the base frame) is sampled once by the caller
for every grasp, so every trajectory type runs here; the kernel composes it with each grasp."""

import math

from ._jit import _jit, _jit_inline
from .effective_mass import _mobility_from_frames
from .ik import _relative_twists, _reset_predictor, _solve_pose_into, _trajectory_step
from .kinematics import _forward_kinematics


@_jit
def evaluate_grasps(
    chain,
    settings,
    bodies,
    motion,
    grasp_rotations,
    grasp_translations,
    times,
    seeds_q,
    q0_given,
    stationary_tangent,
    object_twists,
    out,
    ws,
):
    """``_evaluate_grasp`` of each grasp g (never stopped early): its rows of ``bodies``
    (BodyInertias), of the grasp rotations (G, 3, 3) and translations (G, 3) [m], seeds_q
    (G, nq), q0_given (G,) and of ``out`` (GraspBuffers); its outcome (status, sample, joint)
    in out.outcomes[g] and the value in out.outcome_values[g]. object_twists (N, 6): scratch
    for the object's motion between samples, log6(O_{i-1}^-1 O_i), shared by the grasps."""
    _relative_twists(motion.rotations, motion.positions, object_twists, ws)
    for g in range(grasp_rotations.shape[0]):
        status, sample, joint, value = _evaluate_grasp(
            chain,
            settings,
            bodies,
            motion,
            grasp_rotations[g],
            grasp_translations[g],
            times,
            seeds_q[g],
            q0_given[g],
            stationary_tangent,
            object_twists,
            out,
            g,
            ws,
            (False, times, math.inf),
        )
        out.outcomes[g, 0], out.outcomes[g, 1], out.outcomes[g, 2] = status, sample, joint
        out.outcome_values[g] = value


@_jit
def follow_postures(
    chain,
    settings,
    bodies,
    motion,
    grasp_rotations,
    grasp_translations,
    times,
    seeds_q,
    stationary_tangent,
    object_twists,
    out,
    ws,
    bound_is_max,
    score_weights,
    bounds,
):
    """``evaluate_grasps`` (sample 0 solved from seeds_q[g]) with an early stop: row g stops
    (status 5) as soon as a lower bound of its score exceeds bounds[g] (inf: never).

    The bound, from the effective masses m_i > 0 computed so far (samples where the tip does
    not translate count as 0): their running max (``bound_is_max``), else their running sum
    weighted by score_weights (N,) (1/N for the mean, the trapezoid weights [s] for the
    integral). The caller widens bounds[g] by the rounding of both sums. A mass that is NaN or
    not > 0 (an indefinite or broken mass matrix) bounds nothing: row g is then never stopped,
    so it scores as without the stop.
    """
    _relative_twists(motion.rotations, motion.positions, object_twists, ws)
    for g in range(grasp_rotations.shape[0]):
        status, sample, joint, value = _evaluate_grasp(
            chain,
            settings,
            bodies,
            motion,
            grasp_rotations[g],
            grasp_translations[g],
            times,
            seeds_q[g],
            False,
            stationary_tangent,
            object_twists,
            out,
            g,
            ws,
            (bound_is_max, score_weights, bounds[g]),
        )
        out.outcomes[g, 0], out.outcomes[g, 1], out.outcomes[g, 2] = status, sample, joint
        out.outcome_values[g] = value


@_jit_inline
def _evaluate_grasp(
    chain,
    settings,
    bodies,
    motion,
    grasp_rotation,
    grasp_translation,
    times,
    seed_q,
    q0_given,
    stationary_tangent,
    object_twists,
    out,
    g,
    ws,
    stop,
):
    """One grasp (row g of ``bodies`` and ``out``) along the object's motion: IK and effective
    mass, sample by sample; ``stop`` (bound_is_max, score_weights, bound): the early stop of
    ``follow_postures`` (bound inf: none).

    The same computation as ObjectMotion.tip_motion + IKSolver.solve_trajectory_arrays +
    translational_mobility_in_base + effective_mass_along. Inputs: ``motion`` as
    ``model.trajectory.ObjectMotion`` (object rotations (N, 3, 3), positions (N, 3) [m],
    linear (N, 3) [m] and angular (N, 3) [rad] tangents, base frame; its speed_per_tangent is
    not read); the grasp: tip frame in the object frame (rotation, translation [m]); sample
    times [s]. Sample 0 is solved from seed_q unless q0_given (then seed_q is its solution,
    found by the caller's restarts). object_twists: the object's motion between samples
    (``_relative_twists`` of its poses); the tip's is its adjoint by the grasp inverse,
    log6(G^-1 X G) = Ad_{G^-1} log6(X), no log per grasp. out:
    ``method.packed.GraspBuffers``; the world-frame targets, the tip's twists and tangents
    are written first. ws: ``ik.workspace(n)``.

    Returns:
        (status, sample, joint, value): status 0 OK, 1 IK not converged, 2 joint jump,
        3 joint speed over its limit, 4 sample 0 not converged from the seed (out.q_fail[g]
        holds the last iterate), 5 stopped: the score's lower bound (value) exceeds the
        bound after ``sample`` samples; for out.worst[g, i] samples (tip not translating) the
        caller fills directions and effective masses from out.mobilities[g, i].
    """
    count = times.shape[0]
    base_rotation, base_translation = chain.base_rotation, chain.base_translation
    target_rotations, target_translations = out.target_rotations[g], out.target_translations[g]
    object_rotations, object_positions = motion.rotations, motion.positions
    linear_tangents, angular_tangents = motion.linear_tangents, motion.angular_tangents
    tip_rotation, tangents = ws[19], out.tangents[g]  # ws[19]: scratch 3x3
    tip_twists = out.tip_twists[g]
    g0, g1, g2 = grasp_translation[0], grasp_translation[1], grasp_translation[2]
    for i in range(count):
        if i > 0:  # Ad_{G^-1} (v, w) = (R^T (v + w x p), R^T w), G = (R, p)
            v0, v1, v2 = object_twists[i, 0], object_twists[i, 1], object_twists[i, 2]
            w0, w1, w2 = object_twists[i, 3], object_twists[i, 4], object_twists[i, 5]
            a0 = v0 + (w1 * g2 - w2 * g1)
            a1 = v1 + (w2 * g0 - w0 * g2)
            a2 = v2 + (w0 * g1 - w1 * g0)
            for b in range(3):
                r0, r1, r2 = grasp_rotation[0, b], grasp_rotation[1, b], grasp_rotation[2, b]
                tip_twists[i, b] = r0 * a0 + r1 * a1 + r2 * a2
                tip_twists[i, 3 + b] = r0 * w0 + r1 * w1 + r2 * w2
        # Tip in the base frame: object pose * grasp; lever = object origin -> tip.
        o = object_rotations[i]
        l0 = o[0, 0] * g0 + o[0, 1] * g1 + o[0, 2] * g2
        l1 = o[1, 0] * g0 + o[1, 1] * g1 + o[1, 2] * g2
        l2 = o[2, 0] * g0 + o[2, 1] * g1 + o[2, 2] * g2
        p0 = object_positions[i, 0] + l0
        p1 = object_positions[i, 1] + l1
        p2 = object_positions[i, 2] + l2
        for a in range(3):
            for b in range(3):
                tip_rotation[a, b] = (
                    o[a, 0] * grasp_rotation[0, b]
                    + o[a, 1] * grasp_rotation[1, b]
                    + o[a, 2] * grasp_rotation[2, b]
                )
        w0, w1, w2 = angular_tangents[i, 0], angular_tangents[i, 1], angular_tangents[i, 2]
        tangents[i, 0] = linear_tangents[i, 0] + (w1 * l2 - w2 * l1)
        tangents[i, 1] = linear_tangents[i, 1] + (w2 * l0 - w0 * l2)
        tangents[i, 2] = linear_tangents[i, 2] + (w0 * l1 - w1 * l0)
        # World-frame target: base placement * tip.
        for a in range(3):
            r0, r1, r2 = base_rotation[a, 0], base_rotation[a, 1], base_rotation[a, 2]
            target_translations[i, a] = base_translation[a] + (r0 * p0 + r1 * p1 + r2 * p2)
            for b in range(3):
                target_rotations[i, a, b] = (
                    r0 * tip_rotation[0, b] + r1 * tip_rotation[1, b] + r2 * tip_rotation[2, b]
                )
    q_all, mobilities, tangent_norms = out.q_all[g], out.mobilities[g], out.tangent_norms[g]
    worst, directions = out.worst[g], out.directions[g]
    effective_masses, iterations, q_fail = (
        out.effective_masses[g],
        out.iterations[g],
        out.q_fail[g],
    )
    if q0_given:
        for k in range(seed_q.shape[0]):
            q_all[0, k] = seed_q[k]
        _forward_kinematics(chain, q_all[0], ws)
    else:
        converged, iterations[0] = _solve_pose_into(
            chain, settings, target_rotations[0], target_translations[0], seed_q, q_all[0], ws
        )
        if not converged:
            for k in range(seed_q.shape[0]):
                q_fail[k] = q_all[0, k]
            return 4, 0, 0, 0.0
    _reset_predictor(ws)
    bound_is_max, score_weights, bound = stop
    running = 0.0
    for i in range(count):
        if i > 0:
            status, joint, value = _trajectory_step(
                chain, settings, target_rotations, target_translations, times, i, out, g, ws
            )
            if status != 0:
                return status, i, joint, value
        # ws holds the joint poses at q_all[i] (the IK's last forward kinematics).
        mobility = mobilities[i]
        _mobility_from_frames(chain, bodies, g, ws, mobility)
        t0, t1, t2 = tangents[i, 0], tangents[i, 1], tangents[i, 2]
        norm = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        tangent_norms[i] = norm
        if norm < stationary_tangent:
            worst[i] = True
            continue
        worst[i] = False
        d0, d1, d2 = t0 / norm, t1 / norm, t2 / norm
        directions[i, 0], directions[i, 1], directions[i, 2] = d0, d1, d2
        unit_norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u0, u1, u2 = d0 / unit_norm, d1 / unit_norm, d2 / unit_norm
        quadratic = 0.0
        for a in range(3):
            ua = u0 if a == 0 else (u1 if a == 1 else u2)
            quadratic += ua * (mobility[a, 0] * u0 + mobility[a, 1] * u1 + mobility[a, 2] * u2)
        mass = 1.0 / quadratic
        effective_masses[i] = mass
        if not mass > 0.0:  # NaN or not positive: the running sum bounds nothing; never stop
            bound = math.inf
        if bound < math.inf:
            running = max(running, mass) if bound_is_max else running + score_weights[i] * mass
            if running > bound:
                return 5, i + 1, 0, running
    return 0, count, 0, 0.0
