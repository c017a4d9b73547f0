"""Per-site speed, effective mass and admissible speed along a joint-space direction
(core.analyses.site_speeds): a point mass on a rotating link in closed form, and an
independent re-computation with Pinocchio's frame Jacobians and CRBA on a 6-DOF arm."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, serial_arm_urdf

from grasp_safety_ros.core import ObjectInertia, RobotModel
from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites
from grasp_safety_ros.core.analyses.body_regions import BODY_REGIONS
from grasp_safety_ros.core.analyses.site_speeds import SiteSpeedModel, site_speeds
from grasp_safety_ros.core.exceptions import InvalidInputError

ONE_LINK = """<robot name="one">
<link name="base"/>
<link name="arm"><inertial><origin xyz="{length} 0 0"/><mass value="{mass}"/>
<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
<link name="hand"/>
<joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
<joint name="wrist" type="fixed"><parent link="arm"/><child link="hand"/>
<origin xyz="{reach} 0 0"/></joint>
</robot>"""


def one_link(
    length: float = 0.5, mass: float = 3.0, reach: float = 0.6, armature: float = 0.1
) -> RobotModel:
    """A point mass ``mass`` at ``length`` on a link rotating about z, the tip at ``reach``."""
    urdf = ONE_LINK.format(length=length, mass=mass, reach=reach)
    return RobotModel.from_urdf(urdf, "base", "hand", armature_kgm2=[armature])


def admissible_speed(mass_kg: np.ndarray, name: str) -> np.ndarray:
    """F_tr / sqrt(μ k) from the table row itself (not the module's function)."""
    region = BODY_REGIONS[name]
    mu = 1.0 / (1.0 / region.effective_mass_kg + 1.0 / mass_kg)
    return region.max_transient_force_n / np.sqrt(mu * region.spring_constant_n_per_m)


def test_point_mass_on_a_rotating_link_closed_form() -> None:
    """I about the axis = m L² + a + m_o r² + i (object: point mass m_o with isotropic
    inertia i at the tip); a site at radius ρ moves at ρ|d| and has M_eff = I / ρ²."""
    length, mass, reach, armature, m_o, i_o = 0.5, 3.0, 0.6, 0.1, 1.2, 0.004
    robot = one_link(length, mass, reach, armature)
    inertia = ObjectInertia(m_o, np.zeros(3), i_o * np.eye(3))
    corner = np.array([[0.1, 0.0, 0.0]])  # object frame = tip frame: radius reach + 0.1
    model = SiteSpeedModel.build(
        robot, inertia, pin.SE3.Identity(), resolve_arm_sites(robot), corner, ["chest"]
    )
    assert model.sites.names == ("hand", "object[0]")
    q = np.array([[0.3], [-1.2], [2.0]])
    d = np.array([[0.7], [-2.0], [1e-3]])
    result = site_speeds(model, q, d)
    moment = mass * length**2 + armature + m_o * reach**2 + i_o
    radii = np.array([reach, reach + 0.1])
    rtol = 1e-12  # a handful of operations on O(1) numbers
    np.testing.assert_allclose(result.speed_per_unit, np.abs(d) * radii, rtol=rtol)
    np.testing.assert_allclose(
        result.effective_mass_kg, moment / radii**2 * np.ones((3, 1)), rtol=rtol
    )
    np.testing.assert_allclose(
        result.max_speed_m_s, admissible_speed(result.effective_mass_kg, "chest"), rtol=rtol
    )
    assert not result.stationary.any()
    assert (result.region_index == 0).all()


def test_site_at_rest_gets_its_largest_mass_and_no_speed() -> None:
    robot = one_link()
    model = SiteSpeedModel.build(
        robot,
        ObjectInertia(0.5, np.zeros(3), 1e-3 * np.eye(3)),
        pin.SE3.Identity(),
        resolve_arm_sites(robot),
    )
    result = site_speeds(model, np.zeros((1, 1)), np.zeros((1, 1)))
    moving = site_speeds(model, np.zeros((1, 1)), np.ones((1, 1)))
    assert result.stationary.all() and result.speed_per_unit[0, 0] == 0.0
    assert result.effective_mass_kg[0, 0] == pytest.approx(moving.effective_mass_kg[0, 0])


def test_region_is_the_smallest_admissible_speed_of_the_permitted_ones() -> None:
    """Of all regions (the head ones permit no transient contact: left out), each site is
    assessed against the one with the smallest v_max for its mass."""
    robot = one_link()
    model = SiteSpeedModel.build(
        robot,
        ObjectInertia(0.5, np.zeros(3), 1e-3 * np.eye(3)),
        pin.SE3.Identity(),
        resolve_arm_sites(robot),
    )
    assert all(r.transient_contact_permitted for r in model.regions)
    result = site_speeds(model, np.array([[0.4]]), np.array([[1.0]]))
    mass = result.effective_mass_kg[0, 0]
    by_hand = {r.name: float(admissible_speed(mass, r.name)) for r in model.regions}
    name = min(by_hand, key=by_hand.__getitem__)
    assert model.regions[result.region_index[0, 0]].name == name
    assert result.max_speed_m_s[0, 0] == pytest.approx(by_hand[name], rel=1e-12)


def test_no_permitted_region_is_refused() -> None:
    robot = one_link()
    with pytest.raises(InvalidInputError, match=r"iso_ts_15066\.regions"):
        SiteSpeedModel.build(
            robot,
            ObjectInertia(0.5, np.zeros(3), 1e-3 * np.eye(3)),
            pin.SE3.Identity(),
            resolve_arm_sites(robot),
            None,
            ["face", "neck"],
        )


class IndependentSites:
    """The oracle: the object as its own body on the tip's joint (appendBodyToJoint), a
    frame at every site, M from CRBA (armature on its diagonal) inverted by numpy, frame
    Jacobians (LOCAL_WORLD_ALIGNED); nothing of core.analyses.whole_arm or site_speeds."""

    def __init__(self, robot, sites, inertia, transform_tip_to_object, points) -> None:
        model = robot.model.copy()
        tip = model.frames[robot.tip_frame_id]
        object_in_joint = tip.placement * transform_tip_to_object.inverse()
        model.appendBodyToJoint(
            tip.parentJoint, inertia.spatial_inertia_in_object(), object_in_joint
        )
        self.frames = [
            model.addFrame(
                pin.Frame(f"site{k}", int(j), pin.SE3(np.eye(3), p), pin.FrameType.OP_FRAME)
            )
            for k, (j, p) in enumerate(zip(sites.joint_ids, sites.points_in_joint_m, strict=True))
        ]
        for k, point in enumerate(np.zeros((0, 3)) if points is None else points):
            placement = object_in_joint * pin.SE3(np.eye(3), point)
            self.frames.append(
                model.addFrame(
                    pin.Frame(f"obj{k}", tip.parentJoint, placement, pin.FrameType.OP_FRAME)
                )
            )
        self.model, self.data = model, model.createData()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        upper = pin.crba(self.model, self.data, q)
        return np.triu(upper) + np.triu(upper, 1).T

    def speeds_and_masses(self, q: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per site |J d| and 1/(uᵀ J M⁻¹ Jᵀ u) (u = J d / |J d|; NaN mass where J d = 0)."""
        minv = np.linalg.inv(self.mass_matrix(q))
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        speeds, masses = [], []
        for frame in self.frames:
            jacobian = pin.getFrameJacobian(self.model, self.data, frame, pin.LOCAL_WORLD_ALIGNED)
            velocity = jacobian[:3] @ d
            speed = float(np.linalg.norm(velocity))
            u = velocity / speed if speed > 0.0 else np.full(3, np.nan)
            speeds.append(speed)
            masses.append(1.0 / (u @ jacobian[:3] @ minv @ jacobian[:3].T @ u))
        return np.array(speeds), np.array(masses)


def test_independent_recomputation_on_a_six_dof_arm() -> None:
    """The module's speed, mass and v_max per site against ``IndependentSites``."""
    armature = np.array([0.3, 0.25, 0.2, 0.05, 0.04, 0.02])
    robot = RobotModel.from_urdf(
        serial_arm_urdf(ARM6_AXES), "base_link", "tool", armature_kgm2=armature
    )
    sites = resolve_arm_sites(robot, {"link2": [[0.05, 0.02, 0.1]]})
    inertia = ObjectInertia(1.5, np.array([0.02, -0.01, 0.05]), np.diag([0.004, 0.005, 0.006]))
    transform_tip_to_object = pin.SE3(
        pin.rpy.rpyToMatrix(0.2, -0.4, 0.9), np.array([0.0, 0.03, -0.08])
    )
    points = np.array([[0.1, 0.05, 0.0], [-0.1, 0.05, 0.12], [0.0, -0.07, -0.05]])
    speed_model = SiteSpeedModel.build(
        robot, inertia, transform_tip_to_object, sites, points, ["chest", "hand_fingers"]
    )
    oracle = IndependentSites(robot, sites, inertia, transform_tip_to_object, points)
    bare = oracle.model.copy()
    bare.armature = np.zeros(bare.nv)
    bare_data = bare.createData()
    rng = np.random.default_rng(4)
    q_all = rng.uniform(-2.0, 2.0, (5, 6))
    directions = rng.normal(size=(5, 6))
    result = site_speeds(speed_model, q_all, directions)
    for n, (q, d) in enumerate(zip(q_all, directions, strict=True)):
        # the armature is on CRBA's diagonal (rounding of O(1) sums)
        without = pin.crba(bare, bare_data, q)
        np.testing.assert_allclose(
            np.diag(oracle.mass_matrix(q)) - np.diag(without), armature, atol=1e-12
        )
        speeds, masses = oracle.speeds_and_masses(q, d)
        limits = np.minimum(
            admissible_speed(masses, "chest"), admissible_speed(masses, "hand_fingers")
        )
        # conditioning of M (armature-dominated, < 1e3) times a few ε
        np.testing.assert_allclose(result.speed_per_unit[n], speeds, rtol=1e-10)
        np.testing.assert_allclose(result.effective_mass_kg[n], masses, rtol=1e-9)
        np.testing.assert_allclose(result.max_speed_m_s[n], limits, rtol=1e-9)
    assert len(oracle.frames) == len(speed_model.sites) == len(sites) + len(points)
