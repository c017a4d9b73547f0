"""Batches of grasps through the fused kernel ``kernels.grasp.evaluate_grasps``, with the IK
solver's restarts of a first sample that does not converge (above ``ik``: it drives an
``IKSolver``; ``compiled`` below it knows no IK types)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import GraspSafetyError
from ..model.inertia import ObjectInertia
from ..model.trajectory import ObjectMotion
from .compiled import augmented_bodies, call_kernel, plain_array
from .effective_mass import STATIONARY_TANGENT_M
from .ik import IKSolver
from .packed import BodyInertias, CompiledGraspResult, GraspBuffers, grasp_buffers


def evaluate_grasps_compiled(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    transforms_tip_to_object: Sequence[Any],
    motion: ObjectMotion,
    times_s: np.ndarray,
    seeds_q: np.ndarray,
    motion_is_tip: bool = False,
) -> list[CompiledGraspResult]:
    """Grasps with the fused kernel ``evaluate_grasps``, in one call (solver.compiled must be
    true); one result per grasp, in order.

    Args:
        transforms_tip_to_object: The grasps (the object's inertia moves with the tip).
        seeds_q: The IK seed of sample 0: (nq,) for every grasp, or (G, nq) one per grasp.
        motion: The object's motion at the sample times (``object_motion`` of the
            trajectory), which the kernel composes with each grasp; with ``motion_is_tip``,
            the tip's own motion (composed with the identity; then one grasp).

    Directions and effective masses of samples where the tip does not translate (``worst``)
    are left for the caller. Random restarts of sample 0 run here, as in ``solve_first``.
    """
    from ..kernels.grasp import evaluate_grasps  # imports numba: only when first needed
    from ..kernels.ik import solve_pose, thread_workspace

    chain, settings, robot = solver.chain, solver.settings, solver.robot
    if chain is None or settings is None:
        raise GraspSafetyError("the compiled kernels do not support this chain")
    grasps = [pin.SE3(transform) for transform in transforms_tip_to_object]
    rotations = np.array([grasp.rotation for grasp in grasps]).reshape(-1, 3, 3)
    translations = np.array([grasp.translation for grasp in grasps]).reshape(-1, 3)
    bodies = augmented_bodies(robot, object_inertia, rotations, translations)
    if motion_is_tip:
        rotations = np.repeat(np.eye(3)[None], len(grasps), axis=0)
        translations = np.zeros((len(grasps), 3))
    count = len(grasps)
    times_s = plain_array(times_s)
    nq = robot.model.nq
    out = grasp_buffers(count, len(times_s), nq)
    ws = thread_workspace(robot.model.nv)
    motion = ObjectMotion(*(plain_array(array) for array in motion))
    seeds = plain_array(np.broadcast_to(seeds_q, (count, nq)))
    fixed = (chain, settings)
    shared = (motion, rotations, translations, times_s)
    object_twists = np.empty((len(times_s), 6))
    call_kernel(
        evaluate_grasps,
        *fixed,
        bodies,
        *shared,
        seeds,
        np.zeros(count, dtype=np.bool_),
        STATIONARY_TANGENT_M,
        object_twists,
        out,
        ws,
    )
    reasons = [""] * count
    for g in np.flatnonzero(out.outcomes[:, 0] == 4):  # sample 0 failed from the seed
        total = int(out.iterations[g, 0])
        converged = False
        q_fail = out.q_fail[g]
        for restart in solver.restarts():  # deterministic random restarts
            q0 = np.empty(nq)
            converged, restart_iterations = call_kernel(
                solve_pose,
                *fixed,
                out.target_rotations[g, 0],
                out.target_translations[g, 0],
                plain_array(restart),
                q0,
                ws,
            )
            total += int(restart_iterations)
            if converged:
                break
            q_fail = q0
        if not converged:
            reasons[g] = solver.first_sample_reason(q_fail, times_s)
            continue
        row = slice(g, g + 1)
        call_kernel(
            evaluate_grasps,
            *fixed,
            BodyInertias(*(array[row] for array in bodies)),
            motion,
            rotations[row],
            translations[row],
            times_s,
            q0[None],
            np.ones(1, dtype=np.bool_),
            STATIONARY_TANGENT_M,
            object_twists,
            GraspBuffers(*(array[row] for array in out)),
            ws,
        )
        out.iterations[g, 0] = total
    results = []
    for g in range(count):
        status, index, joint = (int(value) for value in out.outcomes[g])
        if reasons[g]:
            results.append(_no_samples(reasons[g], nq))
            continue
        if status != 0:
            value = float(out.outcome_values[g])
            reasons[g] = solver.failure_reason(status, index, joint, value, out.q_fail[g], times_s)
        else:
            index = len(times_s)
        results.append(
            CompiledGraspResult(
                reasons[g],
                out.q_all[g, :index],
                out.iterations[g, :index],
                out.mobilities[g, :index],
                out.effective_masses[g, :index],
                out.directions[g, :index],
                out.worst[g, :index],
                out.tangent_norms[g, :index],
            )
        )
    return results


def _no_samples(reason: str, nq: int) -> CompiledGraspResult:
    """The result of a grasp whose first sample has no IK solution."""
    empty = np.empty(0)
    return CompiledGraspResult(
        reason,
        np.empty((0, nq)),
        np.zeros(0, dtype=np.int64),
        np.empty((0, 3, 3)),
        empty,
        np.empty((0, 3)),
        np.zeros(0, dtype=bool),
        empty,
    )
