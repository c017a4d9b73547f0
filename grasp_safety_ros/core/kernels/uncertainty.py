"""Effective masses of a batch of grasps over a set of object inertias, compiled (the
inertia-uncertainty and armature-range analyses, ``method.perturbed``).

Per (grasp, sample) the forward kinematics runs once; per inertia, the ranking's own mass
matrix and Cholesky factor (``effective_mass._mobility_from_frames``) with that inertia merged
into the tip body. Merging the object's spatial inertia Y into the tip body is M + Jᵀ Y J (J the
tip body's Jacobian), whatever else M includes (the chain's armature) is in it, and the nominal
inertia gives the ranking's own effective masses."""

from ._jit import _jit
from .effective_mass import _mobility_from_frames
from .kinematics import _forward_kinematics


@_jit
def perturbed_effective_masses(
    chain, bodies, q_all, counts, directions, worst_slots, out, worst_mobilities, mobility, ws
):
    """For each grasp g (axis 0 of q_all (G, N, nq), counts (G,), directions (G, N, 3) unit,
    base axes, and worst_slots (G, N) int64), sample i < counts[g] and inertia p (row
    p * G + g of ``bodies``, BodyInertias): the effective mass 1 / (dᵀ A d) [kg] along
    directions[g, i] into out[p, g, i], A the tip's translational mobility [1/kg] (base axes).
    Where worst_slots[g, i] = s >= 0 (the tip does not translate), A itself goes into
    worst_mobilities[s, p] instead (the caller takes its smallest eigenvalue) and out is left
    untouched. mobility: (3, 3) scratch; ws: ``ik.workspace(n)``."""
    grasps, inertias = q_all.shape[0], out.shape[0]
    for g in range(grasps):
        for i in range(counts[g]):
            _forward_kinematics(chain, q_all[g, i], ws)
            slot = worst_slots[g, i]
            d0, d1, d2 = directions[g, i, 0], directions[g, i, 1], directions[g, i, 2]
            for p in range(inertias):
                target = mobility if slot < 0 else worst_mobilities[slot, p]
                _mobility_from_frames(chain, bodies, p * grasps + g, ws, target)
                if slot < 0:
                    quadratic = (
                        d0 * (mobility[0, 0] * d0 + mobility[0, 1] * d1 + mobility[0, 2] * d2)
                        + d1 * (mobility[1, 0] * d0 + mobility[1, 1] * d1 + mobility[1, 2] * d2)
                        + d2 * (mobility[2, 0] * d0 + mobility[2, 1] * d1 + mobility[2, 2] * d2)
                    )
                    out[p, g, i] = 1.0 / quadratic
