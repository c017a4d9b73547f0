"""Joint velocities, accelerations and torques along given joint paths, compiled: the steps of
``analyses.effort`` (the module docstring there) for G grasps x N samples in one call, on the
shared per-sample terms (``method.terms.SampleTerms``).

Per grasp: the null-space rates from finite differences of the joint path over the path
parameter s (``numpy.gradient``'s formulas, operation for operation, uncontracted, so that the
differences over samples ~1e-6 apart in s round as numpy's do). Per sample: q̇ and q̈ through
the pseudo-inverse of the tip Jacobian, J̇q̇ from the spatial velocities, and the recursive
Newton-Euler torques of the augmented bodies with the armature (world-frame spatial vectors at
the world origin, as ``kernels.terms``' motion subspaces).

The pseudo-inverse is ``numpy.linalg.pinv(J, rcond=1e-10)``'s (singular values at most 1e-10
times the largest count as zero), without forming it: Householder QR of the tall one of J, Jᵀ
(A = Q R); where ‖R‖_F ‖R⁻¹‖_F < 5e9 (then σ_min / σ_max > 2e-10: full rank for pinv) it is
Q R⁻ᵀ (n >= 6) or R⁻¹ Qᵀ (n < 6); otherwise a one-sided Jacobi SVD of R (R = U Σ Vᵀ) gives
A = (Q U) Σ Vᵀ, and the singular values above the cut-off are inverted.
"""

import math

from ._jit import _jit, _jit_exact, _jit_inline
from .kinematics import _forward_kinematics, _joint_difference
from .terms import _motions_and_jacobian

RCOND = 1e-10
"""numpy.linalg.pinv's relative cut-off of the singular values, as analyses.effort uses it."""
_FULL_RANK_BOUND = 5e9
"""‖R‖_F ‖R⁻¹‖_F below this certifies σ_min > 2e-10 σ_max (full rank at RCOND)."""
_JACOBI_TOLERANCE = 1e-15
_JACOBI_SWEEPS = 60


@_jit_exact
def _weighted3(a, f0, b, f1, c, f2):
    """a f0 + b f1 + c f2 rounded as numpy rounds it (no fused multiply-add)."""
    return a * f0 + b * f1 + c * f2


@_jit_inline
def _gradient(f, s, out, count, uniform):
    """numpy.gradient(f[:count], s[:count], axis=0) (edge_order 1) into out[:count]; uniform:
    numpy's constant-spacing case (every np.diff(s) equal to the first)."""
    n = f.shape[1]
    last = count - 1
    for k in range(n):
        out[0, k] = (f[1, k] - f[0, k]) / (s[1] - s[0])
        out[last, k] = (f[last, k] - f[last - 1, k]) / (s[last] - s[last - 1])
    if uniform:
        dx = s[1] - s[0]
        for i in range(1, last):
            for k in range(n):
                out[i, k] = (f[i + 1, k] - f[i - 1, k]) / (2.0 * dx)
        return
    for i in range(1, last):
        dx1 = s[i] - s[i - 1]
        dx2 = s[i + 1] - s[i]
        a = -dx2 / (dx1 * (dx1 + dx2))
        b = (dx2 - dx1) / (dx1 * dx2)
        c = dx1 / (dx2 * (dx1 + dx2))
        for k in range(n):
            out[i, k] = _weighted3(a, f[i - 1, k], b, f[i, k], c, f[i + 1, k])


@_jit_inline
def _path_rates(chain, positions, q_all, s, count, path):
    """Unwrapped joint path (path[0]), dq/ds (path[1]) and d²q/ds² (path[2]) of one grasp's
    ``count`` samples; the derivatives are zero when s does not strictly advance (or
    count < 2), as analyses.effort."""
    q_index, continuous = chain.q_index, chain.continuous
    n = positions.shape[1]
    unwrapped, first, second = path[0], path[1], path[2]
    for k in range(n):
        unwrapped[0, k] = positions[0, k]
    for i in range(1, count):
        for k in range(n):
            step = _joint_difference(q_index, continuous, q_all[i - 1], q_all[i], k)
            unwrapped[i, k] = unwrapped[i - 1, k] + step
    advancing = count > 1
    uniform = True
    for i in range(1, count):
        if not s[i] - s[i - 1] > 0.0:
            advancing = False
        if s[i] - s[i - 1] != s[1] - s[0]:
            uniform = False
    if not advancing:
        for i in range(count):
            for k in range(n):
                first[i, k] = 0.0
                second[i, k] = 0.0
        return
    _gradient(unwrapped, s, first, count, uniform)
    _gradient(first, s, second, count, uniform)


@_jit_inline
def _factorise(jacobian, wide, at, tau, rdiag, rinv):
    """Householder QR of A = Jᵀ (wide: n >= 6) or J, stored by columns of A (at[c] = A[:, c],
    contiguous): reflector v_k in at[k, k:] with factor tau[k], R's diagonal in rdiag and
    R[j, c] (c > j) in at[c, j]; R⁻¹ in rinv. Returns True if the bound of the module
    docstring certifies full rank."""
    n = jacobian.shape[1]
    rows, cols = (n, 6) if wide else (6, n)
    for c in range(cols):
        for r in range(rows):
            at[c, r] = jacobian[c, r] if wide else jacobian[r, c]
    for k in range(cols):
        vk = at[k]
        norm2 = 0.0
        for r in range(k, rows):
            norm2 += vk[r] * vk[r]
        norm = math.sqrt(norm2)
        if norm == 0.0:
            tau[k] = 0.0
            rdiag[k] = 0.0
            continue
        x0 = vk[k]
        alpha = -norm if x0 >= 0.0 else norm
        vk[k] = x0 - alpha
        factor = 2.0 / (norm2 - x0 * x0 + vk[k] * vk[k])
        tau[k] = factor
        rdiag[k] = alpha
        for c in range(k + 1, cols):
            column = at[c]
            w = 0.0
            for r in range(k, rows):
                w += vk[r] * column[r]
            w *= factor
            for r in range(k, rows):
                column[r] -= w * vk[r]
    r_norm2 = 0.0
    inverse_norm2 = 0.0
    for j in range(cols - 1, -1, -1):
        if rdiag[j] == 0.0:
            return False
        inverse = 1.0 / rdiag[j]
        rinv[j, j] = inverse
        r_norm2 += rdiag[j] * rdiag[j]
        inverse_norm2 += inverse * inverse
        for c in range(j + 1, cols):
            total = 0.0
            for k in range(j + 1, c + 1):
                total += at[k, j] * rinv[k, c]
            rinv[j, c] = -total * inverse
            r_norm2 += at[c, j] * at[c, j]
            inverse_norm2 += rinv[j, c] * rinv[j, c]
    return r_norm2 * inverse_norm2 < _FULL_RANK_BOUND * _FULL_RANK_BOUND


@_jit_inline
def _reflect(at, tau, x, rows, cols, forward):
    """x <- Qᵀ x (forward) or Q x, Q the full rows x rows product of the reflectors."""
    for step in range(cols):
        k = step if forward else cols - 1 - step
        if tau[k] == 0.0:
            continue
        vk = at[k]
        w = 0.0
        for r in range(k, rows):
            w += vk[r] * x[r]
        w *= tau[k]
        for r in range(k, rows):
            x[r] -= w * vk[r]


@_jit_inline
def _jacobi_svd(at, rdiag, cols, b, v, sigma):
    """One-sided Jacobi SVD of R (cols x cols, from at and rdiag): R V = U Σ; U's columns in
    b (unit, or zero where σ = 0), V in v, Σ in sigma."""
    for r in range(cols):
        for c in range(cols):
            b[r, c] = rdiag[r] if r == c else (at[c, r] if c > r else 0.0)
            v[r, c] = 1.0 if r == c else 0.0
    for _ in range(_JACOBI_SWEEPS):
        rotated = False
        for i in range(cols - 1):
            for j in range(i + 1, cols):
                alpha = beta = gamma = 0.0
                for r in range(cols):
                    alpha += b[r, i] * b[r, i]
                    beta += b[r, j] * b[r, j]
                    gamma += b[r, i] * b[r, j]
                if abs(gamma) <= _JACOBI_TOLERANCE * math.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = 1.0 / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                if zeta < 0.0:
                    t = -t
                cos = 1.0 / math.sqrt(1.0 + t * t)
                sin = cos * t
                for r in range(cols):
                    bi, bj = b[r, i], b[r, j]
                    b[r, i], b[r, j] = cos * bi - sin * bj, sin * bi + cos * bj
                    vi, vj = v[r, i], v[r, j]
                    v[r, i], v[r, j] = cos * vi - sin * vj, sin * vi + cos * vj
        if not rotated:
            break
    for c in range(cols):
        total = 0.0
        for r in range(cols):
            total += b[r, c] * b[r, c]
        sigma[c] = math.sqrt(total)
        scale = 1.0 / sigma[c] if sigma[c] > 0.0 else 0.0
        for r in range(cols):
            b[r, c] *= scale


@_jit_inline
def _pinv_solve(wide, certified, factors, target, rate_fd, out):
    """out = J⁺ target + (I - J⁺ J) rate_fd (n), J⁺ numpy's pinv at RCOND (module docstring);
    ``factors`` from ``_factorise`` (and ``_jacobi_svd`` unless certified)."""
    at, tau, _, rinv, b, v, sigma, x, y = factors
    n = out.shape[0]
    rows, cols = (n, 6) if wide else (6, n)
    cutoff = 0.0
    if not certified:
        largest = 0.0
        for c in range(cols):
            largest = max(largest, sigma[c])
        cutoff = RCOND * largest
    if wide:  # J = Rᵀ Qᵀ: out = Q [R⁻ᵀ target; 0] + (I - Q Qᵀ) rate_fd, in Q's coordinates
        for r in range(rows):
            x[r] = rate_fd[r]
        _reflect(at, tau, x, rows, cols, True)
        if certified:
            for c in range(cols):
                total = 0.0
                for r in range(c + 1):
                    total += rinv[r, c] * target[r]
                x[c] = total
        else:  # J = V Σ Uᵀ Qᵀ
            for c in range(cols):
                y[c] = x[c]
            for j in range(cols):
                if not sigma[j] > cutoff:
                    continue
                along = 0.0
                for r in range(cols):
                    along += b[r, j] * y[r]
                coefficient = 0.0
                for r in range(cols):
                    coefficient += v[r, j] * target[r]
                coefficient = coefficient / sigma[j] - along
                for r in range(cols):
                    x[r] += coefficient * b[r, j]
        _reflect(at, tau, x, rows, cols, False)
        for r in range(n):
            out[r] = x[r]
        return
    for r in range(6):  # J = Q R (n < 6)
        x[r] = target[r]
    _reflect(at, tau, x, rows, cols, True)
    if certified:  # full column rank: J⁺ J = I
        for r in range(n):
            total = 0.0
            for c in range(r, n):
                total += rinv[r, c] * x[c]
            out[r] = total
        return
    for r in range(n):  # J = Q U Σ Vᵀ
        out[r] = rate_fd[r]
    for j in range(n):
        if not sigma[j] > cutoff:
            continue
        along = 0.0
        coefficient = 0.0
        for r in range(n):
            along += v[r, j] * rate_fd[r]
            coefficient += b[r, j] * x[r]
        coefficient = coefficient / sigma[j] - along
        for r in range(n):
            out[r] += coefficient * v[r, j]


@_jit_inline
def _cross_into(out, row, a0, a1, a2, b0, b1, b2, sign):
    """out[row] += sign (a × b)."""
    out[row, 0] += sign * (a1 * b2 - a2 * b1)
    out[row, 1] += sign * (a2 * b0 - a0 * b2)
    out[row, 2] += sign * (a0 * b1 - a1 * b0)


@_jit
def joint_dynamics(
    chain,
    bodies,
    use_terms,
    terms,
    positions,
    q_all,
    counts,
    motion_of,
    paths,
    object_rotations,
    object_twists,
    grasp_translations,
    gravity,
    out,
    factors,
    ws,
    kinematics,
):
    """q̇, q̈ and τ of G grasps along their joint paths, and per joint max |τ| and RMS τ.

    Args:
        chain: ``ChainArrays``; bodies: augmented ``BodyInertias`` (axis 0 the grasp).
        use_terms: Read the joint poses, motion subspaces, tip origins and Jacobians from
            ``terms`` (``SampleTerms`` along the paths (G, N, ...), world frame); False: compute
            them here (forward kinematics into ``kinematics``, ``ik.workspace(n)``).
        positions: (G, N, n) joint positions; q_all: (G, N, nq) their configurations.
        counts: (G,) int64 samples per grasp (0: skipped; rows from counts[g] on untouched).
        motion_of: (G,) int64: the motion (index into the next three) grasp g follows.
        paths: (M, 3, N) s, ds/dt [1/s], d²s/dt² [1/s²] at the samples of each motion.
        object_rotations: (M, N, 3, 3) the object frame in the base frame.
        object_twists: (M, 2, N, 6) the object origin's twist and its rate (classical
            acceleration), base axes [m/s, rad/s; m/s², rad/s²]; a grasp's tip at r = R p
            (p: grasp_translations (G, 3) [m], object frame) moves at v + ω × r and
            accelerates at a + α × r + ω × (ω × r).
        gravity: (3,) world frame [m/s²].
        out: (velocities, accelerations, torques) (G, N, n) and (peak |τ|, RMS τ) (G, n).
        factors, ws: scratch (``method.dynamics.joint_dynamics``).
    """
    velocities, accelerations, torques, peaks, rms = out
    n = positions.shape[2]
    wide = n >= 6
    armature, base = chain.armature, chain.base_rotation
    axes, prismatic = chain.axes, chain.prismatic
    masses, levers, inertias = bodies.masses, bodies.levers, bodies.rotational_inertias
    path = (ws[0], ws[1], ws[2])
    vl, va, cl, ca, al, aa, force, moment = ws[3], ws[4], ws[5], ws[6], ws[7], ws[8], ws[9], ws[10]
    world = ws[11]  # rows: twist, twist rate (world axes), drift-corrected rate
    fd = ws[12]  # rows: q̇_fd, q̈_fd
    own_motions, own_jacobian = ws[13], ws[14]
    for g in range(counts.shape[0]):
        count = counts[g]
        if count == 0:
            continue
        motion = motion_of[g]
        s, s_rate, s_accel = paths[motion, 0], paths[motion, 1], paths[motion, 2]
        grasp = grasp_translations[g]
        pg0, pg1, pg2 = grasp[0], grasp[1], grasp[2]
        _path_rates(chain, positions[g], q_all[g], s, count, path)
        for k in range(n):
            peaks[g, k] = 0.0
            rms[g, k] = 0.0
        for i in range(count):
            rate, accel = s_rate[i], s_accel[i]
            for k in range(n):
                fd[0, k] = path[1][i, k] * rate
                fd[1, k] = path[2][i, k] * (rate * rate) + path[1][i, k] * accel
            # The tip's twist and rate from the object's (base axes), then in world axes.
            rotation = object_rotations[motion, i]
            r0 = rotation[0, 0] * pg0 + rotation[0, 1] * pg1 + rotation[0, 2] * pg2
            r1 = rotation[1, 0] * pg0 + rotation[1, 1] * pg1 + rotation[1, 2] * pg2
            r2 = rotation[2, 0] * pg0 + rotation[2, 1] * pg1 + rotation[2, 2] * pg2
            twist, twist_rate = object_twists[motion, 0, i], object_twists[motion, 1, i]
            w0, w1, w2 = twist[3], twist[4], twist[5]
            e0, e1, e2 = twist_rate[3], twist_rate[4], twist_rate[5]
            x0 = w1 * r2 - w2 * r1  # ω × r
            x1 = w2 * r0 - w0 * r2
            x2 = w0 * r1 - w1 * r0
            tip_twist = (
                twist[0] + x0,
                twist[1] + x1,
                twist[2] + x2,
                twist_rate[0] + (e1 * r2 - e2 * r1) + (w1 * x2 - w2 * x1),
                twist_rate[1] + (e2 * r0 - e0 * r2) + (w2 * x0 - w0 * x2),
                twist_rate[2] + (e0 * r1 - e1 * r0) + (w0 * x1 - w1 * x0),
            )
            for a in range(3):
                b0, b1, b2 = base[a, 0], base[a, 1], base[a, 2]
                world[0, a] = b0 * tip_twist[0] + b1 * tip_twist[1] + b2 * tip_twist[2]
                world[0, 3 + a] = b0 * w0 + b1 * w1 + b2 * w2
                world[1, a] = b0 * tip_twist[3] + b1 * tip_twist[4] + b2 * tip_twist[5]
                world[1, 3 + a] = b0 * e0 + b1 * e1 + b2 * e2
            if use_terms:
                motions, jacobian = (
                    terms.motions_joint_in_world[g, i],
                    terms.jacobians_tip_in_world[g, i],
                )
                rotations, origins = (
                    terms.rotations_joint_to_world[g, i],
                    terms.translations_joint_in_world[g, i],
                )
                tip = terms.translations_tip_in_world[g, i]
            else:
                _forward_kinematics(chain, q_all[g, i], kinematics)
                rotations, origins, tip = kinematics[0], kinematics[1], kinematics[3]
                motions, jacobian = own_motions, own_jacobian
                _motions_and_jacobian(axes, prismatic, rotations, origins, tip, motions, jacobian)
            certified = _factorise(jacobian, wide, factors[0], factors[1], factors[2], factors[3])
            if not certified:
                _jacobi_svd(factors[0], factors[2], min(n, 6), factors[4], factors[5], factors[6])
            v = velocities[g, i]
            _pinv_solve(wide, certified, factors, world[0], fd[0], v)
            # Spatial velocities V_k and velocity-product accelerations c_k = V_k x S_k q̇_k.
            v0 = v1 = v2 = w0 = w1 = w2 = 0.0
            for k in range(n):
                jl0, jl1, jl2 = motions[k, 0] * v[k], motions[k, 1] * v[k], motions[k, 2] * v[k]
                ja0, ja1, ja2 = motions[k, 3] * v[k], motions[k, 4] * v[k], motions[k, 5] * v[k]
                v0, v1, v2 = v0 + jl0, v1 + jl1, v2 + jl2
                w0, w1, w2 = w0 + ja0, w1 + ja1, w2 + ja2
                vl[k, 0], vl[k, 1], vl[k, 2] = v0, v1, v2
                va[k, 0], va[k, 1], va[k, 2] = w0, w1, w2
                for a in range(3):
                    cl[k, a] = 0.0
                    ca[k, a] = 0.0
                _cross_into(cl, k, w0, w1, w2, jl0, jl1, jl2, 1.0)
                _cross_into(cl, k, v0, v1, v2, ja0, ja1, ja2, 1.0)
                _cross_into(ca, k, w0, w1, w2, ja0, ja1, ja2, 1.0)
            # The drift J̇ q̇: the tip's classical acceleration at q̈ = 0.
            t0, t1, t2 = tip[0], tip[1], tip[2]
            sl0 = sl1 = sl2 = sa0 = sa1 = sa2 = 0.0
            for k in range(n):
                sl0, sl1, sl2 = sl0 + cl[k, 0], sl1 + cl[k, 1], sl2 + cl[k, 2]
                sa0, sa1, sa2 = sa0 + ca[k, 0], sa1 + ca[k, 1], sa2 + ca[k, 2]
            u0 = v0 + (w1 * t2 - w2 * t1)  # tip velocity
            u1 = v1 + (w2 * t0 - w0 * t2)
            u2 = v2 + (w0 * t1 - w1 * t0)
            drift0 = sl0 + (sa1 * t2 - sa2 * t1) + (w1 * u2 - w2 * u1)
            drift1 = sl1 + (sa2 * t0 - sa0 * t2) + (w2 * u0 - w0 * u2)
            drift2 = sl2 + (sa0 * t1 - sa1 * t0) + (w0 * u1 - w1 * u0)
            target = world[2]
            target[0] = world[1, 0] - drift0
            target[1] = world[1, 1] - drift1
            target[2] = world[1, 2] - drift2
            target[3] = world[1, 3] - sa0
            target[4] = world[1, 4] - sa1
            target[5] = world[1, 5] - sa2
            acc = accelerations[g, i]
            _pinv_solve(wide, certified, factors, target, fd[1], acc)
            # RNEA: A_k = A_(k-1) + S_k q̈_k + c_k from (-gravity, 0); body forces
            # f = I A + V x* (I V); τ_k = S_k . (f_k + ... + f_(n-1)) + armature q̈.
            x0, x1, x2 = -gravity[0], -gravity[1], -gravity[2]
            y0 = y1 = y2 = 0.0
            for k in range(n):
                x0 += motions[k, 0] * acc[k] + cl[k, 0]
                x1 += motions[k, 1] * acc[k] + cl[k, 1]
                x2 += motions[k, 2] * acc[k] + cl[k, 2]
                y0 += motions[k, 3] * acc[k] + ca[k, 0]
                y1 += motions[k, 4] * acc[k] + ca[k, 1]
                y2 += motions[k, 5] * acc[k] + ca[k, 2]
                al[k, 0], al[k, 1], al[k, 2] = x0, x1, x2
                aa[k, 0], aa[k, 1], aa[k, 2] = y0, y1, y2
            for k in range(n):
                r, lever, inertia, mass = rotations[k], levers[g, k], inertias[g, k], masses[g, k]
                c0 = origins[k, 0] + r[0, 0] * lever[0] + r[0, 1] * lever[1] + r[0, 2] * lever[2]
                c1 = origins[k, 1] + r[1, 0] * lever[0] + r[1, 1] * lever[1] + r[1, 2] * lever[2]
                c2 = origins[k, 2] + r[2, 0] * lever[0] + r[2, 1] * lever[1] + r[2, 2] * lever[2]
                w0, w1, w2 = va[k, 0], va[k, 1], va[k, 2]
                v0, v1, v2 = vl[k, 0], vl[k, 1], vl[k, 2]
                p0 = mass * (v0 + (w1 * c2 - w2 * c1))  # momentum
                p1 = mass * (v1 + (w2 * c0 - w0 * c2))
                p2 = mass * (v2 + (w0 * c1 - w1 * c0))
                e0, e1, e2 = aa[k, 0], aa[k, 1], aa[k, 2]
                f0 = mass * (al[k, 0] + (e1 * c2 - e2 * c1))
                f1 = mass * (al[k, 1] + (e2 * c0 - e0 * c2))
                f2 = mass * (al[k, 2] + (e0 * c1 - e1 * c0))
                # R I Rᵀ w and R I Rᵀ e: into body axes, through I, back.
                bw0 = r[0, 0] * w0 + r[1, 0] * w1 + r[2, 0] * w2
                bw1 = r[0, 1] * w0 + r[1, 1] * w1 + r[2, 1] * w2
                bw2 = r[0, 2] * w0 + r[1, 2] * w1 + r[2, 2] * w2
                be0 = r[0, 0] * e0 + r[1, 0] * e1 + r[2, 0] * e2
                be1 = r[0, 1] * e0 + r[1, 1] * e1 + r[2, 1] * e2
                be2 = r[0, 2] * e0 + r[1, 2] * e1 + r[2, 2] * e2
                iw0 = inertia[0, 0] * bw0 + inertia[0, 1] * bw1 + inertia[0, 2] * bw2
                iw1 = inertia[1, 0] * bw0 + inertia[1, 1] * bw1 + inertia[1, 2] * bw2
                iw2 = inertia[2, 0] * bw0 + inertia[2, 1] * bw1 + inertia[2, 2] * bw2
                ie0 = inertia[0, 0] * be0 + inertia[0, 1] * be1 + inertia[0, 2] * be2
                ie1 = inertia[1, 0] * be0 + inertia[1, 1] * be1 + inertia[1, 2] * be2
                ie2 = inertia[2, 0] * be0 + inertia[2, 1] * be1 + inertia[2, 2] * be2
                h0 = r[0, 0] * iw0 + r[0, 1] * iw1 + r[0, 2] * iw2 + (c1 * p2 - c2 * p1)
                h1 = r[1, 0] * iw0 + r[1, 1] * iw1 + r[1, 2] * iw2 + (c2 * p0 - c0 * p2)
                h2 = r[2, 0] * iw0 + r[2, 1] * iw1 + r[2, 2] * iw2 + (c0 * p1 - c1 * p0)
                m0 = r[0, 0] * ie0 + r[0, 1] * ie1 + r[0, 2] * ie2 + (c1 * f2 - c2 * f1)
                m1 = r[1, 0] * ie0 + r[1, 1] * ie1 + r[1, 2] * ie2 + (c2 * f0 - c0 * f2)
                m2 = r[2, 0] * ie0 + r[2, 1] * ie1 + r[2, 2] * ie2 + (c0 * f1 - c1 * f0)
                force[k, 0] = f0 + (w1 * p2 - w2 * p1)
                force[k, 1] = f1 + (w2 * p0 - w0 * p2)
                force[k, 2] = f2 + (w0 * p1 - w1 * p0)
                moment[k, 0] = m0 + (w1 * h2 - w2 * h1) + (v1 * p2 - v2 * p1)
                moment[k, 1] = m1 + (w2 * h0 - w0 * h2) + (v2 * p0 - v0 * p2)
                moment[k, 2] = m2 + (w0 * h1 - w1 * h0) + (v0 * p1 - v1 * p0)
            tau = torques[g, i]
            f0 = f1 = f2 = m0 = m1 = m2 = 0.0
            for k in range(n - 1, -1, -1):  # the subtree's total
                f0, f1, f2 = f0 + force[k, 0], f1 + force[k, 1], f2 + force[k, 2]
                m0, m1, m2 = m0 + moment[k, 0], m1 + moment[k, 1], m2 + moment[k, 2]
                tau[k] = (
                    motions[k, 0] * f0
                    + motions[k, 1] * f1
                    + motions[k, 2] * f2
                    + motions[k, 3] * m0
                    + motions[k, 4] * m1
                    + motions[k, 5] * m2
                    + armature[k] * acc[k]
                )
                peaks[g, k] = max(peaks[g, k], abs(tau[k]))
                rms[g, k] += tau[k] * tau[k]
        for k in range(n):
            rms[g, k] = math.sqrt(rms[g, k] / count)
