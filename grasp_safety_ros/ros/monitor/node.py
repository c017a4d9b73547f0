"""The ``grasp_safety_monitor`` node: a live speed-scaling factor for ros2_control.

Per /joint_states message (only the newest: the subscription keeps one), every site's speed
and effective mass along its current velocity, robot + carried object + rotor inertia, against
its body region's ISO/TS 15066 transient-contact speed (core.analyses.speed_scaling); the
factor f = min(1, min_k margin · v_max,k / |v_k|) goes out on ``~/speed_scaling``
(control_msgs/SpeedScalingFactor, reliable + transient-local, depth 1: remap it to
``/<controller>/speed_scaling_input``), the per-region status on ``~/status``
(grasp_safety_msgs/SpeedScalingStatus), the state of the monitor on /diagnostics.
Fail-safe: factor 0 with the reason (governor.py). An advisory governor, not a certified
safety function (docs/ros/monitor.md).

A thin adapter: the robot and the shared parameters come from the ranking node's code
(robot_bundle, parameters, declaration); one thread (SingleThreadedExecutor) runs every
callback, so the analysis (which reuses its Pinocchio data) needs no lock.
"""

from __future__ import annotations

import os
import signal
import sys
import time
import traceback
from collections.abc import Callable
from functools import partial
from types import FrameType
from typing import Any, NoReturn

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import InertiaStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String

from ...core.analyses.arm_sites import resolve_arm_sites
from ...core.analyses.speed_scaling import IncreaseLimiter, SpeedScaling, payload_speed_model
from ...core.exceptions import GraspSafetyError
from ..conversions import check_frame_id, object_inertia_from_msg
from ..parameters.declaration import declare_node_parameters, typed_parameters
from ..robot.bundle import build_robot
from ..runtime.collector import freeze_long_lived, thaw
from ..service.errors import StartupError
from ..topics.qos import LATCHED
from .governor import Decision, Governor
from .parameters import (
    MONITOR_TABLE,
    RUNTIME,
    MonitorSettings,
    Payload,
    monitor_settings,
    payload_points,
)

try:  # built by `make setup`; without them the executable says so in one line (run)
    from control_msgs.msg import SpeedScalingFactor
    from grasp_safety_msgs.msg import SpeedScalingStatus

    from .messages import diagnostic_status, status_msg
except ImportError as missing:
    MISSING_INTERFACES = (
        f"interface package {(missing.name or str(missing)).split('.')[0]} missing: build it "
        "with `make setup` (control_msgs needs ../shared/interfaces beside the checkout)"
    )
else:
    MISSING_INTERFACES = ""

NODE_NAME = "grasp_safety_monitor"
NEWEST_STATE = QoSProfile(
    depth=1,
    history=qos_profile_sensor_data.history,
    reliability=qos_profile_sensor_data.reliability,
    durability=qos_profile_sensor_data.durability,
)
"""Sensor-data QoS keeping one message: a state waiting while the last is computed is
replaced by a newer one, so the queue never grows and only the newest is assessed."""
STATUS_DEPTH = 100
"""~/status keeps the last 100 (0.2 s at 500 Hz) for a reliable subscriber that falls behind."""
WATCHDOG_CHECKS_PER_TIMEOUT = 5
"""The silence of /joint_states is checked this many times per joint_states_timeout_s."""


class MonitorNode(Node):
    """Publishes the speed-scaling factor for the robot's current motion.

    Raises:
        StartupError: a parameter is invalid or the robot description cannot be used.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.add_pre_set_parameters_callback(partial(typed_parameters, table=MONITOR_TABLE))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._started = False
        try:
            declare_node_parameters(self, MONITOR_TABLE)
            values = {name: self.get_parameter(name).value for name in MONITOR_TABLE.specs}
            self._settings: MonitorSettings = monitor_settings(values)
            self._bundle = build_robot(self._settings.node, None)
            self._payload = self._settings.payload
            self._governor = Governor(
                self._settings.joint_states_timeout_s,
                IncreaseLimiter(self._settings.max_increase_per_s, 0.0, time.monotonic()),
                self._settings.closed_loop,
                self._settings.controller_latency_s,
            )
            self._rebuild()
        except (GraspSafetyError, InvalidParameterValueException) as error:
            self.destroy_node()
            raise StartupError(str(error)) from None
        self._last: Decision | None = None
        self._last_refusal = ""
        self._factor_pub = self.create_publisher(SpeedScalingFactor, "~/speed_scaling", LATCHED)
        self._status_pub = self.create_publisher(SpeedScalingStatus, "~/status", STATUS_DEPTH)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "/joint_states", self._on_joint_states, NEWEST_STATE)
        self.create_subscription(InertiaStamped, "~/payload", self._guarded(self._on_payload), 10)
        if self._bundle is None:
            self.create_subscription(
                String, "/robot_description", self._guarded(self._on_description), LATCHED
            )
        self._watchdog = self._create_watchdog()
        self.create_timer(self._settings.node.diagnostics_period_s, self._publish_diagnostics)
        self._started = True
        self._publish(self._governor.fail("no /joint_states yet", time.monotonic()), None)
        if self._bundle is not None:
            freeze_long_lived()  # the robot serves: full collections no longer walk its heap

    # --- Inputs ------------------------------------------------------------------------------

    def _on_joint_states(self, msg: JointState) -> None:
        try:
            decision = self._governor.on_state(
                msg.name, msg.position, msg.velocity, time.monotonic()
            )
        except Exception as error:  # a defect: fail safe, keep serving
            self.get_logger().error(f"joint_states: internal error:\n{traceback.format_exc()}")
            decision = self._governor.fail(_internal_error(error), time.monotonic())
        self._publish(decision, msg.header.stamp)

    def _on_payload(self, msg: InertiaStamped) -> None:
        """A new carried object (m = 0: nothing), inertia in the tip frame; refused (one line
        on the log and /diagnostics) in another frame or over max_mass_kg: then factor 0 with
        the refusal as the reason until a valid payload arrives (the carried object is not
        the previous one any more)."""
        node = self._settings.node
        try:
            check_frame_id(msg.header.frame_id, [node.tip_frame], "payload.header.frame_id")
            inertia = object_inertia_from_msg(msg.inertia, node.max_mass_kg, "payload.inertia")
            settings = self._settings
            points = payload_points(inertia, settings.points_in_tip_m, settings.box_size_m)
            previous, self._payload = self._payload, Payload(inertia, points)
            try:
                self._rebuild()
            except GraspSafetyError:
                self._payload = previous
                raise
        except GraspSafetyError as error:
            self._refuse("payload", error)
            self._governor.refuse_payload(self._last_refusal)
            self._publish(self._governor.fail(self._last_refusal, time.monotonic()), None)
            return
        self._governor.refuse_payload("")
        self.get_logger().info(
            f"payload: {inertia.mass_kg:g} kg" if inertia else "payload: nothing carried (m = 0)"
        )

    def _on_description(self, msg: String) -> None:
        if self._bundle is not None:
            return
        try:
            self._bundle = build_robot(self._settings.node, msg.data)
            self._rebuild()
        except GraspSafetyError as error:
            self._bundle = None
            self._refuse("/robot_description", error)
            return
        freeze_long_lived()

    def _rebuild(self) -> None:
        """The analysis for the current robot and payload (nothing before a robot)."""
        if self._bundle is None:
            return
        robot = self._bundle.robot
        sites = resolve_arm_sites(robot, self._settings.node.analysis.arm_points_m)
        payload = self._payload
        model = payload_speed_model(
            robot,
            sites,
            payload.inertia,
            payload.points_in_tip_m,
            self._settings.node.analysis.iso_regions,
        )
        settings = self._settings
        self._governor.set_scaling(SpeedScaling(model, settings.margin, settings.rest_speed_m_s))
        self.get_logger().info(
            f"robot from {self._bundle.origin}: {robot.base_frame} -> {robot.tip_frame}, "
            f"{robot.num_joints} joints, {len(model.sites)} sites, regions "
            f"{', '.join(r.name for r in model.regions)}"
        )

    # --- Parameters --------------------------------------------------------------------------

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        try:
            for parameter in parameters:
                MONITOR_TABLE.check(parameter.name, parameter.value)
                if self._started and parameter.name not in RUNTIME:
                    return SetParametersResult(
                        successful=False,
                        reason=f"{parameter.name}: read at start-up only; changeable at run "
                        f"time: {', '.join(RUNTIME)}",
                    )
            if self._started:
                self._apply({p.name: p.value for p in parameters})
        except GraspSafetyError as error:
            return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _apply(self, changes: dict[str, Any]) -> None:
        values = {name: self.get_parameter(name).value for name in MONITOR_TABLE.specs}
        settings = monitor_settings({**values, **changes})
        self._settings = settings
        self._governor.timeout_s = settings.joint_states_timeout_s
        self._governor.limiter.max_increase_per_s = settings.max_increase_per_s
        self._governor.closed_loop = settings.closed_loop
        self._governor.controller_latency_s = settings.controller_latency_s
        if self._governor.scaling is not None:
            self._governor.scaling.margin = settings.margin
        self.destroy_timer(self._watchdog)
        self._watchdog = self._create_watchdog()

    # --- Outputs -----------------------------------------------------------------------------

    def _create_watchdog(self) -> Timer:
        period = self._settings.joint_states_timeout_s / WATCHDOG_CHECKS_PER_TIMEOUT
        return self.create_timer(period, self._on_watchdog)

    def _on_watchdog(self) -> None:
        decision = self._governor.check_timeout(time.monotonic())
        if decision is not None:
            self._publish(decision, None)

    def _publish(self, decision: Decision, stamp: Time | None) -> None:
        try:
            self._send(decision, stamp)
        except Exception as error:  # a defect: log it, fail safe, keep spinning
            self.get_logger().error(f"publish: internal error:\n{traceback.format_exc()}")
            self._send(self._governor.fail(_internal_error(error), time.monotonic()), None)

    def publish_stop(self) -> None:
        """Factor 0 on shutdown: the latched factor must not outlive the monitor."""
        self._factor_pub.publish(SpeedScalingFactor(factor=0.0))

    def destroy_node(self) -> None:
        """Destroy the node and unfreeze the heap frozen for its robot (runtime.collector)."""
        super().destroy_node()
        thaw()

    def _send(self, decision: Decision, stamp: Time | None) -> None:
        first_failure = decision.fail_safe and (
            self._last is None or self._last.fail_safe != decision.fail_safe
        )
        self._last = decision
        self._factor_pub.publish(SpeedScalingFactor(factor=decision.factor))
        if self._status_pub.get_subscription_count():
            stamp = stamp if stamp is not None else self.get_clock().now().to_msg()
            self._status_pub.publish(status_msg(decision, stamp, self._settings.node.base_frame))
        if first_failure:  # once per reason, not per message
            self.get_logger().warning(f"factor 0: {decision.fail_safe}")
            self._publish_diagnostics()

    def _refuse(self, source: str, error: BaseException | str) -> None:
        self._last_refusal = f"{source} refused: {error}"
        self.get_logger().warning(self._last_refusal)
        self._publish_diagnostics()

    def _guarded(self, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        def guarded(msg: Any) -> None:
            try:
                callback(msg)
            except Exception as error:  # last resort: keep serving
                self.get_logger().error(f"internal error:\n{traceback.format_exc()}")
                self._refuse("input", _internal_error(error))

        return guarded

    def diagnostics_status(self) -> DiagnosticStatus:
        """The monitor's current DiagnosticStatus (also published on /diagnostics)."""
        payload = self._payload.inertia
        return diagnostic_status(
            NODE_NAME,
            self._last,
            self._governor.counters,
            self._settings,
            self._bundle,
            f"{payload.mass_kg:g} kg" if payload else "nothing carried",
            self._last_refusal,
        )

    def _publish_diagnostics(self) -> None:
        if self._diagnostics_pub.get_subscription_count() == 0:
            return
        self._diagnostics_pub.publish(
            DiagnosticArray(
                header=Header(stamp=self.get_clock().now().to_msg()),
                status=[self.diagnostics_status()],
            )
        )


def _interrupt(signal_number: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt(signal.Signals(signal_number).name)


def _internal_error(error: BaseException) -> str:
    return f"internal error: {type(error).__name__}: {error}"


def run(args: list[str] | None = None) -> int:
    """Run the monitor until SIGINT/SIGTERM or shut-down; 1 on a start-up error (one line).

    The monitor handles the signals itself (rclpy's handlers would shut the context down
    first): on the way out it publishes factor 0, so its latched factor does not outlive it.
    """
    logger = rclpy.logging.get_logger(NODE_NAME)
    if MISSING_INTERFACES:
        logger.error(f"start-up failed: {MISSING_INTERFACES}")
        return 1
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as error:  # bad --ros-args or params file
        logger.error(f"start-up failed: {str(error).strip().splitlines()[0]}")
        return 1
    for number in (signal.SIGINT, signal.SIGTERM):  # raised in spin: its timers wake it
        signal.signal(number, _interrupt)
    node: MonitorNode | None = None
    status = 0
    try:
        node = MonitorNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except StartupError as error:
        logger.error(f"start-up failed: {error}")
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for number in (signal.SIGINT, signal.SIGTERM):  # a second signal (ros2 launch sends
            signal.signal(number, signal.SIG_IGN)  # one more) no longer interrupts teardown
        if node is not None:
            try:
                node.publish_stop()
            except Exception as error:  # the context may be gone: say so, still tear down
                logger.error(f"shutdown: could not publish factor 0: {error}")
            node.destroy_node()
        rclpy.try_shutdown()
    return status


def main(args: list[str] | None = None) -> NoReturn:
    """The console script ``grasp_safety_monitor``."""
    status = run(args)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)  # as the ranking node: no interpreter teardown of native handles
