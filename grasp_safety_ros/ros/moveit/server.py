"""``~/plan_grasps``: a moveit_msgs/srv/GraspPlanning server that answers a grasp planner's
grasps safest first (docs/ros/moveit.md).

The grasps come from the upstream planner (parameter ``moveit.grasp_planner_service``; the
request forwarded as is) or, with no planner, from the request's ``candidate_grasps``. They
are ranked by the node's ranking (its robot, object and settings; the object moves from
``target.pose`` to the goal: ``moveit.object_goal``, or the last pose of the latest
``~/object_trajectory``), and answered as the same Grasp messages in the node's order
(moveit.grasps). Threads: the service callback is a coroutine; while it waits for the planner
(at most ``moveit.planner_timeout_s``) it is suspended and holds no executor thread, so any
number of requests can wait while the planner's answers are taken (a request that slept on its
thread left none for them once EXECUTOR_THREADS requests waited). One timer of the server, on
the steady clock (so also with use_sim_time and no /clock) and running only while a request
waits, ends each wait every WAIT_STEP_S: service appeared, deadline passed, node shutting down
or a look that raised; the planner's answer ends its wait at once. At most
``moveit.max_waiting`` requests wait at once (each costs CPU at every executor wake-up); one
more is answered FAILURE at once, naming the parameter.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import Pose
from moveit_msgs.msg import MoveItErrorCodes
from moveit_msgs.srv import GraspPlanning
from nav_msgs.msg import Path
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from trajectory_msgs.msg import MultiDOFJointTrajectory

from ...core.exceptions import GraspSafetyError, InvalidInputError
from ..conversions.geometry import check_frame_id
from ..conversions.requests import transforms_from_pose_msgs
from ..service.errors import ShuttingDownError
from ..service.message_checks import check_no_subnormals
from ..service.ranking_job import Snapshot
from ..topics.qos import SERVICE
from .grasps import (
    goal_pose,
    object_path,
    planner_qualities,
    pose_array_of_grasps,
    ranked_grasps,
    trajectory_goal,
)

SOURCE = "grasp_safety"
"""``error_code.source`` of the answers this server makes itself."""
WAIT_STEP_S = 0.1
"""How often the server looks whether a request's wait for the planner is over [s]. rclpy's
executor resumes every suspended coroutine at each of its wake-ups, a tick among them: the
step trades the node's CPU while many requests wait against how late a timeout, the service's
appearance or the shut-down is seen (the planner's answer is seen at once)."""


class PlannerError(Exception):
    """No usable answer from the upstream planner (or none asked for: too many requests
    waiting): ``code`` (MoveItErrorCodes) and why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True, eq=False)  # each wait its own (hashed by identity)
class _Wait:
    """A request suspended until ``condition()`` (True) or ``deadline_s`` (time.monotonic,
    False); ``over`` holds the outcome."""

    over: Future
    condition: Callable[[], bool]
    deadline_s: float


class GraspPlanningServer:
    """The ``~/plan_grasps`` service of a node.

    Args:
        node: The node serving it (spun by a multi-threaded executor).
        rank: The node's ranking: (PoseArray, Path, inertia or None, metric, source=,
            grasps_field=, quality=, quality_field=) -> grasp_safety_msgs/GraspRanking;
            raises GraspSafetyError.
        snapshot: The node's settings and state now.
        report_error: Logs a refusal and reports it on /diagnostics: (source, error).
        latest_trajectory: The latest ``~/object_trajectory`` message, or None.
        stopping: Set when the node shuts down.
    """

    def __init__(
        self,
        node: Node,
        rank: Callable[..., Any],
        snapshot: Callable[[], Snapshot],
        report_error: Callable[[str, BaseException | str], None],
        latest_trajectory: Callable[[], Path | MultiDOFJointTrajectory | None],
        stopping: threading.Event,
    ) -> None:
        self._node = node
        self._rank = rank
        self._snapshot = snapshot
        self._report_error = report_error
        self._latest_trajectory = latest_trajectory
        self._stopping = stopping
        self._group = ReentrantCallbackGroup()
        self._clients: dict[str, Any] = {}
        self._clients_lock = threading.Lock()
        self._waits: set[_Wait] = set()  # the suspended requests, left by their coroutine
        self._waits_lock = threading.Lock()  # the waits, their outcomes and the timer's state
        self._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)  # lives with the timer
        self._timer = node.create_timer(  # reset by a new wait, cancelled by a look at none
            WAIT_STEP_S,
            self._look,
            callback_group=MutuallyExclusiveCallbackGroup(),  # no take while a look cancels
            clock=self._steady_clock,
            autostart=False,
        )
        self.service = node.create_service(
            GraspPlanning,
            "~/plan_grasps",
            self._on_plan_grasps,
            qos_profile=SERVICE,
            callback_group=self._group,
        )

    def _parameter(self, name: str) -> Any:
        return self._node.get_parameter(f"moveit.{name}").value

    @property
    def waiting(self) -> int:
        """Requests suspended while they wait for the planner."""
        with self._waits_lock:
            return len(self._waits)

    async def _on_plan_grasps(
        self, request: GraspPlanning.Request, response: GraspPlanning.Response
    ) -> GraspPlanning.Response:
        code = response.error_code
        code.source = SOURCE
        try:
            check_no_subnormals(request)
            grasps, field = await self._grasps_to_rank(request)
            response.grasps = self._rerank(request, grasps, field)
            code.val = MoveItErrorCodes.SUCCESS
        except PlannerError as error:
            code.val, code.message = error.code, str(error)
            self._report_error("plan_grasps", error)
        except ShuttingDownError as error:  # answered, not reported: the node is going
            code.val, code.message = MoveItErrorCodes.PREEMPTED, str(error)
        except GraspSafetyError as error:
            code.val, code.message = MoveItErrorCodes.FAILURE, str(error)
            self._report_error("plan_grasps", error)
        except Exception as error:  # last resort: answer and log rather than drop the request
            trace = traceback.format_exc()
            self._node.get_logger().error(f"plan_grasps: internal error:\n{trace}")
            code.val = MoveItErrorCodes.FAILURE
            code.message = f"internal error: {type(error).__name__}: {error}"
            self._report_error("plan_grasps", code.message)
        return response

    async def _grasps_to_rank(self, request: GraspPlanning.Request) -> tuple[list[Any], str]:
        """The grasps to rank and their field name: the planner's answer, or without a
        planner the request's candidate_grasps."""
        service = self._parameter("grasp_planner_service")
        if service:
            answer = await self._call_planner(service, request)
            if answer.error_code.val != MoveItErrorCodes.SUCCESS:
                raise PlannerError(
                    answer.error_code.val,
                    answer.error_code.message
                    or f"the grasp planner {service} failed with error code "
                    f"{answer.error_code.val}",
                )
            return list(answer.grasps), "grasps"
        if not request.candidate_grasps:
            raise InvalidInputError(
                "candidate_grasps",
                "is empty and no grasp planner is set (parameter moveit.grasp_planner_service): "
                "give the grasps to rank, or set the planner whose grasps to rank",
            )
        return list(request.candidate_grasps), "candidate_grasps"

    def _client(self, service: str) -> Any:
        with self._clients_lock:
            if service not in self._clients:
                try:
                    self._clients[service] = self._node.create_client(
                        GraspPlanning, service, callback_group=self._group
                    )
                except Exception as error:  # rclpy's invalid-name exceptions
                    raise InvalidInputError(
                        "moveit.grasp_planner_service", f"{service!r}: {error}"
                    ) from None
            return self._clients[service]

    async def _call_planner(self, service: str, request: GraspPlanning.Request) -> Any:
        """The planner's answer within moveit.planner_timeout_s (PlannerError otherwise)."""
        timeout_s = float(self._parameter("planner_timeout_s"))
        deadline = time.monotonic() + timeout_s
        client = self._client(service)
        if not await self._wait(client.service_is_ready, deadline):
            raise PlannerError(
                MoveItErrorCodes.COMMUNICATION_FAILURE,
                f"the grasp planner service {service} is not available (waited "
                f"moveit.planner_timeout_s={timeout_s:g} s)",
            )
        future = client.call_async(request)
        try:
            answered = await self._wait(future.done, deadline, answer=future)
        finally:
            if not future.done():  # timed out or shutting down: the answer is not awaited
                client.remove_pending_request(future)
                future.cancel()
        if not answered:
            raise PlannerError(
                MoveItErrorCodes.TIMED_OUT,
                f"the grasp planner {service} did not answer within "
                f"moveit.planner_timeout_s={timeout_s:g} s",
            )
        return future.result()

    async def _wait(
        self, condition: Callable[[], bool], deadline: float, answer: Future | None = None
    ) -> bool:
        """Wait, suspended, until ``condition()`` (True) or ``deadline`` (time.monotonic,
        False), looked at now, every WAIT_STEP_S by the server's timer and when ``answer`` is
        done; raises ShuttingDownError once the node shuts down, and what ``condition``
        raised."""
        wait = _Wait(Future(), condition, deadline)
        most = int(self._parameter("max_waiting"))
        with self._waits_lock:
            self._end_if_over(wait)
            if wait.over.done():
                return bool(wait.over.result())
            if len(self._waits) >= most:
                raise PlannerError(
                    MoveItErrorCodes.FAILURE,
                    f"{len(self._waits)} requests already wait for the grasp planner "
                    f"(moveit.max_waiting={most}): retry later, or raise moveit.max_waiting",
                )
            self._waits.add(wait)
            if self._timer.is_canceled():
                self._timer.reset()
        if answer is not None:
            answer.add_done_callback(lambda _: self._look_at(wait))
        try:
            return bool(await wait.over)
        finally:
            with self._waits_lock:
                self._waits.discard(wait)

    def _look(self) -> None:
        """The timer's callback: ends the waits that are over; cancels the timer when no
        request waits (reset by the next one)."""
        with self._waits_lock:
            if not self._waits:
                self._timer.cancel()
            for wait in self._waits:
                self._end_if_over(wait)

    def _look_at(self, wait: _Wait) -> None:
        """Ends ``wait`` if it is over: the planner's answer came (a done callback)."""
        with self._waits_lock:
            self._end_if_over(wait)

    def _end_if_over(self, wait: _Wait) -> None:
        """Complete ``wait.over`` if its wait is over (caller holds the waits' lock): an
        exception of ``condition`` is its outcome, so the request is answered, not lost."""
        if wait.over.done():  # its coroutine has not resumed yet
            return
        try:
            if self._stopping.is_set():
                raise ShuttingDownError("plan_grasps abandoned: the node is shutting down")
            if wait.condition():
                wait.over.set_result(True)
            elif time.monotonic() > wait.deadline_s:
                wait.over.set_result(False)
        except Exception as error:
            wait.over.set_exception(error)

    def _rerank(self, request: GraspPlanning.Request, grasps: list[Any], field: str) -> list[Any]:
        """The grasps in the node's order, with their safety qualities (moveit.grasps)."""
        settings = self._snapshot().settings
        poses = pose_array_of_grasps(grasps, field)
        check_frame_id(
            poses.header.frame_id,
            [settings.object_frame, settings.base_frame],
            f"{field}[0].grasp_pose.header.frame_id",
        )
        transforms_from_pose_msgs(poses.poses, field, ".grasp_pose.pose")  # names a bad one
        goal, duration_s = self._goal(settings.base_frame)
        path = object_path(request.target, settings.base_frame, goal, duration_s)
        quality = planner_qualities(grasps) if self._parameter("planner_quality") else None
        ranking = self._rank(
            poses,
            path,
            None,
            "",
            source="plan_grasps",
            grasps_field=field,
            quality=quality,
            quality_field=f"{field}[].grasp_quality",
        )
        return ranked_grasps(grasps, ranking, self._parameter("infeasible"))

    def _goal(self, base_frame: str) -> tuple[Pose, float]:
        """The object's goal pose (base frame) and the motion's duration [s] (0: the node's
        trajectory.duration_s): moveit.object_goal, else the end of ~/object_trajectory."""
        values = self._parameter("object_goal")
        if len(values) == 7:
            return goal_pose(values), 0.0
        goal = trajectory_goal(self._latest_trajectory(), base_frame)
        if goal is not None:
            return goal
        raise InvalidInputError(
            "moveit.object_goal",
            "is empty and no ~/object_trajectory has arrived: set the object's goal pose "
            "(x y z qx qy qz qw, base frame) or publish its trajectory",
        )
