"""The per-(grasp, sample) terms every analysis shares, compiled: joint and tip poses, the tip
Jacobian, the tip's mobility and the inverse joint-space inertia of the augmented chain
(``method.terms``).

M is the one ``_mobility_from_frames`` builds and factorises for the ranking, so the ranking and
the analyses read the same mass matrix (whatever it includes: object, armature)."""

from ._jit import _jit, _jit_inline
from .effective_mass import _mobility_from_frames, _substituted_row
from .kinematics import _forward_kinematics, _joint_axis_in_world


@_jit_inline
def _motions_and_jacobian(axes, prismatic, jr, jp, ft, motions, jacobian):
    """Every joint's motion subspace at the world origin (motions (n, 6)) and the tip
    Jacobian (6 x n, LOCAL_WORLD_ALIGNED), from the joint rotations jr, origins jp and tip
    origin ft (world frame; the chain's axes, prismatic)."""
    for k in range(axes.shape[0]):
        u0, u1, u2, w0, w1, w2, slide = _joint_axis_in_world(axes, prismatic, jr, k)
        p0, p1, p2 = jp[k, 0], jp[k, 1], jp[k, 2]
        motions[k, 0] = (p1 * w2 - p2 * w1) + slide * u0
        motions[k, 1] = (p2 * w0 - p0 * w2) + slide * u1
        motions[k, 2] = (p0 * w1 - p1 * w0) + slide * u2
        motions[k, 3], motions[k, 4], motions[k, 5] = w0, w1, w2
        dx, dy, dz = ft[0] - p0, ft[1] - p1, ft[2] - p2
        jacobian[0, k] = (w1 * dz - w2 * dy) + slide * u0
        jacobian[1, k] = (w2 * dx - w0 * dz) + slide * u1
        jacobian[2, k] = (w0 * dy - w1 * dx) + slide * u2
        jacobian[3, k], jacobian[4, k], jacobian[5, k] = w0, w1, w2


@_jit
def sample_terms(chain, bodies, q_all, counts, optional, out, lower_inverse, angular, ws):
    """For each grasp g (axis 0 of q_all (G, N, nq), of ``bodies`` and of ``out``) and its
    samples i < counts[g]: joint poses and motion subspaces, tip pose and tip Jacobian, and
    where ``optional`` (two flags) asks, the tip's 6 x 6 mobility and M^-1, into ``out``
    (``method.terms.SampleTerms``; the fields not asked and the rows from counts[g] on are
    left untouched).
    lower_inverse: (n, n) and angular: (n, 3) scratch; ws: ``ik.workspace(n)``."""
    axes, prismatic = chain.axes, chain.prismatic
    n = axes.shape[0]
    jr, jp, fr, ft = ws[0], ws[1], ws[2], ws[3]
    inverse_diagonal, factor, top = ws[14], ws[15], ws[19]
    tip_mobilities, inverses = optional
    for g in range(q_all.shape[0]):
        for i in range(counts[g]):
            _forward_kinematics(chain, q_all[g, i], ws)
            if tip_mobilities or inverses:  # M and its Cholesky factor
                _mobility_from_frames(chain, bodies, g, ws, top)
            joint_rotations, joint_origins = (
                out.rotations_joint_to_world[g, i],
                out.translations_joint_in_world[g, i],
            )
            jacobian, motions = out.jacobians_tip_in_world[g, i], out.motions_joint_in_world[g, i]
            for a in range(3):
                out.translations_tip_in_world[g, i, a] = ft[a]
                for b in range(3):
                    out.rotations_tip_to_world[g, i, a, b] = fr[a, b]
            _motions_and_jacobian(axes, prismatic, jr, jp, ft, motions, jacobian)
            for k in range(n):
                for a in range(3):
                    joint_origins[k, a] = jp[k, a]
                    for b in range(3):
                        joint_rotations[k, a, b] = jr[k, a, b]
            if tip_mobilities:
                mobility = out.mobilities_tip_in_base[g, i]
                _tip_mobility(chain.base_rotation, ws, jacobian, angular, top, mobility)
            if inverses:
                _mass_matrix_inverse(
                    factor, inverse_diagonal, lower_inverse, out.mass_matrix_inverses[g, i]
                )


@_jit_inline
def _tip_mobility(base_rotation, ws, jacobian, angular, top, mobility):
    """The tip's 6 x 6 mobility J M^-1 J^T, base axes, rows [linear; angular], from what
    ``_mobility_from_frames`` leaves: its linear block ``top`` and X_v = L^-1 J_v^T (ws[18]),
    L (M = L L^T: strict lower triangle in ws[15], 1/L_jj in ws[14]); X_w = L^-1 J_w^T (into
    ``angular``, J_w from the world-frame ``jacobian``) gives the other blocks, X^T X."""
    n = jacobian.shape[1]
    linear, factor, inverse_diagonal = ws[18], ws[15], ws[14]
    for i in range(n):
        w0, w1, w2 = jacobian[3, i], jacobian[4, i], jacobian[5, i]
        r = base_rotation  # J_w's column in base axes: R^T w
        x0 = r[0, 0] * w0 + r[1, 0] * w1 + r[2, 0] * w2
        x1 = r[0, 1] * w0 + r[1, 1] * w1 + r[2, 1] * w2
        x2 = r[0, 2] * w0 + r[1, 2] * w1 + r[2, 2] * w2
        x0, x1, x2 = _substituted_row(factor, inverse_diagonal, angular, i, x0, x1, x2)
        angular[i, 0], angular[i, 1], angular[i, 2] = x0, x1, x2
    for a in range(3):
        for b in range(3):
            mobility[a, b] = top[a, b]
            cross = 0.0
            for i in range(n):
                cross += linear[i, a] * angular[i, b]
            mobility[a, 3 + b] = cross
            mobility[3 + b, a] = cross
        for b in range(a, 3):
            total = 0.0
            for i in range(n):
                total += angular[i, a] * angular[i, b]
            mobility[3 + a, 3 + b] = total
            mobility[3 + b, 3 + a] = total


@_jit_inline
def _mass_matrix_inverse(factor, inverse_diagonal, lower_inverse, minv):
    """M^-1 from M = L L^T (L's strict lower triangle in ``factor``, 1/L_jj in
    inverse_diagonal): L^-1 by forward substitution (into lower_inverse), M^-1 = L^-T L^-1."""
    n = minv.shape[0]
    for j in range(n):
        lower_inverse[j, j] = inverse_diagonal[j]
        for r in range(j + 1, n):
            total = 0.0
            for k in range(j, r):
                total -= factor[r, k] * lower_inverse[k, j]
            lower_inverse[r, j] = total * inverse_diagonal[r]
    for a in range(n):
        for b in range(a, n):
            total = 0.0
            for r in range(b, n):
                total += lower_inverse[r, a] * lower_inverse[r, b]
            minv[a, b] = total
            minv[b, a] = total
