"""The per-(grasp, sample) terms the analyses share, computed once along each grasp's joint
path: joint and tip poses, the tip Jacobian and, only when a wanted analysis reads them
(``OPTIONAL_TERMS``), the tip's 6x6 mobility J M⁻¹ Jᵀ and the inverse joint-space inertia M⁻¹
of the augmented chain (robot + object), by the compiled kernel ``kernels.terms.sample_terms``:
for many grasps in one call (``grasps_terms``, how ``analyses.safety_report.analyse`` takes them
for chunks of feasible grasps) or for one (``grasp_terms``, the same numbers bit for bit).

It is the one traversal every analysis reads from (pinocchio's ``computeAllTerms`` pattern)
instead of rerunning kinematics per sample: the exposed points (``analyses.exposed_points``)
read the tip's poses and 6x6 mobility, effort (``analyses.effort``) the joint frames, motion
subspaces and the tip's origin and Jacobian, the whole-arm sites the joint frames, motion
subspaces, the tip Jacobian and M⁻¹. M is the ranking's own
(``kernels.effective_mass._mobility_from_frames``), so whatever the ranking's M includes, the
analyses' does too. The terms' memory is kept per thread and reused once nothing refers to it
(``KEPT_TERMS_SAMPLES``). Chains the kernels do not support have no terms; the analyses then
run Pinocchio per sample, their reference path (``test_performance_paths`` holds both equal).
"""

from __future__ import annotations

import math
import sys
import threading
from collections.abc import Collection, Sequence
from concurrent.futures import Executor
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from .compiled import augmented_bodies, call_kernel, plain_array, pose_arrays
from .packed import BodyInertias, ChainArrays
from .pool import split_grasps


class SampleTerms(NamedTuple):
    """Terms of G grasps x N samples (axis 0 the grasp, axis 1 the sample; ``of_grasp``
    drops axis 0) of a chain of n joints, world frame (Pinocchio's model root) unless said.

    The Jacobian is Pinocchio's LOCAL_WORLD_ALIGNED one at the tip: rows [linear; angular],
    world axes, linear part the velocity of the tip origin. The tip's mobility is J M⁻¹ Jᵀ
    with J's rows in base axes (its linear block: the ranking's translational mobility, to
    rounding), computed from the Cholesky factor of M. It and M⁻¹ (OPTIONAL_TERMS) are
    computed only when asked (else undefined). A joint's motion subspace is its
    unit twist at the world origin, [p × w + slide u; w] (u its axis, p its origin, w = u for
    a revolute joint and 0 for a prismatic one, slide = 1 - |w|).
    """

    rotations_joint_to_world: np.ndarray  # (G, N, n, 3, 3) joint frames
    translations_joint_in_world: np.ndarray  # (G, N, n, 3) [m]
    motions_joint_in_world: np.ndarray  # (G, N, n, 6) motion subspaces at the world origin [m; 1]
    rotations_tip_to_world: np.ndarray  # (G, N, 3, 3) tip frame
    translations_tip_in_world: np.ndarray  # (G, N, 3) [m]
    jacobians_tip_in_world: np.ndarray  # (G, N, 6, n) [m/rad or 1; rad/rad or rad/m]
    mobilities_tip_in_base: np.ndarray  # (G, N, 6, 6) J M^-1 J^T, base axes [1/kg, ...]
    mass_matrix_inverses: np.ndarray  # (G, N, n, n) M^-1 of the augmented chain [1/kg, ...]

    def of_grasp(self, g: int, count: int | None = None) -> SampleTerms:
        """Grasp g's terms (axis 0 dropped), its first ``count`` samples (all: None)."""
        return SampleTerms(*(array[g, :count] for array in self))


OPTIONAL_TERMS = ("mobilities_tip_in_base", "mass_matrix_inverses")
"""The fields of SampleTerms computed only when asked (``batch_terms``' ``optional``): for a
7-joint arm the tip's mobility costs a tenth of the kernel's time, M⁻¹ a quarter."""

KEPT_TERMS_SAMPLES = 30_000
"""Each thread keeps the memory of released terms, up to this many samples' worth for the
chain asked (``field_shapes``), for the next ``sample_terms_buffers``: returned to the
allocator, freed terms come back as fresh pages whose first touch costs as much as the kernel
that fills them (whole arm of 10 grasps x 201 samples: 0.5 µs per sample of 1.0, measured). A
chunk of ``analyses.base.TERMS_CHUNK_SAMPLES`` (25,000) of any chain fits with a fifth to spare
(64 MB for a 7-joint arm, 115 MB for a 12-joint one; ``test_terms`` holds the chunk within).
The whole arm's outputs may take as much again beside them (``points._exposure_buffers``)."""


def field_shapes(n: int) -> tuple[tuple[int, ...], ...]:
    """The shapes of one sample's fields of SampleTerms (in field order), n joints."""
    return ((n, 3, 3), (n, 3), (n, 6), (3, 3), (3,), (6, n), (6, 6), (n, n))


def sample_elements(n: int) -> int:
    """float64 elements of one sample's terms, n joints."""
    return sum(math.prod(shape) for shape in field_shapes(n))


def kept_elements(n: int, per_sample: int = 0) -> int:
    """float64 elements the threads' kept blocks may hold: KEPT_TERMS_SAMPLES samples' terms
    of an n-joint chain, and as many samples of ``per_sample`` elements more (a caller's own
    outputs in the same blocks, e.g. the whole arm's, so neither evicts the other)."""
    return KEPT_TERMS_SAMPLES * (sample_elements(n) + per_sample)


class _Blocks(threading.local):
    """Per thread, the memory blocks of earlier terms (one flat float64 array each)."""

    def __init__(self) -> None:
        self.blocks: list[np.ndarray] = []


_BLOCKS = _Blocks()


def _block(size: int, kept: int) -> np.ndarray | None:
    """A float64 block of at least ``size`` elements: a kept one no array refers to any longer
    (only this list holds it: every view of a block, SampleTerms' fields and their slices,
    holds a reference to it), else a new one when the kept stay within ``kept`` elements with
    it (the oldest unreferenced ones dropped first), else None."""
    limit = kept - size
    if size == 0 or limit < 0:  # nothing to keep, or more than is kept: the kept stay
        return None
    blocks = _BLOCKS.blocks
    for k in range(len(blocks)):
        if blocks[k].size >= size and sys.getrefcount(blocks[k]) == 2:  # the list's, the call's
            return blocks[k]
    for k in range(len(blocks) - 1, -1, -1):
        if sum(b.size for b in blocks) <= limit:
            break
        if sys.getrefcount(blocks[k]) == 2:
            del blocks[k]
    if sum(b.size for b in blocks) > limit:
        return None
    blocks.insert(0, np.empty(size))
    return blocks[0]


def sample_terms_buffers(grasps: int, count: int, n: int) -> SampleTerms:
    """Uninitialised SampleTerms for ``grasps`` grasps of ``count`` samples, n joints: views of
    one kept block (``_block``; the memory of earlier terms no longer referenced when there is
    one), else an array per field (terms beyond what the threads keep)."""
    shapes = field_shapes(n)
    sizes = [grasps * count * math.prod(shape) for shape in shapes]
    block = _block(sum(sizes), kept_elements(n))
    if block is None:
        return SampleTerms(*(np.empty((grasps, count, *shape)) for shape in shapes))
    fields, start = [], 0
    for shape, size in zip(shapes, sizes, strict=True):
        fields.append(block[start : start + size].reshape(grasps, count, *shape))
        start += size
    return SampleTerms(*fields)


def configurations(robot: RobotModel, joint_positions: np.ndarray) -> np.ndarray:
    """Pinocchio configurations (..., nq) of chain joint positions (..., n) [rad or m]: a
    continuous joint's angle as (cos, sin), as ``RobotModel.q_from_positions``."""
    positions = np.asarray(joint_positions, dtype=float)
    model = robot.model
    if model.nq == model.nv:
        return positions.copy()
    q = np.empty((*positions.shape[:-1], model.nq))
    for k, joint in enumerate(list(model.joints)[1:]):
        if joint.nq == 2:
            q[..., joint.idx_q] = np.cos(positions[..., k])
            q[..., joint.idx_q + 1] = np.sin(positions[..., k])
        else:
            q[..., joint.idx_q] = positions[..., k]
    return q


def grasp_terms(
    robot: RobotModel,
    chain: ChainArrays,
    object_inertia: ObjectInertia,
    transform_tip_to_object: pin.SE3,
    joint_positions: np.ndarray,
) -> SampleTerms:
    """The terms of one grasp along its joint path ((N, n) positions, chain order), axis 0
    dropped. ``chain``: ``compiled.chain_arrays(robot)`` (numba must be installed)."""
    return grasps_terms(
        robot, chain, object_inertia, [transform_tip_to_object], [joint_positions]
    )[0].of_grasp(0)


def grasps_terms(
    robot: RobotModel,
    chain: ChainArrays,
    object_inertia: ObjectInertia,
    transforms_tip_to_object: Sequence[pin.SE3],
    joint_positions: Sequence[np.ndarray],
    optional: Collection[str] = OPTIONAL_TERMS,
    executor: Executor | None = None,
) -> tuple[SampleTerms, np.ndarray]:
    """The terms of G grasps along their joint paths ((N_g, n) positions each, chain order),
    in one kernel call, and the sample counts N_g (G,). Axis 1 has max N_g rows; grasp g's
    rows from N_g on are undefined (``SampleTerms.of_grasp(g, N_g)`` drops them). Each grasp's
    terms are those ``grasp_terms`` gives it alone, bit for bit (the same kernel code per
    grasp). ``chain``: ``compiled.chain_arrays(robot)`` (numba must be installed);
    ``optional``: the OPTIONAL_TERMS computed, ``executor``: the pool that shares the call
    out (``batch_terms``)."""
    bodies = augmented_bodies(robot, object_inertia, *pose_arrays(transforms_tip_to_object))
    q_all, counts = padded_configurations(robot, joint_positions)
    return batch_terms(chain, bodies, q_all, counts, optional, executor), counts


def padded_configurations(
    robot: RobotModel, joint_positions: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """The ``configurations`` (G, max N_g, nq) of G joint paths ((N_g, n) chain positions
    each), zero past each path's end, and the counts N_g (G,), as the kernels take them."""
    counts = np.array([len(positions) for positions in joint_positions], dtype=np.int64)
    q_all = np.zeros((len(counts), int(counts.max(initial=0)), robot.model.nq))
    for g, positions in enumerate(joint_positions):
        q_all[g, : counts[g]] = configurations(robot, positions)
    return q_all, counts


def batch_terms(
    chain: ChainArrays,
    bodies: BodyInertias,
    q_all: np.ndarray,
    counts: np.ndarray,
    optional: Collection[str] = OPTIONAL_TERMS,
    executor: Executor | None = None,
) -> SampleTerms:
    """The terms of G grasps in one kernel call: grasp g's augmented ``bodies`` (axis 0 the
    grasp, ``compiled.augmented_bodies``) along its first counts[g] configurations of
    ``q_all`` (G, N, nq); its rows from counts[g] on are left uninitialised, and so are the
    OPTIONAL_TERMS not in ``optional`` (another name: InvalidInputError). The buffers are
    ``sample_terms_buffers``' (kept memory when there is some). ``executor``: a thread pool
    (``pool.executor_for``) whose threads and the caller each run the kernel on a range of
    the grasps (``pool.split_grasps``; the same bits); None: one call on this thread."""
    from ..kernels.ik import thread_workspace
    from ..kernels.terms import sample_terms

    unknown = sorted(set(optional).difference(OPTIONAL_TERMS))
    if unknown:  # a misspelt name would leave its field as an earlier call filled it
        raise InvalidInputError("optional", f"unknown terms {unknown}; valid: {OPTIONAL_TERMS}")

    q_all = plain_array(q_all)
    n = chain.axes.shape[0]
    out = sample_terms_buffers(q_all.shape[0], q_all.shape[1], n)
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    flags = tuple(name in optional for name in OPTIONAL_TERMS)

    def run(start: int, stop: int) -> None:
        if start < stop:
            call_kernel(
                sample_terms,
                chain,
                BodyInertias(*(array[start:stop] for array in bodies)),
                q_all[start:stop],
                counts[start:stop],
                flags,
                SampleTerms(*(array[start:stop] for array in out)),
                np.empty((n, n)),
                np.empty((n, 3)),
                thread_workspace(n),
            )

    split_grasps(executor, q_all.shape[0], run)
    return out


def point_jacobians(terms: SampleTerms, joint: int, points_in_world_m: np.ndarray) -> np.ndarray:
    """Linear Jacobians (..., K, 3, n) of points fixed to the body of chain joint ``joint``
    (0-based), world axes, from a grasp's terms (leading axes as in ``terms``, e.g. (N,)).

    ``points_in_world_m`` (..., K, 3) [m]: the points' world positions at each sample. Column
    k <= joint is joint k's motion subspace moved to the point, v + w × p (S = (v, w) at the
    world origin); the columns of the joints after ``joint`` are zero. For the whole-arm
    analysis: a link site's Jacobian, then J M⁻¹ Jᵀ with ``mass_matrix_inverses``.
    """
    motions = terms.motions_joint_in_world[..., None, :, :]  # (..., 1, n, 6)
    points = np.asarray(points_in_world_m, dtype=float)[..., :, None, :]  # (..., K, 1, 3)
    linear, angular = motions[..., :3], motions[..., 3:]
    columns = np.empty(np.broadcast_shapes(linear.shape, points.shape))  # (..., K, n, 3)
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # v + w × p, row a
        columns[..., a] = linear[..., a] + (
            angular[..., b] * points[..., c] - angular[..., c] * points[..., b]
        )
    columns[..., joint + 1 :, :] = 0.0
    return np.swapaxes(columns, -1, -2)
