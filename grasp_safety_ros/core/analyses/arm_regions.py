"""ISO/TS 15066 transient contact of each body region with the sites of the arm
(core.analyses.iso15066, Annex A): per region, the force ratio F/F_tr = v·sqrt(μ k)/F_tr at
every (sample, site), the worst over both and where it occurs, admissibility, and
T_min = T · worst ratio (``whole_arm`` computes the site speeds and masses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .iso15066 import ADMISSIBLE_RATIO_TOLERANCE, BodyRegion


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
    still = ~(speeds > 0.0)
    rows = np.arange(grasps)
    with np.errstate(divide="ignore"):
        inverse_masses = 1.0 / masses
    force = np.empty_like(speeds)  # one buffer for every region (no temporaries per region)
    columns = []
    for region in regions:
        # transient_contact_force_n's operations in place: F = v sqrt(k / (1/m_h + 1/m_r))
        with np.errstate(divide="ignore", invalid="ignore"):  # m_h = m_r = inf: μ = inf
            np.add(1.0 / region.effective_mass_kg, inverse_masses, out=force)
            np.divide(1.0, force, out=force)
            np.multiply(force, region.spring_constant_n_per_m, out=force)
            np.sqrt(force, out=force)
            np.multiply(speeds, force, out=force)
        np.copyto(force, 0.0, where=still)  # a site at rest: no force (not 0·inf)
        if force.shape[1]:  # at the peak force: F/F_tr's maximum, or inf wherever moving
            where = np.argmax(force, axis=1)
            peak = force[rows, where]
            if region.max_transient_force_n is None:
                worst = np.where(still[rows, where], 0.0, np.inf)
            else:
                worst = peak / region.max_transient_force_n
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
