"""ISO/TS 15066 transient contact of each body region with the sites of the arm
(core.analyses.iso15066, Annex A): per region, the force ratio F/F_tr = v·sqrt(μ k)/F_tr at
every (sample, site), the worst over both and where it occurs, admissibility, and
T_min = T · worst ratio (``whole_arm`` computes the site speeds and masses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .iso15066 import ADMISSIBLE_RATIO_TOLERANCE, BodyRegion, transient_contact_force_n


@dataclass(frozen=True)
class WholeArmRegion:
    """ISO/TS 15066 transient contact of one body region with any site of the arm.

    Attributes:
        region: Region name.
        transient_contact_permitted: False where the TS permits none (ratio inf when moving).
        worst_force_ratio: max over samples and sites of F/F_tr (0 when nothing moves).
        worst_site, worst_sample: Where the peak force occurs (first on ties, sample-major):
            its site's speed and mass there give peak_contact_force_n.
        peak_contact_force_n: max over samples and sites of F = v·sqrt(μ k) [N].
        admissible: worst_force_ratio <= 1 (+ ADMISSIBLE_RATIO_TOLERANCE).
        min_duration_s: T · worst_force_ratio [s] (0 when nothing moves).
    """

    region: str
    transient_contact_permitted: bool
    worst_force_ratio: float
    worst_site: int
    worst_sample: int
    peak_contact_force_n: float
    admissible: bool
    min_duration_s: float


def assess_sites(
    speed_m_s: np.ndarray,
    effective_mass_kg: np.ndarray,
    duration_s: float,
    regions: Sequence[BodyRegion],
) -> tuple[WholeArmRegion, ...]:
    """Each region's worst case over (N, K) site speeds [m/s] and effective masses [kg]."""
    speeds = np.asarray(speed_m_s, dtype=float)
    masses = np.asarray(effective_mass_kg, dtype=float)
    return assess_sites_batch(speeds[None], masses[None], [duration_s], regions)[0]


def assess_sites_batch(
    speed_m_s: np.ndarray,
    effective_mass_kg: np.ndarray,
    durations_s: Sequence[float],
    regions: Sequence[BodyRegion],
) -> list[tuple[WholeArmRegion, ...]]:
    """``assess_sites`` of G motions at once: (G, N, K) speeds [m/s] and masses [kg] (rows a
    motion does not have: speed 0), (G,) durations [s]; the same numbers, one array pass per
    region over every motion."""
    grasps, _, count_sites = speed_m_s.shape
    speeds = speed_m_s.reshape(grasps, -1)
    masses = effective_mass_kg.reshape(grasps, -1)
    moving = speeds > 0.0
    columns = []
    for region in regions:
        with np.errstate(divide="ignore", invalid="ignore"):  # m_h = m_r = inf: μ = inf
            force = transient_contact_force_n(speeds, masses, region)
        force = np.where(moving, force, 0.0)  # a site at rest: no force (not 0·inf)
        if region.max_transient_force_n is None:
            ratio = np.where(moving, np.inf, 0.0)
        else:
            ratio = force / region.max_transient_force_n
        if ratio.shape[1]:  # at the peak force: F/F_tr's maximum, or inf wherever moving
            where = np.argmax(force, axis=1)
            rows = np.arange(grasps)
            worst, peak = ratio[rows, where], force[rows, where]
        else:
            where, worst, peak = np.zeros(grasps, dtype=int), np.zeros(grasps), np.zeros(grasps)
        columns.append((where.tolist(), worst.tolist(), peak.tolist()))
    results = []
    for g in range(grasps):
        assessed = []
        for region, (where, worst_list, peak_list) in zip(regions, columns, strict=True):
            sample, site = divmod(where[g], count_sites) if count_sites else (0, 0)
            worst = worst_list[g]
            assessed.append(
                WholeArmRegion(
                    region=region.name,
                    transient_contact_permitted=region.transient_contact_permitted,
                    worst_force_ratio=worst,
                    worst_site=int(site),
                    worst_sample=int(sample),
                    peak_contact_force_n=peak_list[g],
                    admissible=worst <= 1.0 + ADMISSIBLE_RATIO_TOLERANCE,
                    min_duration_s=durations_s[g] * worst if worst > 0.0 else 0.0,
                )
            )
        results.append(tuple(assessed))
    return results
