"""Whole-arm exposure: site Jacobians by finite differences, effective mass as the minimum
kinetic energy, a 2-link planar closed form with armature, the tip site against the method,
site resolution, ISO/TS 15066 over sites and the whole-arm ranking."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from conftest import BAXTER_SEED, book_trajectory, random_positions
from tolerances import rounding_tolerance

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS, BodyRegion, select_regions
from grasp_safety_ros.core.analyses.iso15066 import assess_motion
from grasp_safety_ros.core.analyses.whole_arm import (
    ArmTerms,
    assess_sites,
    evaluate_whole_arm,
    evaluate_whole_arm_on_terms,
    order_by_whole_arm,
    pinocchio_kinematic_terms,
    resolve_arm_sites,
    site_exposure,
    site_jacobians,
    whole_arm_score,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.effective_mass import augmented_model

BOOK = solid_box(0.34, (0.15, 0.22, 0.015))
GRASPS = [
    Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "grasp"), f"spine_{y:+.1f}")
    for y in (-0.1, 0.0, 0.1)
]
USER_POINTS = {"link2": [[0.05, 0.02, 0.1]], "link4": [[0.0, 0.0, 0.0], [0.1, -0.05, 0.2]]}


def with_armature(robot: RobotModel, armature: np.ndarray) -> pin.Model:
    """A copy of the chain model with ``model.armature`` set (what RobotModel will write)."""
    model = robot.model.copy()
    model.armature = np.asarray(armature, dtype=float)
    return model


def site_positions_in_world(
    model: pin.Model, robot: RobotModel, q: np.ndarray, points: dict
) -> np.ndarray:
    """World positions of the user points, from the link frames' placements (no Jacobian)."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    rows = []
    for link, link_points in points.items():
        frame = model.getFrameId(link, pin.FrameType.BODY)
        rows += [data.oMf[frame].act(np.array(p, dtype=float)) for p in link_points]
    return np.array(rows)


def test_site_jacobians_match_finite_differences(arm7: RobotModel) -> None:
    sites = resolve_arm_sites(arm7, USER_POINTS, defaults=False)
    model = with_armature(arm7, np.full(arm7.model.nv, 0.3))
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(4):
        q = arm7.q_from_positions(random_positions(arm7, rng))
        kinematics = pinocchio_kinematic_terms(model, q[None])
        terms = ArmTerms(*kinematics, np.zeros((1, model.nv)))
        positions, jacobians = site_jacobians(sites, terms)
        np.testing.assert_allclose(
            positions[0], site_positions_in_world(model, arm7, q, USER_POINTS), atol=1e-12
        )
        for j in range(model.nv):
            step = np.zeros(model.nv)
            step[j] = h
            plus = site_positions_in_world(model, arm7, pin.integrate(model, q, step), USER_POINTS)
            minus = site_positions_in_world(
                model, arm7, pin.integrate(model, q, -step), USER_POINTS
            )
            np.testing.assert_allclose(jacobians[0, :, :, j], (plus - minus) / (2 * h), atol=1e-8)


def test_effective_mass_is_the_minimum_kinetic_energy(arm7: RobotModel) -> None:
    """min ½ q̇ᵀ(M + diag(armature))q̇ over q̇ with uᵀ J_p q̇ = |v| equals ½ M_eff |v|²: solved
    in the null space of the constraint (no M⁻¹), M from CRBA without armature plus the
    diagonal, J_p by finite differences."""
    armature = np.linspace(0.05, 0.4, arm7.model.nv)
    grasp = pin.SE3(pin.rpy.rpyToMatrix(0.2, -0.4, 0.3), np.array([0.02, -0.05, 0.08]))
    plain = augmented_model(arm7, BOOK, grasp)
    model = plain.copy()
    model.armature = armature
    sites = resolve_arm_sites(arm7, USER_POINTS)
    rng = np.random.default_rng(8)
    h = 1e-6
    for _ in range(4):
        positions = random_positions(arm7, rng)
        q = arm7.q_from_positions(positions)
        rates = rng.normal(size=model.nv)
        terms = ArmTerms(*pinocchio_kinematic_terms(model, q[None]), rates[None])
        exposure = site_exposure(sites, terms, arm7.transform_base_to_world)
        mass_matrix = pin.crba(plain, plain.createData(), q)
        mass_matrix = np.triu(mass_matrix) + np.triu(mass_matrix, 1).T + np.diag(armature)
        data = model.createData()
        for k, (joint_id, point) in enumerate(
            zip(sites.joint_ids, sites.points_in_joint_m, strict=True)
        ):

            def world(
                q_value: np.ndarray, joint_id: int = joint_id, point=point, data=data
            ) -> np.ndarray:
                pin.forwardKinematics(model, data, q_value)
                return data.oMi[int(joint_id)].act(point)

            jacobian = np.empty((3, model.nv))
            for j in range(model.nv):
                step = np.zeros(model.nv)
                step[j] = h
                jacobian[:, j] = (
                    world(pin.integrate(model, q, step)) - world(pin.integrate(model, q, -step))
                ) / (2 * h)
            velocity = jacobian @ rates
            speed = np.linalg.norm(velocity)
            assert exposure.speed_m_s[0, k] == pytest.approx(speed, rel=1e-6)
            constraint = jacobian.T @ (velocity / speed)  # c with cᵀ q̇ = |v|
            particular = constraint * speed / (constraint @ constraint)
            null = np.linalg.svd(constraint[None])[2][1:].T  # orthonormal basis of null(cᵀ)
            z = np.linalg.solve(null.T @ mass_matrix @ null, -null.T @ mass_matrix @ particular)
            best = particular + null @ z
            kinetic = 0.5 * best @ mass_matrix @ best
            mass = exposure.effective_mass_kg[0, k]
            assert kinetic == pytest.approx(0.5 * mass * speed**2, rel=1e-6)
            assert 0.5 * rates @ mass_matrix @ rates >= kinetic * (1 - 1e-9)  # q̇ itself is one


PLANAR = """<robot name="planar">
<link name="base"/>
<link name="upper"><inertial><origin xyz="{l1} 0 0"/><mass value="{m1}"/>
<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
<link name="fore"><inertial><origin xyz="{l2} 0 0"/><mass value="{m2}"/>
<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
<link name="hand"/>
<joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
<joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
<origin xyz="{l1} 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="5"/>
</joint>
<joint name="wrist" type="fixed"><parent link="fore"/><child link="hand"/>
<origin xyz="{l2} 0 0"/></joint>
</robot>"""


def test_two_link_planar_elbow_closed_form() -> None:
    """Point masses m1 at the elbow, m2 at the hand, rotor inertias a1, a2: the elbow moves
    along e ⟂ upper arm with J_e = l1 e [1, 0], so M_eff = det(M) / (l1² M22) with
    M11 = m1 l1² + m2 (l1² + l2² + 2 l1 l2 c2) + a1, M12 = m2 (l2² + l1 l2 c2), M22 = m2 l2² + a2.
    """
    l1, l2, m1, m2, a1, a2 = 0.4, 0.3, 2.0, 1.5, 0.2, 0.05
    robot = RobotModel.from_urdf(PLANAR.format(l1=l1, l2=l2, m1=m1, m2=m2), "base", "hand")
    model = with_armature(robot, [a1, a2])
    sites = resolve_arm_sites(robot, {"upper": [[l1, 0.0, 0.0]]})
    assert sites.names == ("hand", "upper[0]")
    rng = np.random.default_rng(2)
    q_all = rng.uniform(-2.5, 2.5, (6, 2))
    rates = rng.normal(size=(6, 2))
    terms = ArmTerms(*pinocchio_kinematic_terms(model, q_all), rates)
    exposure = site_exposure(sites, terms, robot.transform_base_to_world)
    c2 = np.cos(q_all[:, 1])
    m11 = m1 * l1**2 + m2 * (l1**2 + l2**2 + 2 * l1 * l2 * c2) + a1
    m12 = m2 * (l2**2 + l1 * l2 * c2)
    m22 = m2 * l2**2 + a2
    np.testing.assert_allclose(
        exposure.effective_mass_kg[:, 1], (m11 * m22 - m12**2) / (l1**2 * m22), rtol=1e-12
    )
    np.testing.assert_allclose(exposure.speed_m_s[:, 1], l1 * np.abs(rates[:, 0]), rtol=1e-12)
    elbow = l1 * np.stack([np.cos(q_all[:, 0]), np.sin(q_all[:, 0]), 0 * c2], axis=1)
    np.testing.assert_allclose(exposure.positions_in_base_m[:, 1], elbow, atol=1e-15)
    # The elbow at rest (shoulder still): flagged, its only direction of motion is used.
    rates[:, 0] = 0.0
    still = site_exposure(sites, ArmTerms(*terms[:4], rates), robot.transform_base_to_world)
    assert still.stationary[:, 1].all() and not still.stationary[:, 0].any()
    np.testing.assert_allclose(still.speed_m_s[:, 1], 0.0)
    np.testing.assert_allclose(
        still.effective_mass_kg[:, 1], exposure.effective_mass_kg[:, 1], rtol=1e-9
    )
    # Armature flows in: without it the elbow is lighter.
    bare = ArmTerms(*pinocchio_kinematic_terms(robot.model, q_all), terms.joint_velocities)
    lighter = site_exposure(sites, bare, robot.transform_base_to_world).effective_mass_kg[:, 1]
    assert np.all(lighter < exposure.effective_mass_kg[:, 1])


def test_armature_and_object_flow_in_through_the_augmented_model() -> None:
    """``model.armature`` written on the robot's model (as RobotModel does) reaches the
    augmented model: the elbow closed form with the object (point mass m3 with isotropic
    inertia i at the hand) added to the forearm: m2 -> m2 + m3, rotational term i."""
    from grasp_safety_ros.core import ObjectInertia

    l1, l2, m1, m2, m3, i, a1, a2 = 0.4, 0.3, 2.0, 1.5, 0.7, 0.01, 0.2, 0.05
    robot = RobotModel.from_urdf(PLANAR.format(l1=l1, l2=l2, m1=m1, m2=m2), "base", "hand")
    robot.model.armature = np.array([a1, a2])
    model = augmented_model(
        robot, ObjectInertia(m3, np.zeros(3), i * np.eye(3)), pin.SE3.Identity()
    )
    sites = resolve_arm_sites(robot, {"upper": [[l1, 0.0, 0.0]]}, defaults=False)
    q_all = np.random.default_rng(5).uniform(-2.5, 2.5, (5, 2))
    terms = ArmTerms(*pinocchio_kinematic_terms(model, q_all), np.ones((5, 2)))
    mass = site_exposure(sites, terms, robot.transform_base_to_world).effective_mass_kg[:, 0]
    c2, m = np.cos(q_all[:, 1]), m2 + m3
    m11 = m1 * l1**2 + m * (l1**2 + l2**2 + 2 * l1 * l2 * c2) + i + a1
    m12 = m * (l2**2 + l1 * l2 * c2) + i
    m22 = m * l2**2 + i + a2
    np.testing.assert_allclose(mass, (m11 * m22 - m12**2) / (l1**2 * m22), rtol=1e-12)


@pytest.fixture(scope="module")
def book(baxter: RobotModel) -> tuple:
    trajectory = book_trajectory(goal_rotation_log=(0.2, -0.3, 0.25))
    evaluator = GraspSafetyEvaluator(baxter)
    evaluations = [
        evaluator.evaluate(g, BOOK, trajectory, k, seed_positions=BAXTER_SEED)
        for k, g in enumerate(GRASPS)
    ]
    sites = resolve_arm_sites(baxter, {"right_lower_forearm": [[0.05, 0.0, 0.1]]})
    whole = [
        evaluate_whole_arm(baxter, e, BOOK, g, trajectory, sites)
        for e, g in zip(evaluations, GRASPS, strict=True)
    ]
    return trajectory, evaluations, sites, whole


def test_tip_site_reproduces_the_method(baxter: RobotModel, book: tuple) -> None:
    _, evaluations, sites, whole = book
    tip = sites.names.index(baxter.tip_frame)
    assert sites.names[:tip] == baxter.joint_names[2:]
    for evaluation, result in zip(evaluations, whole, strict=True):
        assert evaluation.feasible, evaluation.reason
        moving = ~result.stationary[:, tip]
        assert not moving[0] and not moving[-1] and moving[1:-1].all()  # at rest at both ends
        np.testing.assert_allclose(
            result.effective_mass_kg[moving, tip],
            evaluation.effective_mass_kg[moving],
            rtol=1e-8,
        )
        np.testing.assert_allclose(
            result.speed_m_s[:, tip], evaluation.tip_speed_m_s, rtol=1e-7, atol=1e-12
        )
        np.testing.assert_allclose(
            result.directions_in_base[moving, tip],
            evaluation.directions_in_base[moving],
            atol=1e-8,
        )


def test_iso_over_sites_is_the_worst_per_site_assessment(book: tuple) -> None:
    trajectory, _, sites, whole = book
    result = whole[0]
    duration = trajectory.duration_s
    regions = ("chest", "upper_arm_elbow", "face")
    assessed = assess_sites(
        result.speed_m_s, result.effective_mass_kg, duration, [BODY_REGIONS[r] for r in regions]
    )
    for region in assessed:
        per_site = [
            assess_motion(
                result.speed_m_s[:, k], result.effective_mass_kg[:, k], duration, [region.region]
            ).regions[0]
            for k in range(len(sites))
        ]
        worst_k = int(np.argmax([a.worst_force_ratio for a in per_site]))
        worst = per_site[worst_k]
        assert region.worst_force_ratio == pytest.approx(worst.worst_force_ratio, rel=1e-12)
        assert region.peak_contact_force_n == pytest.approx(
            max(a.peak_contact_force_n for a in per_site), rel=1e-12
        )
        assert region.admissible == all(a.admissible for a in per_site)
        if region.transient_contact_permitted:
            assert region.worst_site == worst_k
            assert region.min_duration_s == pytest.approx(worst.min_duration_s, rel=1e-12)
    chest = result.region("chest")
    assert result.min_duration_s >= chest.min_duration_s
    energy, site, sample = result.worst_energy
    assert energy == pytest.approx(
        0.5 * result.effective_mass_kg[sample, site] * result.speed_m_s[sample, site] ** 2
    )


def iso_force_n(speed_m_s: float, robot_mass_kg: float, region: BodyRegion) -> float:
    """ISO/TS 15066 Annex A, written out: F = v · sqrt(μ k), μ = (1/m_h + 1/m_r)⁻¹."""
    reduced = 1.0 / (1.0 / region.effective_mass_kg + 1.0 / robot_mass_kg)
    return speed_m_s * math.sqrt(reduced * region.spring_constant_n_per_m)


WHERE_TOLERANCE = rounding_tolerance(1.0, 8)
"""The ISO formula recomputed from the reported mass and speed vs the reported peak: the same
six operations (condition 1) in another order: k = 8."""


def test_every_regions_where_fields_reproduce_its_peak_force(
    baxter: RobotModel, book: tuple
) -> None:
    """For every region, those without transient contact too (ratio inf wherever a site
    moves), the reported site and sample give, through their speed and mass, the reported
    peak force, and that is the largest force over every site and sample (the compiled and
    the Pinocchio paths; the tip's own assessment likewise)."""
    from grasp_safety_ros.core.method.ik import compiled_available
    from grasp_safety_ros.core.method.terms import SampleTerms, grasp_terms

    trajectory, evaluations, sites, whole = book
    forbidden = {r.name for r in BODY_REGIONS.values() if not r.transient_contact_permitted}
    assert {"skull_forehead", "face", "neck"} <= forbidden
    chain = GraspSafetyEvaluator(baxter).ik.chain
    results = list(whole)  # the Pinocchio path
    if compiled_available():  # and the compiled one, on the shared terms
        for evaluation, grasp in zip(evaluations, GRASPS, strict=True):
            pose = grasp.transform_tip_to_object
            terms = grasp_terms(baxter, chain, BOOK, pose, evaluation.joint_positions)
            batch = SampleTerms(*(array[None] for array in terms))
            counts = np.array([len(evaluation.times_s)])
            results += evaluate_whole_arm_on_terms(
                baxter,
                [evaluation],
                [trajectory],
                [grasp],
                sites,
                select_regions(None),
                batch,
                counts,
            )
    for result in results:
        assert {r.region for r in result.regions} >= forbidden
        speeds, masses = result.speed_m_s, result.effective_mass_kg
        for assessed in result.regions:
            region = BODY_REGIONS[assessed.region]
            site, sample = assessed.worst_site, assessed.worst_sample
            at_peak = iso_force_n(speeds[sample, site], masses[sample, site], region)
            assert at_peak == pytest.approx(assessed.peak_contact_force_n, rel=WHERE_TOLERANCE), (
                assessed.region
            )
            moving = speeds > 0.0
            forces = [
                iso_force_n(v, m, region)
                for v, m in zip(speeds[moving], masses[moving], strict=True)
            ]
            assert at_peak >= max(forces) * (1.0 - WHERE_TOLERANCE), assessed.region
            if not region.transient_contact_permitted:
                assert assessed.worst_force_ratio == math.inf
    tip = assess_motion(
        evaluations[0].tip_speed_m_s,
        evaluations[0].effective_mass_kg,
        trajectory.duration_s,
        ["face", "chest"],
    )
    for assessed in tip.regions:
        sample = assessed.worst_sample
        assert assessed.contact_force_n[sample] == assessed.peak_contact_force_n
        assert assessed.peak_contact_force_n == assessed.contact_force_n.max() > 0.0


def test_whole_arm_ranking(book: tuple) -> None:
    _, _, _, whole = book
    forces = [whole_arm_score(w, "upper_arm_elbow") for w in whole]
    assert order_by_whole_arm(whole, "upper_arm_elbow") == tuple(np.argsort(forces, kind="stable"))


def test_a_site_that_cannot_move_against_an_immovable_region_has_no_force(book: tuple) -> None:
    """m_h = inf and m_r = inf (a site at rest that cannot move): F = 0·v, not 0·inf = NaN;
    the whole-arm order stays total (a NaN score, if any, goes last)."""
    from dataclasses import replace

    wall = BodyRegion("wall", 100.0, 200.0, 50_000.0, math.inf)
    speeds = np.array([[0.0, 0.5], [0.0, 0.2]])
    masses = np.array([[math.inf, 2.0], [math.inf, 3.0]])
    (assessed,) = assess_sites(speeds, masses, 1.0, [wall])
    expected = 0.5 * math.sqrt(2.0 * 50_000.0)  # μ = m_r where m_h = inf
    assert assessed.peak_contact_force_n == pytest.approx(expected, rel=1e-12)
    assert assessed.worst_site == 1 and assessed.admissible == (expected <= 200.0)
    _, _, _, whole = book
    region = "upper_arm_elbow"
    assert whole[0].feasible
    unknown = tuple(replace(r, peak_contact_force_n=math.nan) for r in whole[0].regions)
    rest = [w for w in whole[1:] if w.feasible]
    order = order_by_whole_arm([replace(whole[0], regions=unknown), *rest], region)
    by_force = sorted(rest, key=lambda w: whole_arm_score(w, region))
    assert order == (*(w.index for w in by_force), whole[0].index)


def test_sites_resolved_once(arm7: RobotModel) -> None:
    sites = resolve_arm_sites(arm7, {"link3": [[0.1, 0.0, 0.0]], "base_link": [[0, 0, 0]]})
    assert sites.names == ("j3", "j4", "j5", "j6", "j7", "tool", "link3[0]")
    assert sites.links == ("link3", "link4", "link5", "link6", "link7", "tool", "link3")
    assert sites.dropped == ("base_link[0]",)  # welded to the base: never moves
    np.testing.assert_array_equal(sites.support[-1], [True] * 3 + [False] * 4)
    with pytest.raises(InvalidInputError, match=r"robot\.exposed_points_m\.lnk3: .*link3") as err:
        resolve_arm_sites(arm7, {"lnk3": [[0, 0, 0]]})
    assert "\n" not in str(err.value)
    for bad in ({"link3": [[0, 0]]}, {"link3": [[0, 0, np.nan]]}, [[0, 0, 0]]):
        with pytest.raises(InvalidInputError, match=r"robot\.exposed_points_m"):
            resolve_arm_sites(arm7, bad)


def _scenario(tmp_path, **changes) -> str:
    import yaml

    from grasp_safety_ros.paths import config_file

    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["trajectory"]["dt_s"] = 0.1
    data["posture"] = {"restarts": 0}
    for key, value in changes.items():
        section, _, leaf = key.partition("__")
        if leaf:
            data.setdefault(section, {})[leaf] = value
        else:
            data[key] = value
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_cli_rank_by_whole_arm(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from grasp_safety_ros.cli.main import main

    scenario = _scenario(
        tmp_path,
        rank_by="whole_arm",
        robot__exposed_points_m={"right_lower_forearm": [[0.05, 0.0, 0.1]]},
        whole_arm__region="upper_arm_elbow",
    )
    out = tmp_path / "out.json"
    assert main(["rank", scenario, "--json", str(out)]) == 0
    table = capsys.readouterr().out
    assert "whole arm (sites: right_e0, " in table and "right_lower_forearm[0]" in table
    result = json.loads(out.read_text())
    assert result["whole_arm"]["sites"][-1] == "right_lower_forearm[0]"
    assert result["whole_arm"]["rank_region"] == "upper_arm_elbow"
    region = BODY_REGIONS["upper_arm_elbow"]
    peaks = []
    for grasp in result["grasps"]:
        whole = grasp["whole_arm"]
        masses = np.array(whole["effective_mass_kg"], dtype=float)  # None (inf) -> nan
        speeds = np.array(whole["speed_m_s"])
        assert masses.shape == (len(grasp["samples"]["t_s"]), len(result["whole_arm"]["sites"]))
        reduced = 1.0 / (1.0 / region.effective_mass_kg + 1.0 / np.nan_to_num(masses, nan=np.inf))
        force = speeds * np.sqrt(reduced * region.spring_constant_n_per_m)
        worst = whole["regions"]["upper_arm_elbow"]
        assert worst["peak_contact_force_n"] == pytest.approx(force.max(), rel=1e-12)
        sample, site = np.unravel_index(np.argmax(force), force.shape)
        assert worst["site"] == result["whole_arm"]["sites"][site]
        assert worst["time_s"] == pytest.approx(grasp["samples"]["t_s"][sample])
        ratios = [
            r["worst_force_ratio"] for r in whole["regions"].values() if r["worst_force_ratio"]
        ]
        assert whole["min_duration_s"] == pytest.approx(2.0 * max(ratios), rel=1e-12)
        peaks.append(worst["peak_contact_force_n"])
    assert result["ranking"] == sorted(range(3), key=lambda k: (peaks[k], k))
    assert result["paper_ranking"] == sorted(range(3), key=lambda k: result["grasps"][k]["score"])


def test_cli_whole_arm_bad_input(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from grasp_safety_ros.cli.main import main

    for changes, message in (
        (
            {"robot__exposed_points_m": {"right_lower_forarm": [[0, 0, 0]]}},
            "robot.exposed_points_m.right_lower_forarm: unknown link 'right_lower_forarm'; "
            "did you mean right_lower_forearm",
        ),
        ({"robot__exposed_points_m": {"right_lower_forearm": [[0, 0]]}}, "must be a list of"),
        ({"whole_arm__region": "elbow"}, "whole_arm.region: unknown body region 'elbow'"),
        (
            {"whole_arm__region": ["chest"]},
            "whole_arm.region: must be one body region name, got ['chest']; regions: ",
        ),
        ({"whole_arm__enabled": "yes"}, "whole_arm.enabled: must be true or false"),
    ):
        assert main(["rank", _scenario(tmp_path, **changes)]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_whole_arm_follows_the_redundancy_resolved_motion(tmp_path) -> None:
    """With redundancy on, the arm moves along the optimised joint path: the whole arm's tip
    site then has the optimised tip effective mass wherever the tip moves."""
    import yaml

    from grasp_safety_ros.core.analyses.safety_report import analyse
    from grasp_safety_ros.paths import config_file
    from grasp_safety_ros.scenario.schema import parse_scenario

    data = yaml.safe_load(config_file("book_baxter_extended.yaml").read_text())
    data["trajectory"]["dt_s"] = 0.1
    data.update(redundancy=True, rank_by="whole_arm")
    data.pop("uncertainty")
    scenario = parse_scenario(data, tmp_path)
    evaluator = GraspSafetyEvaluator(scenario.robot.load())
    report = analyse(
        evaluator,
        scenario.grasps,
        scenario.object_inertia,
        scenario.trajectory,
        scenario.options,
        scenario.robot.seed,
    )
    applied = [k for k, r in enumerate(report.redundancy) if r.applied]
    assert applied
    for k in applied:
        whole, resolution = report.whole_arm[k], report.redundancy[k]
        tip = whole.site_names.index(evaluator.robot.tip_frame)
        moving = ~whole.stationary[:, tip]
        np.testing.assert_allclose(
            whole.effective_mass_kg[moving, tip],
            resolution.effective_mass_kg[moving],
            rtol=1e-8,
        )
        assert not np.allclose(
            resolution.effective_mass_kg, report.ranking.evaluations[k].effective_mass_kg
        )


def test_tip_twists_from_the_object_motion_equal_the_trajectorys() -> None:
    """The vectorised twists (object motion sampled once) equal each trajectory's tip_twists,
    for the quintic and for a waypoint path."""
    from grasp_safety_ros.core.analyses.whole_arm import tip_twists_in_base
    from grasp_safety_ros.core.method.points import tip_twists_into
    from grasp_safety_ros.paths import config_file
    from grasp_safety_ros.scenario.schema import load_scenario

    grasp = pin.SE3(pin.rpy.rpyToMatrix(0.3, 0.2, -0.1), np.array([0.05, -0.1, 0.02]))
    waypoints = load_scenario(config_file("book_baxter_waypoints.yaml")).trajectory
    for trajectory in (book_trajectory(goal_rotation_log=(0.2, -0.3, 0.25)), waypoints):
        times = trajectory.times_s()
        expected = trajectory.tip_twists(grasp, times)[0]
        got = tip_twists_in_base(trajectory, grasp, times)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
        # several grasps at once, world axes of a rotated base: each its own tip_twists
        tips = np.array([grasp.translation, [0.1, 0.0, -0.2], [0.0, 0.3, 0.1]])
        many = np.zeros((4, len(times), 6))
        tip_twists_into(trajectory.object_motion(times), tips, grasp.rotation, [2, 0, 3], many)
        assert not many[1].any()  # a row not asked for
        for tip, got in zip(tips, many[[2, 0, 3]], strict=True):
            twists = trajectory.tip_twists(pin.SE3(grasp.rotation, tip), times)[0]
            expected = (twists.reshape(-1, 2, 3) @ grasp.rotation.T).reshape(-1, 6)
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * np.abs(expected).max())


def test_cli_rank_by_whole_arm_chooses_postures_by_it(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With posture restarts, rank_by whole_arm picks each start posture by the force it
    ranks by: the JSON records it, and it is the force the whole-arm block reports."""
    import json

    from grasp_safety_ros.cli.main import main

    scenario = _scenario(
        tmp_path, rank_by="whole_arm", whole_arm__region="upper_arm_elbow", posture={"restarts": 4}
    )
    out = tmp_path / "out.json"
    assert main(["rank", scenario, "--json", str(out)]) == 0
    assert "chosen by whole_arm:upper_arm_elbow " in capsys.readouterr().out
    for grasp in json.loads(out.read_text())["grasps"]:
        posture = grasp["posture"]
        assert posture["criterion"] == "whole_arm:upper_arm_elbow"
        assert posture["criterion_value"] <= posture["criterion_single_ik"]
        worst = grasp["whole_arm"]["regions"]["upper_arm_elbow"]
        assert posture["criterion_value"] == pytest.approx(worst["peak_contact_force_n"], 1e-12)
    assert main(["rank", _scenario(tmp_path, posture={"restarts": 4}), "--json", str(out)]) == 0
    assert "criterion" not in json.loads(out.read_text())["grasps"][0]["posture"]
