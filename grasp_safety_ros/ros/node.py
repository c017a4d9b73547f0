"""The ``grasp_safety`` node: ranks candidate grasps with the core, over a service and topics.

A thin adapter: messages are converted in conversions.py, parameters validated in
parameters.py, the work is GraspSafetyEvaluator.rank followed by
core.analyses.safety_report.analyse (metric point, ISO/TS 15066, inertia uncertainty, grasp
quality, redundancy, effort). See docs/ros/interface.md for the interface.

Threads: a NodeExecutor (a MultiThreadedExecutor) with EXECUTOR_THREADS threads. The service
sits in its own reentrant callback group, the input topics in a mutually exclusive one,
everything else (parameters, /robot_description, /joint_states, the diagnostics timer) in the
default group. One ranking computes at a time (the compute lock: the core's solvers keep
scratch data), in arrival order and in slices: a ranking hands the lock to waiting requests
after 0.2 s at its next progress check (ranking_job.FairComputeLock), so a small request does
not wait for a large one; a request that cannot get the lock within
``service_busy_timeout_s`` is answered busy, a ranking longer than ``max_compute_time_s``
(time queued not counted) or whose client has left the ROS graph is abandoned
(docs/ros/reliability.md). The GIL still makes a long ranking share the CPU with the other
callbacks. The markers are built, and the ranking published (serialised), only once they
have had a subscriber; a late transient-local subscriber gets the latest (_OnDemandPublisher).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, NoReturn

import numpy as np
import rclpy
import rclpy.utilities
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Inertia, InertiaStamped, PoseArray
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import (
    PublisherEventCallbacks,
    QoSMessageLostInfo,
    QoSPublisherMatchedInfo,
    SubscriptionEventCallbacks,
)
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
)
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.service_introspection import ServiceIntrospectionState
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from service_msgs.msg import ServiceEventInfo
from std_msgs.msg import Float64MultiArray, Header, String
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from ..core.analyses.exposed_points import check_metric_point
from ..core.analyses.safety_report import AnalysisOptions, analyse, posture_criterion
from ..core.exceptions import GraspSafetyError, InvalidInputError
from ..core.input_checks import finite_array
from ..core.method.posture import select_postures
from ..core.method.ranking import Ranking, check_metric
from ..core.model.inertia import ObjectInertia
from ..core.model.robot import NO_ARMATURE_NOTE, RobotModel
from .arm_points import check_arm_point_links
from .conversions import (
    check_frame_id,
    check_grasp_array,
    grasps_from_pose_array,
    grasps_with_joint_trajectories,
    markers_msg,
    object_inertia_from_msg,
    object_trajectory_of_request,
    report_msg,
    seed_from_joint_state,
    trajectory_from_msg,
)
from .declaration import declare_node_parameters, typed_parameters
from .executor import NodeExecutor, request_header
from .memory import memory_kib, release_free_heap
from .message_checks import check_finite_result, check_no_subnormals
from .parameters import (
    PARAMETERS,
    NodeSettings,
    RobotBundle,
    build_robot,
    check_parameter,
    settings_from_parameters,
)
from .ranking_job import ClientWatch, FairComputeLock
from .robot_group import PENDING_FIELDS, ROBOT_GROUP, group_complete, pending_reason

NODE_NAME = "grasp_safety"
EXECUTOR_THREADS = 4
"""Service calls, topic input and parameter/diagnostics callbacks each get a thread."""

LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
"""Results: late subscribers (RViz, ``ros2 topic echo``) get the last ranking."""
INPUT = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
"""Candidate grasps, their quality, the object trajectory and inertia: every message counts
(the pairing rules follow their order), so none is overwritten in the node's queue (keep the
last 10 dropped the oldest of a burst unreported); a reliable publisher is slowed down
instead, and what the middleware still loses is counted (``lost.<topic>`` on /diagnostics)."""
SERVICE = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Requests wait in the service's queue until a thread takes them; the default (keep the last
10) silently dropped the oldest when more than EXECUTOR_THREADS + 10 were in flight."""
MAX_ABS_GRASP_QUALITY = 1e9
"""Grasp qualities beyond +/-1e9 are refused: the min-max normalisation of the combined score
overflowed (1.8e308 and -1.8e308 gave a NaN combined score, ranked first)."""
_STANDARD_OVERRIDES = ("use_sim_time", "qos_overrides.", "start_type_description_service")


class StartupError(GraspSafetyError):
    """The node cannot start: bad parameters or no usable robot description."""


class NotReadyError(GraspSafetyError):
    """No robot model yet."""


class BusyError(GraspSafetyError):
    """Another ranking held the compute lock for longer than service_busy_timeout_s."""


class ComputeTimeExceededError(GraspSafetyError):
    """A ranking ran longer than max_compute_time_s and was abandoned."""


class ShuttingDownError(GraspSafetyError):
    """The node is shutting down: the ranking was abandoned."""


class ClientGoneError(GraspSafetyError):
    """The request's client left the ROS graph: the ranking was abandoned."""


@dataclass
class _Status:
    """What /diagnostics reports (guarded by the node's state lock)."""

    rankings: int = 0
    refused: int = 0
    last_compute_time_s: float = 0.0
    last_feasible: int = 0
    last_infeasible: int = 0
    last_source: str = ""
    last_error: str = ""
    last_was_error: bool = False
    robot_description_error: str = ""  # why the last /robot_description was not used
    robot_parameters_pending: str = ""  # why the robot group is not applied yet
    abandoned: int = 0  # rankings abandoned at shut-down
    ignored_descriptions: int = 0  # /robot_description messages ignored (parameters rule)
    refused_by_source: dict[str, int] = field(default_factory=dict)
    lost_by_source: dict[str, int] = field(default_factory=dict)  # the middleware's count


@dataclass(frozen=True)
class _Snapshot:
    """Consistent view of the state one ranking uses."""

    settings: NodeSettings
    bundle: RobotBundle | None
    joint_state: tuple[Sequence[str], Sequence[float]] | None
    inertia_override: ObjectInertia | None


SERVICE_EVENTS_KEPT = 1024
"""Request arrivals (client GID, sequence number, time) kept to identify a request's client."""


GRAPH_CHECK_PERIOD_S = 0.02
GRAPH_CHECK_ATTEMPTS = 100
"""After a subscriber matches or leaves, _OnDemandPublisher waits up to 100 x 0.02 s for the ROS
graph to show it (the subscribers' durabilities decide whether the kept message is sent)."""


class _OnDemandPublisher:
    """A latched (transient-local) publisher that builds and serialises its message only for
    subscribers.

    ``publish(build)`` builds and publishes at once when the topic has a subscriber; else it
    keeps ``build`` and runs it when a subscriber that asks for the latest message
    (transient-local durability) connects (the publisher's matched event, then the ROS graph
    for the durability), so a late subscriber still gets the latest message and nobody pays
    for messages no one receives. A volatile subscriber is not sent the kept message: it asked
    for messages published after it subscribed only. A publication reaches every matched
    subscriber, so while a volatile one is matched the kept message stays kept (a stale
    ranking is never delivered to a reader that did not ask for it); it is sent when the
    volatile subscribers have left, or replaced by the next message. Once a message was
    published (the publisher's history holds it), every later one is published at once,
    subscribers or not: a late subscriber receives the latest message only, never an older
    one from the history.
    """

    def __init__(self, node: Node, msg_type: Any, topic: str) -> None:
        self._node = node
        self._lock = threading.Lock()
        self._pending: Callable[[], Any] | None = None
        self._holds_message = False  # the publisher's history holds a message
        self._graph_check = node.create_timer(GRAPH_CHECK_PERIOD_S, self._check_graph)
        self._graph_check.cancel()  # runs after a match only
        self._graph_attempts = 0
        self.publisher = node.create_publisher(
            msg_type,
            topic,
            LATCHED,
            event_callbacks=PublisherEventCallbacks(matched=self._on_matched),
        )

    def publish(self, build: Callable[[], Any]) -> None:
        """Publish ``build()`` now if someone subscribes (or the history holds an older
        message), else when someone does."""
        with self._lock:  # keeps the order: a late publish never overtakes a newer one
            if self._holds_message or self.publisher.get_subscription_count() > 0:
                self._pending = None
                self.publisher.publish(build())
                self._holds_message = True
                return
            self._pending = build

    def _on_matched(self, info: QoSPublisherMatchedInfo) -> None:
        """A subscriber connected or left: once the ROS graph shows the change (it can lag
        the match), send the kept message if every subscriber wants the latest one."""
        if info.current_count == 0:
            return
        with self._lock:
            if self._pending is not None:
                self._graph_attempts = GRAPH_CHECK_ATTEMPTS
                self._graph_check.reset()

    def _check_graph(self) -> None:
        with self._lock:
            endpoints = self._node.get_subscriptions_info_by_topic(self.publisher.topic_name)
            lagging = len(endpoints) != self.publisher.get_subscription_count()
            self._graph_attempts -= 1
            if lagging and self._graph_attempts > 0:
                return
            self._graph_check.cancel()
            wanted = bool(endpoints) and all(
                endpoint.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                for endpoint in endpoints
            )
            if self._pending is not None and wanted:
                build, self._pending = self._pending, None
                self.publisher.publish(build())
                self._holds_message = True


class GraspSafetyNode(Node):
    """Ranks grasps by the effective mass of robot + object along the object's trajectory.

    Args:
        **kwargs: Passed to rclpy.node.Node (e.g. ``context``, ``parameter_overrides``).

    Raises:
        StartupError: a parameter is invalid or the robot description cannot be used.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._setup()
        except StartupError:
            self.destroy_node()
            raise

    # --- Set-up ------------------------------------------------------------------------------

    def _setup(self) -> None:
        self._state_lock = threading.Lock()
        self._compute_lock = FairComputeLock()
        self._stopping = threading.Event()  # set by abandon_rankings at shut-down
        self._started = False
        self._startup_rejection = ""
        self._startup_failure = ""
        self._waiting_for_robot = False
        self._topic_description: str | None = None
        self._joint_state: tuple[Sequence[str], Sequence[float]] | None = None
        self._candidates: PoseArray | None = None
        self._candidates_pending = False
        self._candidates_quality: tuple[float, ...] | None = None  # paired with _candidates
        self._pending_quality: tuple[float, ...] | None = None  # waits for the next set
        self._trajectory: Path | MultiDOFJointTrajectory | None = None
        self._inertia_override: ObjectInertia | None = None
        self._status = _Status()
        self._pending_robot: dict[str, Any] = {}  # robot group values accepted, not applied
        self._arrivals: deque[tuple[int, int, bytes]] = deque(maxlen=SERVICE_EVENTS_KEPT)
        self._trim_pending = False

        self.add_pre_set_parameters_callback(typed_parameters)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        try:
            declare_node_parameters(self)
        except GraspSafetyError as error:
            raise StartupError(str(error)) from None
        except (InvalidParameterValueException, InvalidParameterTypeException) as error:
            raise StartupError(self._startup_rejection or str(error)) from None
        self._values = {name: self.get_parameter(name).value for name in PARAMETERS}
        try:
            self._settings = settings_from_parameters(self._values)
            self._robot = build_robot(self._settings, None)
        except GraspSafetyError as error:
            raise StartupError(str(error)) from None
        self._warn_unknown_overrides()

        self._service_group = ReentrantCallbackGroup()
        self._topic_group = topics = MutuallyExclusiveCallbackGroup()
        self._ranking_pub = _OnDemandPublisher(self, GraspRanking, "~/ranking")
        self._ranked_pub = self.create_publisher(PoseArray, "~/ranked_grasps", LATCHED)
        self._markers_pub = _OnDemandPublisher(self, MarkerArray, "~/markers")
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._service = self.create_service(
            RankGrasps,
            "~/rank_grasps",
            self._on_rank_grasps,
            qos_profile=SERVICE,
            callback_group=self._service_group,
        )
        # Which client sent a request: the service's introspection events (metadata only)
        # carry the client's GID and the request's sequence number.
        # rcl keeps a pointer to the clock: it must live as long as the service
        self._event_clock = Clock(clock_type=ClockType.SYSTEM_TIME)
        self._service.configure_introspection(
            self._event_clock, SERVICE, ServiceIntrospectionState.METADATA
        )
        self.create_subscription(
            RankGrasps.Event,
            f"{self._service.service_name}/_service_event",
            self._on_service_event,
            SERVICE,
        )
        inputs = (
            (PoseArray, "~/candidate_grasps", self._on_candidates, INPUT, topics),
            (Float64MultiArray, "~/candidate_grasp_quality", self._on_quality, INPUT, topics),
            (Path, "~/object_trajectory", self._on_trajectory, INPUT, topics),
            (
                MultiDOFJointTrajectory,
                "~/object_multi_dof_trajectory",
                self._on_trajectory,
                INPUT,
                topics,
            ),
            (InertiaStamped, "~/object_inertia", self._on_inertia, INPUT, topics),
            (JointState, "/joint_states", self._on_joint_states, qos_profile_sensor_data, None),
            (String, "/robot_description", self._on_robot_description, LATCHED, None),
        )
        for msg_type, topic, callback, qos, group in inputs:
            source = topic.removeprefix("~/")
            self.create_subscription(
                msg_type,
                topic,
                self._guarded(source, callback),
                qos,
                callback_group=group,
                event_callbacks=SubscriptionEventCallbacks(
                    message_lost=partial(self._on_message_lost, source)
                ),
            )
        self._diagnostics_timer = self.create_timer(
            self._settings.diagnostics_period_s, self._on_diagnostics_timer
        )
        self._started = True
        if self._robot is not None:
            self._log_robot(self._robot)

    def _guarded(self, source: str, callback: Callable[[Any], None]) -> Callable[[Any], None]:
        """``callback`` for a topic, after refusing a message with a subnormal float (an int
        sent as a float); an unexpected exception (a bug) is logged and reported on
        /diagnostics instead of stopping the executor."""

        def guarded(msg: Any) -> None:
            try:
                check_no_subnormals(msg, source)
            except GraspSafetyError as error:
                self._report_error(source, error)
                return
            try:
                callback(msg)
            except Exception as error:  # last resort: keep serving
                self.get_logger().error(f"{source}: internal error:\n{traceback.format_exc()}")
                self._report_error(source, _internal_error(error))

        return guarded

    def _on_message_lost(self, source: str, info: QoSMessageLostInfo) -> None:
        """The middleware reports messages of a topic lost before the node took them."""
        with self._state_lock:
            lost = self._status.lost_by_source
            lost[source] = lost.get(source, 0) + info.total_count_change
        self.get_logger().warning(
            f"{source}: {info.total_count_change} message(s) lost before the node took them "
            f"({info.total_count} in all)"
        )

    def abandon_rankings(self) -> None:
        """Make the running ranking (and any later one) stop at its next progress check: for
        shut-down, so that no executor thread outlives the node."""
        self._stopping.set()
        self._compute_lock.stop()

    @property
    def abandoned_rankings(self) -> int:
        """Rankings abandoned because the node is shutting down."""
        with self._state_lock:
            return self._status.abandoned

    def _warn_unknown_overrides(self) -> None:
        for name in sorted(self._parameter_overrides):
            if name not in PARAMETERS and not name.startswith(_STANDARD_OVERRIDES):
                self.get_logger().warning(
                    f"ignoring unknown parameter '{name}'; parameters: {', '.join(PARAMETERS)}"
                )

    def _log_robot(self, bundle: RobotBundle) -> None:
        robot = bundle.robot
        self.get_logger().info(
            f"robot from {bundle.origin}: {robot.base_frame} -> {robot.tip_frame}, "
            f"{robot.num_joints} joints ({', '.join(robot.joint_names)})"
        )

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

    # --- Parameters --------------------------------------------------------------------------

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        try:
            if not self._started:  # declaration: one parameter at a time, checked alone
                for parameter in parameters:
                    check_parameter(parameter.name, parameter.value)
            else:
                self._apply_parameters({p.name: p.value for p in parameters})
        except GraspSafetyError as error:
            reason = str(error)
            if self._started:
                self.get_logger().warning(f"refused parameter change: {reason}")
            else:
                self._startup_rejection = reason
            return SetParametersResult(successful=False, reason=reason)
        except Exception as error:  # last resort: refuse the change rather than stop
            self.get_logger().error(f"parameters: internal error:\n{traceback.format_exc()}")
            reason = _internal_error(error)
            if not self._started:
                self._startup_rejection = reason
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

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
            self._log_robot(bundle)
        if period_changed:
            self._diagnostics_timer.cancel()
            self.destroy_timer(self._diagnostics_timer)
            self._diagnostics_timer = self.create_timer(
                settings.diagnostics_period_s, self._on_diagnostics_timer
            )

    # --- Robot description and joint states --------------------------------------------------

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
                reason = _internal_error(error)
            if self._waiting_for_robot:
                # wait_for_robot raises it, main() logs it once
                self._startup_failure = f"robot from /robot_description: {reason}"
            else:
                with self._state_lock:
                    self._status.robot_description_error = reason
                self._report_error("/robot_description", reason)  # the working model stays
            return
        with self._state_lock:
            if _robot_key(self._settings) != _robot_key(settings):
                return  # robot parameters changed meanwhile; they rebuilt the model
            self._robot = bundle
            self._status.robot_description_error = ""
        if bundle is not None:
            self._log_robot(bundle)

    def _on_joint_states(self, msg: JointState) -> None:
        with self._state_lock:
            self._joint_state = (list(msg.name), list(msg.position))

    # --- Service -----------------------------------------------------------------------------

    def _on_rank_grasps(
        self, request: RankGrasps.Request, response: RankGrasps.Response
    ) -> RankGrasps.Response:
        try:
            check_no_subnormals(request)
            response.ranking = self._rank(
                request.grasps,
                object_trajectory_of_request(
                    request.object_trajectory, request.object_multi_dof_trajectory
                ),
                request.object_inertia,
                request.metric,
                source="rank_grasps",
                grasps_field="grasps",
                quality=_quality(request.grasp_quality, "grasp_quality"),
                metric_point=request.metric_point,
                quality_field="grasp_quality",
                joint_trajectories=request.joint_trajectories,
                client_watch=self._client_watch(request_header()),
            )
            response.success = True
        except ShuttingDownError as error:  # answered, not reported: the node is going
            response.success = False
            response.message = str(error)
            with self._state_lock:
                self._status.abandoned += 1
        except GraspSafetyError as error:
            response.success = False
            response.message = str(error)
            self._report_error("rank_grasps", error)
        except Exception as error:  # last resort: answer and log rather than drop the request
            self.get_logger().error(f"rank_grasps: internal error:\n{traceback.format_exc()}")
            response.success = False
            response.message = _internal_error(error)
            self._report_error("rank_grasps", error)
        return response

    def _client_watch(self, header: Any) -> ClientWatch:
        """The watch on the client of the request of ``header`` (None: not run by
        NodeExecutor, the clients present now stand in)."""
        if header is None:
            return ClientWatch(self._service_clients)
        return ClientWatch(self._service_clients, partial(self._client_of, header))

    def _service_clients(self) -> list[bytes]:
        """GIDs of the rank_grasps clients' endpoints in the ROS graph (request writers and
        response readers, on the DDS topics ``rq/<service>Request`` and ``rr/<service>Reply``;
        none where the middleware names them otherwise)."""
        name = self._service.service_name.lstrip("/")
        writers = self.get_publishers_info_by_topic(f"rq/{name}Request", no_mangle=True)
        readers = self.get_subscriptions_info_by_topic(f"rr/{name}Reply", no_mangle=True)
        return [bytes(endpoint.endpoint_gid) for endpoint in (*writers, *readers)]

    def _on_service_event(self, event: Any) -> None:
        info = event.info
        if info.event_type == ServiceEventInfo.REQUEST_RECEIVED:
            stamp_ns = info.stamp.sec * 1_000_000_000 + info.stamp.nanosec
            with self._state_lock:
                self._arrivals.append((info.sequence_number, stamp_ns, bytes(info.client_gid)))

    def _client_of(self, header: Any) -> bytes | None:
        """The GID of the client that sent the request of ``header`` (same sequence number,
        the arrival closest in time, within a second), or None when not known (yet)."""
        number, received_ns = header.request_id.sequence_number, header.received_timestamp
        with self._state_lock:
            matches = [
                (abs(stamp_ns - received_ns), gid)
                for seq, stamp_ns, gid in self._arrivals
                if seq == number and abs(stamp_ns - received_ns) < 1_000_000_000
            ]
        return min(matches)[1] if matches else None

    # --- Topics ------------------------------------------------------------------------------

    def _on_candidates(self, msg: PoseArray) -> None:
        settings = self._snapshot().settings
        try:
            check_grasp_array(
                msg,
                settings.object_frame,
                settings.base_frame,
                settings.max_grasps,
                "candidate_grasps",
            )
        except GraspSafetyError as error:
            self._report_error("candidate_grasps", error)
            return
        with self._state_lock:
            quality, self._pending_quality = self._pending_quality, None
            if quality is not None and len(quality) != len(msg.poses):
                discarded, quality = len(quality), None
            else:
                discarded = None
            self._candidates, self._candidates_pending = msg, True
            self._candidates_quality = quality
        if discarded is not None:
            self._report_error(
                "candidate_grasp_quality",
                InvalidInputError(
                    "candidate_grasp_quality.data",
                    f"has {discarded} values but the new candidate set has {len(msg.poses)} "
                    "grasps; discarded",
                ),
            )
        self._rank_topics()

    def _on_quality(self, msg: Float64MultiArray) -> None:
        """Pair a quality vector with the current candidate set or hold it for the next one.

        The current set takes it if it has the same length and no quality yet (it is then
        ranked again, with the quality); otherwise it waits for the next candidate set, which
        takes it if the lengths match. An empty vector clears a waiting one.
        """
        try:
            quality = _quality(msg.data, "candidate_grasp_quality.data")
        except GraspSafetyError as error:
            self._report_error("candidate_grasp_quality", error)
            return
        with self._state_lock:
            current = self._candidates
            if (
                quality is not None
                and current is not None
                and self._candidates_quality is None
                and len(current.poses) == len(quality)
            ):
                self._candidates_quality, self._candidates_pending = quality, True
                self._pending_quality = None
            else:
                self._pending_quality = quality
                return
        self._rank_topics()

    def _on_trajectory(self, msg: Path | MultiDOFJointTrajectory) -> None:
        settings = self._snapshot().settings
        source = (
            "object_multi_dof_trajectory"
            if isinstance(msg, MultiDOFJointTrajectory)
            else "object_trajectory"
        )
        try:
            trajectory_from_msg(
                msg,
                settings.base_frame,
                settings.trajectory_dt_s,
                settings.trajectory_duration_s,
                settings.max_samples,
            )
        except GraspSafetyError as error:
            self._report_error(source, error)
            return
        with self._state_lock:
            self._trajectory = msg
        self._rank_topics()

    def _on_inertia(self, msg: InertiaStamped) -> None:
        settings = self._snapshot().settings
        try:
            check_frame_id(
                msg.header.frame_id, [settings.object_frame], "object_inertia.header.frame_id"
            )
            override = object_inertia_from_msg(msg.inertia, settings.max_mass_kg)
        except GraspSafetyError as error:
            self._report_error("object_inertia", error)
            return
        with self._state_lock:
            self._inertia_override = override
        self.get_logger().info(
            "object inertia override "
            + (f"set: {override.mass_kg:g} kg" if override else "cleared (m = 0)")
        )

    def _rank_topics(self) -> None:
        """Rank the candidate set if it is new (not ranked yet) and a trajectory is known."""
        with self._state_lock:
            grasps, path = self._candidates, self._trajectory
            quality = self._candidates_quality
            if grasps is None or path is None or not self._candidates_pending:
                return
            self._candidates_pending = False
        try:
            self._rank(
                grasps,
                path,
                None,
                "",
                source="topics",
                grasps_field="candidate_grasps",
                quality=quality,
                quality_field="candidate_grasp_quality",
            )
        except NotReadyError as error:
            with self._state_lock:
                self._candidates_pending = True  # retried with the next trajectory
            self._report_error("topics", error)
        except ShuttingDownError:
            pass  # the node is going: nothing to report
        except GraspSafetyError as error:
            self._report_error("topics", error)

    # --- Ranking -----------------------------------------------------------------------------

    def _snapshot(self) -> _Snapshot:
        with self._state_lock:
            return _Snapshot(
                self._settings, self._robot, self._joint_state, self._inertia_override
            )

    def _rank(
        self,
        grasps_msg: PoseArray,
        trajectory_msg: Path | MultiDOFJointTrajectory,
        inertia_msg: Inertia | None,
        metric: str,
        source: str,
        grasps_field: str,
        quality: tuple[float, ...] | None = None,
        metric_point: str = "",
        quality_field: str = "grasp_quality",
        joint_trajectories: Sequence[JointTrajectory] = (),
        client_watch: ClientWatch | None = None,
    ) -> GraspRanking:
        """Convert, rank, analyse, publish; return the GraspRanking. Raises GraspSafetyError.

        Args:
            quality: One grasp quality per grasp (higher is better), or None.
            metric_point: The request's metric point; empty: the parameter's.
            joint_trajectories: One planned joint trajectory per grasp, or none (IK).
            client_watch: The service's clients at the request's arrival: the ranking stops
                when they are all gone.
        """
        state = self._snapshot()
        settings, bundle = state.settings, state.bundle
        if bundle is None:
            raise NotReadyError(
                "no robot description yet: set the robot_description or urdf parameter or "
                "publish the URDF on /robot_description"
            )
        trajectory = trajectory_from_msg(
            trajectory_msg,
            settings.base_frame,
            settings.trajectory_dt_s,
            settings.trajectory_duration_s,
            settings.max_samples,
        )
        grasps = grasps_from_pose_array(
            grasps_msg,
            settings.object_frame,
            settings.base_frame,
            trajectory,
            settings.max_grasps,
            grasps_field,
        )
        grasps = grasps_with_joint_trajectories(
            grasps, joint_trajectories, max_samples=settings.max_samples
        )
        samples = len(trajectory.times_s())
        total = sum(
            samples if g.joint_trajectory is None else len(g.joint_trajectory.times_s)
            for g in grasps
        )
        if total > settings.max_total_samples:
            raise InvalidInputError(
                f"{grasps_field}.poses",
                f"{len(grasps)} grasps x {samples} samples = {total} samples; at "
                f"most max_total_samples={settings.max_total_samples} are allowed",
            )
        object_inertia = state.inertia_override
        if inertia_msg is not None:
            object_inertia = object_inertia_from_msg(inertia_msg, settings.max_mass_kg)
        object_inertia = object_inertia or settings.object_inertia
        if object_inertia is None:
            raise InvalidInputError(
                "object_inertia",
                "m is 0 and no default object is configured (parameters object.mass_kg, "
                "object.inertia_about_com_kgm2)",
            )
        metric = check_metric(metric or settings.metric, "metric")
        options = _analysis_options(
            settings.analysis, len(grasps), quality, metric_point, quality_field
        )
        seed = bundle.seed
        if seed is None and settings.use_joint_states_seed and state.joint_state is not None:
            seed = seed_from_joint_state(*state.joint_state, bundle.robot)

        if not self._compute_lock.acquire(timeout=settings.service_busy_timeout_s):
            if self._stopping.is_set():
                raise ShuttingDownError("ranking not started: the node is shutting down")
            raise BusyError(
                f"busy: another ranking has been running for more than "
                f"service_busy_timeout_s={settings.service_busy_timeout_s:g} s; try again"
            )
        try:
            started = time.perf_counter()
            deadline_check = _progress_check(
                settings, self._stopping, self._compute_lock, client_watch
            )
            ranking = bundle.evaluator.rank(
                grasps,
                object_inertia,
                trajectory,
                seed_positions=seed,
                metric=metric,
                progress=deadline_check,
            )
            ranking = select_postures(
                bundle.evaluator,
                grasps,
                object_inertia,
                trajectory,
                ranking,
                settings.posture,
                progress=deadline_check,
                criterion=posture_criterion(bundle.robot, options),
            )
            report = analyse(
                bundle.evaluator,
                grasps,
                object_inertia,
                trajectory,
                options,
                ranking=ranking,
                progress=deadline_check,
            )
            compute_time_s = time.perf_counter() - started
        finally:
            self._compute_lock.release()

        stamp = self.get_clock().now().to_msg()
        result = report_msg(
            report, grasps_msg, settings.base_frame, stamp, compute_time_s, settings.response
        )
        check_finite_result(result)  # no NaN or inf ranks a grasp
        self._ranking_pub.publish(lambda: result)
        self._ranked_pub.publish(result.ranked_grasps)
        # The markers may be built later (on demand): keep what they need only, not the
        # report and its per-sample arrays (0.5 GB kept after a 1,000 x 481 request)
        labels, order, scores = _labels_only(ranking), report.order, report.scores
        not_admissible = {
            a.index for a in report.iso if a.feasible and not a.admissible_where_permitted
        }
        tips = [replace(g, joint_trajectory=None) if g.joint_trajectory else g for g in grasps]
        self._markers_pub.publish(
            lambda: markers_msg(
                labels,
                tips,
                trajectory,
                settings.base_frame,
                stamp,
                order=order,
                scores=scores,
                not_admissible=not_admissible,
            )
        )
        feasible = sum(1 for e in ranking.evaluations if e.feasible)
        with self._state_lock:
            status = self._status
            status.rankings += 1
            status.last_compute_time_s = compute_time_s
            status.last_feasible = feasible
            status.last_infeasible = len(ranking.evaluations) - feasible
            status.last_source = source
            status.last_was_error = False
            self._trim_pending = True
        # Debug, not info: an rclpy log call that is emitted costs about 2 ms here (its caller
        # lookup, inspect.getmodule, scans every loaded module); /diagnostics has the counts.
        self.get_logger().debug(
            f"{source}: ranked {len(grasps)} grasps ({feasible} feasible) in "
            f"{compute_time_s:.3f} s; order {list(report.order)}"
        )
        self._publish_diagnostics()
        return result

    # --- Diagnostics -------------------------------------------------------------------------

    def _report_error(self, source: str, error: BaseException | str) -> None:
        with self._state_lock:
            self._status.refused += 1
            by_source = self._status.refused_by_source
            by_source[source] = by_source.get(source, 0) + 1
            self._status.last_error = f"{source}: {error}"
            self._status.last_source = source
            self._status.last_was_error = True
        self.get_logger().warning(f"{source}: refused: {error}")
        self._publish_diagnostics()

    def diagnostics_status(self) -> DiagnosticStatus:
        """The node's current DiagnosticStatus (also published on /diagnostics)."""
        with self._state_lock:
            status, settings, bundle = self._status, self._settings, self._robot
            if bundle is None:
                level, message = DiagnosticStatus.ERROR, "no robot description yet"
            elif status.robot_parameters_pending:
                level, message = DiagnosticStatus.WARN, status.robot_parameters_pending
            elif status.last_was_error:
                level, message = DiagnosticStatus.WARN, f"input refused: {status.last_error}"
            elif status.rankings:
                level = DiagnosticStatus.OK
                message = (
                    f"last ranking: {status.last_feasible} feasible, "
                    f"{status.last_infeasible} infeasible"
                )
            else:
                level, message = DiagnosticStatus.OK, "ready, no ranking yet"
            values = {
                "robot_source": bundle.origin if bundle else "",
                "backend": bundle.evaluator.ik.backend_used if bundle else "",
                "base_frame": settings.base_frame,
                "tip_frame": settings.tip_frame,
                "rankings": status.rankings,
                "refused_inputs": status.refused,
                "last_source": status.last_source,
                "last_compute_time_s": f"{status.last_compute_time_s:.6f}",
                "last_feasible_grasps": status.last_feasible,
                "last_infeasible_grasps": status.last_infeasible,
                "last_error": status.last_error,
                "robot_description_error": status.robot_description_error,
                "robot_parameters_pending": status.robot_parameters_pending,
                "armature": _armature_status(bundle.robot) if bundle else "",
                "ignored_robot_descriptions": status.ignored_descriptions,
                **{f"refused.{k}": n for k, n in sorted(status.refused_by_source.items())},
                **{f"lost.{k}": n for k, n in sorted(status.lost_by_source.items())},
                **{f"memory.{k}": n for k, n in memory_kib().items()},
            }
        return DiagnosticStatus(
            level=level,
            name=f"{NODE_NAME}: grasp ranking",
            message=message,
            hardware_id=f"{settings.base_frame}->{settings.tip_frame}",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )

    def _on_diagnostics_timer(self) -> None:
        """Give the heap freed by the last rankings back to the system while none runs (the
        allocator keeps its high-water mark otherwise), then publish the status."""
        with self._state_lock:
            trim, self._trim_pending = self._trim_pending, False
        if trim and not self._compute_lock.locked():
            release_free_heap()
        elif trim:
            with self._state_lock:
                self._trim_pending = True  # next time
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        if self._diagnostics_pub.get_subscription_count() == 0:
            return  # volatile: nobody would receive it
        self._diagnostics_pub.publish(
            DiagnosticArray(
                header=Header(stamp=self.get_clock().now().to_msg()),
                status=[self.diagnostics_status()],
            )
        )


def _labels_only(ranking: Ranking) -> Ranking:
    """``ranking`` without its per-sample arrays and postures: what the markers read (index,
    name, feasibility, score, order, metric)."""
    empty = np.empty(0)
    arrays = dict.fromkeys(
        (
            "times_s",
            "joint_positions",
            "directions_in_base",
            "effective_mass_kg",
            "direction_is_worst_case",
            "tip_speed_m_s",
            "ik_iterations",
        ),
        empty,
    )
    return replace(
        ranking,
        postures=(),
        evaluations=tuple(replace(e, **arrays) for e in ranking.evaluations),
    )


def _robot_key(settings: NodeSettings) -> tuple[Any, ...]:
    """The settings a robot model depends on."""
    return (settings.robot_source, settings.base_frame, settings.tip_frame, settings.ik_seed)


def _quality(values: Sequence[float], field: str) -> tuple[float, ...] | None:
    """Grasp qualities of a message array (finite, |q| <= MAX_ABS_GRASP_QUALITY); None when
    empty (pure safety ranking)."""
    if len(values) == 0:
        return None
    checked = finite_array(np.asarray(values, dtype=float), field)
    largest = float(np.max(np.abs(checked)))
    if largest > MAX_ABS_GRASP_QUALITY:
        raise InvalidInputError(
            field,
            f"must be within +/-{MAX_ABS_GRASP_QUALITY:g} (any unit, higher is better), got "
            f"a value of magnitude {largest:g}",
        )
    return tuple(float(v) for v in checked)


def _analysis_options(
    defaults: AnalysisOptions,
    num_grasps: int,
    quality: tuple[float, ...] | None,
    metric_point: str,
    quality_field: str,
) -> AnalysisOptions:
    """The parameters' analysis options with a request's quality and metric point."""
    if quality is not None and len(quality) != num_grasps:
        raise InvalidInputError(
            quality_field, f"must have one value per grasp ({num_grasps}), got {len(quality)}"
        )
    metric_point = check_metric_point(metric_point or defaults.metric_point, "metric_point")
    if metric_point != "tip" and defaults.points_in_object_m is None:
        raise InvalidInputError(
            "metric_point",
            f"{metric_point!r} needs the object's points: set the node parameter "
            "object.points_in_object_m, object.box_size_m or object.cylinder_*",
        )
    return replace(defaults, metric_point=metric_point, grasp_quality=quality)


def _internal_error(error: BaseException) -> str:
    """The answer to an unexpected exception (a bug): its type and text."""
    return f"internal error: {type(error).__name__}: {error}"


def _progress_check(
    settings: NodeSettings,
    stopping: threading.Event,
    lock: FairComputeLock,
    client_watch: ClientWatch | None,
) -> Callable[[int, int], None]:
    """A progress callback for rank() and analyse(): abandons the work when the node shuts
    down, after max_compute_time_s of computing (time queued behind other rankings not
    counted), or when the request's clients are gone; between steps it shares the compute
    lock with waiting requests (FairComputeLock.share)."""
    deadline = time.perf_counter() + settings.max_compute_time_s

    def check(done: int, total: int) -> None:
        nonlocal deadline
        if done >= total:
            return
        if stopping.is_set():
            raise ShuttingDownError(
                f"ranking abandoned after {done} of {total} steps: the node is shutting down"
            )
        if time.perf_counter() > deadline:
            raise ComputeTimeExceededError(
                f"ranking abandoned after {done} of {total} steps: longer than "
                f"max_compute_time_s={settings.max_compute_time_s:g} s; send fewer grasps or "
                "raise trajectory.dt_s"
            )
        if client_watch is not None and client_watch.gone():
            raise ClientGoneError(
                f"ranking abandoned after {done} of {total} steps: its client left"
            )
        deadline += lock.share()

    return check


def _armature_status(robot: RobotModel) -> str:
    """The chain's armature per joint [kg m^2 or kg], or the note that none was given."""
    if not robot.armature_given:
        return NO_ARMATURE_NOTE
    return ", ".join(
        f"{name} {value:g}"
        for name, value in zip(robot.joint_names, robot.armature_kgm2, strict=True)
    )


class _Stop(Exception):  # noqa: N818  (a signal, not an error)
    """SIGINT or SIGTERM arrived: raised in the main thread by the node's signal handler."""


def _raise_stop(signal_number: int, frame: Any) -> None:
    raise _Stop(signal.Signals(signal_number).name)


def main(args: list[str] | None = None) -> NoReturn:
    """The console script: run the node (``run``), then leave the process at once with its
    status. Everything is shut down and logged by then; the interpreter's teardown would
    destroy what native code still holds in an order that ends in std::terminate about one
    stop in two ("terminate called without an active exception", SIGABRT, after the last
    line; measured by repeated SIGINT stops of the node)."""
    status = run(args)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def run(args: list[str] | None = None) -> int:
    """Run the node until SIGINT or SIGTERM. Exit status 1 on a start-up error (one log line).

    The node handles the signals itself (rclpy's handlers would shut the context down at
    once, under the running callbacks: their responses and log lines then failed with "Failed
    to publish log message to rosout" and "exception was never retrieved"): the executor spins
    in a thread, the main thread waits; at a signal the rankings are abandoned, their requests
    answered, the callbacks joined, the node destroyed, and one last line logged.
    """
    logger = rclpy.logging.get_logger(NODE_NAME)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as error:  # rclpy's RCLError: bad --ros-args or params file
        first_line = str(error).strip().splitlines()[0] if str(error).strip() else "rcl error"
        logger.error(f"start-up failed: {first_line}")
        return 1
    previous = {n: signal.signal(n, _raise_stop) for n in (signal.SIGINT, signal.SIGTERM)}
    node: GraspSafetyNode | None = None
    executor: MultiThreadedExecutor | None = None
    spinner: threading.Thread | None = None
    spinning = threading.Event()
    spinning.set()
    status, reason = 0, "the context was shut down"
    try:
        node = GraspSafetyNode()
        executor = NodeExecutor(num_threads=EXECUTOR_THREADS)
        executor.add_node(node)
        node.wait_for_robot(executor)
        spinner = threading.Thread(
            target=_spin_until, args=(executor, spinning), name="executor", daemon=True
        )
        spinner.start()
        spinner.join()  # interrupted by the signal handler's exception
    except StartupError as error:
        logger.error(f"start-up failed: {error}")
        status = 1
    except _Stop as stop:
        reason = str(stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for number, handler in previous.items():  # a second signal no longer interrupts
            signal.signal(number, signal.SIG_IGN if handler is _raise_stop else handler)
        if node is not None:
            node.abandon_rankings()
        if executor is not None:
            spinning.clear()  # the spin thread leaves its wait before the executor goes
            if spinner is not None:
                spinner.join(timeout=10.0)
            executor.shutdown()
            _join_callbacks(executor)
        if node is not None:
            abandoned = node.abandoned_rankings
            node.destroy_node()
            if status == 0:
                logger.info(
                    f"shut down ({reason}); {abandoned} ranking(s) abandoned, their requests "
                    "answered"
                )
        rclpy.try_shutdown()
        rclpy.utilities.get_default_context().destroy()  # the middleware's participant goes
    return status


SPIN_PERIOD_S = 0.1
"""How often the spin thread of main() looks whether it should stop [s]."""


def _spin_until(executor: Executor, spinning: threading.Event) -> None:
    """Spin ``executor`` while ``spinning`` is set. Executor.shutdown destroys its guard
    condition at once, so it must not run while another thread waits in spin()
    (std::terminate at exit)."""
    try:
        while spinning.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
    except ExternalShutdownException:  # rclpy.shutdown() elsewhere: main() then stops
        pass


def _join_callbacks(executor: MultiThreadedExecutor) -> None:
    """Wait until every callback the executor started has returned (its response sent).

    Jazzy's ``Executor.shutdown`` is documented to wait for outstanding callbacks but does not
    (its wait is skipped once the shut-down flag is set), so a service callback abandoned at
    shut-down could still be sending its response while the node is destroyed, which crashed
    the process. The callbacks run on the executor's thread pool; joining it waits for them
    (an abandoned ranking stops within one grasp).
    """
    pool = getattr(executor, "_executor", None)  # rclpy's ThreadPoolExecutor of callbacks
    if pool is not None:
        pool.shutdown(wait=True)


if __name__ == "__main__":
    main()
