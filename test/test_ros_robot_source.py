"""ros.robot.source over real rclpy: parameter changes at run time (the robot group applied
together) and the robot from /robot_description (harness: ros_node_harness.py)."""

from __future__ import annotations

import time

from conftest import ARM6_AXES, serial_arm_urdf
from diagnostic_msgs.msg import DiagnosticStatus
from ros_node_harness import (
    BOOK,
    LATCHED,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    book_request,
)
from std_msgs.msg import String

# --- Parameters at run time --------------------------------------------------------------------


def test_invalid_parameters_are_refused_with_a_reason(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(object__mass_kg=-1.0)
    assert not result.successful and "object.mass_kg" in result.reason
    (result,) = ros.set_parameters(metric="median")
    assert not result.successful and "metric" in result.reason
    (result,) = ros.set_parameters(trajectory__dt_s="fast")  # declared a double
    assert not result.successful and "expected 'Type.DOUBLE' got 'Type.STRING'" in result.reason
    response = ros.rank(book_request())  # nothing changed
    assert response.success and response.ranking.metric == "mean"


def test_robot_parameters_that_do_not_fit_are_pending_until_the_group_is_consistent(
    ros: NodeUnderTest,
) -> None:
    """A frame or seed that does not fit the other robot parameters is accepted as pending
    (another parameter of the group may follow: ros2 param load sets them one at a time), the
    old model serving and /diagnostics saying why; a change that makes the group consistent
    applies it. A complete group (urdf, base_frame, tip_frame, ik_seed) that does not fit is
    refused with the reason."""
    try:
        (result,) = ros.set_parameters(tip_frame="no_such_frame")
        assert result.successful, result.reason
        status = ros.node.diagnostics_status()
        assert status.level == DiagnosticStatus.WARN
        assert "robot parameters pending (tip_frame)" in status.message
        assert "tip_frame: frame 'no_such_frame' not found" in status.message
        assert status.hardware_id == "base->right_gripper"  # the model that serves
        assert ros.rank(book_request()).success
        (result,) = ros.set_parameters(ik_seed=[0.0, 1.0])
        assert result.successful, result.reason
        (result,) = ros.set_parameters(base_frame="base")
        assert result.successful, result.reason
        (result,) = ros.set_parameters(urdf="example-robot-data:baxter")  # completes the group
        assert not result.successful
        pending = "base_frame, ik_seed, tip_frame, urdf"
        assert f"robot parameters {pending} are not consistent" in result.reason
        assert "the model from urdf (base -> right_gripper) serves" in result.reason
        (result,) = ros.set_parameters(tip_frame="right_gripper")  # the seed is still wrong
        assert result.successful
        assert "ik_seed: must have shape [7]" in ros.node.diagnostics_status().message
        (result,) = ros.set_parameters(ik_seed=list(BOOK.robot.seed))  # consistent: applied
        assert result.successful, result.reason
        assert "robot parameters" not in ros.node.diagnostics_status().message
    finally:
        ros.set_parameters(tip_frame="right_gripper", ik_seed=list(BOOK.robot.seed))


def test_valid_parameter_change_applies(ros: NodeUnderTest) -> None:
    try:
        (result,) = ros.set_parameters(metric="max")
        assert result.successful, result.reason
        response = ros.rank(book_request())
        assert response.success and response.ranking.metric == "max"
        for evaluation in response.ranking.evaluations:
            assert evaluation.score == max(evaluation.effective_mass_kg)
        (result,) = ros.set_parameters(tip_frame="right_wrist")  # rebuilds the robot model
        assert result.successful, result.reason
        assert ros.rank(book_request()).success
    finally:
        ros.set_parameters(metric="mean", tip_frame="right_gripper")


# --- Robot from /robot_description -------------------------------------------------------------


def test_robot_from_robot_description_topic() -> None:
    harness = NodeUnderTest(
        {"base_frame": "base_link", "tip_frame": "tool", "object.mass_kg": 0.0}
    )
    publisher = harness.client.create_publisher(String, "/robot_description", LATCHED)
    try:
        request = book_request()
        request.object_trajectory.header.frame_id = "base_link"
        not_ready = harness.rank(request)
        assert not not_ready.success
        assert not_ready.message.startswith("no robot description yet")

        bad = serial_arm_urdf(ARM6_AXES).replace('"tool"', '"flange"')
        publisher.publish(String(data=bad))  # no tip frame 'tool': refused, still no robot
        time.sleep(0.3)
        assert not harness.node.has_robot
        publisher.publish(String(data=serial_arm_urdf(ARM6_AXES)))
        assert harness.spin_until(lambda: harness.node.has_robot)
        response = harness.rank(request)
        assert response.success, response.message
        assert len(response.ranking.evaluations) == 3
        assert len(response.ranking.joint_names) == 6
        request.metric_point = "leading_point"  # this node has no object points
        refused = harness.rank(request)
        assert not refused.success
        assert refused.message.startswith(
            "metric_point: 'leading_point' needs the object's points: set the node parameter "
            "object.points_in_object_m"
        ), refused.message
        request.metric_point = ""

        publisher.publish(String(data=bad))  # a bad update keeps the current robot
        time.sleep(0.3)
        assert harness.node.has_robot
        assert harness.rank(request).success
    finally:
        harness.client.destroy_publisher(publisher)
        harness.close()
