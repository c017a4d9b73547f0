"""The live speed-scaling analysis (core.analyses.speed_scaling), against closed forms.

Oracles: a one-joint arm (a rotating link, a payload and a point beyond the tip) has a site
effective mass I/r^2 and speed r|q̇| in closed form, hence the factor of ISO/TS 15066's
formulas written out here; on a 7-joint arm, the identity that scaling q̇ by f leaves every
effective mass unchanged, so the state q̇·f is exactly at the limit (its factor is 1 and any
faster state's is below 1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ARM7_AXES, serial_arm_urdf

from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites
from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.speed_scaling import (
    IncreaseLimiter,
    SpeedScaling,
    check_margin,
    check_rest_speed,
    headroom,
    payload_speed_model,
    region_speeds,
    scaling_factor,
)
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.model.inertia import ObjectInertia
from grasp_safety_ros.core.model.robot import RobotModel

EPS = np.finfo(float).eps
LINK_MASS_KG, LINK_COM_M, LINK_IZZ_KGM2, TIP_M = 2.0, 0.3, 0.02, 0.5
ARMATURE_KGM2 = 0.15
PERMITTED = [r for r in BODY_REGIONS.values() if r.transient_contact_permitted]


def one_joint_urdf() -> str:
    """A link turning about z: mass at (LINK_COM_M, 0, 0), the tool frame at (TIP_M, 0, 0)."""
    inertia = f'ixx="0.01" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="{LINK_IZZ_KGM2}"'
    return (
        '<robot name="one"><link name="base"/>'
        f'<link name="arm"><inertial><origin xyz="{LINK_COM_M} 0 0"/>'
        f'<mass value="{LINK_MASS_KG}"/><inertia {inertia}/></inertial></link>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>'
        '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="3"/></joint>'
        '<link name="tool"/><joint name="tool_joint" type="fixed"><parent link="arm"/>'
        f'<child link="tool"/><origin xyz="{TIP_M} 0 0"/></joint></robot>'
    )


def v_max_m_s(effective_mass_kg: float, region_name: str) -> float:
    """ISO/TS 15066 Annex A: F_tr / sqrt(mu k), mu = (1/m_h + 1/m_r)^-1, written out."""
    region = BODY_REGIONS[region_name]
    mu = 1.0 / (1.0 / region.effective_mass_kg + 1.0 / effective_mass_kg)
    return region.max_transient_force_n / math.sqrt(mu * region.spring_constant_n_per_m)


def test_factor_of_given_speeds_and_limits() -> None:
    speeds = np.array([0.0, 2.0, 0.5, 1.0])
    limits = np.array([0.001, 1.0, 0.25, 4.0])  # the site at rest does not limit
    assert scaling_factor(speeds, limits) == 0.5
    assert scaling_factor(speeds, limits, margin=0.8) == pytest.approx(0.4, rel=4 * EPS)
    assert scaling_factor(np.array([0.1]), np.array([1.0])) == 1.0  # never above 1
    assert scaling_factor(np.zeros(3), np.zeros(3)) == 1.0  # nothing moves
    assert scaling_factor(np.zeros(0), np.zeros(0)) == 1.0
    assert headroom(speeds, limits, margin=0.5) == 0.25
    assert headroom(np.zeros(2), np.ones(2)) == math.inf


def test_sites_at_or_below_the_rest_speed_do_not_limit() -> None:
    speeds = np.array([0.0005, 0.001, 0.5])
    limits = np.array([1e-6, 1e-6, 0.25])  # the two slow ones would give 0.002 and 0.001
    assert headroom(speeds, limits, rest_speed_m_s=0.001) == 0.5
    assert headroom(speeds, limits) == pytest.approx(0.001, rel=EPS)  # rest 0: they limit
    assert scaling_factor(speeds[:2], limits[:2], rest_speed_m_s=0.001) == 1.0
    assert headroom(speeds[:2], limits[:2], rest_speed_m_s=0.001) == math.inf
    (status,) = region_speeds(
        ("a", "b"), speeds[:2], np.ones(2), [BODY_REGIONS["chest"]], rest_speed_m_s=0.001
    )
    assert (status.site, status.speed_m_s, status.factor) == ("", 0.0, 1.0)


@pytest.mark.parametrize("rest", [-0.001, 0.011, math.nan])
def test_rest_speed_outside_its_range_is_refused(rest: float) -> None:
    with pytest.raises(InvalidInputError, match=r"speed_scaling\.rest_speed_m_s: must be"):
        check_rest_speed(rest)


@pytest.mark.parametrize("margin", [0.0, -0.1, 1.5, math.nan])
def test_margin_outside_0_1_is_refused(margin: float) -> None:
    with pytest.raises(InvalidInputError, match=r"speed_scaling\.margin"):
        check_margin(margin)


def test_increase_limiter_bounds_rises_only() -> None:
    limiter = IncreaseLimiter(max_increase_per_s=2.0, factor=0.0, time_s=10.0)
    assert limiter(1.0, 10.1) == pytest.approx(0.2, abs=8 * EPS)  # 2/s for 0.1 s
    assert limiter(1.0, 10.3) == pytest.approx(0.6, abs=8 * EPS)
    assert limiter(0.25, 10.31) == 0.25  # a fall passes at once
    assert limiter(0.3, 10.31) == 0.25  # no time, no rise
    assert limiter(0.3, 11.0) == 0.3  # never above the target
    assert limiter(0.0, 9.0) == 0.0  # time going back: falls still pass
    assert limiter(1.0, 8.0) == 0.0  # ... rises do not


@pytest.fixture(scope="module")
def one_joint() -> RobotModel:
    return RobotModel.from_urdf(one_joint_urdf(), "base", "tool").with_armature([ARMATURE_KGM2])


@pytest.mark.parametrize("qd", [0.4, -1.3, 3.0])
@pytest.mark.parametrize("margin", [1.0, 0.7])
def test_one_joint_arm_with_payload_matches_the_closed_form(
    one_joint: RobotModel, qd: float, margin: float
) -> None:
    payload_kg, payload_i, point_dx = 1.5, 0.004, 0.08
    payload = ObjectInertia(payload_kg, np.zeros(3), np.eye(3) * payload_i)
    sites = resolve_arm_sites(one_joint)
    assert sites.names == ("tool",)  # one joint: the tip only
    model = payload_speed_model(one_joint, sites, payload, np.array([[point_dx, 0, 0]]), None)
    analysis = SpeedScaling(model, margin)
    state = analysis.assess(np.array([0.7]), np.array([qd]))
    inertia = LINK_IZZ_KGM2 + LINK_MASS_KG * LINK_COM_M**2 + ARMATURE_KGM2
    inertia += payload_i + payload_kg * TIP_M**2  # about the joint axis [kg m^2]
    radii = {"tool": TIP_M, "object[0]": TIP_M + point_dx}
    expected = 1.0
    for region in PERMITTED:
        status = next(r for r in state.regions if r.region == region.name)
        # the outer point is the worst for every region: v sqrt(mu) grows with the radius
        r = radii["object[0]"]
        mass = inertia / r**2
        assert status.site == "object[0]"
        assert status.effective_mass_kg == pytest.approx(mass, rel=1e-12)
        assert status.speed_m_s == pytest.approx(r * abs(qd), rel=1e-12)
        assert status.max_speed_m_s == pytest.approx(v_max_m_s(mass, region.name), rel=1e-12)
        expected = min(expected, margin * v_max_m_s(mass, region.name) / (r * abs(qd)))
    assert state.factor == pytest.approx(expected, rel=1e-12)
    assert (state.limiting_site == "object[0]") == (expected < 1.0)


def test_one_joint_arm_at_rest_and_without_payload(one_joint: RobotModel) -> None:
    sites = resolve_arm_sites(one_joint)
    analysis = SpeedScaling(payload_speed_model(one_joint, sites, None, None, None))
    assert analysis.speed_model.sites.names == ("tool",)  # no payload: no payload points
    at_rest = analysis.assess(np.array([0.2]), np.array([0.0]))
    assert at_rest.factor == 1.0 and at_rest.limiting_site == ""
    assert all(r.site == "" and r.factor == 1.0 for r in at_rest.regions)
    moving = analysis.assess(np.array([0.2]), np.array([2.0]))
    mass = (LINK_IZZ_KGM2 + LINK_MASS_KG * LINK_COM_M**2 + ARMATURE_KGM2) / TIP_M**2
    expected = min(v_max_m_s(mass, r.name) for r in PERMITTED) / (TIP_M * 2.0)
    assert moving.factor == pytest.approx(min(1.0, expected), rel=1e-12)


@pytest.fixture(scope="module")
def arm7_scaling() -> SpeedScaling:
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool")
    payload = ObjectInertia(1.0, np.array([0.0, 0.0, 0.05]), np.eye(3) * 0.002)
    corners = np.array(box_corners_in_object([0.1, 0.08, 0.06], payload.com_in_object_m))
    model = payload_speed_model(robot, resolve_arm_sites(robot), payload, corners, None)
    return SpeedScaling(model, margin=0.9)


def test_scaling_the_velocity_by_the_factor_reaches_the_limit(
    arm7_scaling: SpeedScaling,
) -> None:
    """f(q, f·q̇) = 1 and f(q, (1 + 1e-6)·f·q̇) < 1: effective masses do not depend on |q̇|."""
    rng = np.random.default_rng(3)
    robot = arm7_scaling.speed_model.robot
    assert len(arm7_scaling.speed_model.sites) == 5 + 1 + 8  # joints 3..7, tip, 8 corners
    for _ in range(20):
        q = rng.uniform(-2.5, 2.5, robot.num_joints)
        qd = rng.uniform(-3.0, 3.0, robot.num_joints)
        state = arm7_scaling.assess(q, qd)
        assert 0.0 < state.factor < 1.0, state.factor
        at_limit = arm7_scaling.assess(q, state.factor * qd)
        assert at_limit.factor == pytest.approx(1.0, abs=1e-12)
        assert arm7_scaling.assess(q, (1.0 + 1e-6) * state.factor * qd).factor < 1.0
        worst = min(state.regions, key=lambda r: r.factor)
        assert worst.factor == pytest.approx(state.factor, rel=1e-12)
        assert (worst.site, worst.region) == (state.limiting_site, state.limiting_region)


def test_region_speeds_pick_the_site_nearest_its_limit() -> None:
    chest = BODY_REGIONS["chest"]
    names = ("a", "b", "c")
    speeds = np.array([1.0, 0.0, 0.4])
    masses = np.array([1.0, 50.0, 60.0])  # b is at rest: never the worst
    (status,) = region_speeds(names, speeds, masses, [chest])
    ratios = [speeds[k] / v_max_m_s(masses[k], "chest") for k in (0, 2)]
    assert status.site == ("a", "c")[int(np.argmax(ratios))]
    assert status.factor == pytest.approx(min(1.0, 1.0 / max(ratios)), rel=1e-12)


def test_bad_states_are_refused_naming_the_field(arm7_scaling: SpeedScaling) -> None:
    with pytest.raises(InvalidInputError, match=r"joint_states\.velocity"):
        arm7_scaling.assess(np.zeros(7), np.array([0.0, math.nan, 0, 0, 0, 0, 0]))
    with pytest.raises(InvalidInputError, match=r"joint_states\.position"):
        arm7_scaling.assess(np.zeros(6), np.zeros(7))
