"""Effective masses of grasps along their evaluated joint paths for a set of object inertias,
by the compiled kernel ``kernels.uncertainty.perturbed_effective_masses`` (the inertia
uncertainty and armature-range analyses; their Pinocchio loop is the reference).

The IK does not depend on the object's inertia, so the joint paths are reused and only the
joint-space inertia changes, M_aug = M + Jᵀ Y J: per (grasp, sample) the kernel factorises the
chain's own M once (the ranking's, armature included) and per inertia solves a 6 x 6 system.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from functools import partial

import numpy as np
import pinocchio as pin

from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .compiled import call_kernel, plain_array, pose_arrays
from .effective_mass import robot_inertia_arrays
from .packed import BodyInertias, ChainArrays
from .terms import padded_configurations

GRASP_CHUNK = 16
"""Grasps per kernel call: bounds the spatial inertias (inertias x chunk x 36 floats) and the
masses (inertias x chunk x samples floats) held at once."""


def spatial_inertias_in_tip(
    inertias: Sequence[ObjectInertia], rotations: np.ndarray, translations: np.ndarray
) -> np.ndarray:
    """(P, G, 6, 6) spatial inertias of P object inertias in the tip frames of G grasps
    (Pinocchio's matrix, [linear; angular]: [[m I, -m ĉ], [m ĉ, I_c - m ĉ ĉ]], c the centre of
    mass, I_c the rotational inertia about it); rotations (G, 3, 3), translations (G, 3) [m]:
    the tip frame in the object frame."""
    masses = np.array([i.mass_kg for i in inertias])[:, None]  # (P, 1)
    coms = np.array([i.com_in_object_m for i in inertias], dtype=float)  # (P, 3)
    tensors = np.array([i.inertia_about_com_kgm2 for i in inertias], dtype=float)
    # In the tip frame: c' = Rᵀ (c - t), I' = Rᵀ I R (R, t: the tip in the object frame).
    com = np.einsum("gba,pgb->pga", rotations, coms[:, None] - translations[None])
    tensor = np.einsum("gba,pbc,gcd->pgad", rotations, tensors, rotations)
    skew = np.zeros((*com.shape, 3))
    skew[..., 0, 1], skew[..., 0, 2] = -com[..., 2], com[..., 1]
    skew[..., 1, 0], skew[..., 1, 2] = com[..., 2], -com[..., 0]
    skew[..., 2, 0], skew[..., 2, 1] = -com[..., 1], com[..., 0]
    weighted = masses[..., None, None] * skew
    out = np.empty((len(masses), len(rotations), 6, 6))
    out[..., :3, :3] = masses[..., None, None] * np.eye(3)
    out[..., :3, 3:] = -weighted
    out[..., 3:, :3] = weighted
    out[..., 3:, 3:] = tensor - weighted @ skew
    return out


def perturbed_effective_masses(
    robot: RobotModel,
    chain: ChainArrays,
    inertias: Sequence[ObjectInertia],
    transforms_tip_to_object: Sequence[pin.SE3],
    joint_positions: Sequence[np.ndarray],
    directions_in_base: Sequence[np.ndarray],
    worst: Sequence[np.ndarray],
    executor: Executor | None = None,
) -> list[np.ndarray]:
    """Per grasp, the effective masses (P, N_g) [kg] of its N_g samples for the P inertias.

    Args:
        chain: ``compiled.chain_arrays(robot)`` (numba must be installed); its armature is the
            one used.
        inertias: The object's inertias (object frame).
        transforms_tip_to_object: The grasps (tip frame in the object frame).
        joint_positions: Per grasp, (N_g, n) chain joint positions [rad or m].
        directions_in_base: Per grasp, (N_g, 3) unit directions of the tip's motion, base axes;
            the mass is 1 / (dᵀ A d), A the tip's translational mobility [1/kg].
        worst: Per grasp, (N_g,) bool: where set, the largest effective mass over directions
            (1 / smallest eigenvalue of A) instead.
        executor: A thread pool (``pool.executor_for``) to share the chunks of GRASP_CHUNK
            grasps out over (the kernel runs without the GIL); the results equal the serial
            ones bit for bit. None: serial.
    """
    run = partial(
        _chunk_masses,
        robot,
        chain,
        inertias,
        transforms_tip_to_object,
        joint_positions,
        directions_in_base,
        worst,
    )
    chunks = [
        slice(start, start + GRASP_CHUNK) for start in range(0, len(joint_positions), GRASP_CHUNK)
    ]
    parts = (
        executor.map(run, chunks) if executor is not None and len(chunks) > 1 else map(run, chunks)
    )
    return [masses for part in parts for masses in part]


def _chunk_masses(
    robot: RobotModel,
    chain: ChainArrays,
    inertias: Sequence[ObjectInertia],
    transforms_tip_to_object: Sequence[pin.SE3],
    joint_positions: Sequence[np.ndarray],
    directions_in_base: Sequence[np.ndarray],
    worst: Sequence[np.ndarray],
    chunk: slice,
) -> list[np.ndarray]:
    """``perturbed_effective_masses`` of the grasps in ``chunk``, by one kernel call."""
    from ..kernels.ik import thread_workspace
    from ..kernels.uncertainty import perturbed_effective_masses as kernel

    n = robot.model.nv
    ws = thread_workspace(n)
    scratch = (
        np.empty((n, 6)),
        np.empty((3, 3)),
        np.empty((6, 6)),
        np.empty((6, 6)),
        np.empty(6, dtype=np.int64),
        np.empty(6),
    )
    bodies = BodyInertias(*(plain_array(array[None]) for array in robot_inertia_arrays(robot)))
    positions = joint_positions[chunk]
    q_all, counts = padded_configurations(robot, positions)
    count, longest = q_all.shape[:2]
    spatial = spatial_inertias_in_tip(inertias, *pose_arrays(transforms_tip_to_object[chunk]))
    directions = np.zeros((count, longest, 3))
    slots = np.full((count, longest), -1, dtype=np.int64)
    flagged = 0
    for g, (p, d, w) in enumerate(
        zip(positions, directions_in_base[chunk], worst[chunk], strict=True)
    ):
        directions[g, : len(p)] = d
        marked = np.flatnonzero(w)
        slots[g, marked] = flagged + np.arange(len(marked))
        flagged += len(marked)
    out = np.empty((len(inertias), count, longest))
    worst_mobilities = np.empty((max(flagged, 1), len(inertias), 3, 3))
    call_kernel(
        kernel,
        chain,
        bodies,
        spatial,
        q_all,
        counts,
        directions,
        slots,
        out,
        worst_mobilities,
        scratch,
        ws,
    )
    if flagged:
        smallest = np.linalg.eigvalsh(worst_mobilities[:flagged])[..., 0]  # (W, P)
        rows, columns = np.nonzero(slots >= 0)
        out[:, rows, columns] = 1.0 / smallest.T
    return [out[:, g, :size].copy() for g, size in enumerate(counts)]
