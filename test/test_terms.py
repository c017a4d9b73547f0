"""The shared per-(grasp, sample) terms (core/method/terms.py) equal Pinocchio, and so do the
analyses that consume them (exposed points, effort, point Jacobians, whole arm) against their
Pinocchio reference paths."""

from __future__ import annotations

import sys

import numpy as np
import pinocchio as pin
import pytest
from fast_paths import BOX, TERM_ARMS, needs_numba, one_grasp, terms_case
from tolerances import (
    assert_close_to_scale,
    dynamics_tolerance,
    effort_tolerances,
    kinematics_tolerance,
)

from grasp_safety_ros.core import RobotModel
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method import terms as terms_module
from grasp_safety_ros.core.method.backend import Backend
from grasp_safety_ros.core.method.effective_mass import (
    augmented_model,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.method.terms import (
    KEPT_TERMS_SAMPLES,
    OPTIONAL_TERMS,
    SampleTerms,
    grasps_terms,
    sample_terms_buffers,
)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_shared_terms_equal_pinocchio(name: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, _ = terms_case(robot, 11)
    model = augmented_model(robot, BOX, grasp.transform_tip_to_object)
    data = model.createData()
    kinematic, dynamic = kinematics_tolerance(robot), dynamics_tolerance(robot, terms)
    for i, positions in enumerate(evaluation.joint_positions):
        q = robot.q_from_positions(positions)
        pin.computeMinverse(model, data, q)
        upper = np.triu(data.Minv)
        assert_close_to_scale(
            terms.mass_matrix_inverses[i], upper + np.triu(upper, 1).T, "Minv", dynamic
        )
        pin.computeJointJacobians(model, data, q)
        tip = pin.updateFramePlacement(model, data, robot.tip_frame_id)
        jacobian = pin.getFrameJacobian(
            model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        assert_close_to_scale(terms.jacobians_tip_in_world[i], jacobian, "tip Jacobian", kinematic)
        assert_close_to_scale(
            terms.rotations_tip_to_world[i], tip.rotation, "tip rotation", kinematic
        )
        assert_close_to_scale(
            terms.translations_tip_in_world[i], tip.translation, "tip origin", kinematic
        )
        for k in range(robot.num_joints):
            placement = data.oMi[k + 1]
            assert_close_to_scale(
                terms.rotations_joint_to_world[i, k], placement.rotation, "joint R", kinematic
            )
            assert_close_to_scale(
                terms.translations_joint_in_world[i, k],
                placement.translation,
                "joint p",
                kinematic,
            )
            motion = pin.getJointJacobian(model, data, k + 1, pin.ReferenceFrame.WORLD)[:, k]
            assert_close_to_scale(
                terms.motions_joint_in_world[i, k], motion, "motion subspace", kinematic
            )
        mobility = translational_mobility_in_base(robot, model, data, q)
        assert_close_to_scale(
            terms.mobilities_tip_in_base[i, :3, :3], mobility, "tip mobility", dynamic
        )
        rotation = robot.transform_base_to_world.rotation  # J's rows into base axes
        in_base = np.vstack([rotation.T @ jacobian[:3], rotation.T @ jacobian[3:]])
        mobility6 = in_base @ (upper + np.triu(upper, 1).T) @ in_base.T
        _assert_mobility_blocks_close(terms.mobilities_tip_in_base[i], mobility6, dynamic)


def _assert_mobility_blocks_close(
    actual: np.ndarray, expected: np.ndarray, tolerance: float
) -> None:
    """The tip's 6x6 mobility A = J M⁻¹ Jᵀ = Wᵀ W (W = L⁻¹ Jᵀ, M = L Lᵀ) block by block, rows
    [linear; angular]: block A_ab = W_aᵀ W_b rounds relative to |W_a| |W_b|, i.e. to
    sqrt(max|A_aa| max|A_bb|), which bounds its entries (Cauchy-Schwarz; for a diagonal block
    its own largest entry), not to the whole 6x6's largest entry (the angular block's, which
    may be many times the linear block's). ``tolerance``: k · cond · eps (``dynamics_tolerance``:
    the triangular solves' rounding relative to |W| grows at most with cond(M))."""
    scales = [float(np.abs(expected[3 * a : 3 * a + 3, 3 * a : 3 * a + 3]).max()) for a in (0, 1)]
    for a in (0, 1):
        for b in (0, 1):
            block = np.s_[3 * a : 3 * a + 3, 3 * b : 3 * b + 3]
            scale = max(np.sqrt(scales[a] * scales[b]), 1e-300)
            error = float(np.abs(actual[block] - expected[block]).max()) / scale
            assert error <= tolerance, f"6 x 6 block {a}{b}: {error:.2e} > {tolerance:.2e}"


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_exposed_points_from_shared_terms_equal_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    from grasp_safety_ros.core.analyses.exposed_points import (
        box_corners_in_object,
        evaluate_exposed_points,
        evaluate_exposed_points_on_terms,
    )

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = terms_case(robot, 12)
    points = box_corners_in_object([0.08, 0.12, 0.2])
    reference = evaluate_exposed_points(robot, evaluation, BOX, grasp, motion, points)
    (shared,) = evaluate_exposed_points_on_terms(
        robot, [evaluation], [grasp], [motion], points, *one_grasp(terms)
    )
    tolerance = dynamics_tolerance(robot, terms)
    for field in ("effective_mass_kg", "directions_in_base"):
        assert_close_to_scale(getattr(shared, field), getattr(reference, field), field, tolerance)
    np.testing.assert_array_equal(shared.leading_point_index, reference.leading_point_index)
    np.testing.assert_array_equal(shared.worst_point_index, reference.worst_point_index)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_effort_from_shared_terms_equals_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    from grasp_safety_ros.core.analyses.effort import evaluate_effort, evaluate_efforts
    from grasp_safety_ros.core.method.backend import Backend

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = terms_case(robot, 13)
    reference = evaluate_effort(robot, evaluation, BOX, grasp, motion)
    batched, _ = one_grasp(terms)
    chain = Backend.for_robot(robot).chain
    (shared,) = evaluate_efforts(robot, [evaluation], BOX, [grasp], motion, None, batched, chain)
    tolerances = effort_tolerances(robot, evaluation, BOX, grasp, reference)
    for field in ("joint_velocities", "joint_accelerations", "joint_torques", "peak_abs_torque"):
        expected = getattr(reference, field)
        assert_close_to_scale(getattr(shared, field), expected, field, tolerances[field])


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_point_jacobians_from_shared_terms_equal_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    """A point on each link (0.1 m off its joint origin) and the tip: linear Jacobians from the
    terms equal Pinocchio's frame Jacobians (LOCAL_WORLD_ALIGNED) of frames placed there."""
    from grasp_safety_ros.core.method.terms import point_jacobians

    robot: RobotModel = request.getfixturevalue(name)
    _, evaluation, terms, _ = terms_case(robot, 14)
    model = robot.model.copy()
    offset = pin.SE3(np.eye(3), np.array([0.03, -0.05, 0.1]))
    frames = [
        model.addFrame(pin.Frame(f"site{k}", k + 1, 0, offset, pin.FrameType.OP_FRAME))
        for k in range(robot.num_joints)
    ]
    data = model.createData()
    tip = point_jacobians(terms, robot.num_joints - 1, terms.translations_tip_in_world[:, None])
    tolerance = kinematics_tolerance(robot)
    assert_close_to_scale(
        tip[:, 0], terms.jacobians_tip_in_world[:, :3], "tip as a point", tolerance
    )
    for i, positions in enumerate(evaluation.joint_positions[::10]):
        q = robot.q_from_positions(positions)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, frame in enumerate(frames):
            point = data.oMf[frame].translation
            ours = point_jacobians(terms, k, point[None, None])  # every sample, one point
            expected = pin.getFrameJacobian(
                model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            )[:3]
            assert_close_to_scale(ours[10 * i, 0], expected, f"site on link {k}", tolerance)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_whole_arm_from_shared_terms_equals_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    """Sites of the whole arm (the defaults and a point on every link) on the compiled path:
    positions, directions, speeds, masses, energies and the regions' worst cases."""
    from grasp_safety_ros.core.analyses.body_regions import select_regions
    from grasp_safety_ros.core.analyses.whole_arm import (
        evaluate_whole_arm,
        evaluate_whole_arm_on_terms,
        resolve_arm_sites,
    )

    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = terms_case(robot, 16)
    links = {
        frame.name
        for frame in robot.model.frames
        if frame.type == pin.FrameType.BODY and frame.parentJoint > 0
    }
    sites = resolve_arm_sites(robot, {link: [[0.03, -0.05, 0.1]] for link in sorted(links)})
    reference = evaluate_whole_arm(robot, evaluation, BOX, grasp, motion, sites)
    (shared,) = evaluate_whole_arm_on_terms(
        robot, [evaluation], [motion], [grasp], sites, select_regions(None), *one_grasp(terms)
    )
    assert reference.stationary.any() and not reference.stationary.all()  # both branches
    np.testing.assert_array_equal(shared.stationary, reference.stationary)
    kinematic, dynamic = kinematics_tolerance(robot), dynamics_tolerance(robot, terms)
    assert_close_to_scale(
        shared.positions_in_base_m, reference.positions_in_base_m, "positions", kinematic
    )
    for field in ("speed_m_s", "energy_j"):  # the joint rates through J⁺; energies through M
        assert_close_to_scale(getattr(shared, field), getattr(reference, field), field, dynamic)
    moving = ~reference.stationary
    masses, expected = shared.effective_mass_kg, reference.effective_mass_kg
    assert_close_to_scale(masses[moving], expected[moving], "masses", dynamic)
    # At rest the mass is 1/λ_min of the mobility A, conditioned by λ_max/λ_min (here up to
    # 1e6): λ_min agrees to rounding of A's scale, so compare 1/M_eff.
    assert_close_to_scale(
        1.0 / masses[~moving], 1.0 / expected[~moving], "1/masses at rest", dynamic
    )
    assert_close_to_scale(
        shared.directions_in_base[moving],
        reference.directions_in_base[moving],
        "directions",
        dynamic,
    )
    still = reference.stationary  # eigenvectors: up to sign
    signs = np.sign(
        np.einsum(
            "ka,ka->k", shared.directions_in_base[still], reference.directions_in_base[still]
        )
    )
    assert_close_to_scale(
        shared.directions_in_base[still] * signs[:, None],
        reference.directions_in_base[still],
        "directions at rest",
        dynamic,
    )
    for a, b in zip(shared.regions, reference.regions, strict=True):
        assert (a.region, a.worst_site, a.worst_sample, a.admissible) == (
            b.region,
            b.worst_site,
            b.worst_sample,
            b.admissible,
        )
        assert a.peak_contact_force_n == pytest.approx(b.peak_contact_force_n, rel=dynamic)
        assert a.worst_force_ratio == pytest.approx(b.worst_force_ratio, rel=dynamic)


@needs_numba
@pytest.mark.parametrize("name", TERM_ARMS)
def test_terms_without_optional_fields_are_the_same_numbers(
    name: str, request: pytest.FixtureRequest
) -> None:
    """Terms asked without an optional field (or with none) have every other field bit for
    bit as with all, and the optional fields not asked are not computed: each call's terms
    land in kept memory filled with NaN first, so that a field asked but skipped would be
    NaN (not the numbers an earlier call left there)."""
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, _, _ = terms_case(robot, 11)
    chain = Backend.for_robot(robot).chain
    assert chain is not None
    args = (robot, chain, BOX, [grasp.transform_tip_to_object], [evaluation.joint_positions])
    full, counts = grasps_terms(*args)
    held = [array.copy() for array in full]  # the kept memory comes back to the next call
    del full
    blocks = terms_module._BLOCKS.blocks
    for optional in (("mobilities_tip_in_base",), ("mass_matrix_inverses",), ()):
        filled = []  # the addresses of the unreferenced kept blocks, filled with NaN
        for k in range(len(blocks)):
            if sys.getrefcount(blocks[k]) == 2:  # the list's and the call's references only
                blocks[k].fill(np.nan)
                filled.append(blocks[k].__array_interface__["data"][0])
        lean, _ = grasps_terms(*args, optional=optional)
        assert lean[0].__array_interface__["data"][0] in filled  # the terms start a block
        for field_name, ours, theirs in zip(SampleTerms._fields, lean, held, strict=True):
            rows = ours[0, : counts[0]]
            if field_name in optional or field_name not in OPTIONAL_TERMS:
                assert np.array_equal(rows, theirs[0, : counts[0]]), field_name
            else:
                assert np.isnan(rows).all(), field_name
        del lean, ours, rows  # the block is free for the next call


@needs_numba
def test_an_unknown_optional_term_is_refused_by_name(arm7: RobotModel) -> None:
    """A misspelt optional field would silently leave stale numbers: it is an error naming
    the argument and the valid names."""
    grasp, evaluation, _, _ = terms_case(arm7, 11)
    chain = Backend.for_robot(arm7).chain
    assert chain is not None
    args = (arm7, chain, BOX, [grasp.transform_tip_to_object], [evaluation.joint_positions])
    with pytest.raises(InvalidInputError, match=r"^optional: unknown terms \['mobilities'\]"):
        grasps_terms(*args, optional=("mobilities",))


@needs_numba
def test_terms_memory_is_reused_only_once_nothing_refers_to_it(arm7: RobotModel) -> None:
    """Released terms' memory comes back (no fresh pages) with the same numbers as new
    memory; terms still referenced, even by a slice, are never overwritten."""
    grasp, evaluation, _, _ = terms_case(arm7, 5)
    chain = Backend.for_robot(arm7).chain
    assert chain is not None

    def compute() -> SampleTerms:
        return grasps_terms(
            arm7, chain, BOX, [grasp.transform_tip_to_object], [evaluation.joint_positions]
        )[0]

    def address(terms: SampleTerms) -> int:
        return int(terms.rotations_joint_to_world.__array_interface__["data"][0])

    first = compute()
    expected = [array.copy() for array in first]
    kept_slice, released = first.of_grasp(0, 3), [address(first)]
    del first
    second = compute()  # the first's block is still referred to by kept_slice
    assert not np.shares_memory(second.mass_matrix_inverses, kept_slice.mass_matrix_inverses)
    for array, fresh in zip(kept_slice, expected, strict=True):
        assert np.array_equal(array, fresh[0, :3])
    released.append(address(second))
    del second, kept_slice
    third = compute()  # one of the two blocks, now unreferenced, comes back
    assert address(third) in released
    for array, fresh in zip(third, expected, strict=True):
        assert np.array_equal(array, fresh)


def test_kept_terms_memory_survives_requests_it_cannot_hold() -> None:
    """A request larger than KEPT_TERMS_SAMPLES, or of no samples, neither evicts the kept
    unreferenced blocks nor adds one: the next ordinary request still gets kept memory."""

    def kept_blocks() -> list[int]:  # addresses, so that no reference is held
        return [block.__array_interface__["data"][0] for block in terms_module._BLOCKS.blocks]

    sample_terms_buffers(2, 10, 7)  # at least one kept block, unreferenced once dropped
    before = kept_blocks()
    large = sample_terms_buffers(1, KEPT_TERMS_SAMPLES + 1, 7)
    empty = sample_terms_buffers(0, 0, 7)
    assert kept_blocks() == before
    del large, empty
    again = sample_terms_buffers(2, 10, 7)
    assert again.rotations_joint_to_world.__array_interface__["data"][0] in before


@needs_numba
def test_a_full_chunk_of_a_12_joint_chain_comes_back_to_the_next_chunk() -> None:
    """The memory each thread keeps holds a chunk of the analyses (TERMS_CHUNK_SAMPLES) of a
    12-joint chain: the first chunk's terms are a kept block, the second's land in it (no
    fresh pages to touch)."""
    from conftest import serial_arm_urdf

    from grasp_safety_ros.core.analyses.base import TERMS_CHUNK_SAMPLES

    robot = RobotModel.from_urdf(serial_arm_urdf(("z", "y", "x") * 4, seed=3), "base_link", "tool")
    chain = Backend.for_robot(robot).chain
    assert chain is not None and robot.num_joints == 12
    path = np.random.default_rng(4).uniform(-1.0, 1.0, (TERMS_CHUNK_SAMPLES, 12))
    args = (robot, chain, BOX, [pin.SE3.Identity()], [path])
    first, _ = grasps_terms(*args)
    blocks = terms_module._BLOCKS.blocks
    (kept,) = [k for k, b in enumerate(blocks) if np.shares_memory(b, first.mass_matrix_inverses)]
    address = blocks[kept].__array_interface__["data"][0]
    del first
    second, _ = grasps_terms(*args)
    assert second.mass_matrix_inverses.size == TERMS_CHUNK_SAMPLES * 12 * 12
    assert second.rotations_joint_to_world.__array_interface__["data"][0] == address
