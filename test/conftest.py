"""Shared fixtures: small robots from inline URDF, so unit tests are hermetic."""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import settings

from grasp_safety_ros.core import ObjectTrajectory, RobotModel
from grasp_safety_ros.core.input_checks import pose_from_position_quat

# Property tests: no deadline on this shared machine; in CI (env CI set) the examples are
# derived from each test's name (derandomize), so a run is reproducible.
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def _inertial(mass: float, inertia: Sequence[float], com: Sequence[float]) -> str:
    ixx, iyy, izz = inertia
    x, y, z = com
    return (
        f'<inertial><origin xyz="{x} {y} {z}"/><mass value="{mass}"/>'
        f'<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>'
    )


def serial_arm_urdf(
    axes: Sequence[str],
    mass_scale: float = 1.0,
    joint_type: str = "revolute",
    seed: int = 0,
) -> str:
    """A serial arm with generic link offsets (about 0.3 m), joints about ``axes``.

    Link masses and inertias are random (fixed seed) times ``mass_scale``; the last link
    carries the ``tool`` frame 0.1 m beyond its joint.
    """
    rng = np.random.default_rng(seed)
    vectors = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
    parts = ['<robot name="arm">', '<link name="base_link"/>']
    parent = "base_link"
    for k, axis in enumerate(axes):
        link = f"link{k + 1}"
        mass = float(rng.uniform(0.5, 2.0)) * mass_scale
        inertia = rng.uniform(0.005, 0.02, 3)
        inertia = [
            min(inertia[0], inertia[1] + inertia[2]),
            min(inertia[1], inertia[0] + inertia[2]),
            min(inertia[2], inertia[0] + inertia[1]),
        ]
        com = rng.uniform(-0.05, 0.1, 3)
        parts.append(
            f'<link name="{link}">'
            + _inertial(mass, [i * mass_scale for i in inertia], com)
            + "</link>"
        )
        offset = rng.uniform([-0.1, -0.1, 0.15], [0.2, 0.1, 0.3]) if k else [0.0, 0.0, 0.1]
        origin = " ".join(f"{x:.4f}" for x in offset)
        parts.append(
            f'<joint name="j{k + 1}" type="{joint_type}"><parent link="{parent}"/>'
            f'<child link="{link}"/><origin xyz="{origin}" rpy="0 0 0"/>'
            f'<axis xyz="{vectors[axis]}"/>'
            '<limit lower="-3.0" upper="3.0" effort="100" velocity="10"/></joint>'
        )
        parent = link
    parts.append('<link name="tool"/>')
    parts.append(
        f'<joint name="tool_joint" type="fixed"><parent link="{parent}"/><child link="tool"/>'
        '<origin xyz="0 0 0.1" rpy="0.3 -0.2 0.1"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)


ARM6_AXES = ("z", "y", "y", "x", "y", "z")
ARM7_AXES = ("z", "y", "z", "y", "z", "y", "x")


@pytest.fixture(scope="session")
def arm6() -> RobotModel:
    """A 6-DOF arm."""
    return RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")


@pytest.fixture(scope="session")
def arm7() -> RobotModel:
    """A 7-DOF (redundant) arm."""
    return RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool")


@pytest.fixture(scope="session")
def baxter() -> RobotModel:
    """Baxter's right arm from example-robot-data."""
    return RobotModel.from_urdf("example-robot-data:baxter", "base", "right_gripper")


@pytest.fixture(scope="session")
def prismatic_arm() -> RobotModel:
    """The 7-DOF arm with a prismatic third joint."""
    urdf = serial_arm_urdf(ARM7_AXES).replace(
        '<joint name="j3" type="revolute"', '<joint name="j3" type="prismatic"'
    )
    return RobotModel.from_urdf(urdf, "base_link", "tool")


@pytest.fixture(scope="session")
def geared_arm() -> RobotModel:
    """The 7-DOF arm with reflected rotor inertia on every joint: M, M⁻¹ and RNEA include it
    (once)."""
    armature = [0.3, 0.25, 0.2, 0.1, 0.05, 0.04, 0.02]
    return RobotModel.from_urdf(
        serial_arm_urdf(ARM7_AXES), "base_link", "tool", armature_kgm2=armature
    )


@pytest.fixture(scope="session")
def continuous_arm() -> RobotModel:
    """The 7-DOF arm with continuous joints (nq = 14, nv = 7)."""
    return RobotModel.from_urdf(
        serial_arm_urdf(ARM7_AXES, joint_type="continuous"), "base_link", "tool"
    )


DOCS = Path(__file__).resolve().parents[1] / "docs"


def shown_in_docs(page: str, start: str) -> re.Pattern[str]:
    """What ``docs/<page>`` shows from ``start`` to the next backtick (the end of its code
    span, or of its fenced block: a log line shown alone), whitespace joined (a quote may
    wrap), as a pattern in which the page's ``...`` stands for any text. A test that matches
    the output it gets against it holds the page's quote of a log line."""
    text = " ".join((DOCS / page).read_text().split())
    (quote,) = re.findall(re.escape(start) + "[^`]*", text)
    return re.compile(".*".join(re.escape(part) for part in quote.strip().split("...")))


BAXTER_SEED = (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0)


def book_trajectory(
    dt_s: float = 0.05,
    duration_s: float = 2.0,
    goal_rotation_log: Sequence[float] = (0.0, 0.0, 0.0),
) -> ObjectTrajectory:
    """The paper's book motion, (1, 0, 0.03) -> (1.1, -0.38, 0.16) m, quat_xyzw (0.5, 0.5,
    0.5, 0.5); the goal orientation optionally turned by exp(goal_rotation_log) (object axes)."""
    start = pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "start")
    goal = pose_from_position_quat([1.1, -0.38, 0.16], [0.5, 0.5, 0.5, 0.5], "goal")
    goal.rotation = goal.rotation @ pin.exp3(np.array(goal_rotation_log, dtype=float))
    return ObjectTrajectory(start, goal, duration_s, dt_s)


def random_positions(robot: RobotModel, rng: np.random.Generator) -> np.ndarray:
    """Joint positions drawn uniformly inside the limits (unlimited joints: [-pi, pi])."""
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    return rng.uniform(lower, upper)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix."""
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    return pin.Quaternion(*quat).toRotationMatrix()


@pytest.fixture()
def context() -> Iterator[Any]:
    """An rclpy Context of the test's own, in a claimed ROS domain (ros_domains.py) with
    localhost discovery, shut down after the test (rclpy imported here: lazily)."""
    import rclpy
    from rclpy.context import Context
    from ros_domains import claim_ros_domain

    with pytest.MonkeyPatch.context() as patch, claim_ros_domain() as claim:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        rclpy_context = Context()
        rclpy.init(context=rclpy_context, domain_id=claim.domain_id)
        yield rclpy_context
        rclpy.shutdown(context=rclpy_context)


# --- The grasp_safety node over real rclpy (ros_node_harness.py, imported lazily: rclpy) -------
# A test module using them imports ros_node_harness._localhost_only (autouse) first.


@pytest.fixture(scope="module")
def ros() -> Iterator[Any]:
    """The node with ros_node_harness.NODE_PARAMETERS, shared by a test module."""
    from ros_node_harness import NODE_PARAMETERS, NodeUnderTest

    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


@pytest.fixture()
def own_ros() -> Iterator[Any]:
    """A node of its own (own ROS domain): no candidate set, trajectory or quality left by
    earlier tests, which the topic-pairing rules would otherwise act on."""
    from ros_node_harness import NODE_PARAMETERS, NodeUnderTest

    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


@pytest.fixture(scope="module")
def core_evaluator() -> Any:
    """The core's evaluator of the node's robot (Baxter's right arm)."""
    from grasp_safety_ros.core import GraspSafetyEvaluator

    robot = RobotModel.from_urdf("example-robot-data:baxter", "base", "right_gripper")
    return GraspSafetyEvaluator(robot)


@pytest.fixture(scope="module")
def core_ranking(core_evaluator: Any) -> Any:
    """The core's ranking of the book scenario, as the node's service must answer it."""
    from ros_node_harness import BOOK, BOOK_GRASPS, book_trajectory

    return core_evaluator.rank(
        BOOK_GRASPS, BOOK.object_inertia, book_trajectory(), BOOK.robot.seed, "mean"
    )
