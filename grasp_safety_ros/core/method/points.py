"""Effective masses at points of the moving chain over (grasp, sample, point), on the shared
terms (``terms.SampleTerms``) by the compiled kernels ``kernels.points``: points fixed to the
tip (``analyses.exposed_points``) and sites fixed to the links (``analyses.whole_arm``).

A point's translational mobility is A = J_p M⁻¹ J_pᵀ [1/kg] (M of the augmented chain, as the
ranking's); its effective mass along a unit direction u is 1 / (uᵀ A u) [kg]. Where a point
has no direction (it does not move), its A is handed back for the analysis to take the
direction of largest effective mass (an eigen-decomposition, as on the Pinocchio path).
"""

from __future__ import annotations

import numpy as np

from .compiled import call_kernel, plain_array
from .terms import SampleTerms


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
    call_kernel(
        kernel,
        plain_array(terms.mobilities_tip_in_base),
        plain_array(terms.rotations_tip_to_world),
        np.ascontiguousarray(counts, dtype=np.int64),
        plain_array(base_rotation),
        plain_array(points_in_tip_m),
        plain_array(directions_in_base),
        still,
        motion_of,
        masses,
        mobilities,
        np.empty((3, 3)),
        np.empty((3, 6)),
    )
    return masses, mask, mobilities


def site_masses(
    terms: SampleTerms,
    counts: np.ndarray,
    site_joints: np.ndarray,
    points_in_joint_m: np.ndarray,
    support: np.ndarray,
    joint_velocities: np.ndarray,
    stationary_speed_m_s: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """World positions (G, N, K, 3) [m], velocities (G, N, K, 3) [m/s], speeds (G, N, K) and
    effective masses along the velocity (G, N, K) [kg] of K sites fixed to the links.

    Args:
        terms, counts: The grasps' terms (axis 0 the grasp, N rows) and sample counts (G,):
            the joints' frames, motion subspaces and M⁻¹ are read, so they must have been
            computed with the optional ``mass_matrix_inverses`` (``terms.OPTIONAL_TERMS``).
        site_joints: (K,) the chain joint (0-based) whose frame carries each site.
        points_in_joint_m: (K, 3) the sites in those frames [m].
        support: (K, n) True where chain joint c moves the site's body.
        joint_velocities: (G, N, n) q̇ [rad/s or m/s].
        stationary_speed_m_s: Below this speed a site has no direction: its mass is left
            undefined (as in rows beyond a grasp's count).
    """
    from ..kernels.points import site_masses as kernel

    grasps, samples = terms.jacobians_tip_in_world.shape[:2]
    count, n = len(site_joints), terms.mass_matrix_inverses.shape[-1]
    positions = np.empty((grasps, samples, count, 3))
    velocities = np.empty((grasps, samples, count, 3))
    speeds = np.empty((grasps, samples, count))
    masses = np.empty((grasps, samples, count))
    call_kernel(
        kernel,
        plain_array(terms.rotations_joint_to_world),
        plain_array(terms.translations_joint_in_world),
        plain_array(terms.motions_joint_in_world),
        plain_array(terms.mass_matrix_inverses),
        np.ascontiguousarray(counts, dtype=np.int64),
        np.ascontiguousarray(site_joints, dtype=np.int64),
        plain_array(points_in_joint_m),
        plain_array(support, bool),  # ArmSites.support is frozen
        plain_array(joint_velocities),
        float(stationary_speed_m_s),
        positions,
        velocities,
        speeds,
        masses,
        np.empty((3, n)),
        np.empty(n),
    )
    return positions, velocities, speeds, masses


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
    )
    if fallback.any():
        jacobian, twist, rate = jacobians[fallback], twists[fallback], base[fallback]
        pseudo_inverse = np.linalg.pinv(jacobian, rcond=PSEUDO_INVERSE_RCOND)
        residual = twist - (jacobian @ rate[..., None])[..., 0]
        rates[fallback] = rate + (pseudo_inverse @ residual[..., None])[..., 0]
    return rates
