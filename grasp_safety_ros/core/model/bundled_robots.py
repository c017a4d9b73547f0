"""Robots of the example-robot-data wheel with a chain and an IK seed that are known to work.

Each entry names its URDF as ``example-robot-data:<name>`` (robot.example_robot_data_names), the
chain's base and tip frames and a seed: chain joint positions [rad or m], base to tip, within
the joint limits and away from singularities (the tip Jacobian's sixth singular value is
checked in test/test_robots_and_frames.py, where a small ranking runs from each seed).
"""

from __future__ import annotations

from dataclasses import dataclass

EXAMPLE_ROBOT_DATA_PREFIX = "example-robot-data:"
"""How a robot description names a URDF of the example-robot-data wheel (robot.resolve_urdf,
which imports this module: the unknown-name message lists BUNDLED_ROBOTS)."""


@dataclass(frozen=True)
class BundledRobot:
    """A chain of an example-robot-data robot.

    Attributes:
        name: The name of ``example-robot-data:<name>``.
        base_frame, tip_frame: The chain's ends.
        seed: IK seed, chain joint order [rad or m] (as ``robot.seed`` of a scenario and the
            node's ``ik_seed``).
        note: What the chain is, in a few words.
    """

    name: str
    base_frame: str
    tip_frame: str
    seed: tuple[float, ...]
    note: str = ""

    @property
    def urdf(self) -> str:
        """The robot description as the scenario and the node take it."""
        return f"{EXAMPLE_ROBOT_DATA_PREFIX}{self.name}"


BUNDLED_ROBOTS: tuple[BundledRobot, ...] = (
    BundledRobot(
        "baxter", "base", "right_gripper", (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0), "right arm"
    ),
    BundledRobot(
        "panda", "panda_link0", "panda_hand", (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)
    ),
    BundledRobot("ur3", "base_link", "tool0", (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)),
    BundledRobot("ur5", "base_link", "tool0", (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)),
    BundledRobot("ur10", "base_link", "tool0", (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)),
    BundledRobot(
        "kinova",
        "j2s6s200_link_base",
        "j2s6s200_end_effector",
        (0.39, 2.03, 4.5, -0.53, 4.43, 1.25),
        "Jaco2 j2s6s200",
    ),
    BundledRobot("xarm7", "link_base", "link_eef", (-1.39, 0.61, -0.27, 0.89, 0.92, 1.54, -0.22)),
    BundledRobot("z1", "link00", "gripperStator", (0.0, 1.48, -1.44, 0.0, 0.0, 0.0)),
    BundledRobot(
        "tiago",
        "torso_lift_link",
        "arm_tool_link",
        (0.94, -0.26, -1.19, 1.65, -0.89, 0.6, 0.79),
        "arm from the torso",
    ),
    BundledRobot(
        "pr2",
        "torso_lift_link",
        "r_gripper_tool_frame",
        (-0.79, 0.44, -1.55, -1.16, 0.0, -1.05, 0.0),
        "right arm from the torso",
    ),
    BundledRobot(
        "talos_left_arm",
        "arm_left_1_link",
        "gripper_left_base_link",
        (1.18, -1.16, -1.67, -0.7, 0.35, 0.21),
        "left arm alone (its first joint is the URDF's root)",
    ),
    BundledRobot(
        "talos_reduced",
        "torso_2_link",
        "gripper_left_base_link",
        (-0.52, 1.44, 0.0, -1.18, 0.0, 0.0, 0.0),
        "left arm from the torso",
    ),
    BundledRobot(
        "icub",
        "chest",
        "r_hand",
        (-0.87, 0.71, 0.88, 1.31, 0.05, -0.31, -0.07),
        "right arm from the chest",
    ),
)
"""The chains ``grasp-safety robots`` lists, each verified by test/test_robots_and_frames.py."""
