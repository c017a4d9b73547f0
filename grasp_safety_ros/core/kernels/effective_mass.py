"""Translational mobility J M^-1 J^T at the tip (composite-rigid-body mass matrix and a
Cholesky factor), compiled.

``bodies`` is ``method.effective_mass.BodyInertias`` (mass, centre of mass and rotational inertia
of each body, the object merged into the last), one value passed as a whole."""

import math

from ._jit import _jit, _jit_inline
from .kinematics import _forward_kinematics, _joint_axis_in_world


@_jit_inline
def _mobility_from_frames(chain, bodies, ws, out):
    """[J M^-1 J^T]_3x3 at the tip origin, base axes [1/kg], from the joint and tip poses in ws.

    M: joint-space inertia of the chain whose body k has mass masses[k], centre of mass
    levers[k] and rotational inertia about it rotational_inertias[k] (joint-k frame), by the
    composite-rigid-body algorithm in world axes; M^-1 through its Cholesky factor.
    """
    base_rotation, axes, prismatic = chain.base_rotation, chain.axes, chain.prismatic
    masses, levers = bodies.masses, bodies.levers
    rotational_inertias = bodies.rotational_inertias
    jr, jp, ft = ws[0], ws[1], ws[3]
    mass_matrix, sv, sw, jt, io, tmp = ws[15], ws[16], ws[17], ws[18], ws[19], ws[20]
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
    # Composite inertia of bodies k..n-1 about the world origin: mass, first moment h, io.
    total_mass = 0.0
    h0 = h1 = h2 = 0.0
    for i in range(3):
        for j in range(3):
            io[i, j] = 0.0
    for k in range(n - 1, -1, -1):
        m = masses[k]
        lx, ly, lz = levers[k, 0], levers[k, 1], levers[k, 2]
        c0 = jp[k, 0] + jr[k, 0, 0] * lx + jr[k, 0, 1] * ly + jr[k, 0, 2] * lz
        c1 = jp[k, 1] + jr[k, 1, 0] * lx + jr[k, 1, 1] * ly + jr[k, 1, 2] * lz
        c2 = jp[k, 2] + jr[k, 2, 0] * lx + jr[k, 2, 1] * ly + jr[k, 2, 2] * lz
        for i in range(3):
            r0, r1, r2 = jr[k, i, 0], jr[k, i, 1], jr[k, i, 2]
            for j in range(3):
                tmp[i, j] = (
                    r0 * rotational_inertias[k, 0, j]
                    + r1 * rotational_inertias[k, 1, j]
                    + r2 * rotational_inertias[k, 2, j]
                )
        cc = c0 * c0 + c1 * c1 + c2 * c2
        mc0, mc1, mc2 = m * c0, m * c1, m * c2
        for i in range(3):
            t0, t1, t2 = tmp[i, 0], tmp[i, 1], tmp[i, 2]
            mci = mc0 if i == 0 else (mc1 if i == 1 else mc2)
            io[i, 0] += (t0 * jr[k, 0, 0] + t1 * jr[k, 0, 1] + t2 * jr[k, 0, 2]) - mci * c0
            io[i, 1] += (t0 * jr[k, 1, 0] + t1 * jr[k, 1, 1] + t2 * jr[k, 1, 2]) - mci * c1
            io[i, 2] += (t0 * jr[k, 2, 0] + t1 * jr[k, 2, 1] + t2 * jr[k, 2, 2]) - mci * c2
            io[i, i] += m * cc
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
        n0 = (h1 * v2 - h2 * v1) + io[0, 0] * w0 + io[0, 1] * w1 + io[0, 2] * w2
        n1 = (h2 * v0 - h0 * v2) + io[1, 0] * w0 + io[1, 1] * w1 + io[1, 2] * w2
        n2 = (h0 * v1 - h1 * v0) + io[2, 0] * w0 + io[2, 1] * w1 + io[2, 2] * w2
        for i in range(k + 1):
            value = (
                sv[i, 0] * f0
                + sv[i, 1] * f1
                + sv[i, 2] * f2
                + sw[i, 0] * n0
                + sw[i, 1] * n1
                + sw[i, 2] * n2
            )
            mass_matrix[i, k] = value
            mass_matrix[k, i] = value
    # Cholesky M = L L^T (lower triangle), X = L^-1 J^T (in jt), A = X^T X.
    for j in range(n):
        total = mass_matrix[j, j]
        for k in range(j):
            total -= mass_matrix[j, k] * mass_matrix[j, k]
        diagonal = math.sqrt(total)
        mass_matrix[j, j] = diagonal
        for i in range(j + 1, n):
            total = mass_matrix[i, j]
            for k in range(j):
                total -= mass_matrix[i, k] * mass_matrix[j, k]
            mass_matrix[i, j] = total / diagonal
    for c in range(3):
        for i in range(n):
            total = jt[i, c]
            for k in range(i):
                total -= mass_matrix[i, k] * jt[k, c]
            jt[i, c] = total / mass_matrix[i, i]
    for a in range(3):
        for b in range(a, 3):
            total = 0.0
            for i in range(n):
                total += jt[i, a] * jt[i, b]
            out[a, b] = total
            out[b, a] = total


@_jit
def translational_mobilities(chain, bodies, q_all, out, ws):
    """_mobility_from_frames for each row of q_all, into out (N, 3, 3); ws:
    ``ik.workspace(n)``."""
    for sample in range(q_all.shape[0]):
        _forward_kinematics(chain, q_all[sample], ws)
        _mobility_from_frames(chain, bodies, ws, out[sample])
