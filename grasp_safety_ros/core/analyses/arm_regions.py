"""ISO/TS 15066 transient contact of each body region with the sites of the arm
(core.analyses.iso15066, Annex A): per region, the force ratio F/F_tr = v·sqrt(μ k)/F_tr at
every (sample, site), the worst over both and where it occurs, admissibility, and
T_min = T · worst ratio (``whole_arm`` computes the site speeds and masses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .body_regions import BodyRegion
from .iso15066 import ADMISSIBLE_RATIO_TOLERANCE


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
    compiled: bool = False,
) -> list[tuple[WholeArmRegion, ...]]:
    """``assess_sites`` of G motions at once: (G, N, K) speeds [m/s] and masses [kg] (rows a
    motion does not have: speed 0), (G,) durations [s]; the same numbers, one array pass per
    region over every motion, or with ``compiled`` (numba installed) the peaks by
    ``method.points.region_peaks``, the same bits without evaluating most forces."""
    grasps, _, count_sites = speed_m_s.shape
    if compiled and speed_m_s.size:
        from ..method.points import region_peaks

        human_inverse = np.array([1.0 / r.effective_mass_kg for r in regions])  # inf: 0
        springs = np.array([r.spring_constant_n_per_m for r in regions])
        where, peak = region_peaks(speed_m_s, effective_mass_kg, human_inverse, springs)
    else:
        where, peak = _region_peaks(speed_m_s, effective_mass_kg, regions)
    moving = np.zeros(where.shape, dtype=bool)  # the site at each peak moves
    if speed_m_s.size:
        moving = np.take_along_axis(speed_m_s.reshape(grasps, -1), where, axis=1) > 0.0
    columns = []
    for r, region in enumerate(regions):
        if region.max_transient_force_n is None:  # inf wherever a site moves
            worst = np.where(moving[:, r], np.inf, 0.0)
        else:
            worst = peak[:, r] / region.max_transient_force_n
        columns.append((where[:, r].tolist(), worst.tolist(), peak[:, r].tolist()))
    named = [(r.name, r.transient_contact_permitted) for r in regions]
    results = []
    for g in range(grasps):
        assessed = []
        for (name, permitted), (where_list, worst_list, peak_list) in zip(
            named, columns, strict=True
        ):
            sample, site = divmod(where_list[g], count_sites) if count_sites else (0, 0)
            worst = worst_list[g]
            assessed.append(
                WholeArmRegion(
                    name,
                    permitted,
                    worst,
                    site,
                    sample,
                    peak_list[g],
                    worst <= 1.0 + ADMISSIBLE_RATIO_TOLERANCE,
                    durations_s[g] * worst if worst > 0.0 else 0.0,
                )
            )
        results.append(tuple(assessed))
    return results


def _region_peaks(
    speed_m_s: np.ndarray, effective_mass_kg: np.ndarray, regions: Sequence[BodyRegion]
) -> tuple[np.ndarray, np.ndarray]:
    """For (G, N, K) speeds and masses: each region's first largest force F = v sqrt(μ k)
    (0 where not v > 0), its flat index into (N, K) and value, both (G, R), in numpy."""
    grasps = speed_m_s.shape[0]
    speeds = speed_m_s.reshape(grasps, -1)
    masses = effective_mass_kg.reshape(grasps, -1)
    still = ~(speeds > 0.0)
    rows = np.arange(grasps)
    with np.errstate(divide="ignore"):
        inverse_masses = 1.0 / masses
    force = np.empty_like(speeds)  # one buffer for every region (no temporaries per region)
    where = np.zeros((grasps, len(regions)), dtype=np.int64)
    peak = np.zeros((grasps, len(regions)))
    if not force.shape[1]:
        return where, peak
    for r, region in enumerate(regions):
        # transient_contact_force_n's operations in place: F = v sqrt(k / (1/m_h + 1/m_r))
        with np.errstate(divide="ignore", invalid="ignore"):  # m_h = m_r = inf: μ = inf
            np.add(1.0 / region.effective_mass_kg, inverse_masses, out=force)
            np.divide(1.0, force, out=force)
            np.multiply(force, region.spring_constant_n_per_m, out=force)
            np.sqrt(force, out=force)
            np.multiply(speeds, force, out=force)
        np.copyto(force, 0.0, where=still)  # a site at rest: no force (not 0·inf)
        where[:, r] = np.argmax(force, axis=1)
        peak[:, r] = force[rows, where[:, r]]
    return where, peak
