"""Joint velocities, accelerations and torques of G grasps along their joint paths in one call
of the compiled kernel ``kernels.effort.joint_dynamics`` (the effort analysis's compiled path,
``analyses.effort.evaluate_efforts``; its module docstring states the method)."""

from __future__ import annotations

from concurrent.futures import Executor
from typing import NamedTuple

import numpy as np

from .compiled import call_kernel, plain_array
from .packed import BodyInertias, ChainArrays
from .pool import split_grasps
from .terms import SampleTerms, sample_terms_buffers


class JointDynamics(NamedTuple):
    """Per-sample q̇, q̈, τ (G, N, n) of G grasps (rows from a grasp's count on: undefined)
    and per joint max |τ| and RMS τ over each grasp's samples (G, n) [SI: rad or m, s, N m
    or N]."""

    velocities: np.ndarray
    accelerations: np.ndarray
    torques: np.ndarray
    peak_abs_torques: np.ndarray
    rms_torques: np.ndarray


def joint_dynamics(
    chain: ChainArrays,
    bodies: BodyInertias,
    positions: np.ndarray,
    q_all: np.ndarray,
    counts: np.ndarray,
    motion_of: np.ndarray,
    paths: np.ndarray,
    object_rotations: np.ndarray,
    object_twists: np.ndarray,
    grasp_translations: np.ndarray,
    gravity: np.ndarray,
    terms: SampleTerms | None = None,
    executor: Executor | None = None,
) -> JointDynamics:
    """q̇, q̈ and τ of every grasp in one kernel call (``executor``: a thread pool whose
    threads and the caller each run it on a range of the grasps, ``pool.split_grasps``; the
    same bits).

    Args:
        chain: ``compiled.chain_arrays`` of the robot (numba must be installed).
        bodies: The grasps' augmented bodies (``compiled.augmented_bodies``, axis 0 the grasp).
        positions: (G, N, n) joint positions [rad or m], chain order; q_all: (G, N, nq) their
            Pinocchio configurations (``terms.configurations``).
        counts: (G,) samples per grasp (0: none); rows from counts[g] on are ignored.
        motion_of: (G,) the motion grasp g follows (index into the next three).
        paths: (M, 3, N) each motion's path parameter s, ds/dt [1/s] and d²s/dt² [1/s²].
        object_rotations: (M, N, 3, 3) the object frame in the base frame.
        object_twists: (M, 2, N, 6) the object origin's twist and its rate, base axes
            [m/s, rad/s; m/s², rad/s²] (``tip_twists`` of the identity grasp).
        grasp_translations: (G, 3) the tip origin in the object frame [m].
        gravity: (3,) [m/s²] in the world frame (the model's).
        terms: The shared terms along these paths (``batch_terms``); None: the kernel
            computes the kinematics it needs itself (no M⁻¹, nothing stored).
    """
    from ..kernels.effort import joint_dynamics as kernel
    from ..kernels.ik import thread_workspace

    positions, q_all = plain_array(positions), plain_array(q_all)
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    grasps, samples, n = positions.shape
    use_terms = terms is not None
    if terms is None:
        terms = sample_terms_buffers(0, 0, n)
    terms = SampleTerms(*(plain_array(array) for array in terms))
    out = JointDynamics(
        np.zeros((grasps, samples, n)),
        np.zeros((grasps, samples, n)),
        np.zeros((grasps, samples, n)),
        np.zeros((grasps, n)),
        np.zeros((grasps, n)),
    )
    shared = (
        plain_array(paths),
        plain_array(object_rotations),
        plain_array(object_twists),
    )
    motion_of = np.ascontiguousarray(motion_of, dtype=np.int64)
    translations, gravity = plain_array(grasp_translations), plain_array(gravity)

    def run(start: int, stop: int) -> None:
        call_kernel(
            kernel,
            chain,
            BodyInertias(*(array[start:stop] for array in bodies)),
            use_terms,
            SampleTerms(*(array[start:stop] for array in terms)),
            positions[start:stop],
            q_all[start:stop],
            counts[start:stop],
            motion_of[start:stop],
            *shared,
            translations[start:stop],
            gravity,
            tuple(array[start:stop] for array in out),
            *_scratch(samples, n),
            thread_workspace(n),
        )

    split_grasps(executor, grasps, run)
    return out


def _scratch(samples: int, n: int) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The kernel's scratch (factors, ws) for paths of ``samples`` samples, n joints: one per
    kernel call (each thread its own)."""
    wide, narrow = max(n, 6), min(n, 6)
    factors = (
        np.empty((narrow, wide)),
        np.empty(narrow),
        np.empty(narrow),
        np.empty((narrow, narrow)),
        np.empty((narrow, narrow)),
        np.empty((narrow, narrow)),
        np.empty(narrow),
        np.empty(wide),
        np.empty(narrow),
    )
    ws = (
        *(np.empty((samples, n)) for _ in range(3)),
        *(np.empty((n, 3)) for _ in range(8)),
        np.empty((3, 6)),
        np.empty((2, n)),
        np.empty((n, 6)),
        np.empty((6, n)),
    )
    return factors, ws
