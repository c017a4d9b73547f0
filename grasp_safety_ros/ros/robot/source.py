"""Where the node's robot comes from, as a base class of GraspSafetyNode: its parameters (the
robot group applied together, robot.group) or /robot_description, and the wait for it at
start-up."""

from __future__ import annotations

import time
import traceback
from typing import Any

from rclpy.executors import Executor, ExternalShutdownException
from rclpy.timer import Timer
from std_msgs.msg import String

from ...core.exceptions import GraspSafetyError, InvalidInputError
from ..parameters import PARAMETERS, NodeSettings, settings_from_parameters
from ..parameters.arm_points import check_arm_point_links
from ..runtime.collector import freeze_long_lived, thaw
from ..service.errors import StartupError, internal_error
from ..topics.diagnostics import DiagnosticsNode
from .bundle import RobotBundle, build_robot
from .group import PENDING_FIELDS, ROBOT_GROUP, group_complete, pending_reason


class RobotSource(DiagnosticsNode):
    """The robot part of the grasp_safety node (GraspSafetyNode sets the attributes below):
    the model serving requests, rebuilt when the robot parameters change or, when they give
    no robot, from /robot_description."""

    _values: dict[str, Any]
    _pending_robot: dict[str, Any]  # robot group values accepted, not applied
    _topic_description: str | None
    _waiting_for_robot: bool
    _startup_failure: str
    _diagnostics_timer: Timer

    def _robot_ready(self, bundle: RobotBundle) -> None:
        """``bundle`` now serves (built, warmed up): log it and freeze the long-lived heap
        (runtime.collector: no full collection walks it again; the previous robot's is
        unfrozen and collected first)."""
        freeze_long_lived()
        robot = bundle.robot
        self.get_logger().info(
            f"robot from {bundle.origin}: {robot.base_frame} -> {robot.tip_frame}, "
            f"{robot.num_joints} joints ({', '.join(robot.joint_names)})"
        )

    def destroy_node(self) -> None:
        """Destroy the node and unfreeze the heap frozen for its robot (_robot_ready)."""
        super().destroy_node()
        thaw()

    @property
    def has_robot(self) -> bool:
        """Whether a robot model is loaded (requests can be answered)."""
        with self._state_lock:
            return self._robot is not None

    def wait_for_robot(self, executor: Executor) -> None:
        """Spin ``executor`` until a robot model is loaded (at start-up, from the topic).

        Raises:
            StartupError: nothing usable arrived within robot_description_timeout_s.
        """
        if self.has_robot:
            return
        timeout = self._settings.robot_description_timeout_s
        self.get_logger().info(
            "parameters robot_description and urdf are empty: waiting "
            + (f"up to {timeout:g} s" if timeout > 0 else "for ever")
            + " for /robot_description"
        )
        deadline = time.monotonic() + timeout
        self._waiting_for_robot = True
        try:
            self._spin_until_robot(executor, timeout, deadline)
        finally:
            self._waiting_for_robot = False

    def _spin_until_robot(self, executor: Executor, timeout: float, deadline: float) -> None:
        while not self.has_robot:
            if self._startup_failure:
                raise StartupError(self._startup_failure)
            if timeout > 0 and time.monotonic() > deadline:
                raise StartupError(
                    "no robot description: parameters robot_description and urdf are empty and "
                    f"nothing arrived on /robot_description within {timeout:g} s "
                    "(robot_description_timeout_s)"
                )
            if not self.context.ok():
                raise ExternalShutdownException()
            executor.spin_once(timeout_sec=0.1)

    def _apply_parameters(self, changes: dict[str, Any]) -> None:
        """Apply a parameter change (raises GraspSafetyError to refuse it).

        The robot group (ROBOT_GROUP) is applied together. ``ros2 param load`` of a new robot's
        file sets its parameters one at a time, each alone inconsistent with the others' old
        values (a frame not in the robot, a seed of another length): such a change is accepted
        as pending, the old model serving, and the group is applied once a change makes it
        consistent. A change that completes the group (every one of urdf or
        robot_description, base_frame, tip_frame, ik_seed pending) and leaves it inconsistent is
        refused with the reason; the others stay pending (log and /diagnostics say so). Errors
        of a parameter alone (type, range, an unreadable URDF) are refused as before.
        """
        changes = {name: value for name, value in changes.items() if name in PARAMETERS}
        if not changes:
            return
        with self._state_lock:
            robot_changes = {k: v for k, v in changes.items() if k in ROBOT_GROUP}
            pending = {**self._pending_robot, **robot_changes}
            values = {**self._values, **pending, **changes}
            settings = settings_from_parameters(values)
            bundle, reason = self._robot, ""
            if not pending and bundle is not None:  # build_robot checks a new robot's
                check_arm_point_links(settings.analysis.arm_points_m, bundle.robot)
            if pending:
                try:
                    bundle = build_robot(settings, self._topic_description)
                except GraspSafetyError as error:
                    if getattr(error, "field", None) not in PENDING_FIELDS:
                        raise
                    reason = pending_reason(pending, error, self._robot)
                    if group_complete(pending):
                        self._status.robot_parameters_pending = reason
                        raise InvalidInputError(", ".join(sorted(robot_changes)), reason) from None
                    others = {k: v for k, v in changes.items() if k not in ROBOT_GROUP}
                    values, bundle = {**self._values, **others}, self._robot
                    settings = settings_from_parameters(values)
                    if bundle is not None:
                        check_arm_point_links(settings.analysis.arm_points_m, bundle.robot)
                self._pending_robot = pending if reason else {}
                self._status.robot_parameters_pending = reason
            period_changed = settings.diagnostics_period_s != self._settings.diagnostics_period_s
            robot_changed = bundle is not self._robot
            self._values, self._settings, self._robot = values, settings, bundle
        if reason:
            self.get_logger().warning(reason)
            self._publish_diagnostics()
        self.get_logger().info(f"parameters set: {', '.join(sorted(changes))}")
        if robot_changed and pending:
            self._publish_diagnostics()  # the pending state, if any, is cleared
        if robot_changed and bundle is not None:
            self._robot_ready(bundle)
        if period_changed:
            self._diagnostics_timer.cancel()
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(
                settings.diagnostics_period_s, self._on_diagnostics_timer
            )

    def _on_robot_description(self, msg: String) -> None:
        with self._state_lock:
            self._topic_description = msg.data
            settings = self._settings
        if settings.robot_source:
            given_by = "robot_description" if settings.robot_description else "urdf"
            reason = (
                f"ignored: the parameter {given_by} gives the robot (empty robot_description "
                "and urdf to take it from the topic)"
            )
            with self._state_lock:
                self._status.ignored_descriptions += 1
                first = self._status.robot_description_error != reason
                self._status.robot_description_error = reason
            if first:  # once, not per message
                self.get_logger().info(f"/robot_description {reason}")
            return
        try:
            if not msg.data.lstrip().startswith("<"):  # never a file path or a package name
                raise InvalidInputError(
                    "/robot_description",
                    f"must be URDF XML; got {len(msg.data)} characters not starting with '<'",
                )
            bundle = build_robot(settings, msg.data)
        except Exception as error:  # GraspSafetyError, or a bug on a strange description
            reason = str(error)
            if not isinstance(error, GraspSafetyError):
                self.get_logger().error(f"/robot_description:\n{traceback.format_exc()}")
                reason = internal_error(error)
            if self._waiting_for_robot:
                # wait_for_robot raises it, main() logs it once
                self._startup_failure = f"robot from /robot_description: {reason}"
            else:
                with self._state_lock:
                    self._status.robot_description_error = reason
                self._report_error("/robot_description", reason)  # the working model stays
            return
        with self._state_lock:
            if robot_key(self._settings) != robot_key(settings):
                return  # robot parameters changed meanwhile; they rebuilt the model
            self._robot = bundle
            self._status.robot_description_error = ""
        if bundle is not None:
            self._robot_ready(bundle)


def robot_key(settings: NodeSettings) -> tuple[str, str, str, tuple[float, ...] | None]:
    """The settings a robot model depends on."""
    return (settings.robot_source, settings.base_frame, settings.tip_frame, settings.ik_seed)
