"""The ``grasp_safety`` node: ranks candidate grasps with the core, over a service and topics.

A thin adapter, its parts grouped by role: messages are converted in the conversions package,
parameters validated in parameters/, requests prepared in service/ranking_inputs.py and computed
by core.pipeline.run_pipeline (ranking, postures, every enabled analysis, armature range); the
robot's source in robot/source.py, /diagnostics in topics/diagnostics.py, the process and the
executor in runtime/. See docs/ros/interface.md.

Threads: a NodeExecutor (a MultiThreadedExecutor) with EXECUTOR_THREADS threads. The service
sits in its own reentrant callback group, the input topics in a mutually exclusive one,
everything else (parameters, /robot_description, /joint_states, the diagnostics timer) in the
default group. One ranking computes at a time (the compute lock: the core's solvers keep
scratch data), in arrival order and in slices: a ranking hands the lock to waiting requests
after 0.2 s at its next progress check (service.ranking_job.FairComputeLock), so a small
request does not wait for a large one; a request that cannot get the lock within
``service_busy_timeout_s`` is answered busy, a ranking longer than ``max_compute_time_s``
(time queued not counted) or whose client has left the ROS graph is abandoned
(docs/ros/reliability.md). The GIL still makes a long ranking share the CPU with the other
callbacks. The markers are built, and the ranking published (serialised), only once they
have had a subscriber; a late transient-local subscriber gets the latest (OnDemandPublisher).
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, NoReturn

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Inertia, InertiaStamped, PoseArray
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
)
from rclpy.parameter import Parameter
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from ..core.analyses.safety_report import SafetyReport
from ..core.exceptions import GraspSafetyError, InvalidInputError
from ..core.model.inertia import ObjectInertia
from ..core.pipeline import PipelineRequest, run_pipeline
from .conversions import (
    check_frame_id,
    check_grasp_array,
    object_inertia_from_msg,
    object_trajectory_of_request,
    report_msg,
    trajectory_from_msg,
)
from .moveit import offer_plan_grasps
from .parameters import PARAMETERS, NodeSettings, check_parameter, settings_from_parameters
from .parameters.declaration import declare_node_parameters, typed_parameters
from .robot.bundle import build_robot
from .robot.source import RobotSource
from .runtime.memory import IdleTrim
from .runtime.middleware import size_shared_memory_for_large_responses
from .runtime.process import run_node
from .runtime.rclpy_private import request_header
from .runtime.read_only import answer_read_only_parameters
from .service.clients import ServiceClients
from .service.errors import (
    BusyError,
    NotReadyError,
    ShuttingDownError,
    StartupError,
    internal_error,
)
from .service.message_checks import check_finite_result, check_no_subnormals
from .service.ranking_inputs import markers_builder, ranking_inputs
from .service.ranking_job import ClientWatch, FairComputeLock, Snapshot, progress_check
from .topics.diagnostics import NodeStatus
from .topics.inputs import PublisherSequences, TopicInputs, check_quality
from .topics.on_demand import OnDemandPublisher
from .topics.qos import INPUT_DEPTHS, LATCHED, SERVICE, subscription_qos

NODE_NAME = "grasp_safety"
EXECUTOR_THREADS = 4
"""Service calls, topic input and parameter/diagnostics callbacks each get a thread."""

_TIMED_SOURCES = ("candidate_grasps", "object_trajectory", "object_multi_dof_trajectory")
"""Input topics whose callbacks get the reception time (to pair a set with its trajectory)."""
_STANDARD_OVERRIDES = ("use_sim_time", "qos_overrides.", "start_type_description_service")


class GraspSafetyNode(RobotSource):
    """Ranks grasps by the effective mass of robot + object along the object's trajectory.

    Its robot (where it comes from, the robot parameter group) is robot.source.RobotSource's
    part, its /diagnostics topics.diagnostics.DiagnosticsNode's; the wiring, the parameter
    callback, the service, the input topics and the ranking are here.

    Args:
        **kwargs: Passed to rclpy.node.Node (e.g. ``context``, ``parameter_overrides``).

    Raises:
        StartupError: a parameter is invalid or the robot description cannot be used.
    """

    diagnostics_name = NODE_NAME

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
        self._topic_description = None
        self._joint_state: tuple[Sequence[str], Sequence[float]] | None = None
        self._topic_inputs = TopicInputs()
        self._inertia_override: ObjectInertia | None = None
        self._status = NodeStatus()
        self._pending_robot = {}
        self._idle_trim = IdleTrim()

        self._declare_parameters()
        self._create_endpoints()
        self._subscribe_inputs()
        self._diagnostics_timer = self.create_timer(
            self._settings.diagnostics_period_s, self._on_diagnostics_timer
        )
        self._started = True
        if self._robot is not None:
            self._robot_ready(self._robot)

    def _declare_parameters(self) -> None:
        """Declares the parameters with their callbacks, then builds the settings and the robot
        from them (StartupError: an invalid value or an unusable robot description)."""
        self.add_pre_set_parameters_callback(typed_parameters)
        answer_read_only_parameters(self)  # ros2 param load of a dump: not "failed"
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

    def _create_endpoints(self) -> None:
        """Creates the output publishers, ~/rank_grasps and ~/plan_grasps."""
        self._service_group = ReentrantCallbackGroup()
        self._topic_group = MutuallyExclusiveCallbackGroup()
        self._ranking_pub = OnDemandPublisher(self, GraspRanking, "~/ranking")
        self._ranked_pub = self.create_publisher(PoseArray, "~/ranked_grasps", LATCHED)
        self._markers_pub = OnDemandPublisher(self, MarkerArray, "~/markers")
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._service = self.create_service(
            RankGrasps,
            "~/rank_grasps",
            self._on_rank_grasps,
            qos_profile=SERVICE,
            callback_group=self._service_group,
        )
        self._request_clients = ServiceClients(self, self._service, RankGrasps.Event)
        self._plan_grasps = offer_plan_grasps(  # ~/plan_grasps (moveit_msgs/GraspPlanning)
            self,
            rank=self._rank,
            snapshot=self._snapshot,
            report_error=self._report_error,
            latest_trajectory=self._topic_inputs.latest_trajectory,
            stopping=self._stopping,
        )

    def _subscribe_inputs(self) -> None:
        """Subscribes the input topics (the grasp inputs in one mutually exclusive group), each
        callback guarded and its lost messages counted."""
        topics = self._topic_group
        inputs = (
            (PoseArray, "~/candidate_grasps", self._on_candidates, topics),
            (Float64MultiArray, "~/candidate_grasp_quality", self._on_quality, topics),
            (Path, "~/object_trajectory", self._on_trajectory, topics),
            (
                MultiDOFJointTrajectory,
                "~/object_multi_dof_trajectory",
                self._on_trajectory,
                topics,
            ),
            (InertiaStamped, "~/object_inertia", self._on_inertia, topics),
            (JointState, "/joint_states", self._on_joint_states, None),
            (String, "/robot_description", self._on_robot_description, None),
        )
        self._input_subscriptions: dict[str, Subscription] = {}
        for msg_type, topic, callback, group in inputs:
            source = topic.removeprefix("~/")
            self._input_subscriptions[source] = self.create_subscription(
                msg_type,
                topic,
                self._guarded(source, callback),  # type: ignore[arg-type]  # rclpy passes
                # (msg, MessageInfo) to a two-argument callback; its hint names one argument
                subscription_qos(source),
                callback_group=group,
                event_callbacks=SubscriptionEventCallbacks(
                    message_lost=partial(self._on_message_lost, source)
                ),
            )

    def _guarded(self, source: str, callback: Callable[..., None]) -> Callable[[Any, Any], None]:
        """``callback`` for a topic, after refusing a message with a subnormal float (an int
        sent as a float) and counting the messages skipped before it (input topics); the
        candidate set and trajectory callbacks also get the reception time [ns]. An
        unexpected exception (a bug) is logged and reported on /diagnostics instead of
        stopping the executor."""
        sequences = PublisherSequences() if source in INPUT_DEPTHS else None
        timed = source in _TIMED_SOURCES

        def guarded(msg: Any, info: dict[str, Any]) -> None:
            try:
                if sequences is not None and (
                    n := sequences.skipped(
                        info["publication_sequence_number"],
                        self._input_subscriptions[source].get_publisher_count(),
                    )
                ):
                    with self._state_lock:
                        skipped = self._status.skipped_by_source
                        skipped[source] = skipped.get(source, 0) + n
                try:
                    check_no_subnormals(msg, source)
                except GraspSafetyError as error:
                    self._report_error(source, error)
                    return
                callback(msg, info["received_timestamp"]) if timed else callback(msg)
            except Exception as error:  # last resort: keep serving
                self.get_logger().error(f"{source}: internal error:\n{traceback.format_exc()}")
                self._report_error(source, internal_error(error))

        return guarded

    def abandon_rankings(self) -> None:
        """Make the running ranking (and any later one) stop at its next progress check: for
        shut-down, so that no executor thread outlives the node."""
        self._stopping.set()
        self._compute_lock.stop()

    @property
    def requests_waiting(self) -> int:
        """~/plan_grasps requests suspended while they wait for the upstream planner."""
        return 0 if self._plan_grasps is None else self._plan_grasps.waiting

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
            reason = internal_error(error)
            if not self._started:
                self._startup_rejection = reason
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    # --- Robot description and joint states --------------------------------------------------

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
                quality=check_quality(request.grasp_quality, "grasp_quality"),
                metric_point=request.metric_point,
                quality_field="grasp_quality",
                joint_trajectories=request.joint_trajectories,
                client_watch=self._request_clients.watch(request_header()),
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
            response.message = internal_error(error)
            self._report_error("rank_grasps", error)
        return response

    # --- Topics ------------------------------------------------------------------------------

    def _on_candidates(self, msg: PoseArray, received_ns: int) -> None:
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
        discarded = self._topic_inputs.set_candidates(msg, received_ns)
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
        """Pair a quality vector with the current candidate set or hold it for the next one
        (TopicInputs.set_quality)."""
        try:
            quality = check_quality(msg.data, "candidate_grasp_quality.data")
        except GraspSafetyError as error:
            self._report_error("candidate_grasp_quality", error)
            return
        if self._topic_inputs.set_quality(quality):
            self._rank_topics()

    def _on_trajectory(self, msg: Path | MultiDOFJointTrajectory, received_ns: int) -> None:
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
        self._topic_inputs.set_trajectory(msg, received_ns)
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
        taken = self._topic_inputs.take()
        if taken is None:
            return
        grasps, path, quality = taken
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
            self._topic_inputs.retry()  # at the next input, with the trajectory before it
            self._report_error("topics", error)
        except ShuttingDownError:
            pass  # the node is going: nothing to report
        except GraspSafetyError as error:
            self._report_error("topics", error)

    # --- Ranking -----------------------------------------------------------------------------

    def _snapshot(self) -> Snapshot:
        with self._state_lock:
            return Snapshot(self._settings, self._robot, self._joint_state, self._inertia_override)

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
        request = ranking_inputs(
            state,
            bundle,
            grasps_msg,
            trajectory_msg,
            inertia_msg,
            metric,
            grasps_field,
            quality,
            metric_point,
            quality_field,
            joint_trajectories,
        )
        if not self._compute_lock.acquire(timeout=settings.service_busy_timeout_s):
            if self._stopping.is_set():
                raise ShuttingDownError("ranking not started: the node is shutting down")
            raise BusyError(
                f"busy: another ranking has been running for more than "
                f"service_busy_timeout_s={settings.service_busy_timeout_s:g} s; try again"
            )
        self._idle_trim.ranking_started()  # no heap trim until the response is published
        try:
            try:
                started = time.perf_counter()
                check = progress_check(settings, self._stopping, self._compute_lock, client_watch)
                report = run_pipeline(bundle.evaluator, request, check)
                compute_time_s = time.perf_counter() - started
            finally:
                self._compute_lock.release()
            result = self._publish_ranking(
                settings, report, request, grasps_msg, compute_time_s, source
            )
        finally:
            self._idle_trim.ranking_done()
        self._publish_diagnostics()
        return result

    def _publish_ranking(
        self,
        settings: NodeSettings,
        report: SafetyReport,
        request: PipelineRequest,
        grasps_msg: PoseArray,
        compute_time_s: float,
        source: str,
    ) -> GraspRanking:
        """Publish a ranking's result on ~/ranking, ~/ranked_grasps and the markers, and count
        it in the status; the result (the service's response)."""
        grasps, trajectory = request.grasps, request.trajectory

        stamp = self.get_clock().now().to_msg()
        result = report_msg(
            report, grasps_msg, settings.base_frame, stamp, compute_time_s, settings.response
        )
        check_finite_result(result)  # no NaN or inf ranks a grasp
        self._ranking_pub.publish(lambda: result)
        self._ranked_pub.publish(result.ranked_grasps)
        self._markers_pub.publish(
            markers_builder(report.ranking, report, grasps, trajectory, settings.base_frame, stamp)
        )
        ranking = report.ranking
        feasible = sum(1 for e in ranking.evaluations if e.feasible)
        with self._state_lock:
            self._status.record_ranking(source, compute_time_s, feasible, len(ranking.evaluations))
        # Debug, not info: an rclpy log call that is emitted costs about 2 ms here (its caller
        # lookup, inspect.getmodule, scans every loaded module); /diagnostics has the counts.
        self.get_logger().debug(
            f"{source}: ranked {len(grasps)} grasps ({feasible} feasible) in "
            f"{compute_time_s:.3f} s; order {list(report.order)}"
        )
        return result


def main(args: list[str] | None = None) -> NoReturn:
    """The console script: run the node (process.run_node), then leave the process at once
    with its status. Everything is shut down and logged by then; the interpreter's teardown
    would destroy what native code still holds in an order that ends in std::terminate about
    one stop in two ("terminate called without an active exception", SIGABRT, after the last
    line; measured by repeated SIGINT stops of the node)."""
    size_shared_memory_for_large_responses()  # before rclpy starts the middleware
    status = run_node(GraspSafetyNode, NODE_NAME, EXECUTOR_THREADS, args)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == "__main__":
    main()
