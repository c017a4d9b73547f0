"""ros.runtime.collector in the nodes: the heap is frozen once a robot serves (the grasp_safety
node and the monitor), frozen again after a robot replacement with nothing of the old robot
left frozen, and unfrozen when the node is destroyed (harness: ros_node_harness.py; the node in
this process, so the test sees its collector)."""

from __future__ import annotations

import gc
import weakref
from collections.abc import Iterator
from typing import Any

import pytest
from conftest import ARM6_AXES, serial_arm_urdf
from rclpy.parameter import Parameter
from ros_node_harness import (
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    book_request,
)
from std_msgs.msg import String

from grasp_safety_ros.ros.monitor.node import MonitorNode

ARM6 = serial_arm_urdf(ARM6_AXES)


def is_frozen(thing: Any) -> bool:
    """Tracked by the collector but in none of its three generations: in the permanent one
    (gc.freeze)."""
    return gc.is_tracked(thing) and not any(
        other is thing for generation in range(3) for other in gc.get_objects(generation)
    )


@pytest.fixture(autouse=True)
def _thawed_after() -> Iterator[None]:
    """Nothing a test froze stays frozen for the next one (a failed test skips destroy)."""
    yield
    gc.unfreeze()


def test_served_robot_is_frozen_and_unfrozen_when_the_node_is_destroyed() -> None:
    harness = NodeUnderTest(NODE_PARAMETERS)
    try:
        bundle = harness.node._robot
        assert bundle is not None and is_frozen(bundle)
        assert harness.rank(book_request()).success  # serving leaves it frozen
        assert is_frozen(bundle)
    finally:
        harness.close()
    assert gc.get_freeze_count() == 0


def test_replaced_robot_is_not_left_frozen(own_ros: NodeUnderTest) -> None:
    """An old robot that only the collector can free (a reference cycle through it, which a
    later change to the evaluator could add; reference counting frees today's) is freed by
    gc.collect() after the replacement, and the new robot is frozen."""
    old = own_ros.node._robot
    object.__setattr__(old, "cycle", old)  # bundle -> its __dict__ -> bundle
    gone = weakref.ref(old)
    del old
    (result,) = own_ros.set_parameters(tip_frame="right_wrist")  # rebuilds the robot
    assert result.successful, result.reason
    new = own_ros.node._robot
    assert new is not None and new.robot.tip_frame == "right_wrist" and is_frozen(new)
    gc.collect()
    assert gone() is None


def monitor_node(context: Any, description: str) -> MonitorNode:
    """The monitor on ARM6 (``description``; empty: from /robot_description), defaults else."""
    overrides = {
        "robot_description": description,
        "urdf": "",
        "base_frame": "base_link",
        "tip_frame": "tool",
    }
    return MonitorNode(
        context=context,
        parameter_overrides=[Parameter(name, value=value) for name, value in overrides.items()],
    )


def test_monitor_freezes_its_robot_at_start_up_and_from_the_topic(context: Any) -> None:
    node = monitor_node(context, ARM6)
    try:
        assert is_frozen(node._bundle)
    finally:
        node.destroy_node()
    assert gc.get_freeze_count() == 0
    node = monitor_node(context, "")
    try:
        assert node._bundle is None and gc.get_freeze_count() == 0
        node._on_description(String(data=ARM6))
        assert node._bundle is not None and is_frozen(node._bundle)
    finally:
        node.destroy_node()
    assert gc.get_freeze_count() == 0
