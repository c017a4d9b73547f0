"""What the node reports on /diagnostics: its counters, their DiagnosticStatus, and the node's
base class that counts and publishes them."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import ClassVar

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import QoSMessageLostInfo
from rclpy.node import Node
from rclpy.publisher import Publisher
from std_msgs.msg import Header

from ...core.model.robot import NO_ARMATURE_NOTE, RobotModel
from ..parameters import NodeSettings
from ..robot.bundle import RobotBundle
from ..runtime.memory import IdleTrim, memory_kib
from ..service.ranking_job import FairComputeLock

_INT32_LIMIT = 2**31
"""DDS counts messages in signed 32-bit integers: a count at or beyond is not one."""


def _signed(value: int) -> int:
    """A size_t from rmw read as the signed 64-bit value it was cast from."""
    value = int(value)
    return value - 2**64 if value >= 2**63 else value


@dataclass
class NodeStatus:
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
    heap_trims: int = 0  # freed heap given back to the system (memory.IdleTrim)
    ignored_descriptions: int = 0  # /robot_description messages ignored (parameters rule)
    refused_by_source: dict[str, int] = field(default_factory=dict)
    lost_by_source: dict[str, int] = field(default_factory=dict)  # the middleware's count
    skipped_by_source: dict[str, int] = field(default_factory=dict)  # overwritten in queues

    def record_ranking(
        self, source: str, compute_time_s: float, feasible: int, total: int
    ) -> None:
        """Count a ranking of ``total`` grasps, ``feasible`` of them feasible."""
        self.rankings += 1
        self.last_compute_time_s = compute_time_s
        self.last_feasible = feasible
        self.last_infeasible = total - feasible
        self.last_source = source
        self.last_was_error = False

    def record_lost(self, source: str, total_count: int, total_count_change: int) -> int:
        """Count the messages of ``source`` the middleware reports lost; the increase.

        The middleware's counters are unsigned in rmw but signed 32-bit in DDS: a negative
        value arrives wrapped (a change of 18446744071562067968 is -2^31), which added as it
        came made the count 1.8e19. The count is the report's running total (the subscription's
        own, never decreasing); where that total is not a plausible count (wrapped, or below
        the count so far), a positive change is added, and anything else leaves it unchanged.
        """
        total, change = _signed(total_count), _signed(total_count_change)
        previous = self.lost_by_source.get(source, 0)
        if 0 <= total < _INT32_LIMIT and total >= previous:
            count = total
        elif 0 < change < _INT32_LIMIT:
            count = previous + change
        else:
            count = previous
        self.lost_by_source[source] = count
        return count - previous

    def record_refusal(self, source: str, error: BaseException | str) -> None:
        """Count an input of ``source`` refused with ``error``."""
        self.refused += 1
        self.refused_by_source[source] = self.refused_by_source.get(source, 0) + 1
        self.last_error = f"{source}: {error}"
        self.last_source = source
        self.last_was_error = True


def armature_status(robot: RobotModel) -> str:
    """The chain's armature per joint [kg m^2 or kg], or the note that none was given."""
    if not robot.armature_given:
        return NO_ARMATURE_NOTE
    return ", ".join(
        f"{name} {value:g}"
        for name, value in zip(robot.joint_names, robot.armature_kgm2, strict=True)
    )


def status_msg(
    status: NodeStatus, settings: NodeSettings, bundle: RobotBundle | None, node_name: str
) -> DiagnosticStatus:
    """The DiagnosticStatus of a node with these counters, settings and robot."""
    if bundle is None:
        level, message = DiagnosticStatus.ERROR, "no robot description yet"
    elif status.robot_parameters_pending:
        level, message = DiagnosticStatus.WARN, status.robot_parameters_pending
    elif status.last_was_error:
        level, message = DiagnosticStatus.WARN, f"input refused: {status.last_error}"
    elif status.rankings:
        level = DiagnosticStatus.OK
        message = (
            f"last ranking: {status.last_feasible} feasible, {status.last_infeasible} infeasible"
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
        "armature": armature_status(bundle.robot) if bundle else "",
        "ignored_robot_descriptions": status.ignored_descriptions,
        **{f"refused.{k}": n for k, n in sorted(status.refused_by_source.items())},
        **{f"lost.{k}": n for k, n in sorted(status.lost_by_source.items())},
        **{f"skipped.{k}": n for k, n in sorted(status.skipped_by_source.items())},
        **{f"memory.{k}": n for k, n in memory_kib().items()},
        "memory.heap_trims": status.heap_trims,
    }
    return DiagnosticStatus(
        level=level,
        name=f"{node_name}: grasp ranking",
        message=message,
        hardware_id=f"{settings.base_frame}->{settings.tip_frame}",
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )


class DiagnosticsNode(Node):
    """The /diagnostics part of the grasp_safety node (a base class of GraspSafetyNode, which
    sets the attributes below): refusals and lost messages counted in its NodeStatus, which
    is published after each event and on the ``diagnostics_period_s`` timer."""

    diagnostics_name: ClassVar[str]
    """The DiagnosticStatus name (the node's default name)."""
    _state_lock: threading.Lock
    _status: NodeStatus
    _settings: NodeSettings
    _robot: RobotBundle | None
    _compute_lock: FairComputeLock
    _idle_trim: IdleTrim
    _diagnostics_pub: Publisher

    def _report_error(self, source: str, error: BaseException | str) -> None:
        with self._state_lock:
            self._status.record_refusal(source, error)
        self.get_logger().warning(f"{source}: refused: {error}")
        self._publish_diagnostics()

    def diagnostics_status(self) -> DiagnosticStatus:
        """The node's current DiagnosticStatus (also published on /diagnostics)."""
        with self._state_lock:
            return status_msg(self._status, self._settings, self._robot, self.diagnostics_name)

    def _on_diagnostics_timer(self) -> None:
        """Give the heap freed by the last rankings back to the system once the node is idle
        (memory.IdleTrim; the allocator keeps its high-water mark otherwise), then publish
        the status."""
        if self._idle_trim.run(self._compute_lock):
            with self._state_lock:
                self._status.heap_trims = self._idle_trim.trims
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

    def _on_message_lost(self, source: str, info: QoSMessageLostInfo) -> None:
        """The middleware reports messages of a topic lost before the node took them."""
        with self._state_lock:
            increase = self._status.record_lost(source, info.total_count, info.total_count_change)
            total = self._status.lost_by_source[source]
        self.get_logger().warning(
            f"{source}: {increase} message(s) lost before the node took them ({total} in all; "
            f"the middleware reported {info.total_count_change} of {info.total_count})"
        )
