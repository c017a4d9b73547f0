"""Batches of grasps through the fused kernel ``kernels.grasp.evaluate_grasps``, with the IK
solver's restarts of a first sample that does not converge (above ``ik``: it drives an
``IKSolver``; ``compiled`` below it knows no IK types)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..exceptions import GraspSafetyError
from ..model.inertia import ObjectInertia
from ..model.trajectory import ObjectMotion
from .compiled import augmented_bodies, call_kernel, plain_array, pose_arrays
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
    from ..kernels.ik import solve_pose

    fixed, bodies, shared, seeds, out, ws = _kernel_inputs(
        solver, object_inertia, transforms_tip_to_object, motion, times_s, seeds_q, motion_is_tip
    )
    motion, rotations, translations, times_s = shared
    count, nq = len(seeds), seeds.shape[1]
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
    return [
        _no_samples(reasons[g], nq) if reasons[g] else _result(solver, out, g, times_s)
        for g in range(count)
    ]


def follow_postures_compiled(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    transforms_tip_to_object: Sequence[Any],
    motion: ObjectMotion,
    times_s: np.ndarray,
    seeds_q: np.ndarray,
    stop: tuple[bool, np.ndarray, np.ndarray],
) -> list[CompiledGraspResult | None]:
    """``evaluate_grasps_compiled`` of start postures, with the early stop of the kernel
    ``follow_postures``: None for a row stopped there (its score certainly above its bound).

    Args:
        seeds_q: (G, nq): row g's IK seed of sample 0 (a solution of its first tip pose).
        stop: (bound_is_max, score_weights (N,), bounds (G,)) as ``follow_postures`` takes
            them (bounds already widened by the rounding of the scores; inf: never stop).

    A row is computed as by ``evaluate_grasps_compiled`` (the same kernel code) up to where
    it stops, so a row that is not stopped gives the same result bit for bit; a row whose
    sample 0 does not converge from its seed goes through ``evaluate_grasps_compiled`` (its
    random restarts).
    """
    from ..kernels.grasp import follow_postures

    fixed, bodies, shared, seeds, out, ws = _kernel_inputs(
        solver, object_inertia, transforms_tip_to_object, motion, times_s, seeds_q, False
    )
    bound_is_max, weights, bounds = stop
    times_s = shared[3]
    call_kernel(
        follow_postures,
        *fixed,
        bodies,
        *shared,
        seeds,
        STATIONARY_TANGENT_M,
        np.empty((len(times_s), 6)),
        out,
        ws,
        bool(bound_is_max),
        plain_array(weights),
        plain_array(bounds),
    )
    results: list[CompiledGraspResult | None] = []
    for g, status in enumerate(out.outcomes[:, 0]):
        if status == 5:
            results.append(None)
        elif status == 4:  # not expected of a start posture: as evaluate_grasps_compiled
            (result,) = evaluate_grasps_compiled(
                solver,
                object_inertia,
                [transforms_tip_to_object[g]],
                shared[0],
                times_s,
                seeds[g],
            )
            results.append(result)
        else:
            results.append(_result(solver, out, g, times_s))
    return results


def _kernel_inputs(
    solver: IKSolver,
    object_inertia: ObjectInertia,
    transforms_tip_to_object: Sequence[Any],
    motion: ObjectMotion,
    times_s: np.ndarray,
    seeds_q: np.ndarray,
    motion_is_tip: bool,
) -> tuple[Any, ...]:
    """The fused kernels' inputs: (chain, settings), the augmented bodies, (motion, grasp
    rotations, translations, times), the (G, nq) seeds, fresh buffers and the workspace."""
    from ..kernels.ik import thread_workspace

    chain, settings, robot = solver.chain, solver.settings, solver.robot
    if chain is None or settings is None:
        raise GraspSafetyError("the compiled kernels do not support this chain")
    rotations, translations = pose_arrays(transforms_tip_to_object)
    count = len(rotations)
    bodies = augmented_bodies(robot, object_inertia, rotations, translations)
    if motion_is_tip:
        rotations = np.repeat(np.eye(3)[None], count, axis=0)
        translations = np.zeros((count, 3))
    times_s = plain_array(times_s)
    nq = robot.model.nq
    out = grasp_buffers(count, len(times_s), nq)
    ws = thread_workspace(robot.model.nv)
    motion = ObjectMotion(*(plain_array(array) for array in motion))
    seeds = plain_array(np.broadcast_to(seeds_q, (count, nq)))
    shared = (motion, rotations, translations, times_s)
    return (chain, settings), bodies, shared, seeds, out, ws


def _result(
    solver: IKSolver, out: GraspBuffers, g: int, times_s: np.ndarray
) -> CompiledGraspResult:
    """Row g of the fused kernel's buffers (status 0 to 3) as a CompiledGraspResult."""
    status, index, joint = (int(value) for value in out.outcomes[g])
    reason = ""
    if status != 0:
        value = float(out.outcome_values[g])
        reason = solver.failure_reason(status, index, joint, value, out.q_fail[g], times_s)
    else:
        index = len(times_s)
    return CompiledGraspResult(
        reason,
        out.q_all[g, :index],
        out.iterations[g, :index],
        out.mobilities[g, :index],
        out.effective_masses[g, :index],
        out.directions[g, :index],
        out.worst[g, :index],
        out.tangent_norms[g, :index],
    )


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
