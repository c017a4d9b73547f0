"""Translational mobility J M^-1 J^T at the tip (composite-rigid-body mass matrix and a
Cholesky factor), compiled.

``bodies`` is ``method.packed.BodyInertias`` (mass, centre of mass and rotational inertia
of each body, the object merged into the last), one value passed as a whole."""

import math

from ._jit import _jit, _jit_inline
from .kinematics import _forward_kinematics, _joint_axis_in_world


@_jit_inline
def _substituted_row(factor, inverse_diagonal, solved, i, x0, x1, x2):
    """Row i of X = L^-1 B for three columns: (b_i - sum_k<i L_ik X_k) / L_ii, from B's row i
    (x0, x1, x2) and X's rows k < i (``solved`` (n, 3)); L's strict lower triangle in
    ``factor``, 1/L_ii in ``inverse_diagonal`` (the Cholesky of ``_mobility_from_frames``)."""
    for k in range(i):
        f = factor[i, k]
        x0 -= f * solved[k, 0]
        x1 -= f * solved[k, 1]
        x2 -= f * solved[k, 2]
    inverse = inverse_diagonal[i]
    return x0 * inverse, x1 * inverse, x2 * inverse


@_jit_inline
def _mobility_from_frames(chain, bodies, g, ws, out):
    """[J M^-1 J^T]_3x3 at the tip origin, base axes [1/kg], from the joint and tip poses in ws.

    M: joint-space inertia of the chain whose body k has mass masses[g, k], centre of mass
    levers[g, k] and rotational inertia about it rotational_inertias[g, k] (joint-k frame,
    symmetric), by the composite-rigid-body algorithm in world axes; M^-1 through its
    Cholesky factor. ``bodies``: BodyInertias of one or more grasps (axis 0), g the grasp.
    The chain's armature is added to the diagonal of M before the factorisation, as Pinocchio's
    crba adds ``model.armature``.
    """
    base_rotation, axes, prismatic = chain.base_rotation, chain.axes, chain.prismatic
    masses, levers = bodies.masses[g], bodies.levers[g]
    rotational_inertias = bodies.rotational_inertias[g]
    jr, jp, ft = ws[0], ws[1], ws[3]
    mass_matrix, sv, sw, jt = ws[15], ws[16], ws[17], ws[18]
    n = axes.shape[0]
    for k in range(n):
        u0, u1, u2, w0, w1, w2, slide = _joint_axis_in_world(axes, prismatic, jr, k)
        p0, p1, p2 = jp[k, 0], jp[k, 1], jp[k, 2]
        sw[k, 0], sw[k, 1], sw[k, 2] = w0, w1, w2
        sv[k, 0] = (p1 * w2 - p2 * w1) + slide * u0
        sv[k, 1] = (p2 * w0 - p0 * w2) + slide * u1
        sv[k, 2] = (p0 * w1 - p1 * w0) + slide * u2
        dx, dy, dz = ft[0] - p0, ft[1] - p1, ft[2] - p2
        l0 = (w1 * dz - w2 * dy) + slide * u0
        l1 = (w2 * dx - w0 * dz) + slide * u1
        l2 = (w0 * dy - w1 * dx) + slide * u2
        for i in range(3):
            jt[k, i] = (
                base_rotation[0, i] * l0 + base_rotation[1, i] * l1 + base_rotation[2, i] * l2
            )
    # Composite inertia of bodies k..n-1 about the world origin: mass, first moment h and
    # rotational inertia io (symmetric: its six entries).
    total_mass = 0.0
    h0 = h1 = h2 = 0.0
    i00 = i01 = i02 = i11 = i12 = i22 = 0.0
    for k in range(n - 1, -1, -1):
        m = masses[k]
        r = jr[k]
        lx, ly, lz = levers[k, 0], levers[k, 1], levers[k, 2]
        c0 = jp[k, 0] + r[0, 0] * lx + r[0, 1] * ly + r[0, 2] * lz
        c1 = jp[k, 1] + r[1, 0] * lx + r[1, 1] * ly + r[1, 2] * lz
        c2 = jp[k, 2] + r[2, 0] * lx + r[2, 1] * ly + r[2, 2] * lz
        inertia = rotational_inertias[k]
        # R I R^T (upper triangle), with t = R I row by row.
        cc = c0 * c0 + c1 * c1 + c2 * c2
        mc0, mc1, mc2 = m * c0, m * c1, m * c2
        r00, r01, r02 = r[0, 0], r[0, 1], r[0, 2]
        r10, r11, r12 = r[1, 0], r[1, 1], r[1, 2]
        r20, r21, r22 = r[2, 0], r[2, 1], r[2, 2]
        j00, j01, j02 = inertia[0, 0], inertia[0, 1], inertia[0, 2]
        j11, j12, j22 = inertia[1, 1], inertia[1, 2], inertia[2, 2]
        t0 = r00 * j00 + r01 * j01 + r02 * j02
        t1 = r00 * j01 + r01 * j11 + r02 * j12
        t2 = r00 * j02 + r01 * j12 + r02 * j22
        i00 += t0 * r00 + t1 * r01 + t2 * r02 + m * cc - mc0 * c0
        i01 += t0 * r10 + t1 * r11 + t2 * r12 - mc0 * c1
        i02 += t0 * r20 + t1 * r21 + t2 * r22 - mc0 * c2
        t0 = r10 * j00 + r11 * j01 + r12 * j02
        t1 = r10 * j01 + r11 * j11 + r12 * j12
        t2 = r10 * j02 + r11 * j12 + r12 * j22
        i11 += t0 * r10 + t1 * r11 + t2 * r12 + m * cc - mc1 * c1
        i12 += t0 * r20 + t1 * r21 + t2 * r22 - mc1 * c2
        t0 = r20 * j00 + r21 * j01 + r22 * j02
        t1 = r20 * j01 + r21 * j11 + r22 * j12
        t2 = r20 * j02 + r21 * j12 + r22 * j22
        i22 += t0 * r20 + t1 * r21 + t2 * r22 + m * cc - mc2 * c2
        h0 += mc0
        h1 += mc1
        h2 += mc2
        total_mass += m
        # Force of the composite moving along joint k: f = m v - h x w, n = h x v + io w.
        v0, v1, v2 = sv[k, 0], sv[k, 1], sv[k, 2]
        w0, w1, w2 = sw[k, 0], sw[k, 1], sw[k, 2]
        f0 = total_mass * v0 - (h1 * w2 - h2 * w1)
        f1 = total_mass * v1 - (h2 * w0 - h0 * w2)
        f2 = total_mass * v2 - (h0 * w1 - h1 * w0)
        n0 = (h1 * v2 - h2 * v1) + i00 * w0 + i01 * w1 + i02 * w2
        n1 = (h2 * v0 - h0 * v2) + i01 * w0 + i11 * w1 + i12 * w2
        n2 = (h0 * v1 - h1 * v0) + i02 * w0 + i12 * w1 + i22 * w2
        for i in range(k + 1):
            value = (
                sv[i, 0] * f0
                + sv[i, 1] * f1
                + sv[i, 2] * f2
                + sw[i, 0] * n0
                + sw[i, 1] * n1
                + sw[i, 2] * n2
            )
            mass_matrix[k, i] = value  # the lower triangle: all the factorisation reads
    # Cholesky M = L L^T (lower triangle; 1/L_jj in inverse_diagonal), X = L^-1 J^T (in jt),
    # A = X^T X: the three columns of X in one pass, the six sums of A in another.
    inverse_diagonal, armature = ws[14], chain.armature  # ws[14]: the IK's step, scratch here
    for j in range(n):
        total = mass_matrix[j, j] + armature[j]
        for k in range(j):
            total -= mass_matrix[j, k] * mass_matrix[j, k]
        inverse = 1.0 / math.sqrt(total)
        inverse_diagonal[j] = inverse
        for i in range(j + 1, n):
            total = mass_matrix[i, j]
            for k in range(j):
                total -= mass_matrix[i, k] * mass_matrix[j, k]
            mass_matrix[i, j] = total * inverse
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    for i in range(n):
        x0, x1, x2 = _substituted_row(
            mass_matrix, inverse_diagonal, jt, i, jt[i, 0], jt[i, 1], jt[i, 2]
        )
        jt[i, 0], jt[i, 1], jt[i, 2] = x0, x1, x2
        a00 += x0 * x0
        a01 += x0 * x1
        a02 += x0 * x2
        a11 += x1 * x1
        a12 += x1 * x2
        a22 += x2 * x2
    out[0, 0], out[0, 1], out[0, 2] = a00, a01, a02
    out[1, 0], out[1, 1], out[1, 2] = a01, a11, a12
    out[2, 0], out[2, 1], out[2, 2] = a02, a12, a22


@_jit
def translational_mobilities(chain, bodies, q_all, out, ws):
    """_mobility_from_frames of the first grasp of ``bodies`` for each row of q_all, into out
    (N, 3, 3); ws: ``ik.workspace(n)``."""
    for sample in range(q_all.shape[0]):
        _forward_kinematics(chain, q_all[sample], ws)
        _mobility_from_frames(chain, bodies, 0, ws, out[sample])


@_jit
def augment_bodies(
    robot_bodies,
    tip_body,
    tip_rotation,
    tip_translation,
    spatial,
    grasp_rotations,
    grasp_translations,
    out,
    scratch,
):
    """``method.effective_mass.augmented_inertia_arrays``, compiled: the chain's bodies
    (``robot_bodies``: BodyInertias of one chain) for each grasp g, the object merged into
    body ``tip_body`` as Pinocchio adds inertias, into ``out`` (BodyInertias, leading grasp
    axis).

    Args:
        tip_rotation, tip_translation: The tip frame in the tip body's joint frame [m].
        spatial: The object's (mass [kg], centre of mass (3,) [m], rotational inertia about it
            (3, 3) [kg m^2]), object frame.
        grasp_rotations, grasp_translations: (G, 3, 3), (G, 3): the tip frame in the object
            frame [m].
        scratch: (4, 3): the object frame's rotation in the joint frame, and the object's
            centre of mass there.
    """
    object_mass, object_lever, object_inertia = spatial
    masses, levers, inertias = robot_bodies
    n = masses.shape[0]
    body_mass = masses[tip_body]
    mass = body_mass + object_mass
    mass_inverse = 1.0 / max(mass, 2.220446049250313e-16)
    reduced = body_mass * object_mass * mass_inverse
    rotation, com = scratch[:3], scratch[3]
    for g in range(grasp_rotations.shape[0]):
        for k in range(n):
            out.masses[g, k] = masses[k]
            for i in range(3):
                out.levers[g, k, i] = levers[k, i]
                for j in range(3):
                    out.rotational_inertias[g, k, i, j] = inertias[k, i, j]
        grasp_rotation, grasp_translation = grasp_rotations[g], grasp_translations[g]
        for i in range(3):  # object frame in the joint frame: tip placement * grasp^-1
            for j in range(3):
                rotation[i, j] = (
                    tip_rotation[i, 0] * grasp_rotation[j, 0]
                    + tip_rotation[i, 1] * grasp_rotation[j, 1]
                    + tip_rotation[i, 2] * grasp_rotation[j, 2]
                )
        for i in range(3):
            origin = tip_translation[i] - (
                rotation[i, 0] * grasp_translation[0]
                + rotation[i, 1] * grasp_translation[1]
                + rotation[i, 2] * grasp_translation[2]
            )
            com[i] = origin + (
                rotation[i, 0] * object_lever[0]
                + rotation[i, 1] * object_lever[1]
                + rotation[i, 2] * object_lever[2]
            )
        arm_square = 0.0
        for i in range(3):
            arm_square += (levers[tip_body, i] - com[i]) ** 2
        tensor = out.rotational_inertias[g, tip_body]
        for i in range(3):
            arm_i = levers[tip_body, i] - com[i]
            for j in range(3):
                turned = 0.0  # (R I_object R^T)[i, j]
                for a in range(3):
                    for b in range(3):
                        turned += rotation[i, a] * object_inertia[a, b] * rotation[j, b]
                skew_square = arm_i * (levers[tip_body, j] - com[j])
                if i == j:
                    skew_square -= arm_square
                tensor[i, j] = inertias[tip_body, i, j] + turned - reduced * skew_square
        out.masses[g, tip_body] = mass
        for i in range(3):
            out.levers[g, tip_body, i] = (
                body_mass * mass_inverse * levers[tip_body, i]
                + object_mass * mass_inverse * com[i]
            )
