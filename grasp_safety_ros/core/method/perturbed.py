"""Effective masses of grasps along their evaluated joint paths for a set of object inertias,
by the compiled kernel ``kernels.uncertainty.perturbed_effective_masses`` (the inertia
uncertainty and armature-range analyses; their Pinocchio loop is the reference).

The IK does not depend on the object's inertia, so the joint paths are reused and only the
joint-space inertia changes: per inertia the object is merged into the tip body as the ranking
merges it (``compiled.augmented_bodies``), and M is the ranking's own (armature included).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .compiled import augmented_bodies, call_kernel, plain_array
from .packed import BodyInertias, ChainArrays
from .terms import configurations

GRASP_CHUNK = 16
"""Grasps per kernel call: bounds the bodies (inertias x chunk x n x 13 floats) and the masses
(inertias x chunk x samples floats) held at once."""


def perturbed_effective_masses(
    robot: RobotModel,
    chain: ChainArrays,
    inertias: Sequence[ObjectInertia],
    transforms_tip_to_object: Sequence[Any],
    joint_positions: Sequence[np.ndarray],
    directions_in_base: Sequence[np.ndarray],
    worst: Sequence[np.ndarray],
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
    """
    from ..kernels.ik import thread_workspace
    from ..kernels.uncertainty import perturbed_effective_masses as kernel

    results: list[np.ndarray] = []
    ws, mobility = thread_workspace(robot.model.nv), np.empty((3, 3))
    for start in range(0, len(joint_positions), GRASP_CHUNK):
        chunk = slice(start, start + GRASP_CHUNK)
        positions = joint_positions[chunk]
        counts = np.array([len(p) for p in positions], dtype=np.int64)
        count, longest = len(counts), int(counts.max(initial=0))
        grasps = [pin.SE3(transform) for transform in transforms_tip_to_object[chunk]]
        rotations = np.array([grasp.rotation for grasp in grasps]).reshape(-1, 3, 3)
        translations = np.array([grasp.translation for grasp in grasps]).reshape(-1, 3)
        parts = [augmented_bodies(robot, i, rotations, translations) for i in inertias]
        bodies = BodyInertias(*(np.concatenate(arrays) for arrays in zip(*parts, strict=True)))
        q_all = np.zeros((count, longest, robot.model.nq))
        directions = np.zeros((count, longest, 3))
        slots = np.full((count, longest), -1, dtype=np.int64)
        flagged = 0
        for g, (p, d, w) in enumerate(
            zip(positions, directions_in_base[chunk], worst[chunk], strict=True)
        ):
            q_all[g, : len(p)] = configurations(robot, p)
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
            q_all,
            counts,
            plain_array(directions),
            slots,
            out,
            worst_mobilities,
            mobility,
            ws,
        )
        if flagged:
            smallest = np.linalg.eigvalsh(worst_mobilities[:flagged])[..., 0]  # (W, P)
            rows, columns = np.nonzero(slots >= 0)
            out[:, rows, columns] = 1.0 / smallest.T
        results.extend(out[:, g, :n].copy() for g, n in enumerate(counts))
    return results
