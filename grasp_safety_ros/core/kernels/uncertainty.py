"""Effective masses of a batch of grasps over a set of object inertias, compiled (the
inertia-uncertainty and armature-range analyses, ``method.perturbed``).

With the object's spatial inertia Y (6 x 6, tip frame) on the tip, M_aug = M + Jᵀ Y J (J the
tip's LOCAL Jacobian), and the push-through identity (M + Jᵀ Y J)⁻¹ Jᵀ = M⁻¹ Jᵀ (I + Y A)⁻¹
with A = J M⁻¹ Jᵀ gives the tip's mobility J M_aug⁻¹ Jᵀ = A (I + Y A)⁻¹: per (grasp, sample)
the forward kinematics, the chain's own M and its Cholesky factor (the ranking's,
``effective_mass._mobility_from_frames``, armature included) and A run once; per inertia only a
6 x 6 solve. I + Y A is similar to I + Y^½ A Y^½ (symmetric, eigenvalues >= 1), so it is
always invertible; no inverse of A or Y is needed (singular arms, point masses)."""

from ._jit import _jit, _jit_inline
from .effective_mass import _mobility_from_frames
from .kinematics import _forward_kinematics, _joint_axis_in_world


@_jit_inline
def _tip_operational_mobility(chain, bodies, ws, columns, mobility, a):
    """A = J M⁻¹ Jᵀ (6 x 6, tip frame, rows [linear; angular]) of the chain alone (``bodies``:
    BodyInertias of one row) at the joint and tip poses in ws. columns: (n, 6) scratch
    (Jᵀ, then L⁻¹ Jᵀ); mobility: (3, 3) scratch."""
    _mobility_from_frames(chain, bodies, 0, ws, mobility)  # M = L Lᵀ: ws[15] and ws[14]
    axes, prismatic = chain.axes, chain.prismatic
    jr, jp, fr, ft = ws[0], ws[1], ws[2], ws[3]
    inverse_diagonal, factor = ws[14], ws[15]
    n = axes.shape[0]
    for k in range(n):  # the tip's LOCAL Jacobian, column k (world quantities turned by frᵀ)
        u0, u1, u2, w0, w1, w2, slide = _joint_axis_in_world(axes, prismatic, jr, k)
        dx, dy, dz = ft[0] - jp[k, 0], ft[1] - jp[k, 1], ft[2] - jp[k, 2]
        l0 = (w1 * dz - w2 * dy) + slide * u0
        l1 = (w2 * dx - w0 * dz) + slide * u1
        l2 = (w0 * dy - w1 * dx) + slide * u2
        for b in range(3):
            columns[k, b] = fr[0, b] * l0 + fr[1, b] * l1 + fr[2, b] * l2
            columns[k, 3 + b] = fr[0, b] * w0 + fr[1, b] * w1 + fr[2, b] * w2
    for r in range(n):  # L⁻¹ Jᵀ by forward substitution
        inverse = inverse_diagonal[r]
        for c in range(6):
            total = columns[r, c]
            for k in range(r):
                total -= factor[r, k] * columns[k, c]
            columns[r, c] = total * inverse
    for i in range(6):
        for j in range(i, 6):
            total = 0.0
            for r in range(n):
                total += columns[r, i] * columns[r, j]
            a[i, j] = total
            a[j, i] = total


@_jit_inline
def _factor_system(a, spatial, system, pivots):
    """I + Y A (Y = ``spatial``, 6 x 6, Pinocchio's spatial inertia [[m I, -m ĉ], [m ĉ, Ĩ]])
    into ``system``, factorised in place by LU with partial pivoting (row swaps in pivots)."""
    m = spatial[0, 0]
    for j in range(6):  # Y A column by column, from Y's blocks: m I, -m ĉ, m ĉ, Ĩ
        t0, t1, t2, r0, r1, r2 = a[0, j], a[1, j], a[2, j], a[3, j], a[4, j], a[5, j]
        for i in range(3):
            total = m * (t0 if i == 0 else (t1 if i == 1 else t2))
            total += spatial[i, 3] * r0 + spatial[i, 4] * r1 + spatial[i, 5] * r2
            system[i, j] = total
            total = spatial[3 + i, 0] * t0 + spatial[3 + i, 1] * t1 + spatial[3 + i, 2] * t2
            total += spatial[3 + i, 3] * r0 + spatial[3 + i, 4] * r1 + spatial[3 + i, 5] * r2
            system[3 + i, j] = total
        system[j, j] += 1.0
    for k in range(6):
        pivot, largest = k, abs(system[k, k])
        for i in range(k + 1, 6):
            if abs(system[i, k]) > largest:
                pivot, largest = i, abs(system[i, k])
        pivots[k] = pivot
        if pivot != k:
            for j in range(6):
                system[k, j], system[pivot, j] = system[pivot, j], system[k, j]
        inverse = 1.0 / system[k, k]
        system[k, k] = inverse  # the pivot's inverse: the solves multiply
        for i in range(k + 1, 6):
            factor = system[i, k] * inverse
            system[i, k] = factor
            for j in range(k + 1, 6):
                system[i, j] -= factor * system[k, j]


@_jit_inline
def _solve_factored(system, pivots, rhs):
    """Solve with ``_factor_system``'s factors (P C = L U, whole rows swapped), rhs (6,) in
    place: the row swaps in order, then L, then U."""
    for k in range(6):
        pivot = pivots[k]
        if pivot != k:
            rhs[k], rhs[pivot] = rhs[pivot], rhs[k]
    for i in range(1, 6):
        total = rhs[i]
        for k in range(i):
            total -= system[i, k] * rhs[k]
        rhs[i] = total
    for i in range(5, -1, -1):
        total = rhs[i]
        for k in range(i + 1, 6):
            total -= system[i, k] * rhs[k]
        rhs[i] = total * system[i, i]


@_jit
def perturbed_effective_masses(
    chain,
    bodies,
    spatial,
    q_all,
    counts,
    directions,
    worst_slots,
    out,
    worst_mobilities,
    scratch,
    ws,
):
    """For each grasp g (axis 0 of q_all (G, N, nq), counts (G,), directions (G, N, 3) unit,
    base axes, worst_slots (G, N) int64), sample i < counts[g] and inertia p (spatial
    (P, G, 6, 6): Y in grasp g's tip frame, rows [linear; angular]): the effective mass
    1 / (dᵀ W d) [kg] along directions[g, i] into out[p, g, i], W the tip's translational
    mobility [1/kg] of the chain (``bodies``: BodyInertias of one row, without the object)
    with Y added. Where worst_slots[g, i] = s >= 0 (the tip does not translate), W itself (tip
    axes) goes into worst_mobilities[s, p] instead (the caller takes its smallest eigenvalue)
    and out is left untouched. scratch: ((n, 6), (3, 3), (6, 6) floats, (6, 6) floats, (6,)
    int64, (6,) floats); ws: ``ik.workspace(n)``."""
    columns, mobility, a, system, pivots, rhs = scratch
    base_rotation, fr = chain.base_rotation, ws[2]
    inertias = out.shape[0]
    for g in range(q_all.shape[0]):
        for i in range(counts[g]):
            _forward_kinematics(chain, q_all[g, i], ws)
            _tip_operational_mobility(chain, bodies, ws, columns, mobility, a)
            slot = worst_slots[g, i]
            d0, d1, d2 = directions[g, i, 0], directions[g, i, 1], directions[g, i, 2]
            w0 = base_rotation[0, 0] * d0 + base_rotation[0, 1] * d1 + base_rotation[0, 2] * d2
            w1 = base_rotation[1, 0] * d0 + base_rotation[1, 1] * d1 + base_rotation[1, 2] * d2
            w2 = base_rotation[2, 0] * d0 + base_rotation[2, 1] * d1 + base_rotation[2, 2] * d2
            e0 = fr[0, 0] * w0 + fr[1, 0] * w1 + fr[2, 0] * w2  # the direction in tip axes
            e1 = fr[0, 1] * w0 + fr[1, 1] * w1 + fr[2, 1] * w2
            e2 = fr[0, 2] * w0 + fr[1, 2] * w1 + fr[2, 2] * w2
            for p in range(inertias):
                _factor_system(a, spatial[p, g], system, pivots)
                if slot < 0:  # dᵀ A (I + Y A)⁻¹ d = (A d)ᵀ z, (I + Y A) z = d (A symmetric)
                    rhs[0], rhs[1], rhs[2] = e0, e1, e2
                    rhs[3] = rhs[4] = rhs[5] = 0.0
                    _solve_factored(system, pivots, rhs)
                    quadratic = 0.0
                    for k in range(6):
                        quadratic += (a[k, 0] * e0 + a[k, 1] * e1 + a[k, 2] * e2) * rhs[k]
                    out[p, g, i] = 1.0 / quadratic
                    continue
                target = worst_mobilities[slot, p]  # A[:3] (I + Y A)⁻¹[:, :3], symmetrised
                for j in range(3):
                    for k in range(6):
                        rhs[k] = 1.0 if k == j else 0.0
                    _solve_factored(system, pivots, rhs)
                    for r in range(3):
                        total = 0.0
                        for k in range(6):
                            total += a[r, k] * rhs[k]
                        target[r, j] = total
                for r in range(3):
                    for j in range(r + 1, 3):
                        mean = 0.5 * (target[r, j] + target[j, r])
                        target[r, j] = mean
                        target[j, r] = mean
