"""Effective masses at points of the moving chain over (grasp, sample, point), compiled, from
the shared per-(grasp, sample) terms (``method.terms.SampleTerms``): points fixed to the tip
(the carried object's exposed points) and sites fixed to the links (the whole arm, sites on
one body sharing its 6 x 6 mobility); the tip twists of an object motion (``tip_twists``)
and the joint velocities that make the tip follow them (``tip_following_rates``); the whole
arm's ISO/TS 15066 worst cases are in ``kernels.regions``.

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


@_jit_inline
def _row_products(matrix, row, vectors, count):
    """The six sums over c < count of matrix[row, c] * vectors[c, t] (t = 0..5), each in
    index order, side by side in registers."""
    t0 = t1 = t2 = t3 = t4 = t5 = 0.0
    for c in range(count):
        weight = matrix[row, c]
        vector = vectors[c]
        t0 += weight * vector[0]
        t1 += weight * vector[1]
        t2 += weight * vector[2]
        t3 += weight * vector[3]
        t4 += weight * vector[4]
        t5 += weight * vector[5]
    return t0, t1, t2, t3, t4, t5


@_jit_inline
def _dot6(row, y0, y1, y2, y3, y4, y5):
    """row . y of a 6-vector row and y = (y0, ..., y5), in index order."""
    total = row[0] * y0 + row[1] * y1 + row[2] * y2
    return total + row[3] * y3 + row[4] * y4 + row[5] * y5


@_jit_inline
def _rotated(rotation, point):
    """rotation @ point (3 x 3, 3), component by component."""
    x0 = rotation[0, 0] * point[0] + rotation[0, 1] * point[1]
    x0 += rotation[0, 2] * point[2]
    x1 = rotation[1, 0] * point[0] + rotation[1, 1] * point[1]
    x1 += rotation[1, 2] * point[2]
    x2 = rotation[2, 0] * point[0] + rotation[2, 1] * point[1]
    x2 += rotation[2, 2] * point[2]
    return x0, x1, x2


@_jit_inline
def _store_in_base(rotation, x0, x1, x2, out):
    """out = rotation^T x: world axes -> base axes (``rotation`` the base's in the world)."""
    for a in range(3):
        out[a] = rotation[0, a] * x0 + rotation[1, a] * x1 + rotation[2, a] * x2


@_jit_inline
def _body_mobility(motions, inverse, origin, moves, columns, solved):
    """J_o^T (n, 6) of a body at its joint's origin o into ``columns`` (v_c + w_c x o, w_c;
    0 where not moves[c]) and M^-1 J_o^T into ``solved``, row by row."""
    n = inverse.shape[0]
    o = origin
    for c in range(n):
        s = motions[c]
        columns[c, 0] = s[0] + (s[4] * o[2] - s[5] * o[1]) if moves[c] else 0.0
        columns[c, 1] = s[1] + (s[5] * o[0] - s[3] * o[2]) if moves[c] else 0.0
        columns[c, 2] = s[2] + (s[3] * o[1] - s[4] * o[0]) if moves[c] else 0.0
        for a in range(3, 6):
            columns[c, a] = s[a] if moves[c] else 0.0
    for a in range(n):
        products = _row_products(inverse, a, columns, n)
        for t in range(6):
            solved[a, t] = products[t]


@_jit_inline
def _body_products(columns, solved, rates, twist, mobility):
    """The body's twist J_o q̇ (6,) and mobility J_o M^-1 J_o^T (6, 6), exactly symmetric (the
    upper triangle's numbers), from ``_body_mobility``'s J_o^T and M^-1 J_o^T."""
    n = columns.shape[0]
    products = _row_products(rates.reshape((1, n)), 0, columns, n)
    for t in range(6):
        twist[t] = products[t]
    for a in range(6):
        products = _row_products(columns.T, a, solved, n)
        for t in range(a, 6):
            mobility[a, t] = products[t]
            mobility[t, a] = products[t]


@_jit_inline
def _lever_quadratic(mobility, u0, u1, u2, l0, l1, l2):
    """y^T L y with y = (u, r x u), r = (l0, l1, l2) the lever from the body's origin: L y by
    L's rows, then y . (L y) (a point's u^T J_p M^-1 J_p^T u from its body's L)."""
    y3 = l1 * u2 - l2 * u1
    y4 = l2 * u0 - l0 * u2
    y5 = l0 * u1 - l1 * u0
    total = u0 * _dot6(mobility[0], u0, u1, u2, y3, y4, y5)
    total += u1 * _dot6(mobility[1], u0, u1, u2, y3, y4, y5)
    total += u2 * _dot6(mobility[2], u0, u1, u2, y3, y4, y5)
    total += y3 * _dot6(mobility[3], u0, u1, u2, y3, y4, y5)
    total += y4 * _dot6(mobility[4], u0, u1, u2, y3, y4, y5)
    return total + y5 * _dot6(mobility[5], u0, u1, u2, y3, y4, y5)


@_jit_inline
def _site_jacobian(motions, rates, p0, p1, p2, moves, width, jacobian):
    """J_p (3, width) of the point p into ``jacobian`` (v_c + w_c x p; 0 where not moves[c])
    and its velocity J_p q̇."""
    v0 = v1 = v2 = 0.0
    for c in range(width):
        s = motions[c]
        jacobian[0, c] = s[0] + (s[4] * p2 - s[5] * p1) if moves[c] else 0.0
        jacobian[1, c] = s[1] + (s[5] * p0 - s[3] * p2) if moves[c] else 0.0
        jacobian[2, c] = s[2] + (s[3] * p1 - s[4] * p0) if moves[c] else 0.0
        v0 += jacobian[0, c] * rates[c]
        v1 += jacobian[1, c] * rates[c]
        v2 += jacobian[2, c] * rates[c]
    return v0, v1, v2


@_jit_inline
def _site_quadratic(inverse, jacobian, weights, u0, u1, u2, width):
    """u^T J_p M^-1 J_p^T u over J_p's first ``width`` columns: w = J_p^T u into ``weights``,
    then w^T M^-1 w."""
    for c in range(width):
        weights[c] = jacobian[0, c] * u0 + jacobian[1, c] * u1 + jacobian[2, c] * u2
    total = 0.0
    for a in range(width):
        inner = 0.0
        for c in range(width):
            inner += inverse[a, c] * weights[c]
        total += weights[a] * inner
    return total


@_jit
def arm_site_exposure(
    joint_rotations,
    joint_origins,
    joint_motions,
    minv,
    counts,
    base_rotation,
    base_translation,
    site_joints,
    points_in_joint,
    support,
    site_columns,
    site_body,
    body_joints,
    body_support,
    joint_velocities,
    stationary_speed,
    positions,
    directions,
    speeds,
    masses,
    energies,
    stationary,
    jacobian,
    weights,
    solved,
    columns,
    body_mobilities,
    body_twists,
):
    """For grasp g, sample i < counts[g] and site k (the point points_in_joint[k] [m] of chain
    joint site_joints[k]'s frame, moved by the joints where support[k], all before
    site_columns[k]): its position (base frame), speed |J_p q̇| and, where that is >=
    ``stationary_speed``, its unit velocity (base axes), effective mass along it,
    1 / (u^T J_p M^-1 J_p^T u) [kg], and energy 0.5 m v^2 [J]; below it, stationary[g, i, k]
    is set, the speed and the energy are 0 and direction and mass are left as they are. Rows
    from counts[g] on: speed 0, mass 1, not stationary (the rest left).

    Sites with site_body[k] = -1 are computed alone: J_p's column c is v_c + w_c x p for the
    supporting joints (S_c = (v_c, w_c) at the world origin:
    SampleTerms.motions_joint_in_world), 0 for the others. Sites with site_body[k] = b >= 0
    share body b (chain joint body_joints[b], the same as site_joints[k], moved by the joints
    where body_support[b]): its twist V = (v_o, w) and 6 x 6 mobility L = J_o M^-1 J_o^T at
    the joint's origin o, once per sample; with the lever r = p - o (the point, world axes),
    v = v_o + w x r and u^T J_p = y^T J_o with y = (u, r x u), so the mass is 1 / (y^T L y)
    (the rigid lever transform of L, as ``tip_point_masses``). Every sum runs in index order;
    independent sums run side by side (a sum's terms one after the other wait for each
    other).

    base_rotation (3, 3), base_translation (3,): the base frame in the world frame.
    jacobian (3, n), weights (n,), solved (n, 6): M^-1 J_o^T, columns (n, 6): J_o^T,
    body_mobilities (B, 6, 6), body_twists (B, 6): scratch."""
    r = base_rotation
    for g in range(joint_motions.shape[0]):
        for i in range(counts[g]):
            motions, inverse, rates = joint_motions[g, i], minv[g, i], joint_velocities[g, i]
            for b in range(body_joints.shape[0]):
                origin = joint_origins[g, i, body_joints[b]]
                mobility, twist = body_mobilities[b], body_twists[b]
                _body_mobility(motions, inverse, origin, body_support[b], columns, solved)
                _body_products(columns, solved, rates, twist, mobility)
            for k in range(site_joints.shape[0]):
                j, t = site_joints[k], base_translation
                l0, l1, l2 = _rotated(joint_rotations[g, i, j], points_in_joint[k])  # the lever
                origin = joint_origins[g, i, j]
                p0, p1, p2 = origin[0] + l0, origin[1] + l1, origin[2] + l2
                _store_in_base(r, p0 - t[0], p1 - t[1], p2 - t[2], positions[g, i, k])
                b = site_body[k]
                width = site_columns[k]
                if b >= 0:
                    v_ = body_twists[b]
                    v0 = v_[0] + (v_[4] * l2 - v_[5] * l1)
                    v1 = v_[1] + (v_[5] * l0 - v_[3] * l2)
                    v2 = v_[2] + (v_[3] * l1 - v_[4] * l0)
                else:
                    v0, v1, v2 = _site_jacobian(
                        motions, rates, p0, p1, p2, support[k], width, jacobian
                    )
                speed = (v0 * v0 + v1 * v1 + v2 * v2) ** 0.5
                stationary[g, i, k] = speed < stationary_speed
                if speed < stationary_speed:
                    speeds[g, i, k] = 0.0
                    energies[g, i, k] = 0.0
                    continue
                speeds[g, i, k] = speed
                u0, u1, u2 = v0 / speed, v1 / speed, v2 / speed
                _store_in_base(r, u0, u1, u2, directions[g, i, k])
                if b >= 0:
                    total = _lever_quadratic(body_mobilities[b], u0, u1, u2, l0, l1, l2)
                else:
                    total = _site_quadratic(inverse, jacobian, weights, u0, u1, u2, width)
                masses[g, i, k] = 1.0 / total
                energies[g, i, k] = 0.5 * masses[g, i, k] * (speed * speed)
        for i in range(counts[g], joint_motions.shape[1]):
            for k in range(site_joints.shape[0]):
                speeds[g, i, k] = 0.0
                masses[g, i, k] = 1.0
                stationary[g, i, k] = False


@_jit
def site_mobilities(
    joint_rotations,
    joint_origins,
    joint_motions,
    minv,
    site_joints,
    points_in_joint,
    support,
    at,
    out,
    jacobian,
):
    """For each row (g, i, k) of ``at``: the translational mobility J_p M^-1 J_p^T (3 x 3,
    world axes) [1/kg] of site k at grasp g's sample i (``arm_site_exposure``'s sites and
    terms): the sites at rest, whose direction is the mobility's eigenvector of largest
    effective mass. jacobian (3, n): scratch."""
    n = minv.shape[2]
    for row in range(at.shape[0]):
        g, i, k = at[row, 0], at[row, 1], at[row, 2]
        j = site_joints[k]
        rotation, origin, point = (
            joint_rotations[g, i, j],
            joint_origins[g, i, j],
            points_in_joint[k],
        )
        l0 = rotation[0, 0] * point[0] + rotation[0, 1] * point[1]
        l0 += rotation[0, 2] * point[2]
        l1 = rotation[1, 0] * point[0] + rotation[1, 1] * point[1]
        l1 += rotation[1, 2] * point[2]
        l2 = rotation[2, 0] * point[0] + rotation[2, 1] * point[1]
        l2 += rotation[2, 2] * point[2]
        p0, p1, p2 = origin[0] + l0, origin[1] + l1, origin[2] + l2
        motions, inverse = joint_motions[g, i], minv[g, i]
        for c in range(n):
            s = motions[c]
            moves = support[k, c]
            jacobian[0, c] = s[0] + (s[4] * p2 - s[5] * p1) if moves else 0.0
            jacobian[1, c] = s[1] + (s[5] * p0 - s[3] * p2) if moves else 0.0
            jacobian[2, c] = s[2] + (s[3] * p1 - s[4] * p0) if moves else 0.0
        for a in range(3):
            for b in range(a, 3):
                total = 0.0
                for c in range(n):
                    inner = 0.0
                    for d in range(n):
                        inner += inverse[c, d] * jacobian[b, d]
                    total += jacobian[a, c] * inner
                out[row, a, b] = total
                out[row, b, a] = total


@_jit
def tip_twists(
    rotations, linear_tangents, angular_tangents, speed_per_tangent, tips, base_rotation, rows, out
):
    """For each grasp g of ``rows`` (its tip origin tips[k] in the object frame [m], k the
    row's index) and sample i of one sampled object motion (rotations (N, 3, 3) object ->
    base, tangents (N, 3) of the object origin, linear and angular, base axes; speed per
    tangent (N,) [1/s]): the tip twist (linear [m/s], angular [rad/s]), world axes, into
    out[g, i]: ``ObjectMotion.tip_tangents`` (w x (R t) + the linear tangent) and the angular
    tangent times the speed per tangent, then base -> world (``base_rotation``)."""
    r = base_rotation
    for k in range(rows.shape[0]):
        g, t = rows[k], tips[k]
        for i in range(rotations.shape[0]):
            rotation, w, rate = rotations[i], angular_tangents[i], speed_per_tangent[i]
            l0 = rotation[0, 0] * t[0] + rotation[0, 1] * t[1] + rotation[0, 2] * t[2]
            l1 = rotation[1, 0] * t[0] + rotation[1, 1] * t[1] + rotation[1, 2] * t[2]
            l2 = rotation[2, 0] * t[0] + rotation[2, 1] * t[1] + rotation[2, 2] * t[2]
            v0 = (w[1] * l2 - w[2] * l1 + linear_tangents[i, 0]) * rate
            v1 = (w[2] * l0 - w[0] * l2 + linear_tangents[i, 1]) * rate
            v2 = (w[0] * l1 - w[1] * l0 + linear_tangents[i, 2]) * rate
            w0, w1, w2 = w[0] * rate, w[1] * rate, w[2] * rate
            for a in range(3):
                out[g, i, a] = r[a, 0] * v0 + r[a, 1] * v1 + r[a, 2] * v2
                out[g, i, 3 + a] = r[a, 0] * w0 + r[a, 1] * w1 + r[a, 2] * w2


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
    dots,
):
    """For grasp g and sample i < counts[g]: q̇ = q̇_s + J⁺ (ξ − J q̇_s) into rates[g, i], with
    J = tip_jacobians[g, i] (6, n), ξ = twists[g, i], q̇_s = spline_rates[g, i]: the
    minimum-norm solution of J x = ξ − J q̇_s by a Householder QR of Jᵀ = Q R (x = Q R⁻ᵀ b),
    backward stable as the pseudo-inverse's SVD. Where that is not the pseudo-inverse's answer
    to rounding (n < 6, or a diagonal entry of R at most ``rank_tolerance`` times the largest:
    J near rank-deficient, where the pseudo-inverse drops directions), fallback[g, i] is set
    and rates[g, i] left as it is, for the caller's pseudo-inverse.

    The reflectors' dot products with every column are taken side by side with the norm
    (one pass over x, the critical path of each reflector a single sum).
    transposed (n, 6), diagonal (6,), scales (6,), solution (n,), dots (6,): scratch."""
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
                # x = transposed[j:, j]: |x|² and every column's x . column side by side
                norm = d0 = d1 = d2 = d3 = d4 = d5 = 0.0
                for r in range(j, n):
                    x, row = transposed[r, j], transposed[r]
                    norm += x * x
                    d0 += x * row[0]
                    d1 += x * row[1]
                    d2 += x * row[2]
                    d3 += x * row[3]
                    d4 += x * row[4]
                    d5 += x * row[5]
                dots[0], dots[1], dots[2], dots[3], dots[4], dots[5] = d0, d1, d2, d3, d4, d5
                norm = norm**0.5
                head = transposed[j, j]
                alpha = -norm if head >= 0.0 else norm
                diagonal[j] = alpha
                transposed[j, j] = head - alpha  # v = x - alpha e_j: |v|² = 2 |x| (|x| + |x_j|)
                length = norm * (norm + abs(head))
                scales[j] = 1.0 / length if length > 0.0 else 0.0
                for c in range(j + 1, 6):  # v . column = x . column - alpha column_j
                    dot = (dots[c] - alpha * transposed[j, c]) * scales[j]
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
    times, positions, interchanged, factors, diagonal, upper, lower, out, last
):
    """``method.executable._clamped_spline_rates``' velocities, operation for operation (no
    fused multiply-adds: its numbers bit for bit): the knots' first derivatives out (N, m) of
    the clamped cubic spline through positions (N, m) at times (N,), N >= 2, columns apart
    (each row's operations run over the columns: the same per column, in vector loops).

    interchanged (N-1,), factors (N-1,): each elimination step's row interchange and factor;
    diagonal, upper, lower (N,): the U factor's diagonals (``_tridiagonal_elimination``);
    last (m,): scratch."""
    count, columns = positions.shape
    for c in range(columns):
        out[0, c] = 0.0  # the right-hand side: q̇ = 0 at both ends
        out[count - 1, c] = 0.0
    for i in range(1, count - 1):
        before_dt, after_dt = times[i] - times[i - 1], times[i + 1] - times[i]
        for c in range(columns):
            before = (positions[i, c] - positions[i - 1, c]) / before_dt
            after = (positions[i + 1, c] - positions[i, c]) / after_dt
            out[i, c] = 3.0 * (after_dt * before + before_dt * after)
    for i in range(count - 1):  # dgtsv's forward elimination
        factor = factors[i]
        if interchanged[i]:
            for c in range(columns):
                swapped = out[i + 1, c]
                out[i + 1, c] = out[i, c] - factor * swapped
                out[i, c] = swapped
        else:
            for c in range(columns):
                out[i + 1, c] = out[i + 1, c] - factor * out[i, c]
    for c in range(columns):
        out[count - 1, c] = out[count - 1, c] / diagonal[count - 1]
        out[count - 2, c] = (out[count - 2, c] - upper[count - 2] * out[count - 1, c]) / diagonal[
            count - 2
        ]
    for i in range(count - 3, -1, -1):
        for c in range(columns):
            out[i, c] = (
                out[i, c] - upper[i] * out[i + 1, c] - lower[i] * out[i + 2, c]
            ) / diagonal[i]
    # the knots' derivatives of the piecewise polynomial: offset 0 into interval i < N-1,
    # the last interval's length at the last knot (computed first: it reads out[N-2])
    i = count - 2
    dx = times[i + 1] - times[i]
    for c in range(columns):
        slope = (positions[i + 1, c] - positions[i, c]) / dx
        t = (out[i, c] + out[i + 1, c] - 2.0 * slope) / dx
        c0, c1, c2 = t / dx, (slope - out[i, c]) / dx - t, out[i, c]
        z1 = 1.0 * dx
        last[c] = 0.0 + c2 * 1.0 * 1.0 + c1 * z1 * 2.0 + c0 * (z1 * dx) * 3.0
    for i in range(count - 1):
        dx = times[i + 1] - times[i]
        for c in range(columns):
            slope = (positions[i + 1, c] - positions[i, c]) / dx
            t = (out[i, c] + out[i + 1, c] - 2.0 * slope) / dx
            c0, c1, c2 = t / dx, (slope - out[i, c]) / dx - t, out[i, c]
            out[i, c] = 0.0 + c2 * 1.0 * 1.0 + c1 * 0.0 * 2.0 + c0 * (0.0 * 0.0) * 3.0
    for c in range(columns):
        out[count - 1, c] = last[c]
