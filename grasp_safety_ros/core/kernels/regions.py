"""The whole arm's ISO/TS 15066 worst case per body region, compiled: numpy's forces and
``argmax`` over every (sample, site) of ``analyses.arm_regions.assess_sites_batch``, bit for
bit, most forces not evaluated (``region_peaks``)."""

import math

from ._jit import _jit_exact

PRUNE_MARGIN = 1e-9
"""Relative margin of ``region_peaks``' pruning: far above the few roundings of its bounds."""
NORMAL_LOW, NORMAL_HIGH = 1e-100, 1e100
"""The range of a speed, mass, 1/m_h, spring constant and first force within which the
pruning bounds neither underflow nor overflow (a product of three stays in 1e±300)."""


@_jit_exact
def region_peaks(
    speeds,
    masses,
    sites,
    human_inverse,
    springs,
    where,
    peak,
    bounds,
    sample_speeds,
    sample_energies,
    kind,
    site_speeds,
    site_energies,
):
    """numpy's ``arm_regions.assess_sites_batch`` forces and their first maximum, bit for bit,
    without evaluating most of them: for motion g and region r, over the entries e = i K + k
    (sample i, site k; K = ``sites``) of speeds[g] and masses[g], F = v sqrt(k / (c + 1/m))
    (c = human_inverse[r] = 1/m_h, k = springs[r], the same operations in the same order;
    0 where not v > 0): where[g, r] the first e of the largest F (or of the first NaN, as
    numpy's argmax) and peak[g, r] that F.

    F² = k / (c a + b) with a = 1/v² and b = 1/(m v²), per entry (``site_speeds``,
    ``site_energies``) and their minima per sample (a bound of the sample's F²). With L the
    largest F of the sample of the largest bound, a sample, then an entry, whose bound is
    below L² by more than PRUNE_MARGIN (the bounds' and F's roundings are a few 1e-16) has
    no F >= L and is not evaluated. Samples where a moving site's speed or mass is outside
    [NORMAL_LOW, NORMAL_HIGH] (the mass may be inf; NaN, 0 and negative are outside) are
    evaluated whole, and everything is where L, 1/m_h (unless 0) or k is outside it (no
    underflow or overflow in the bounds); should every entry still be pruned, the pass is
    made again without pruning.
    bounds, sample_speeds, sample_energies (N,), kind (N,) int64 (0: no site moves,
    1: bounded, 2: evaluated), site_speeds, site_energies (N K,): scratch."""
    samples = speeds.shape[1] // sites if sites > 0 else 0
    for g in range(speeds.shape[0]):
        for i in range(samples):
            smallest_a, smallest_b, state = math.inf, math.inf, 0
            for k in range(sites):
                e = i * sites + k
                v = speeds[g, e]
                if v > 0.0:
                    m = masses[g, e]
                    normal = NORMAL_LOW <= v <= NORMAL_HIGH and (
                        NORMAL_LOW <= m <= NORMAL_HIGH or m == math.inf
                    )
                    state = max(state, 1 if normal else 2)
                    site_speeds[e] = 1.0 / (v * v)
                    site_energies[e] = 1.0 / (m * v * v)
                    smallest_a = min(smallest_a, site_speeds[e])
                    smallest_b = min(smallest_b, site_energies[e])
            sample_speeds[i], sample_energies[i], kind[i] = smallest_a, smallest_b, state
        for r in range(human_inverse.shape[0]):
            c, spring = human_inverse[r], springs[r]
            first, smallest = -1, math.inf
            for i in range(samples):
                bounds[i] = c * sample_speeds[i] + sample_energies[i]
                if kind[i] == 1 and bounds[i] < smallest:
                    first, smallest = i, bounds[i]
            low = -1.0
            for k in range(sites if first >= 0 else 0):
                e = first * sites + k
                if speeds[g, e] > 0.0:
                    force = speeds[g, e] * math.sqrt(spring * (1.0 / (c + 1.0 / masses[g, e])))
                    low = max(low, force)
            prune = (
                NORMAL_LOW <= low <= NORMAL_HIGH
                and (c == 0.0 or NORMAL_LOW <= c <= NORMAL_HIGH)
                and NORMAL_LOW <= spring <= NORMAL_HIGH
            )
            at, top = _peak(
                speeds,
                masses,
                sites,
                g,
                c,
                spring,
                low,
                prune,
                bounds,
                kind,
                site_speeds,
                site_energies,
            )
            if prune and top < 0.0:  # every entry pruned: a bound was wrong, evaluate all
                at, top = _peak(
                    speeds,
                    masses,
                    sites,
                    g,
                    c,
                    spring,
                    low,
                    False,
                    bounds,
                    kind,
                    site_speeds,
                    site_energies,
                )
            where[g, r], peak[g, r] = at, top


@_jit_exact
def _peak(
    speeds, masses, sites, g, c, spring, low, prune, bounds, kind, site_speeds, site_energies
):
    """(first entry, force) of motion g's largest F for one region (``region_peaks``),
    skipping what the bounds prune when ``prune``."""
    scale = low * low * (1.0 - PRUNE_MARGIN)
    samples = speeds.shape[1] // sites if sites > 0 else 0
    at, top = 0, -1.0
    for i in range(samples):
        if prune and (kind[i] == 0 or (kind[i] == 1 and bounds[i] * scale > spring)):
            continue
        for k in range(sites):
            e = i * sites + k
            v = speeds[g, e]
            if prune and kind[i] == 1:  # F = 0, or its bound below L
                if not v > 0.0 or (c * site_speeds[e] + site_energies[e]) * scale > spring:
                    continue
            force = 0.0
            if v > 0.0:
                force = v * math.sqrt(spring * (1.0 / (c + 1.0 / masses[g, e])))
            if force != force:
                return e, force
            if force > top:
                at, top = e, force
    return at, top
