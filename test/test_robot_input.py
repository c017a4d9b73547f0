"""Robot descriptions that are legal URDF but awkward for the method: shared frame names,
mimic joints, multi-DOF and continuous joints, massless links. Each is either the same robot
as an unambiguous description (checked against one) or refused in one line naming the field."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, ARM7_AXES, random_positions, serial_arm_urdf

from grasp_safety_ros.core import InvalidInputError, RobotModel, solid_sphere
from grasp_safety_ros.core.method.compiled import chain_arrays
from grasp_safety_ros.core.method.effective_mass import translational_mobilities_in_base
from grasp_safety_ros.core.model.description import resolve_urdf
from grasp_safety_ros.core.model.robot import find_frame
from grasp_safety_ros.ros.parameters import settings_from_parameters
from grasp_safety_ros.ros.robot.bundle import build_robot


def urdf_text(name: str) -> str:
    path, _ = resolve_urdf(f"example-robot-data:{name}")
    with open(path, encoding="utf-8") as stream:
        return stream.read()


def mass_matrix(robot: RobotModel, positions: np.ndarray) -> np.ndarray:
    data = robot.model.createData()
    upper = pin.crba(robot.model, data, robot.q_from_positions(positions))
    return np.triu(upper) + np.triu(upper, 1).T


def assert_same_robot(a: RobotModel, b: RobotModel, samples: int = 5) -> None:
    """Same number of chain joints, tip poses and mass matrices at random joint positions."""
    assert a.num_joints == b.num_joints
    rng = np.random.default_rng(7)
    for _ in range(samples):
        positions = random_positions(a, rng)
        pose_a, pose_b = a.transform_tip_to_base(positions), b.transform_tip_to_base(positions)
        np.testing.assert_allclose(pose_a.homogeneous, pose_b.homogeneous, atol=1e-12)
        np.testing.assert_allclose(
            mass_matrix(a, positions), mass_matrix(b, positions), atol=1e-12
        )


def one_line(error: pytest.ExceptionInfo[Exception]) -> str:
    text = str(error.value)
    assert "\n" not in text
    return text


# --- shared frame names ----------------------------------------------------------------------


def test_so100_gripper_is_the_link_unless_asked_for_the_joint() -> None:
    renamed = urdf_text("so100").replace(
        '<joint name="gripper" type', '<joint name="g_joint" type'
    )
    link = RobotModel.from_urdf("example-robot-data:so100", "base", "gripper")
    assert_same_robot(link, RobotModel.from_urdf(renamed, "base", "gripper"))
    assert link.tip_frame == "gripper" and link.num_joints == 5
    joint = RobotModel.from_urdf("example-robot-data:so100", "base", "gripper@JOINT")
    assert_same_robot(joint, RobotModel.from_urdf(renamed, "base", "g_joint"))
    assert joint.num_joints == 6 and joint.joint_names[-1] == "gripper"


def test_z1_gripper_stator_is_the_link() -> None:
    renamed = urdf_text("z1").replace('<joint name="gripperStator"', '<joint name="stator_fix"')
    robot = RobotModel.from_urdf("example-robot-data:z1", "link00", "gripperStator")
    assert_same_robot(robot, RobotModel.from_urdf(renamed, "link00", "gripperStator"))
    fixed = RobotModel.from_urdf("example-robot-data:z1", "link00", "gripperStator@FIXED_JOINT")
    assert_same_robot(fixed, RobotModel.from_urdf(renamed, "link00", "stator_fix"))


def test_name_without_a_link_frame_must_say_which() -> None:
    model = pin.buildModelFromXML(serial_arm_urdf(ARM6_AXES))
    joint_frame = model.getFrameId("j6", pin.FrameType.JOINT)
    model.addFrame(
        pin.Frame(
            "j6",
            model.frames[joint_frame].parentJoint,
            joint_frame,
            pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])),
            pin.FrameType.OP_FRAME,
        )
    )
    with pytest.raises(InvalidInputError) as error:
        RobotModel(model, "base_link", "j6")
    assert one_line(error) == (
        "robot.tip_frame: 'j6' names 2 frames: j6@JOINT (on joint 'j6'), j6@OP_FRAME (on joint "
        "'j6'); pick one as 'j6@TYPE' (TYPE: OP_FRAME, JOINT, FIXED_JOINT, BODY, SENSOR)"
    )
    operational = RobotModel(model, "base_link", "j6@OP_FRAME")
    at_joint = RobotModel(model, "base_link", "j6@joint")
    offset = at_joint.transform_tip_to_base(np.zeros(6)).actInv(
        operational.transform_tip_to_base(np.zeros(6))
    )
    np.testing.assert_allclose(offset.translation, [0.0, 0.0, 0.2], atol=1e-15)


def test_frame_type_suffix_errors() -> None:
    model = pin.buildModelFromXML(serial_arm_urdf(ARM6_AXES))
    with pytest.raises(InvalidInputError) as error:
        find_frame(model, "tool@JOINT", "robot.tip_frame")
    assert one_line(error).startswith("robot.tip_frame: frame 'tool' has no JOINT frame; frames:")
    with pytest.raises(KeyError, match="frame 'tool@KNOT' not found"):
        find_frame(model, "tool@KNOT", "robot.tip_frame")


def test_node_parameters_get_the_same_one_line_refusals() -> None:
    so100 = {"urdf": "example-robot-data:so100", "base_frame": "base"}
    bundle = build_robot(settings_from_parameters({**so100, "tip_frame": "gripper"}), None)
    assert bundle is not None and bundle.robot.num_joints == 5
    with pytest.raises(InvalidInputError) as error:
        build_robot(settings_from_parameters({**so100, "tip_frame": "gripper@SENSOR"}), None)
    assert one_line(error).startswith("tip_frame: frame 'gripper' has no SENSOR frame")
    panda = {"urdf": "example-robot-data:panda", "base_frame": "panda_link0"}
    with pytest.raises(InvalidInputError) as error:
        build_robot(settings_from_parameters({**panda, "tip_frame": "panda_rightfinger"}), None)
    assert one_line(error).startswith("tip_frame: joint 'panda_finger_joint2' on the chain")


# --- mimic joints ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("tip", "message"),
    [
        (
            "panda_rightfinger",
            "robot.tip_frame: joint 'panda_finger_joint2' on the chain to 'panda_rightfinger' "
            "mimics joint 'panda_finger_joint1' (URDF <mimic>)",
        ),
        (
            "panda_leftfinger",
            "robot.tip_frame: joint 'panda_finger_joint1' on the chain to 'panda_leftfinger' "
            "is mimicked by joint 'panda_finger_joint2' (URDF <mimic>)",
        ),
    ],
)
def test_chains_with_mimic_joints_are_refused(tip: str, message: str) -> None:
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf("example-robot-data:panda", "panda_link0", tip)
    assert one_line(error).startswith(message)


def fingers_urdf(mimic: bool) -> str:
    """ARM6 with two prismatic fingers on link2, off the chain; fb mimics fa (-2 x + 0.01)."""
    finger = (
        '<link name="finger_{0}"><inertial><origin xyz="0.05 0 0"/><mass value="0.7"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        '<joint name="f{0}" type="prismatic"><parent link="link2"/><child link="finger_{0}"/>'
        '<origin xyz="0.1 0 0.1"/><axis xyz="1 0 0"/>'
        '<limit lower="-1" upper="1" effort="10" velocity="1"/>{1}</joint>'
    )
    tag = '<mimic joint="fa" multiplier="-2" offset="0.01"/>' if mimic else ""
    extra = finger.format("a", "") + finger.format("b", tag)
    return serial_arm_urdf(ARM6_AXES).replace("</robot>", extra + "</robot>")


def test_locked_mimic_joint_follows_its_locked_leader() -> None:
    with_mimic = RobotModel.from_urdf(fingers_urdf(True), "base_link", "tool", {"fa": 0.2})
    follower_at = -2.0 * 0.2 + 0.01
    explicit = RobotModel.from_urdf(
        fingers_urdf(False), "base_link", "tool", {"fa": 0.2, "fb": follower_at}
    )
    assert_same_robot(with_mimic, explicit)
    ignored = RobotModel.from_urdf(fingers_urdf(False), "base_link", "tool", {"fa": 0.2})
    with pytest.raises(AssertionError):
        assert_same_robot(with_mimic, ignored, samples=1)
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(fingers_urdf(True), "base_link", "tool", {"fb": 0.1})
    assert (
        one_line(error) == "robot.locked_joints: joint 'fb' mimics joint 'fa'; lock 'fa' instead"
    )


def test_panda_hand_chain_is_unaffected_by_the_finger_mimic() -> None:
    robot = RobotModel.from_urdf("example-robot-data:panda", "panda_link0", "panda_hand")
    assert robot.num_joints == 7


# --- joint types -----------------------------------------------------------------------------


@pytest.mark.parametrize(("joint_type", "dof"), [("floating", 6), ("planar", 3)])
def test_multi_dof_joints_are_refused_on_the_chain_only(joint_type: str, dof: int) -> None:
    urdf = serial_arm_urdf(ARM6_AXES).replace(
        '<joint name="j3" type="revolute">', f'<joint name="j3" type="{joint_type}">'
    )
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(urdf, "base_link", "tool")
    assert one_line(error).startswith(
        f"robot.tip_frame: joint 'j3' (JointModel{'FreeFlyer' if dof == 6 else 'Planar'}) on "
        f"the chain 'base_link' -> 'tool' has {dof} DOF; only 1-DOF joints"
    )
    downstream = RobotModel.from_urdf(urdf, "link3", "tool")
    assert downstream.joint_names == ("j4", "j5", "j6")


def test_continuous_joints_give_the_revolute_robot() -> None:
    continuous = RobotModel.from_urdf(
        serial_arm_urdf(ARM6_AXES, joint_type="continuous"), "base_link", "tool"
    )
    revolute = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    assert continuous.model.nq == 12 and np.all(np.isinf(continuous.upper_limits))
    rng = np.random.default_rng(3)
    for _ in range(5):
        positions = random_positions(revolute, rng)
        np.testing.assert_allclose(
            continuous.transform_tip_to_base(positions).homogeneous,
            revolute.transform_tip_to_base(positions).homogeneous,
            atol=1e-12,
        )
        np.testing.assert_allclose(
            mass_matrix(continuous, positions), mass_matrix(revolute, positions), atol=1e-12
        )


# --- massless links --------------------------------------------------------------------------


def test_massless_six_dof_arm_moves_only_the_object() -> None:
    """With no robot mass and J square, Λ_tot = Λ_obj: at the object's CoM, m_eff = m."""
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES, mass_scale=0.0), "base_link", "tool")
    sphere = solid_sphere(0.5, 0.05)
    positions = random_positions(robot, np.random.default_rng(5))[None, :]
    for chain in (None, chain_arrays(robot)):
        mobility = translational_mobilities_in_base(
            robot, sphere, pin.SE3.Identity(), robot.q_from_positions(positions[0])[None, :], chain
        )[0]
        np.testing.assert_allclose(mobility, np.eye(3) / 0.5, rtol=1e-9, atol=1e-9)


def test_massless_redundant_arm_is_refused() -> None:
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, mass_scale=0.0), "base_link", "tool")
    assert one_line(error).startswith(
        "robot.urdf: the mass matrix of the chain 'base_link' -> 'tool' is not positive "
        "definite even with an object at the tip (links moved by j1, j2, j3, j4, j5, j6, j7 "
        "have no mass)"
    )


def test_one_massless_link_is_fine() -> None:
    urdf = serial_arm_urdf(ARM7_AXES, seed=1)
    start = urdf.index('<link name="link4">')
    end = urdf.index("</link>", start)
    massless = urdf[:start] + '<link name="link4">' + urdf[end:]
    assert RobotModel.from_urdf(massless, "base_link", "tool").num_joints == 7


def test_xml_entity_bomb_is_refused() -> None:
    entities = '<!ENTITY l0 "lol">' + "".join(
        f'<!ENTITY l{i} "{f"&l{i - 1};" * 10}">' for i in range(1, 10)
    )
    urdf = serial_arm_urdf(ARM6_AXES).replace(
        '<robot name="arm">',
        f'<!DOCTYPE robot [{entities}]><robot name="arm">'
        '<material name="m&l9;"><color rgba="1 0 0 1"/></material>',
    )
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(urdf, "base_link", "tool")
    assert one_line(error).startswith("robot.urdf: cannot read URDF XML: limit on input")


def test_locked_joint_outside_its_limits_is_refused() -> None:
    with pytest.raises(InvalidInputError) as error:
        RobotModel.from_urdf(fingers_urdf(False), "base_link", "tool", {"fa": 1e300})
    assert one_line(error) == (
        "robot.locked_joints.fa: 1e+300 is outside the joint's limits [-1, 1]"
    )
