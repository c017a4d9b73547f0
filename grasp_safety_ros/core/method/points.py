"""Effective masses at points of the moving chain over (grasp, sample, point), on the shared
terms (``terms.SampleTerms``) by the compiled kernels ``kernels.points``: points fixed to the
tip (``analyses.exposed_points``) and sites fixed to the links (``analyses.whole_arm``); the
tip twists and tip-following joint rates, and the whole arm's ISO/TS 15066 peaks.

A point's translational mobility is A = J_p M⁻¹ J_pᵀ [1/kg] (M of the augmented chain, as the
ranking's); its effective mass along a unit direction u is 1 / (uᵀ A u) [kg]. Where a point
has no direction (it does not move), its A is handed back for the analysis to take the
direction of largest effective mass (an eigen-decomposition, as on the Pinocchio path).
"""

from __future__ import annotations

from concurrent.futures import Executor

import numpy as np

from ..model.trajectory import ObjectMotion
from .compiled import call_kernel, plain_array
from .pool import split_grasps
from .terms import SampleTerms, _block, kept_elements, sample_elements


def valid_rows(counts: np.ndarray, samples: int) -> np.ndarray:
    """(G, samples) True for each grasp's first counts[g] samples."""
    return np.arange(samples)[None, :] < np.asarray(counts)[:, None]


def tip_point_masses(
    terms: SampleTerms,
    counts: np.ndarray,
    base_rotation: np.ndarray,
    points_in_tip_m: np.ndarray,
    directions_in_base: np.ndarray,
    stationary: np.ndarray,
    motion_of: np.ndarray,
    executor: Executor | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Effective masses of K points fixed to the tip of G grasps, per sample.

    Args:
        terms, counts: The grasps' terms (axis 0 the grasp, N rows) and sample counts (G,):
            the tip's rotations and 6x6 mobility are read, so they must have been computed
            with the optional ``mobilities_tip_in_base`` (``terms.OPTIONAL_TERMS``).
        base_rotation: (3, 3) the base frame's rotation in the world frame.
        points_in_tip_m: (G, K, 3) the points in each grasp's tip frame [m].
        directions_in_base: (M, N, K, 3) unit directions of the points per motion, base axes.
        stationary: (M, N, K) True where a point has no direction (then ignored).
        motion_of: (G,) the motion (axis 0 of the two above) of each grasp.
        executor: A thread pool whose threads and the caller each run the kernel on a range
            of the grasps (``pool.split_grasps``; the same bits); None: one call here.

    Returns:
        masses (G, N, K) [kg] (undefined where stationary and in rows beyond a grasp's
        count), the mask (G, N, K) of stationary entries in valid rows, and their mobilities
        (S, 3, 3) [1/kg], base axes, in the mask's (C) order.
    """
    from ..kernels.points import tip_point_masses as kernel

    grasps, samples = terms.jacobians_tip_in_world.shape[:2]
    motion_of = np.ascontiguousarray(motion_of, dtype=np.int64)
    still = np.ascontiguousarray(stationary, dtype=bool)
    mask = still[motion_of, :samples] & valid_rows(counts, samples)[..., None]
    mobilities = np.empty((int(mask.sum()), 3, 3))
    masses = np.empty((grasps, samples, points_in_tip_m.shape[1]))
    fields = plain_array(terms.mobilities_tip_in_base), plain_array(terms.rotations_tip_to_world)
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    base_rotation, points = plain_array(base_rotation), plain_array(points_in_tip_m)
    directions = plain_array(directions_in_base)
    rows = np.concatenate(([0], np.cumsum(mask.sum(axis=(1, 2)))))  # first mobility per grasp

    def run(start: int, stop: int) -> None:
        call_kernel(
            kernel,
            *(array[start:stop] for array in fields),
            counts[start:stop],
            base_rotation,
            points[start:stop],
            directions,
            still,
            motion_of[start:stop],
            masses[start:stop],
            mobilities[rows[start] : rows[stop]],
            np.empty((3, 3)),
            np.empty((3, 6)),
        )

    split_grasps(executor, grasps, run)
    return masses, mask, mobilities


SHARED_BODY_SITES = 4
"""Sites on one body from which they share its 6 x 6 mobility per sample
(``arm_site_exposure``): forming it costs about as much as this many sites computed alone."""


def _joint_terms(terms: SampleTerms) -> tuple[np.ndarray, ...]:
    """The joint frames, motion subspaces and M⁻¹ of ``terms``, as the site kernels read them
    (``arm_site_exposure``, ``site_mobilities``)."""
    return tuple(
        plain_array(array)
        for array in (
            terms.rotations_joint_to_world,
            terms.translations_joint_in_world,
            terms.motions_joint_in_world,
            terms.mass_matrix_inverses,
        )
    )


def _shared_bodies(site_joints: np.ndarray, support: np.ndarray) -> tuple[np.ndarray, ...]:
    """(K,) each site's shared body (-1: computed alone), the shared bodies' chain joints (B,)
    and their supports (B, n): the bodies carrying at least SHARED_BODY_SITES sites."""
    joints, first, count = np.unique(site_joints, return_index=True, return_counts=True)
    shared = count >= SHARED_BODY_SITES
    site_body = np.full(len(site_joints), -1, dtype=np.int64)
    for b, joint in enumerate(joints[shared]):
        site_body[site_joints == joint] = b
    return site_body, joints[shared].astype(np.int64), np.asarray(support, bool)[first[shared]]


def _last_columns(support: np.ndarray) -> np.ndarray:
    """(K,) one past the last joint that moves each site (its Jacobian's columns from there
    on are 0: a serial chain's site near the base has fewer terms)."""
    support = np.asarray(support, bool)
    last = support.shape[1] - np.argmax(support[:, ::-1], axis=1)
    return np.where(support.any(axis=1), last, 0).astype(np.int64)


def _exposure_buffers(grasps: int, samples: int, count: int, n: int) -> list[np.ndarray]:
    """Uninitialised (G, N, K, 3) positions and directions, (G, N, K) speeds, masses and
    energies and a (G, N, K) bool mask: views of one block of earlier terms or results no
    array refers to any longer (``terms._block``: fresh pages cost as much to touch as the
    kernel that fills them; the kept blocks may hold an n-joint chain's terms and as much
    again for these: more sites than that share take fresh arrays, not kept memory), else new
    arrays."""
    shape = (grasps, samples, count)
    size = grasps * samples * count
    per_sample = min(9 * count + count // 8 + 1, sample_elements(n))
    block = _block(9 * size + (size + 7) // 8, kept_elements(n, per_sample))
    if block is None:
        vectors = [np.empty((*shape, 3)) for _ in range(2)]
        scalars = [np.empty(shape) for _ in range(3)]
        return [*vectors, *scalars, np.empty(shape, dtype=bool)]
    return [
        block[: 3 * size].reshape(*shape, 3),
        block[3 * size : 6 * size].reshape(*shape, 3),
        *(block[start * size : (start + 1) * size].reshape(shape) for start in (6, 7, 8)),
        block[9 * size :].view(np.bool_)[:size].reshape(shape),
    ]


def arm_site_exposure(
    terms: SampleTerms,
    counts: np.ndarray,
    transform_base_to_world: tuple[np.ndarray, np.ndarray],
    site_joints: np.ndarray,
    points_in_joint_m: np.ndarray,
    support: np.ndarray,
    joint_velocities: np.ndarray,
    stationary_speed_m_s: float,
) -> tuple[np.ndarray, ...]:
    """Positions (G, N, K, 3) [m] (base frame), unit velocities (G, N, K, 3) (base axes),
    speeds (G, N, K) [m/s], effective masses along the velocity (G, N, K) [kg], energies
    ½ M_eff v² (G, N, K) [J] and the stationary mask (G, N, K) of K sites fixed to the
    links; sites on a body carrying SHARED_BODY_SITES or more share its mobility
    (``kernels.points.arm_site_exposure``).

    Args:
        terms, counts: The grasps' terms (axis 0 the grasp, N rows) and sample counts (G,):
            the joints' frames, motion subspaces and M⁻¹ are read, so they must have been
            computed with the optional ``mass_matrix_inverses`` (``terms.OPTIONAL_TERMS``).
        transform_base_to_world: (rotation (3, 3), translation (3,) [m]) of the base frame.
        site_joints: (K,) the chain joint (0-based) whose frame carries each site.
        points_in_joint_m: (K, 3) the sites in those frames [m].
        support: (K, n) True where chain joint c moves the site's body.
        joint_velocities: (G, N, n) q̇ [rad/s or m/s].
        stationary_speed_m_s: Below this speed a site is stationary: speed and energy 0,
            direction and mass undefined (``site_mobilities`` gives what they come from).
    Rows beyond a grasp's count: speed 0, mass 1, not stationary, the rest undefined.
    """
    from ..kernels.points import arm_site_exposure as kernel

    grasps, samples = terms.jacobians_tip_in_world.shape[:2]
    joints = np.ascontiguousarray(site_joints, dtype=np.int64)
    count, n = len(joints), terms.mass_matrix_inverses.shape[-1]
    site_body, body_joints, body_support = _shared_bodies(joints, support)
    outputs = _exposure_buffers(grasps, samples, count, n)
    rotation, translation = transform_base_to_world
    call_kernel(
        kernel,
        *_joint_terms(terms),
        np.ascontiguousarray(counts, dtype=np.int64),
        plain_array(rotation),
        plain_array(translation),
        joints,
        plain_array(points_in_joint_m),
        plain_array(support, bool),  # ArmSites.support is frozen
        _last_columns(support),
        site_body,
        body_joints,
        plain_array(body_support, bool),
        plain_array(joint_velocities),
        float(stationary_speed_m_s),
        *outputs,
        np.empty((3, n)),
        np.empty(n),
        np.empty((n, 6)),
        np.empty((n, 6)),
        np.empty((len(body_joints), 6, 6)),
        np.empty((len(body_joints), 6)),
    )
    return tuple(outputs)


def site_mobilities(
    terms: SampleTerms,
    site_joints: np.ndarray,
    points_in_joint_m: np.ndarray,
    support: np.ndarray,
    at: np.ndarray,
) -> np.ndarray:
    """Translational mobilities J_p M⁻¹ J_pᵀ (S, 3, 3) [1/kg], world axes, of the sites (as
    ``arm_site_exposure``'s) at the rows (g, i, k) of ``at`` (S, 3): grasp, sample, site."""
    from ..kernels.points import site_mobilities as kernel

    at = np.ascontiguousarray(at, dtype=np.int64).reshape(-1, 3)
    out = np.empty((len(at), 3, 3))
    call_kernel(
        kernel,
        *_joint_terms(terms),
        np.ascontiguousarray(site_joints, dtype=np.int64),
        plain_array(points_in_joint_m),
        plain_array(support, bool),
        at,
        out,
        np.empty((3, terms.mass_matrix_inverses.shape[-1])),
    )
    return out


def region_peaks(
    speed_m_s: np.ndarray,
    effective_mass_kg: np.ndarray,
    inverse_human_masses_per_kg: np.ndarray,
    springs_n_per_m: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """For G motions' (G, N, K) site speeds [m/s] and masses [kg] and R body regions (1/m_h
    [1/kg], k [N/m]): the flat index (G, R) into (N, K) of the first largest ISO/TS 15066
    transient force F = v sqrt(k / (1/m_h + 1/m)) (0 where not v > 0) and that force (G, R)
    [N], numpy's arithmetic and ``argmax`` bit for bit, most forces not evaluated
    (``kernels.regions.region_peaks``)."""
    from ..kernels.regions import region_peaks as kernel

    grasps, samples, sites = speed_m_s.shape
    regions = len(inverse_human_masses_per_kg)
    where = np.zeros((grasps, regions), dtype=np.int64)
    peak = np.zeros((grasps, regions))
    call_kernel(
        kernel,
        plain_array(speed_m_s).reshape(grasps, -1),
        plain_array(effective_mass_kg).reshape(grasps, -1),
        sites,
        plain_array(inverse_human_masses_per_kg),
        plain_array(springs_n_per_m),
        where,
        peak,
        np.empty(samples),
        np.empty(samples),
        np.empty(samples),
        np.empty(samples, dtype=np.int64),
        np.empty(samples * sites),
        np.empty(samples * sites),
    )
    return where, peak


def tip_twists_into(
    motion: ObjectMotion,
    tips_in_object_m: np.ndarray,
    base_rotation: np.ndarray,
    rows: list[int],
    out: np.ndarray,
) -> None:
    """The tip twists (linear [m/s], angular [rad/s]), world axes, of the grasps ``rows`` of
    ``out`` (G, N_max, 6), their tip origins at ``tips_in_object_m`` (len(rows), 3) [m,
    object frame], on one sampled object motion (N samples, into out[g, :N]); each grasp's
    numbers whatever the others (``kernels.points.tip_twists``)."""
    from ..kernels.points import tip_twists as kernel

    call_kernel(
        kernel,
        plain_array(motion.rotations),
        plain_array(motion.linear_tangents),
        plain_array(motion.angular_tangents),
        plain_array(motion.speed_per_tangent),
        plain_array(tips_in_object_m),
        plain_array(base_rotation),
        np.array(rows, dtype=np.int64),
        out,
    )


PSEUDO_INVERSE_RCOND = 1e-10
"""Singular values below this times the largest are dropped by the pseudo-inverse of the tip
Jacobian (numpy's ``pinv`` ``rcond``), as on the Pinocchio path."""

QR_RANK_TOLERANCE = 1e-3
"""The compiled minimum-norm solve is used where every diagonal entry of R (Jᵀ = Q R) exceeds
this times the largest (J well conditioned, where it equals the pseudo-inverse's answer to
rounding); elsewhere the pseudo-inverse itself."""


def tip_following_rates(
    tip_jacobians: np.ndarray,
    counts: np.ndarray,
    twists_in_world: np.ndarray,
    spline_rates: np.ndarray,
) -> np.ndarray:
    """q̇ (G, N, n) = q̇_s + J⁺ (ξ − J q̇_s) [rad/s or m/s] of G grasps' samples (rows beyond
    a grasp's count: 0): compiled (a Householder QR of Jᵀ) where J is well conditioned, the
    pseudo-inverse (``PSEUDO_INVERSE_RCOND``) elsewhere.

    Args:
        tip_jacobians: (G, N, 6, n) SampleTerms.jacobians_tip_in_world (world axes at the tip).
        counts: (G,) samples per grasp.
        twists_in_world: (G, N, 6) tip twists ξ (linear [m/s], angular [rad/s]), world axes.
        spline_rates: (G, N, n) q̇_s, the self-motion's rates.
    """
    from ..kernels.points import tip_following_rates as kernel

    grasps, samples, _, n = tip_jacobians.shape
    rates = np.zeros((grasps, samples, n))
    fallback = np.zeros((grasps, samples), dtype=bool)
    jacobians, twists, base = (
        plain_array(a) for a in (tip_jacobians, twists_in_world, spline_rates)
    )
    call_kernel(
        kernel,
        jacobians,
        np.ascontiguousarray(counts, dtype=np.int64),
        twists,
        base,
        QR_RANK_TOLERANCE,
        rates,
        fallback,
        np.empty((n, 6)),
        np.empty(6),
        np.empty(6),
        np.empty(n),
        np.empty(6),
    )
    if fallback.any():
        jacobian, twist, rate = jacobians[fallback], twists[fallback], base[fallback]
        pseudo_inverse = np.linalg.pinv(jacobian, rcond=PSEUDO_INVERSE_RCOND)
        residual = twist - (jacobian @ rate[..., None])[..., 0]
        rates[fallback] = rate + (pseudo_inverse @ residual[..., None])[..., 0]
    return rates
