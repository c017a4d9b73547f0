"""The per-(grasp, sample) terms every analysis shares, compiled: joint and tip poses, the tip
Jacobian and the inverse joint-space inertia of the augmented chain (``method.terms``).

M is the one ``_mobility_from_frames`` builds and factorises for the ranking, so the ranking and
the analyses read the same mass matrix (whatever it includes: object, armature)."""

from ._jit import _jit, _jit_inline
from .effective_mass import _mobility_from_frames
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
def sample_terms(chain, bodies, q_all, counts, out, lower_inverse, ws):
    """For each grasp g (axis 0 of q_all (G, N, nq), of ``bodies`` and of ``out``) and its
    samples i < counts[g]: joint poses and motion subspaces, tip pose, tip Jacobian,
    tip mobility and M^-1 into ``out`` (``method.terms.SampleTerms``); rows from counts[g]
    on are left untouched.
    lower_inverse: (n, n) scratch; ws: ``ik.workspace(n)``."""
    axes, prismatic = chain.axes, chain.prismatic
    n = axes.shape[0]
    jr, jp, fr, ft = ws[0], ws[1], ws[2], ws[3]
    inverse_diagonal, factor = ws[14], ws[15]
    for g in range(q_all.shape[0]):
        for i in range(counts[g]):
            _forward_kinematics(chain, q_all[g, i], ws)
            _mobility_from_frames(chain, bodies, g, ws, out.mobilities_tip_in_base[g, i])
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
            # M = L L^T (L's strict lower triangle in ``factor``, 1/L_jj in inverse_diagonal):
            # L^-1 by forward substitution, then M^-1 = L^-T L^-1.
            for j in range(n):
                lower_inverse[j, j] = inverse_diagonal[j]
                for r in range(j + 1, n):
                    total = 0.0
                    for k in range(j, r):
                        total -= factor[r, k] * lower_inverse[k, j]
                    lower_inverse[r, j] = total * inverse_diagonal[r]
            minv = out.mass_matrix_inverses[g, i]
            for a in range(n):
                for b in range(a, n):
                    total = 0.0
                    for r in range(b, n):
                        total += lower_inverse[r, a] * lower_inverse[r, b]
                    minv[a, b] = total
                    minv[b, a] = total
