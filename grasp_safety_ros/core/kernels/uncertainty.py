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
def _perturbed_mobility(a, spatial, system, solved, out):
    """The translational block (3 x 3, tip axes) of A (I + Y A)⁻¹ for Y = ``spatial`` (6 x 6):
    (I + Y A) Z = [e0 e1 e2] by LU with partial pivoting (system, solved: (6, 6), (6, 3)
    scratch), then A[:3] Z, symmetrised."""
    for i in range(6):
        for j in range(6):
            total = 1.0 if i == j else 0.0
            for k in range(6):
                total += spatial[i, k] * a[k, j]
            system[i, j] = total
        for j in range(3):
            solved[i, j] = 1.0 if i == j else 0.0
    for k in range(6):
        pivot, largest = k, abs(system[k, k])
        for i in range(k + 1, 6):
            if abs(system[i, k]) > largest:
                pivot, largest = i, abs(system[i, k])
        if pivot != k:
            for j in range(6):
                system[k, j], system[pivot, j] = system[pivot, j], system[k, j]
            for j in range(3):
                solved[k, j], solved[pivot, j] = solved[pivot, j], solved[k, j]
        inverse = 1.0 / system[k, k]
        for i in range(k + 1, 6):
            factor = system[i, k] * inverse
            for j in range(k + 1, 6):
                system[i, j] -= factor * system[k, j]
            for j in range(3):
                solved[i, j] -= factor * solved[k, j]
    for j in range(3):
        for i in range(5, -1, -1):
            total = solved[i, j]
            for k in range(i + 1, 6):
                total -= system[i, k] * solved[k, j]
            solved[i, j] = total / system[i, i]
    for i in range(3):
        for j in range(3):
            total = 0.0
            for k in range(6):
                total += a[i, k] * solved[k, j]
            out[i, j] = total
    for i in range(3):
        for j in range(i + 1, 3):
            mean = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = mean
            out[j, i] = mean


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
    and out is left untouched. scratch: ((n, 6), (3, 3), (6, 6), (6, 6), (6, 3), (3,));
    ws: ``ik.workspace(n)``."""
    columns, mobility, a, system, solved, local = scratch
    base_rotation, fr = chain.base_rotation, ws[2]
    inertias = out.shape[0]
    for g in range(q_all.shape[0]):
        for i in range(counts[g]):
            _forward_kinematics(chain, q_all[g, i], ws)
            _tip_operational_mobility(chain, bodies, ws, columns, mobility, a)
            slot = worst_slots[g, i]
            d0, d1, d2 = directions[g, i, 0], directions[g, i, 1], directions[g, i, 2]
            for b in range(3):  # the direction in tip axes: frᵀ (base rotation) d
                world = base_rotation[b, 0] * d0 + base_rotation[b, 1] * d1
                local[b] = world + base_rotation[b, 2] * d2
            e0 = fr[0, 0] * local[0] + fr[1, 0] * local[1] + fr[2, 0] * local[2]
            e1 = fr[0, 1] * local[0] + fr[1, 1] * local[1] + fr[2, 1] * local[2]
            e2 = fr[0, 2] * local[0] + fr[1, 2] * local[1] + fr[2, 2] * local[2]
            for p in range(inertias):
                target = mobility if slot < 0 else worst_mobilities[slot, p]
                _perturbed_mobility(a, spatial[p, g], system, solved, target)
                if slot < 0:
                    quadratic = (
                        e0 * (mobility[0, 0] * e0 + mobility[0, 1] * e1 + mobility[0, 2] * e2)
                        + e1 * (mobility[1, 0] * e0 + mobility[1, 1] * e1 + mobility[1, 2] * e2)
                        + e2 * (mobility[2, 0] * e0 + mobility[2, 1] * e1 + mobility[2, 2] * e2)
                    )
                    out[p, g, i] = 1.0 / quadratic
