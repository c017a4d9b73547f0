"""The compiled point kernels of the analyses (``method.points``: points fixed to the tip, sites
fixed to the links) on the shared terms: closed forms on a one-joint arm, the tip as a point,
and the whole report on the batched terms against one grasp at a time and against the
Pinocchio reference path, infeasible grasps mixed in."""

from __future__ import annotations

import gc
from types import SimpleNamespace
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, book_trajectory, random_positions
from fast_paths import (
    BOX,
    grasps_near_identity,
    needs_numba,
    one_grasp,
    reach_trajectory,
    terms_case,
)
from tolerances import (
    assert_close_to_scale,
    condition_number,
    dynamics_tolerance,
    rounding_tolerance,
)

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    ObjectInertia,
    RobotModel,
)
from grasp_safety_ros.core.analyses.body_regions import select_regions
from grasp_safety_ros.core.analyses.exposed_points import (
    box_corners_in_object,
    evaluate_exposed_points_on_terms,
)
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, analyse
from grasp_safety_ros.core.analyses.whole_arm import (
    evaluate_whole_arm_on_terms,
)
from grasp_safety_ros.core.method.compiled import chain_arrays
from grasp_safety_ros.core.method.points import PSEUDO_INVERSE_RCOND
from grasp_safety_ros.core.method.terms import grasp_terms, grasps_terms

LINK_M, LINK_KG, LINK_IZZ_KGM2, ARMATURE_KGM2 = 0.4, 2.0, 0.03, 0.05
OBJECT = ObjectInertia(0.7, np.zeros(3), np.diag([0.01, 0.02, 0.015]))
CLOSED_FORM = rounding_tolerance(1.0, 32)
"""One joint against its closed forms: M is a scalar and the placement one rotation
(condition 1); k = 32: about 16 operations (the joint's sine and cosine, the lever's products
and sums, M and its inverse, J M⁻¹ Jᵀ, uᵀ A u and 1/x), each rounding once, on either side."""

ONE_JOINT_URDF = f"""<robot name="one"><link name="base"/>
<link name="arm"><inertial><origin xyz="{LINK_M} 0 0"/><mass value="{LINK_KG}"/>
<inertia ixx="0.01" iyy="0.02" izz="{LINK_IZZ_KGM2}" ixy="0" ixz="0" iyz="0"/></inertial></link>
<link name="tool"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
 <limit lower="-3" upper="3" effort="1" velocity="10"/></joint>
<joint name="fix" type="fixed"><parent link="arm"/><child link="tool"/>
 <origin xyz="{LINK_M} 0 0"/></joint>
</robot>"""


def one_joint_inertia_kgm2() -> float:
    """I about the joint axis: link (I_zz + m L²), object at the tip (I_zz + m L²), armature."""
    link = LINK_IZZ_KGM2 + LINK_KG * LINK_M**2
    carried = OBJECT.inertia_about_com_kgm2[2, 2] + OBJECT.mass_kg * LINK_M**2
    return link + carried + ARMATURE_KGM2


@pytest.fixture
def one_joint() -> tuple:
    robot = RobotModel.from_urdf(ONE_JOINT_URDF, "base", "tool", armature_kgm2=[ARMATURE_KGM2])
    angles = np.linspace(-2.0, 2.5, 7)
    chain = chain_arrays(robot)
    assert chain is not None
    terms, counts = grasps_terms(robot, chain, OBJECT, [pin.SE3.Identity()], [angles[:, None]])
    return robot, angles, terms, counts


@needs_numba
def test_tip_points_of_a_one_joint_arm_have_the_closed_form_mass(one_joint: tuple) -> None:
    """A point at radius r moves on a circle: M_eff = I / r² along the tangent, and the
    mobility is (r²/I) t tᵀ (handed back where the point is flagged at rest)."""
    from grasp_safety_ros.core.method.points import tip_point_masses

    robot, angles, terms, counts = one_joint
    offsets = np.array([0.0, 0.1, -0.25])  # along the tool's x: radius L + d
    points = np.column_stack([offsets, np.zeros(3), np.zeros(3)])[None]
    tangents = np.stack([-np.sin(angles), np.cos(angles), np.zeros_like(angles)], axis=1)
    directions = np.repeat(tangents[None, :, None], 3, axis=2)
    still = np.zeros((1, len(angles), 3), dtype=bool)
    still[0, 3, 1] = True  # one point flagged at rest
    masses, mask, mobilities = tip_point_masses(
        terms, counts, robot.transform_base_to_world.rotation, points, directions, still, [0]
    )
    inertia, radii = one_joint_inertia_kgm2(), LINK_M + offsets
    expected = np.broadcast_to(inertia / radii**2, masses.shape[1:])
    assert_close_to_scale(masses[0][~still[0]], expected[~still[0]], "I / r^2", CLOSED_FORM)
    assert mask.sum() == 1 and len(mobilities) == 1
    tangent = tangents[3]
    assert_close_to_scale(
        mobilities[0],
        radii[1] ** 2 / inertia * np.outer(tangent, tangent),
        "mobility",
        CLOSED_FORM,
    )


@needs_numba
@pytest.mark.parametrize("alone", [True, False])
def test_sites_of_a_one_joint_arm_have_the_closed_form_speed_and_mass(
    one_joint: tuple, alone: bool
) -> None:
    """A site at radius r: on a circle, speed |q̇| r, M_eff = I / r² along the tangent, each
    site alone and (four on the body) through the body's shared 6 x 6 mobility; at rest it is
    flagged, its mobility (r²/I) t tᵀ."""
    from grasp_safety_ros.core.method import points

    _, angles, terms, counts = one_joint
    radii, rate = np.array([0.3, 0.1, 0.45, 0.2]), -1.7  # [m], [rad/s]
    sites = 1 if alone else len(radii)
    assert (sites >= points.SHARED_BODY_SITES) != alone
    rates = np.full((1, len(angles), 1), rate)
    rates[0, 2] = 0.0  # at rest: no direction, the mass is left to the caller
    in_joint = np.column_stack([radii, np.zeros(4), np.zeros(4)])[:sites]
    site = (np.zeros(sites, np.int64), in_joint, np.ones((sites, 1), dtype=bool))
    positions, directions, speeds, masses, energies, still = points.arm_site_exposure(
        terms, counts, (np.eye(3), np.zeros(3)), *site, rates, 1e-9
    )
    moving = rates[0, :, 0] != 0.0
    np.testing.assert_array_equal(still[0], ~moving[:, None].repeat(sites, 1))
    inertia = one_joint_inertia_kgm2()
    circle = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    tangent = np.stack([-circle[:, 1], circle[:, 0], np.zeros_like(angles)], axis=1)
    for k, radius in enumerate(radii[:sites]):
        assert_close_to_scale(positions[0, :, k], radius * circle, "positions", CLOSED_FORM)
        expected = np.where(moving, abs(rate) * radius, 0.0)
        assert_close_to_scale(speeds[0, :, k], expected, "speeds", CLOSED_FORM)
        assert_close_to_scale(
            directions[0, moving, k], np.sign(rate) * tangent[moving], "u", CLOSED_FORM
        )
        expected = np.full(moving.sum(), inertia / radius**2)
        assert_close_to_scale(masses[0, moving, k], expected, "I / r^2", CLOSED_FORM)
        expected = 0.5 * inertia * np.where(moving, rate, 0.0) ** 2  # ½ M_eff v² = ½ I q̇²
        assert_close_to_scale(energies[0, :, k], expected, "energy", CLOSED_FORM)
    at = np.argwhere(still)
    mobilities = points.site_mobilities(terms, *site, at)
    for (_, i, k), mobility in zip(at, mobilities, strict=True):
        expected = radii[k] ** 2 / inertia * np.outer(tangent[i], tangent[i])
        assert_close_to_scale(mobility, expected, "mobility", CLOSED_FORM)


@needs_numba
@pytest.mark.parametrize("name", ["arm7", "baxter"])
def test_a_point_at_the_tip_has_the_tips_effective_mass(
    name: str, request: pytest.FixtureRequest
) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    grasp, evaluation, terms, motion = terms_case(robot, 17)
    tip_in_object = grasp.transform_tip_to_object.translation[None]
    (exposed,) = evaluate_exposed_points_on_terms(
        robot, [evaluation], [grasp], [motion], tip_in_object, *one_grasp(terms)
    )
    assert not exposed.direction_is_worst_case.any()
    tolerance = dynamics_tolerance(robot, terms)
    assert_close_to_scale(
        exposed.effective_mass_kg[:, 0], evaluation.effective_mass_kg, "mass", tolerance
    )
    assert_close_to_scale(
        exposed.directions_in_base[:, 0], evaluation.directions_in_base, "direction", tolerance
    )


def _fields(record: object) -> dict:
    return {k: v for k, v in vars(record).items() if isinstance(v, np.ndarray)}


@needs_numba
@pytest.mark.parametrize("name", ["arm7", "baxter"])
def test_the_report_on_batched_terms_equals_one_grasp_at_a_time_and_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    robot: RobotModel = request.getfixturevalue(name)
    if name == "baxter":  # the paper's book motion
        seed, trajectory = np.array(BAXTER_SEED), book_trajectory(0.04)
    else:
        seed = random_positions(robot, np.random.default_rng(18))
        trajectory = reach_trajectory(robot, seed)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable")
    near = grasps_near_identity(4, 19)
    if name == "baxter":  # along the book's spine
        near = [
            Grasp(pin.SE3(np.eye(3), np.array([-0.075, y, 0.0])), f"spine{y}")
            for y in (-0.1, 0.0, 0.1)
        ]
    grasps = [far, *near, far]
    corners = box_corners_in_object([0.08, 0.12, 0.2], [0.0, 0.01, -0.02])
    options = AnalysisOptions(points_in_object_m=corners, whole_arm=True)
    compiled = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    python = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1, backend="python"))
    ranking = compiled.rank(grasps, BOX, trajectory, seed_positions=seed)
    feasible = [k for k, e in enumerate(ranking.evaluations) if e.feasible]
    assert 2 <= len(feasible) < len(grasps)  # both kinds
    report = analyse(compiled, grasps, BOX, trajectory, options, ranking=ranking)
    reference = analyse(python, grasps, BOX, trajectory, options, ranking=ranking)
    np.testing.assert_array_equal(report.scores, reference.scores)
    assert report.order == reference.order
    for k, (evaluation, grasp) in enumerate(zip(ranking.evaluations, grasps, strict=True)):
        ours = (report.exposed[k], report.whole_arm[k])
        theirs = (reference.exposed[k], reference.whole_arm[k])
        if k not in feasible:
            assert not any(r.feasible for r in ours + theirs)
            continue
        terms = grasp_terms(
            robot,
            chain_arrays(robot),
            BOX,
            grasp.transform_tip_to_object,
            evaluation.joint_positions,
        )
        tolerance = dynamics_tolerance(robot, terms)
        one = one_grasp(terms)
        alone = (
            evaluate_exposed_points_on_terms(
                robot, [evaluation], [grasp], [trajectory], corners, *one
            )[0],
            evaluate_whole_arm_on_terms(
                robot,
                [evaluation],
                [trajectory],
                [grasp],
                report.arm_sites,
                select_regions(None),
                *one,
            )[0],
        )
        for batch, single, slow in zip(ours, alone, theirs, strict=True):
            for field, value in _fields(batch).items():
                np.testing.assert_array_equal(value, getattr(single, field), err_msg=field)
                expected = getattr(slow, field)
                if value.dtype == bool or value.dtype.kind == "i":
                    np.testing.assert_array_equal(value, expected, err_msg=field)
                elif field != "effective_mass_kg" and "direction" not in field:
                    assert_close_to_scale(value, expected, field, tolerance)
            moving = ~getattr(slow, "stationary", getattr(slow, "direction_is_worst_case", None))
            assert_close_to_scale(
                batch.effective_mass_kg[moving], slow.effective_mass_kg[moving], "m", tolerance
            )
            assert_close_to_scale(
                batch.directions_in_base[moving], slow.directions_in_base[moving], "u", tolerance
            )
        assert report.whole_arm[k].regions == alone[1].regions


@needs_numba
@pytest.mark.parametrize("n", [4, 6, 7, 9])
def test_tip_following_rates_equal_the_pseudo_inverses(n: int) -> None:
    """q̇_s + J⁺(ξ − J q̇_s): compiled where J is well conditioned, the pseudo-inverse where J
    is rank-deficient (a repeated row) or has fewer than 6 columns; both within rounding."""
    from grasp_safety_ros.core.method.points import tip_following_rates

    rng = np.random.default_rng(n)
    jacobians = rng.normal(size=(2, 5, 6, n))
    jacobians[1, 2, 5] = jacobians[1, 2, 4]  # rank 5: the pseudo-inverse drops a direction
    twists, base = rng.normal(size=(2, 5, 6)), rng.normal(size=(2, 5, n))
    counts = np.array([5, 3])
    rates = tip_following_rates(jacobians, counts, twists, base)
    pseudo_inverse = np.linalg.pinv(jacobians, rcond=1e-10)
    residual = twists - (jacobians @ base[..., None])[..., 0]
    expected = base + (pseudo_inverse @ residual[..., None])[..., 0]
    # A Householder QR (compiled) vs an SVD (numpy): both backward stable, so they agree to
    # cond(J) · eps (over the singular values the pseudo-inverse keeps); k = 4 n roundings
    # of the n-term products (Q, R, the back substitution, J q̇).
    tolerance = rounding_tolerance(condition_number(jacobians, PSEUDO_INVERSE_RCOND), 4 * n)
    assert_close_to_scale(rates[0], expected[0], "rates", tolerance)
    assert_close_to_scale(rates[1, :3], expected[1, :3], "rates, singular sample", tolerance)
    np.testing.assert_array_equal(rates[1, 3:], 0.0)  # beyond the grasp's count
    if n >= 6:  # the minimum-norm solution: J q̇ = ξ where J has full row rank
        moved = (jacobians[0] @ rates[0][..., None])[..., 0]
        assert_close_to_scale(moved, twists[0], "J q̇ = ξ", tolerance)


@needs_numba
def test_terms_in_small_chunks_give_the_same_report_and_progress_per_grasp(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One grasp per chunk and no chunk kept (every analysis computes its terms again): the
    same report bit for bit, and progress after every grasp of every analysis, in order, so a
    request can be abandoned between chunks."""
    from grasp_safety_ros.core.analyses import base

    seed = random_positions(arm7, np.random.default_rng(18))
    trajectory = reach_trajectory(arm7, seed)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable")
    grasps = [*grasps_near_identity(3, 19), far]
    corners = box_corners_in_object([0.08, 0.12, 0.2])
    options = AnalysisOptions(points_in_object_m=corners, whole_arm=True, effort=True)
    evaluator = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=seed)
    whole = analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)
    monkeypatch.setattr(base, "TERMS_CHUNK_SAMPLES", 1)
    monkeypatch.setattr(base, "TERMS_CACHE_SAMPLES", 1)
    calls: list[tuple[int, int]] = []
    chunked = analyse(
        evaluator,
        grasps,
        BOX,
        trajectory,
        options,
        ranking=ranking,
        progress=lambda *a: calls.append(a),
    )
    assert calls == [(k, 3 * len(grasps)) for k in range(1, 3 * len(grasps) + 1)]
    for ours, theirs in zip(
        chunked.exposed + chunked.whole_arm + chunked.effort,
        whole.exposed + whole.whole_arm + whole.effort,
        strict=True,
    ):
        for field, value in _fields(ours).items():
            np.testing.assert_array_equal(value, getattr(theirs, field), err_msg=field)

    def abandon(done: int, total: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking, progress=abandon)


@needs_numba
def test_exposed_points_on_recycled_terms_buffers_equal_one_chunk(
    arm7: RobotModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without the whole arm no analysis reads the terms twice, so each chunk's terms are
    computed into the memory of the previous chunk's (released, nothing refers to it): no
    new memory is taken, and the exposed points stay those of one chunk for all grasps, bit
    for bit (a reader holding a view of reused memory would differ), and read-only. (The
    garbage collector is off during the chunked run: a collection between two chunks may
    free another kept block, which the next chunk then takes, new memory neither.)"""
    from grasp_safety_ros.core.analyses import base
    from grasp_safety_ros.core.method import backend
    from grasp_safety_ros.core.method import terms as terms_module

    seed = random_positions(arm7, np.random.default_rng(18))
    trajectory = reach_trajectory(arm7, seed)
    far = Grasp(pin.SE3(np.eye(3), np.array([0.0, 0.0, 5.0])), "unreachable")
    grasps = [*grasps_near_identity(3, 19), far]
    options = AnalysisOptions(points_in_object_m=box_corners_in_object([0.08, 0.12, 0.2]))
    evaluator = GraspSafetyEvaluator(arm7, EvaluationConfig(workers=1))
    ranking = evaluator.rank(grasps, BOX, trajectory, seed_positions=seed)
    whole = analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)
    addresses: list[int] = []  # of each chunk's memory (no reference to it held)
    computed = backend.grasps_terms

    def spy(*args: Any) -> Any:
        terms, counts = computed(*args)
        addresses.append(terms.rotations_joint_to_world.__array_interface__["data"][0])
        return terms, counts

    monkeypatch.setattr(backend, "grasps_terms", spy)
    monkeypatch.setattr(base, "TERMS_CHUNK_SAMPLES", 1)

    def kept() -> list[int]:  # the addresses of the kept blocks (no reference held)
        return [block.__array_interface__["data"][0] for block in terms_module._BLOCKS.blocks]

    gc.collect()  # blocks held only by garbage cycles are free before the run
    before = kept()
    gc.disable()
    try:
        chunked = analyse(evaluator, grasps, BOX, trajectory, options, ranking=ranking)
    finally:
        gc.enable()
    feasible = sum(e.feasible for e in ranking.evaluations)
    assert feasible >= 2 and len(addresses) == feasible and len(set(addresses)) == 1
    assert kept() == before and addresses[0] in before  # no new memory taken
    for ours, theirs in zip(chunked.exposed, whole.exposed, strict=True):
        for field, value in _fields(ours).items():
            np.testing.assert_array_equal(value, getattr(theirs, field), err_msg=field)
            assert not (ours.feasible and value.flags.writeable), field


@needs_numba
@pytest.mark.parametrize("name", ["arm7", "baxter", "prismatic_arm", "continuous_arm"])
def test_sites_sharing_their_bodys_mobility_equal_pinocchio(
    name: str, request: pytest.FixtureRequest
) -> None:
    """Several random points on the base-most moving link, on a link without a joint of its
    own (welded to a moving one) and on the tip's link: through their body's shared 6 x 6
    mobility (u^T J_p M⁻¹ J_pᵀ u = yᵀ L y, y = (u, r × u)) equal to the Pinocchio
    reference's per-site J_p M⁻¹ J_pᵀ."""
    from grasp_safety_ros.core.analyses.arm_sites import _child_link
    from grasp_safety_ros.core.analyses.whole_arm import evaluate_whole_arm, resolve_arm_sites
    from grasp_safety_ros.core.method.points import SHARED_BODY_SITES, _shared_bodies

    robot: RobotModel = request.getfixturevalue(name)
    model = robot.model
    grasp, evaluation, terms, motion = terms_case(robot, 23)
    moving = [f for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint > 0]
    base_most = min(moving, key=lambda f: f.parentJoint)
    welded = [f for f in moving if f.name != _child_link(model, f.parentJoint)]
    assert welded, "a link without a joint of its own"
    rng = np.random.default_rng(24)
    count = SHARED_BODY_SITES + 1
    links = {base_most.name, welded[0].name, robot.tip_frame}
    points = {link: rng.uniform(-0.3, 0.3, (count, 3)) for link in sorted(links)}
    sites = resolve_arm_sites(robot, points)
    site_body = _shared_bodies(sites.joint_ids - 1, sites.support)[0]
    shared = np.array([name.endswith("]") for name in sites.names])
    assert (site_body[shared] >= 0).all()  # every user point through its body's mobility
    reference = evaluate_whole_arm(robot, evaluation, BOX, grasp, motion, sites)
    (ours,) = evaluate_whole_arm_on_terms(
        robot, [evaluation], [motion], [grasp], sites, select_regions(None), *one_grasp(terms)
    )
    np.testing.assert_array_equal(ours.stationary, reference.stationary)
    still = reference.stationary
    assert still.any() and not still.all()
    tolerance = dynamics_tolerance(robot, terms)
    for field in ("positions_in_base_m", "speed_m_s", "energy_j"):
        assert_close_to_scale(getattr(ours, field), getattr(reference, field), field, tolerance)
    np.testing.assert_allclose(  # each moving mass to its own size: 1/(yᵀ L y) is as
        # accurate as the quadratic form, whose roundings the tolerance bounds relatively
        ours.effective_mass_kg[~still],
        reference.effective_mass_kg[~still],
        rtol=tolerance,
    )
    assert_close_to_scale(  # at rest 1/λ_min (conditioned by λ_max/λ_min): compare 1/m
        1.0 / ours.effective_mass_kg[still],
        1.0 / reference.effective_mass_kg[still],
        "1/m at rest",
        tolerance,
    )
    assert_close_to_scale(
        ours.directions_in_base[~still], reference.directions_in_base[~still], "u", tolerance
    )


def _region_peaks_case() -> tuple[np.ndarray, np.ndarray, list]:
    """Speeds and masses (G, N, K) with what argmax's order decides: exact ties (a repeated
    sample, a repeated site), sites and samples at rest, masses inf, 0 and negative, a NaN
    force in one motion; regions of finite and infinite m_h, without F_tr too."""
    from grasp_safety_ros.core.analyses.body_regions import BodyRegion

    rng = np.random.default_rng(25)
    speeds = rng.uniform(0.0, 2.0, (4, 30, 5)) ** 3
    masses = rng.uniform(0.5, 20.0, (4, 30, 5))
    speeds[rng.uniform(size=speeds.shape) < 0.2] = 0.0
    speeds[:, 7] = speeds[:, 3]  # a repeated sample
    masses[:, 7] = masses[:, 3]
    speeds[:, :, 4], masses[:, :, 4] = speeds[:, :, 1], masses[:, :, 1]  # a repeated site
    speeds[:, 0] = 0.0  # a rest end
    masses[0, 5, 2], masses[1, 9, 0], masses[1, 9, 3] = np.inf, 0.0, -3.0
    masses[2, 11, 1] = np.nan
    speeds[2, 11, 1] = 1.0
    speeds[3] = 0.0  # nothing moves
    regions = [
        *select_regions(None),
        BodyRegion("rigid", 100.0, 200.0, 30_000.0, np.inf),
        BodyRegion("forbidden", 100.0, None, 30_000.0, 5.0),
    ]
    return speeds, masses, regions


@needs_numba
def test_compiled_region_peaks_are_numpys_bit_for_bit() -> None:
    """The compiled peaks evaluate few forces (a sample whose bound, from its largest v² and
    largest m v², is below a force found holds no maximum) yet give numpy's forces and
    argmax, ties, rest, inf, 0, negative and NaN masses included."""
    from grasp_safety_ros.core.analyses.arm_regions import _region_peaks, assess_sites_batch

    speeds, masses, regions = _region_peaks_case()
    durations = [2.0, 1.5, 3.0, 1.0]
    with np.errstate(invalid="ignore"):
        compiled = assess_sites_batch(speeds, masses, durations, regions, compiled=True)
        expected = assess_sites_batch(speeds, masses, durations, regions)
        where, peak = _region_peaks(speeds, masses, regions)
    # every field; the floats bit for bit (repr round-trips a float; NaN == NaN as text)
    assert repr(compiled) == repr(expected)
    assert np.isnan(peak[2]).all() and (peak[3] == 0.0).all() and (where[3] == 0).all()
    assert np.isnan(peak[1]).any() and np.isinf(peak[:2]).any()  # m < 0; m_h = m = inf
    tied = np.isin(where[:2] // 5, [3, 7]) | np.isin(where[:2] % 5, [1, 4])
    assert tied.any()  # the ties decide somewhere: the first of them
    assert not (np.isin(where[:2] // 5, [7]) | np.isin(where[:2] % 5, [4])).any()


@needs_numba
@pytest.mark.parametrize(
    ("speeds_m_s", "masses_kg", "human_mass_kg", "spring_n_per_m"),
    [
        ([1e-8, 1e-155], [1e-300, 1e300], 40.0, 1e300),  # a*b products beyond 1e±308
        ([1e-45, 1e-170], [1.0, 1e300], 1e300, 3e4),  # v² subnormal, 1/m_h tiny
        ([1e120, 2.0], [3.0, 1e-120], np.inf, 3e4),  # v² overflows, m v² underflows
    ],
)
def test_compiled_region_peaks_are_numpys_at_the_ends_of_the_float_range(
    speeds_m_s: list[float], masses_kg: list[float], human_mass_kg: float, spring_n_per_m: float
) -> None:
    """Speeds, masses, m_h and k whose pruning bounds would overflow or underflow: those
    samples are evaluated whole, so numpy's peak and its first index (not a pruned -1 or an
    earlier sample). k and m_h of 1e300 are beyond what a BodyRegion accepts (1e±100), not
    beyond what the kernel takes: numpy's side reads them from a stand-in."""
    from grasp_safety_ros.core.analyses.arm_regions import _region_peaks
    from grasp_safety_ros.core.method.points import region_peaks

    speeds = np.array(speeds_m_s).reshape(1, 2, 1)
    masses = np.array(masses_kg).reshape(1, 2, 1)
    region = SimpleNamespace(
        effective_mass_kg=human_mass_kg, spring_constant_n_per_m=spring_n_per_m
    )
    with np.errstate(all="ignore"):
        where, peak = region_peaks(
            speeds, masses, np.array([1.0 / human_mass_kg]), np.array([spring_n_per_m])
        )
        expected_where, expected_peak = _region_peaks(speeds, masses, [region])
    np.testing.assert_array_equal(where, expected_where)
    np.testing.assert_array_equal(peak, expected_peak)
    assert (peak >= 0.0).all()


def test_whole_arm_outputs_and_a_chunk_of_terms_are_kept_side_by_side() -> None:
    """The whole arm's outputs (``points._exposure_buffers``) go in the threads' kept blocks
    beside a full chunk of a 12-joint chain's terms: while those terms are held, a second
    request of outputs reuses the first's block, and no block is added or evicted."""
    from grasp_safety_ros.core.analyses.base import TERMS_CHUNK_SAMPLES
    from grasp_safety_ros.core.method import terms as terms_module
    from grasp_safety_ros.core.method.points import _exposure_buffers

    gc.collect()
    held = terms_module.sample_terms_buffers(1, TERMS_CHUNK_SAMPLES, 12)
    first = _exposure_buffers(1, TERMS_CHUNK_SAMPLES, 14, 12)
    address = first[0].base.ctypes.data
    kept = [block.ctypes.data for block in terms_module._BLOCKS.blocks]
    assert held.mass_matrix_inverses.base.ctypes.data in kept and address in kept
    del first
    second = _exposure_buffers(1, TERMS_CHUNK_SAMPLES, 14, 12)
    assert second[0].base.ctypes.data == address  # the same memory, not fresh pages
    assert [block.ctypes.data for block in terms_module._BLOCKS.blocks] == kept
    del second
    many = _exposure_buffers(1, 2_000, 1000, 12)  # more per sample than the outputs' share
    still = [block.ctypes.data for block in terms_module._BLOCKS.blocks]
    assert many[0].base is None or many[0].base.ctypes.data not in still
    assert held.mass_matrix_inverses.base.ctypes.data in still  # the terms in use stay kept
    del held, many
    terms_module._BLOCKS.blocks.clear()  # the next tests' threads start without 140 MB kept
