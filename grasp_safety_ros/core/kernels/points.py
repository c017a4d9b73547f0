"""Effective masses at points of the moving chain over (grasp, sample, point), compiled, from
the shared per-(grasp, sample) terms (``method.terms.SampleTerms``): points fixed to the tip
(the carried object's exposed points) and sites fixed to the links (the whole arm); and the
joint velocities that make the tip follow its twist (``tip_following_rates``).

A point's translational mobility is A = J_p M^-1 J_p^T [1/kg] and its effective mass along a
unit direction u is 1 / (u^T A u); a point that does not move has no direction, so its A is
handed back (``method.points`` takes its smallest eigenvalue, as the Pinocchio path does).
The self-motion's joint rates come from the clamped cubic spline through the samples
(``clamped_spline_velocities``, ``method.executable``'s numbers bit for bit)."""

from ._jit import _jit, _jit_exact, _jit_inline


@_jit_inline
def _quadratic(mobility, row, a, b):
    """row[a]^T mobility row[b] (6-vectors, 6 x 6)."""
    total = 0.0
    for s in range(6):
        inner = 0.0
        for t in range(6):
            inner += mobility[s, t] * row[b, t]
        total += row[a, s] * inner
    return total


@_jit
def tip_point_masses(
    tip_mobilities,
    tip_rotations,
    counts,
    base_rotation,
    points_in_tip,
    directions,
    stationary,
    motion_of,
    masses,
    stationary_mobilities,
    lever_rotation,
    row,
):
    """For grasp g, sample i < counts[g] and point k fixed to the tip at points_in_tip[g, k]
    (tip frame [m]): masses[g, i, k] = 1 / (u^T A u), u = directions[m, i, k] (base axes,
    m = motion_of[g]); where stationary[m, i, k], A (base axes) goes into the next row of
    stationary_mobilities instead ((g, i, k) order) and masses[g, i, k] is left as it is.

    The point's Jacobian (base axes) is J_p = J_v - r^ J_w with r the tip -> point lever, so
    u^T A u = y^T (J M^-1 J^T) y with y = (u, r x u): each point costs a quadratic form of the
    tip's 6 x 6 mobility.

    Args:
        tip_mobilities, tip_rotations, counts: SampleTerms' fields of the grasps (the tip's
            mobility in base axes, its frame in the world frame) and their sample counts.
        base_rotation: (3, 3) the base frame's rotation in the world frame.
        lever_rotation (3, 3), row (3, 6): scratch.
    """
    r = base_rotation
    count = 0
    for g in range(tip_mobilities.shape[0]):
        m = motion_of[g]
        for i in range(counts[g]):
            mobility, tip = tip_mobilities[g, i], tip_rotations[g, i]
            for a in range(3):  # tip frame -> base axes
                for b in range(3):
                    lever_rotation[a, b] = (
                        r[0, a] * tip[0, b] + r[1, a] * tip[1, b] + r[2, a] * tip[2, b]
                    )
            for k in range(points_in_tip.shape[1]):
                p = points_in_tip[g, k]
                l0 = lever_rotation[0, 0] * p[0] + lever_rotation[0, 1] * p[1]
                l0 += lever_rotation[0, 2] * p[2]
                l1 = lever_rotation[1, 0] * p[0] + lever_rotation[1, 1] * p[1]
                l1 += lever_rotation[1, 2] * p[2]
                l2 = lever_rotation[2, 0] * p[0] + lever_rotation[2, 1] * p[1]
                l2 += lever_rotation[2, 2] * p[2]
                if not stationary[m, i, k]:
                    u = directions[m, i, k]
                    row[0, 0], row[0, 1], row[0, 2] = u[0], u[1], u[2]
                    row[0, 3] = l1 * u[2] - l2 * u[1]
                    row[0, 4] = l2 * u[0] - l0 * u[2]
                    row[0, 5] = l0 * u[1] - l1 * u[0]
                    masses[g, i, k] = 1.0 / _quadratic(mobility, row, 0, 0)
                    continue
                for a in range(3):  # y_a = (e_a, r x e_a)
                    for s in range(6):
                        row[a, s] = 0.0
                    row[a, a] = 1.0
                row[0, 4], row[0, 5] = l2, -l1
                row[1, 3], row[1, 5] = -l2, l0
                row[2, 3], row[2, 4] = l1, -l0
                out = stationary_mobilities[count]
                for a in range(3):
                    for b in range(a, 3):
                        value = _quadratic(mobility, row, a, b)
                        out[a, b] = value
                        out[b, a] = value
                count += 1


@_jit
def site_masses(
    joint_rotations,
    joint_origins,
    joint_motions,
    minv,
    counts,
    site_joints,
    points_in_joint,
    support,
    joint_velocities,
    stationary_speed,
    positions,
    velocities,
    speeds,
    masses,
    jacobian,
    weights,
):
    """For grasp g, sample i < counts[g] and site k (the point points_in_joint[k] [m] of chain
    joint site_joints[k]'s frame, moved by the joints where support[k]): its world position,
    velocity J_p q̇ [m/s] and speed, and where the speed is >= ``stationary_speed`` its
    effective mass along the velocity, 1 / (u^T J_p M^-1 J_p^T u) [kg] (else left as it is).

    J_p's column c is v_c + w_c x p for the supporting joints (S_c = (v_c, w_c) at the world
    origin: SampleTerms.motions_joint_in_world), 0 for the others: their terms (exact zeros)
    are skipped, so a site near the base costs a fraction of one at the tip.
    jacobian (3, n), weights (n,): scratch."""
    n = minv.shape[2]
    for g in range(joint_motions.shape[0]):
        for i in range(counts[g]):
            motions, inverse, rates = joint_motions[g, i], minv[g, i], joint_velocities[g, i]
            for k in range(site_joints.shape[0]):
                j = site_joints[k]
                rotation, origin, point = (
                    joint_rotations[g, i, j],
                    joint_origins[g, i, j],
                    (points_in_joint[k]),
                )
                p0 = origin[0] + rotation[0, 0] * point[0] + rotation[0, 1] * point[1]
                p0 += rotation[0, 2] * point[2]
                p1 = origin[1] + rotation[1, 0] * point[0] + rotation[1, 1] * point[1]
                p1 += rotation[1, 2] * point[2]
                p2 = origin[2] + rotation[2, 0] * point[0] + rotation[2, 1] * point[1]
                p2 += rotation[2, 2] * point[2]
                positions[g, i, k, 0], positions[g, i, k, 1], positions[g, i, k, 2] = p0, p1, p2
                v0 = v1 = v2 = 0.0
                for c in range(n):  # J_p's zero columns (and their zero terms) skipped
                    if support[k, c]:
                        s = motions[c]
                        jacobian[0, c] = s[0] + (s[4] * p2 - s[5] * p1)
                        jacobian[1, c] = s[1] + (s[5] * p0 - s[3] * p2)
                        jacobian[2, c] = s[2] + (s[3] * p1 - s[4] * p0)
                        v0 += jacobian[0, c] * rates[c]
                        v1 += jacobian[1, c] * rates[c]
                        v2 += jacobian[2, c] * rates[c]
                velocities[g, i, k, 0], velocities[g, i, k, 1], velocities[g, i, k, 2] = v0, v1, v2
                speed = (v0 * v0 + v1 * v1 + v2 * v2) ** 0.5
                speeds[g, i, k] = speed
                if speed < stationary_speed:
                    continue
                u0, u1, u2 = v0 / speed, v1 / speed, v2 / speed
                for c in range(n):
                    if support[k, c]:
                        weights[c] = (
                            jacobian[0, c] * u0 + jacobian[1, c] * u1 + jacobian[2, c] * u2
                        )
                total = 0.0
                for a in range(n):
                    if support[k, a]:
                        inner = 0.0
                        for c in range(n):
                            if support[k, c]:
                                inner += inverse[a, c] * weights[c]
                        total += weights[a] * inner
                masses[g, i, k] = 1.0 / total


@_jit
def tip_following_rates(
    tip_jacobians,
    counts,
    twists,
    spline_rates,
    rank_tolerance,
    rates,
    fallback,
    transposed,
    diagonal,
    scales,
    solution,
):
    """For grasp g and sample i < counts[g]: q̇ = q̇_s + J⁺ (ξ − J q̇_s) into rates[g, i], with
    J = tip_jacobians[g, i] (6, n), ξ = twists[g, i], q̇_s = spline_rates[g, i]: the
    minimum-norm solution of J x = ξ − J q̇_s by a Householder QR of Jᵀ = Q R (x = Q R⁻ᵀ b),
    backward stable as the pseudo-inverse's SVD. Where that is not the pseudo-inverse's answer
    to rounding (n < 6, or a diagonal entry of R at most ``rank_tolerance`` times the largest:
    J near rank-deficient, where the pseudo-inverse drops directions), fallback[g, i] is set
    and rates[g, i] left as it is, for the caller's pseudo-inverse.

    transposed (n, 6), diagonal (6,), scales (6,), solution (n,): scratch."""
    n = tip_jacobians.shape[3]
    for g in range(tip_jacobians.shape[0]):
        for i in range(counts[g]):
            fallback[g, i] = n < 6
            if n < 6:
                continue
            jacobian, base = tip_jacobians[g, i], spline_rates[g, i]
            for r in range(n):
                for c in range(6):
                    transposed[r, c] = jacobian[c, r]
            largest = 0.0
            for j in range(6):  # reflector j: I - scales[j] v vᵀ, v kept in transposed[j:, j]
                norm = 0.0
                for r in range(j, n):
                    norm += transposed[r, j] * transposed[r, j]
                norm = norm**0.5
                alpha = -norm if transposed[j, j] >= 0.0 else norm
                diagonal[j] = alpha
                transposed[j, j] -= alpha
                length = 0.0
                for r in range(j, n):
                    length += transposed[r, j] * transposed[r, j]
                scales[j] = 2.0 / length if length > 0.0 else 0.0
                for c in range(j + 1, 6):
                    dot = 0.0
                    for r in range(j, n):
                        dot += transposed[r, j] * transposed[r, c]
                    dot *= scales[j]
                    for r in range(j, n):
                        transposed[r, c] -= dot * transposed[r, j]
                largest = max(largest, abs(alpha))
            for j in range(6):
                if not abs(diagonal[j]) > rank_tolerance * largest:
                    fallback[g, i] = True
            if fallback[g, i]:
                continue
            for j in range(6):  # Rᵀ z = ξ − J q̇_s (R's strict upper part in transposed)
                total = twists[g, i, j]
                for c in range(n):
                    total -= jacobian[j, c] * base[c]
                for k in range(j):
                    total -= transposed[k, j] * solution[k]
                solution[j] = total / diagonal[j]
            for r in range(6, n):
                solution[r] = 0.0
            for j in range(5, -1, -1):  # x = Q (z, 0): the reflectors in reverse order
                dot = 0.0
                for r in range(j, n):
                    dot += transposed[r, j] * solution[r]
                dot *= scales[j]
                for r in range(j, n):
                    solution[r] -= dot * transposed[r, j]
            for c in range(n):
                rates[g, i, c] = base[c] + solution[c]


@_jit_exact
def clamped_spline_velocities(
    times, positions, interchanged, factors, diagonal, upper, lower, out
):
    """``method.executable._clamped_spline_rates``' velocities, operation for operation (no
    fused multiply-adds: its numbers bit for bit): the knots' first derivatives out (N, m) of
    the clamped cubic spline through positions (N, m) at times (N,), N >= 2, columns apart.

    interchanged (N-1,), factors (N-1,): each elimination step's row interchange and factor;
    diagonal, upper, lower (N,): the U factor's diagonals (``_tridiagonal_elimination``)."""
    count, columns = positions.shape
    for c in range(columns):
        out[0, c] = 0.0  # the right-hand side: q̇ = 0 at both ends
        out[count - 1, c] = 0.0
        for i in range(1, count - 1):
            before = (positions[i, c] - positions[i - 1, c]) / (times[i] - times[i - 1])
            after = (positions[i + 1, c] - positions[i, c]) / (times[i + 1] - times[i])
            out[i, c] = 3.0 * (
                (times[i + 1] - times[i]) * before + (times[i] - times[i - 1]) * after
            )
        for i in range(count - 1):  # dgtsv's forward elimination
            if interchanged[i]:
                swapped = out[i + 1, c]
                out[i + 1, c] = out[i, c] - factors[i] * swapped
                out[i, c] = swapped
            else:
                out[i + 1, c] = out[i + 1, c] - factors[i] * out[i, c]
        out[count - 1, c] = out[count - 1, c] / diagonal[count - 1]
        out[count - 2, c] = (out[count - 2, c] - upper[count - 2] * out[count - 1, c]) / diagonal[
            count - 2
        ]
        for i in range(count - 3, -1, -1):
            out[i, c] = (
                out[i, c] - upper[i] * out[i + 1, c] - lower[i] * out[i + 2, c]
            ) / diagonal[i]
        # the knots' derivatives of the piecewise polynomial: offset 0 into interval i < N-1,
        # the last interval's length at the last knot (computed first: it reads out[N-2])
        i = count - 2
        dx = times[i + 1] - times[i]
        slope = (positions[i + 1, c] - positions[i, c]) / dx
        t = (out[i, c] + out[i + 1, c] - 2.0 * slope) / dx
        c0, c1, c2 = t / dx, (slope - out[i, c]) / dx - t, out[i, c]
        z1 = 1.0 * dx
        last = 0.0 + c2 * 1.0 * 1.0 + c1 * z1 * 2.0 + c0 * (z1 * dx) * 3.0
        for i in range(count - 1):
            dx = times[i + 1] - times[i]
            slope = (positions[i + 1, c] - positions[i, c]) / dx
            t = (out[i, c] + out[i + 1, c] - 2.0 * slope) / dx
            c0, c1, c2 = t / dx, (slope - out[i, c]) / dx - t, out[i, c]
            out[i, c] = 0.0 + c2 * 1.0 * 1.0 + c1 * 0.0 * 2.0 + c0 * (0.0 * 0.0) * 3.0
        out[count - 1, c] = last
