"""The scrambled Halton sequence of posture selection's IK seeds (``posture.restart_seeds``),
without importing scipy.stats."""

from __future__ import annotations

import functools
import math

import numpy as np


def scrambled_halton(dimensions: int, count: int, seed: int) -> np.ndarray:
    """The first ``count`` points (count, dimensions) in [0, 1) of the Halton sequence with
    Owen's digit scrambling: those of ``scipy.stats.qmc.Halton(d=dimensions, scramble=True,
    seed=seed).random(count)`` (scipy 1.17; its ``rng=`` keyword draws others) bit for bit
    (tested), without importing scipy.stats (0.5-1 s).

    Dimension k is the van der Corput sequence in the k-th prime base b, point i the sum over
    its base-b digits d_j(i) (j = 0, 1, ...) of perm_j[d_j(i)] b^-(j+1), with one random
    permutation perm_j of the digits per position j (ceil(54 / log2 b) - 1 positions, as far
    as a double resolves), drawn by ``numpy.random.default_rng(seed).shuffle`` in the order
    of the bases and positions. The points of each (dimensions, count, seed) are computed
    once per process (a request of a few grasps spent more time here than in its IK) and
    copied out.
    """
    return _scrambled_halton(dimensions, count, seed).copy()


@functools.lru_cache(maxsize=16)
def _scrambled_halton(dimensions: int, count: int, seed: int) -> np.ndarray:
    """``scrambled_halton``'s points, kept (read-only)."""
    rng = np.random.default_rng(seed)
    points = np.zeros((count, dimensions))
    for k, base in enumerate(_primes(dimensions)):
        positions = math.ceil(54 / math.log2(base)) - 1
        permutations = np.repeat(np.arange(base)[None], positions, axis=0)
        for permutation in permutations:
            rng.shuffle(permutation)
        quotient = np.arange(count)
        scale = 1.0 / base
        column = points[:, k]
        for j in range(positions):  # the same operations, in the same order, as scipy's
            column += permutations[j, quotient % base] * scale
            quotient //= base
            scale /= base
    points.setflags(write=False)
    return points


def _primes(count: int) -> list[int]:
    """The first ``count`` primes."""
    primes: list[int] = []
    candidate = 2
    while len(primes) < count:
        if all(candidate % p for p in primes if p * p <= candidate):
            primes.append(candidate)
        candidate += 1
    return primes
