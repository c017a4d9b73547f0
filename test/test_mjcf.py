"""MJCF (MuJoCo XML) robot descriptions: read with Pinocchio's MJCF reader, armature included;
the same arm as URDF + robot.armature_kgm2 gives the same numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions
from tolerances import assert_close_to_scale, condition_number, rounding_tolerance

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.method.joint_trajectory import PlannedJointTrajectory

LINKS = (  # (body position in parent [m], joint axis, mass [kg], CoM [m], diagonal inertia)
    ((0.0, 0.0, 0.1), (0, 0, 1), 3.0, (0.0, 0.01, 0.12), (0.03, 0.03, 0.01)),
    ((0.0, 0.05, 0.25), (0, 1, 0), 2.5, (0.1, 0.0, 0.02), (0.01, 0.04, 0.04)),
    ((0.3, 0.0, 0.0), (0, 1, 0), 1.5, (0.12, 0.0, 0.0), (0.005, 0.02, 0.02)),
    ((0.25, 0.0, 0.02), (1, 0, 0), 0.8, (0.03, 0.0, 0.01), (0.002, 0.003, 0.003)),
)
ARMATURE = (0.4, 0.35, 0.2, 0.05)
TOOL = (0.1, 0.0, 0.0)


def vector(values) -> str:
    return " ".join(f"{v:g}" for v in values)


def arm_mjcf(armature: tuple[float, ...] = ARMATURE, mesh: bool = True) -> str:
    """The arm in MJCF: radians, armature per joint, a mesh geom whose file does not exist."""
    parts = [
        '<mujoco model="arm"><compiler angle="radian"/>',
        '<asset><mesh name="shell" file="no/such/shell.stl"/></asset>' if mesh else "",
        '<worldbody><body name="base_link">',
    ]
    for k, (position, axis, mass, com, inertia) in enumerate(LINKS):
        parts.append(
            f'<body name="link{k + 1}" pos="{vector(position)}">'
            f'<joint name="j{k + 1}" type="hinge" axis="{vector(axis)}" range="-2.5 2.5" '
            f'armature="{armature[k]:g}"/>'
            f'<inertial pos="{vector(com)}" mass="{mass:g}" diaginertia="{vector(inertia)}"/>'
            + ('<geom type="mesh" mesh="shell"/>' if mesh else "")
        )
    parts.append(f'<site name="tool" pos="{vector(TOOL)}"/>')
    parts.append("</body>" * len(LINKS) + "</body></worldbody></mujoco>")
    return "".join(parts)


def arm_urdf() -> str:
    parts = ['<robot name="arm"><link name="base_link"/>']
    parent = "base_link"
    for k, (position, axis, mass, com, inertia) in enumerate(LINKS):
        ixx, iyy, izz = inertia
        parts.append(
            f'<link name="link{k + 1}"><inertial><origin xyz="{vector(com)}"/>'
            f'<mass value="{mass:g}"/><inertia ixx="{ixx:g}" ixy="0" ixz="0" iyy="{iyy:g}" '
            f'iyz="0" izz="{izz:g}"/></inertial></link>'
            f'<joint name="j{k + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link{k + 1}"/><origin xyz="{vector(position)}"/>'
            f'<axis xyz="{vector(axis)}"/>'
            '<limit lower="-2.5" upper="2.5" effort="50" velocity="2"/></joint>'
        )
        parent = f"link{k + 1}"
    parts.append(
        f'<link name="tool"/><joint name="tool_joint" type="fixed"><parent link="{parent}"/>'
        f'<child link="tool"/><origin xyz="{vector(TOOL)}"/></joint></robot>'
    )
    return "".join(parts)


def symmetric(upper: np.ndarray) -> np.ndarray:
    upper = np.triu(upper)
    return upper + np.triu(upper, 1).T


def test_mjcf_text_and_file_load_with_their_armature_and_missing_meshes(tmp_path: Path) -> None:
    from_text = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    (tmp_path / "arm.xml").write_text(arm_mjcf())
    from_file = RobotModel.from_urdf("arm.xml", "base_link", "tool", relative_to=tmp_path)
    for robot in (from_text, from_file):
        assert robot.joint_names == ("j1", "j2", "j3", "j4")
        np.testing.assert_array_equal(robot.armature_kgm2, ARMATURE)
        assert robot.armature_given
    override = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool", armature_kgm2={"j1": 1.0})
    np.testing.assert_array_equal(override.armature_kgm2, [1.0, *ARMATURE[1:]])


def test_a_partial_armature_mapping_keeps_the_mjcf_armature_of_the_other_joints(
    tmp_path: Path,
) -> None:
    """Naming one joint must not zero the others' rotor inertia (that would lower every
    effective mass): in the model, a scenario (value and range) and the node parameters."""
    from grasp_safety_ros.ros.parameters import settings_from_parameters
    from grasp_safety_ros.ros.robot.bundle import build_robot
    from grasp_safety_ros.scenario.schema import parse_robot

    kept = [*ARMATURE[:3], 0.1]
    robot = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    np.testing.assert_array_equal(robot.with_armature({"j4": 0.1}).armature_kgm2, kept)
    (tmp_path / "arm.xml").write_text(arm_mjcf())
    for armature, lower in (({"j4": 0.1}, kept), ({"j4": [0.0, 0.1]}, [*ARMATURE[:3], 0.0])):
        spec = parse_robot(
            {
                "urdf": "arm.xml",
                "base_frame": "base_link",
                "tip_frame": "tool",
                "armature_kgm2": armature,
            }
        )
        loaded = spec.load(tmp_path)
        np.testing.assert_array_equal(loaded.armature_kgm2, kept)
        bounds = spec.armature_range(loaded)
        np.testing.assert_array_equal(bounds.lower_kgm2, lower)
        np.testing.assert_array_equal(bounds.upper_kgm2, kept)
    settings = settings_from_parameters(
        {
            "robot_description": arm_mjcf(),
            "base_frame": "base_link",
            "tip_frame": "tool",
            "robot.armature_kgm2": [0.1],
            "robot.armature_joint_names": ["j4"],
        }
    )
    bundle = build_robot(settings, None)
    assert bundle is not None
    np.testing.assert_array_equal(bundle.robot.armature_kgm2, kept)


def test_mjcf_equals_urdf_with_armature_to_1e_12() -> None:
    mjcf = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    urdf = RobotModel.from_urdf(arm_urdf(), "base_link", "tool", armature_kgm2=list(ARMATURE))
    np.testing.assert_array_equal(mjcf.lower_limits, urdf.lower_limits)
    rng = np.random.default_rng(2)
    mjcf_data, urdf_data = mjcf.model.createData(), urdf.model.createData()
    for _ in range(5):
        positions = random_positions(urdf, rng)
        q = urdf.q_from_positions(positions)
        np.testing.assert_allclose(
            symmetric(pin.crba(mjcf.model, mjcf_data, q)),
            symmetric(pin.crba(urdf.model, urdf_data, q)),
            rtol=0,
            atol=1e-12,
        )
        pose_mjcf, pose_urdf = (
            mjcf.transform_tip_to_base(positions),
            urdf.transform_tip_to_base(positions),
        )
        np.testing.assert_allclose(pose_mjcf.homogeneous, pose_urdf.homogeneous, atol=1e-12)
    seed = np.array([0.3, -0.4, 0.9, 0.2])
    start = urdf.transform_tip_to_base(seed)
    trajectory = ObjectTrajectory(start, start, 1.0, 0.1)  # unused: the grasp has its plan
    times = np.linspace(0.0, 1.0, 6)
    positions = seed + np.outer(times, [0.3, -0.2, 0.4, 0.5])
    plan = PlannedJointTrajectory(urdf.joint_names, times, positions)
    box = solid_box(0.3, [0.05, 0.05, 0.08])
    grasps = [Grasp(pin.SE3.Identity(), "tip", plan)]
    config = EvaluationConfig(workers=1)
    a = GraspSafetyEvaluator(mjcf, config).rank(grasps, box, trajectory, seed).evaluations[0]
    b = GraspSafetyEvaluator(urdf, config).rank(grasps, box, trajectory, seed).evaluations[0]
    assert a.feasible and b.feasible
    np.testing.assert_allclose(a.effective_mass_kg, b.effective_mass_kg, rtol=1e-12)
    np.testing.assert_allclose(
        a.links_only_effective_mass_kg, b.links_only_effective_mass_kg, rtol=1e-12
    )


def test_mjcf_body_with_geoms_and_no_inertial_is_refused() -> None:
    text = arm_mjcf().replace(
        '<inertial pos="0.12 0 0" mass="1.5" diaginertia="0.005 0.02 0.02"/>', ""
    )
    with pytest.raises(InvalidInputError, match=r"robot.urdf: MJCF bodies link3 have geoms"):
        RobotModel.from_urdf(text, "base_link", "tool")
    with pytest.raises(InvalidInputError, match=r"robot.urdf: cannot read MJCF XML"):
        RobotModel.from_urdf("<mujoco><worldbody><body", "base_link", "tool")


def test_node_takes_an_mjcf_robot_description() -> None:
    from grasp_safety_ros.ros.parameters import settings_from_parameters
    from grasp_safety_ros.ros.robot.bundle import build_robot

    settings = settings_from_parameters(
        {"robot_description": arm_mjcf(), "base_frame": "base_link", "tip_frame": "tool"}
    )
    bundle = build_robot(settings, None)
    assert bundle is not None and bundle.origin == "robot_description"
    np.testing.assert_array_equal(bundle.robot.armature_kgm2, ARMATURE)
    from_topic = build_robot(
        settings_from_parameters({"base_frame": "base_link", "tip_frame": "tool"}), arm_mjcf()
    )
    assert from_topic is not None and from_topic.origin == "/robot_description"
    assert from_topic.robot.joint_names == ("j1", "j2", "j3", "j4")


# --- Frames below jointless bodies: where MuJoCo places them ----------------------------------

PLACED_M = 1e-9
"""Frames agree with MuJoCo's to this distance [m] and angle [rad] (both rounding-level)."""


def turn(x: float, y: float, z: float) -> np.ndarray:
    return pin.exp3(np.array([x, y, z]))


def chain_bodies(depth: int) -> list[tuple]:
    """(name, parent, pos, rotation, joint axis or None, sites) of an arm whose two hinges are
    followed by ``depth`` jointless bodies, each offset and turned, then a 'hand' (turned 90°
    about z, site 'tcp' at x 0.1) and a hinged 'wrist' carrying a jointless 'palm' and
    below it a jointless 'finger' (site 'pad'). The base body 'base_link' sits at the world
    origin."""
    bodies = [
        ("link1", "base_link", (0.0, 0.0, 0.1), turn(0, 0, 0), (0, 0, 1), []),
        ("link2", "link1", (0.0, 0.05, 0.25), turn(0.2, 0, 0), (0, 1, 0), []),
    ]
    parent = "link2"
    for k in range(depth):
        name = f"fixed{k + 1}"
        rotation = turn(0.3 * (k + 1), -0.2, 0.4)
        bodies.append((name, parent, (0.5, 0.1 * k, 0.05), rotation, None, []))
        parent = name
    bodies += [
        ("hand", parent, (0.2, 0.0, 0.0), turn(0, 0, np.pi / 2), None, [("tcp", (0.1, 0, 0))]),
        ("wrist", parent, (0.0, 0.1, 0.2), turn(0, 0.3, 0), (1, 0, 0), []),
        ("palm", "wrist", (0.05, 0.0, 0.1), turn(0, 0.2, 0.1), None, []),
        ("finger", "palm", (0.15, 0.0, 0.05), turn(0.5, 0, 0.2), None, [("pad", (0.1, 0, 0))]),
    ]
    return bodies


def chain_mjcf(bodies: list[tuple]) -> str:
    children: dict[str, list[tuple]] = {}
    for body in bodies:
        children.setdefault(body[1], []).append(body)

    def body_xml(name: str, parent: str, pos, rotation, axis, sites) -> str:
        quat = pin.Quaternion(rotation)
        joint = f'<joint name="{name}_joint" axis="{vector(axis)}" range="-3 3"/>' if axis else ""
        return (
            f'<body name="{name}" pos="{vector(pos)}" '
            f'quat="{quat.w!r} {quat.x!r} {quat.y!r} {quat.z!r}">{joint}'
            '<inertial pos="0.05 0.01 0.02" mass="0.7" diaginertia="0.01 0.02 0.015"/>'
            + "".join(f'<site name="{s}" pos="{vector(p)}"/>' for s, p in sites)
            + "".join(body_xml(*child) for child in children.get(name, []))
            + "</body>"
        )

    inner = "".join(body_xml(*child) for child in children["base_link"])
    return (
        '<mujoco model="chain"><compiler angle="radian"/><worldbody><body name="base_link">'
        f"{inner}</body></worldbody></mujoco>"
    )


def chain_urdf(bodies: list[tuple]) -> str:
    """The same geometry in URDF: hinges as revolute joints, the rest fixed, sites as links."""
    parts = ['<robot name="chain"><link name="base_link"/>']
    inertial = (
        '<inertial><origin xyz="0.05 0.01 0.02"/><mass value="0.7"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.015"/></inertial>'
    )
    for name, parent, pos, rotation, axis, sites in bodies:
        kind = "revolute" if axis else "fixed"
        rpy = " ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(rotation))
        parts.append(
            f'<link name="{name}">{inertial}</link><joint name="{name}_joint" type="{kind}">'
            f'<parent link="{parent}"/><child link="{name}"/>'
            f'<origin xyz="{vector(pos)}" rpy="{rpy}"/>'
            + (
                f'<axis xyz="{vector(axis)}"/><limit lower="-3" upper="3" effort="50" '
                'velocity="2"/>'
                if axis
                else ""
            )
            + "</joint>"
        )
        for site, offset in sites:
            parts.append(
                f'<link name="{site}"/><joint name="{site}_site" type="fixed">'
                f'<parent link="{name}"/><child link="{site}"/><origin xyz="{vector(offset)}"/>'
                "</joint>"
            )
    return "".join(parts) + "</robot>"


def test_the_issue_case_a_site_below_a_jointless_body_lands_where_mujoco_puts_it() -> None:
    """A hinge body, a jointless body at x 0.5, a body at x 0.2 turned 90° about z with a site
    at x 0.1: MuJoCo places the site at (0.7, 0.1, 0) (Pinocchio 4.1 alone: (0.2, 0.1, 0))."""
    from grasp_safety_ros.core.model.robot import load_urdf_model

    xml = (
        '<mujoco><worldbody><body name="arm"><joint name="j1" axis="0 0 1"/>'
        '<inertial pos="0.1 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>'
        '<body name="plate" pos="0.5 0 0">'
        '<inertial pos="0 0 0" mass="0.5" diaginertia="0.01 0.01 0.01"/>'
        '<body name="hand" pos="0.2 0 0" euler="0 0 90">'
        '<inertial pos="0 0 0" mass="0.3" diaginertia="0.01 0.01 0.01"/>'
        '<site name="tcp" pos="0.1 0 0"/></body></body></body></worldbody></mujoco>'
    )
    model = load_urdf_model(xml)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    tcp = data.oMf[model.getFrameId("tcp")]
    np.testing.assert_allclose(tcp.translation, [0.7, 0.1, 0.0], rtol=0, atol=PLACED_M)
    np.testing.assert_allclose(tcp.rotation, turn(0, 0, np.pi / 2), rtol=0, atol=PLACED_M)


WRIST = '<joint name="wrist_joint" axis="1 0 0" range="-3 3"/>'
WRISTS = {  # the wrist's hinge as written, unbounded, with a reference angle, or sliding
    "hinge": WRIST,
    "unbounded": '<joint name="wrist_joint" axis="1 0 0"/>',
    "ref": '<joint name="wrist_joint" axis="1 0 0" range="-3 3" ref="0.7"/>',
    "slide": '<joint name="wrist_joint" type="slide" axis="1 0 0" range="-0.3 0.3"/>',
}


@pytest.mark.parametrize(
    ("depth", "wrist"),
    [(1, "hinge"), (2, "hinge"), (3, "hinge"), (2, "unbounded"), (3, "ref"), (1, "slide")],
)
def test_sites_and_bodies_below_jointless_chains_match_mujoco(depth: int, wrist: str) -> None:
    """Oracle: MuJoCo's own forward kinematics (xpos/xmat, site_xpos/site_xmat) of the same
    MJCF at random configurations (Pinocchio's q: MuJoCo's qpos minus qpos0, the joints'
    ``ref``), every body and site."""
    import mujoco

    from grasp_safety_ros.core.model.robot import load_urdf_model

    xml = chain_mjcf(chain_bodies(depth)).replace(WRIST, WRISTS[wrist])
    model, mj_model = load_urdf_model(xml), mujoco.MjModel.from_xml_string(xml)
    mj_data, data = mujoco.MjData(mj_model), model.createData()
    rng = np.random.default_rng(depth)
    for _ in range(5):
        angles = rng.uniform(-3.0, 3.0, mj_model.nq)
        mj_data.qpos[:] = angles
        mujoco.mj_kinematics(mj_model, mj_data)
        q = np.zeros(model.nq)
        for joint_id in range(1, model.njoints):
            index = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, model.names[joint_id])
            address = mj_model.jnt_qposadr[index]
            q[model.joints[joint_id].idx_q] = angles[address] - mj_model.qpos0[address]
        pin.framesForwardKinematics(model, data, q)
        for kind, names, origins, axes in (
            (
                mujoco.mjtObj.mjOBJ_BODY,
                ("hand", "wrist", "palm", "finger"),
                mj_data.xpos,
                mj_data.xmat,
            ),
            (mujoco.mjtObj.mjOBJ_SITE, ("tcp", "pad"), mj_data.site_xpos, mj_data.site_xmat),
        ):
            for name in names:
                index = mujoco.mj_name2id(mj_model, kind, name)
                placement = data.oMf[model.getFrameId(name)]
                np.testing.assert_allclose(
                    placement.translation, origins[index], rtol=0, atol=PLACED_M, err_msg=name
                )
                np.testing.assert_allclose(
                    placement.rotation.ravel(), axes[index], rtol=0, atol=PLACED_M, err_msg=name
                )


def test_a_tip_site_below_jointless_bodies_ranks_as_the_same_urdf() -> None:
    """tip_frame on the MJCF site 'pad' (two jointless bodies below a hinged wrist, itself below
    two jointless bodies) ranks as the URDF of the same geometry with a 'pad' link: same tip
    poses, same masses along the same planned joint path (both Pinocchio; fixed joints merged
    in another order: rounding, k · cond(M) · eps)."""
    bodies = chain_bodies(2)
    mjcf = RobotModel.from_urdf(chain_mjcf(bodies), "base_link", "pad")
    urdf = RobotModel.from_urdf(chain_urdf(bodies), "base_link", "pad")
    assert mjcf.joint_names == urdf.joint_names
    times = np.linspace(0.0, 1.0, 6)
    positions = np.array([0.3, -0.4, 0.9]) + np.outer(times, [0.3, -0.2, 0.4])
    for row in positions:
        np.testing.assert_allclose(
            mjcf.transform_tip_to_base(row).homogeneous,
            urdf.transform_tip_to_base(row).homogeneous,
            rtol=0,
            atol=PLACED_M,
        )
    plan = PlannedJointTrajectory(urdf.joint_names, times, positions)
    start = urdf.transform_tip_to_base(positions[0])
    trajectory = ObjectTrajectory(start, start, 1.0, 0.1)  # unused: the grasp has its plan
    box = solid_box(0.3, [0.05, 0.05, 0.08])
    grasps = [Grasp(pin.SE3.Identity(), "tip", plan)]
    config = EvaluationConfig(workers=1)
    a = GraspSafetyEvaluator(mjcf, config).rank(grasps, box, trajectory, positions[0])
    b = GraspSafetyEvaluator(urdf, config).rank(grasps, box, trajectory, positions[0])
    assert a.evaluations[0].feasible and b.evaluations[0].feasible
    data = urdf.model.createData()
    masses = [symmetric(pin.crba(urdf.model, data, urdf.q_from_positions(p))) for p in positions]
    tolerance = rounding_tolerance(condition_number(masses), 16 * urdf.num_joints)
    assert_close_to_scale(
        a.evaluations[0].effective_mass_kg, b.evaluations[0].effective_mass_kg, "mass", tolerance
    )
    assert a.order == b.order


def test_a_frame_that_cannot_be_placed_as_mujoco_is_refused_naming_it() -> None:
    """A frame that a fixed offset from its Pinocchio joint cannot put where MuJoCo puts it at
    both configurations (here: MuJoCo reads a description whose second hinge sits elsewhere)
    is refused, naming the frame."""
    from grasp_safety_ros.core.model.mjcf_frames import place_frames_as_mujoco
    from grasp_safety_ros.core.model.robot import load_urdf_model

    bodies = chain_bodies(1)
    model = load_urdf_model(chain_mjcf(bodies))
    moved = [
        (name, parent, (0.1, 0.2, 0.3) if name == "link2" else pos, rotation, axis, sites)
        for name, parent, pos, rotation, axis, sites in bodies
    ]
    with pytest.raises(InvalidInputError, match=r"robot\.urdf: MJCF frame 'link2'"):
        place_frames_as_mujoco(model, chain_mjcf(moved), is_xml=True)
