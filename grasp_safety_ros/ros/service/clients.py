"""Which client sent each request of a service, and whether it is still in the ROS graph."""

from __future__ import annotations

import threading
from collections import deque
from functools import partial
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.service import Service
from rclpy.service_introspection import ServiceIntrospectionState
from service_msgs.msg import ServiceEventInfo

from ..topics.qos import SERVICE
from .ranking_job import ClientWatch

SERVICE_EVENTS_KEPT = 1024
"""Request arrivals (client GID, sequence number, time) kept to identify a request's client."""

SERVICE_EVENTS_QUEUED = 4 * SERVICE_EVENTS_KEPT
"""Service events kept in the middleware until read by hand: each request has two (request
received, response sent), and they are read only at a ranking's first client check, so the
depth covers twice SERVICE_EVENTS_KEPT requests in between."""


class TakenByHand(CallbackGroup):
    """A callback group whose entities no executor waits on or runs (``can_execute`` is
    false): their messages stay in the middleware's history until taken by hand.

    The service's events come two per request; taken by the executor, each woke it and ran a
    callback beside the ranking (4-5 ms of a 10 x 101 round trip of 10-15 ms). Only a ranking
    that runs past its first client check needs them.
    """

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class ServiceClients:
    """The clients of ``service``: its introspection events (metadata only) carry each
    request's client GID and sequence number; ``watch`` gives a ranking its ClientWatch.

    The events are read when a watch first asks for its client (TakenByHand), from a history
    of the last SERVICE_EVENTS_QUEUED; an executor that ignores callback groups' ``can_execute``
    runs the subscription's callback instead, with the same record.
    """

    def __init__(self, node: Node, service: Service, event_type: Any) -> None:
        self._node, self._service = node, service
        self._lock = threading.Lock()
        self._arrivals: deque[tuple[int, int, bytes]] = deque(maxlen=SERVICE_EVENTS_KEPT)
        # rcl keeps a pointer to the clock: it must live as long as the service
        self._event_clock = Clock(clock_type=ClockType.SYSTEM_TIME)
        service.configure_introspection(
            self._event_clock, SERVICE, ServiceIntrospectionState.METADATA
        )
        kept = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,  # never fills: the events' writer never waits
            depth=SERVICE_EVENTS_QUEUED,
            reliability=SERVICE.reliability,
            durability=SERVICE.durability,
        )
        self._events = node.create_subscription(
            event_type,
            f"{service.service_name}/_service_event",
            self._on_service_event,
            kept,
            callback_group=TakenByHand(),
        )

    def watch(self, header: Any) -> ClientWatch:
        """The watch on the client of the request of ``header`` (None: not run by
        NodeExecutor, the clients present now stand in)."""
        if header is None:
            return ClientWatch(self.clients)
        return ClientWatch(self.clients, partial(self._client_of, header))

    def clients(self) -> list[bytes]:
        """GIDs of the service's clients' endpoints in the ROS graph (request writers and
        response readers, on the DDS topics ``rq/<service>Request`` and ``rr/<service>Reply``;
        none where the middleware names them otherwise)."""
        name = self._service.service_name.lstrip("/")
        writers = self._node.get_publishers_info_by_topic(f"rq/{name}Request", no_mangle=True)
        readers = self._node.get_subscriptions_info_by_topic(f"rr/{name}Reply", no_mangle=True)
        return [bytes(endpoint.endpoint_gid) for endpoint in (*writers, *readers)]

    def _on_service_event(self, event: Any) -> None:
        with self._lock:
            self._record(event)

    def _record(self, event: Any) -> None:
        info = event.info
        if info.event_type == ServiceEventInfo.REQUEST_RECEIVED:
            stamp_ns = info.stamp.sec * 1_000_000_000 + info.stamp.nanosec
            self._arrivals.append((info.sequence_number, stamp_ns, bytes(info.client_gid)))

    def _take_events(self) -> None:
        """Record the events waiting in the subscription's history (call with the lock)."""
        subscription = self._events
        try:
            with subscription.handle:
                while True:
                    taken = subscription.handle.take_message(subscription.msg_type, False)
                    if taken is None:
                        return
                    self._record(taken[0])
        except InvalidHandle:  # the node is being destroyed: nothing more to learn
            return

    def _client_of(self, header: Any) -> bytes | None:
        """The GID of the client that sent the request of ``header`` (same sequence number,
        the arrival closest in time, within a second), or None when not known (yet)."""
        number, received_ns = header.request_id.sequence_number, header.received_timestamp
        with self._lock:
            self._take_events()
            matches = [
                (abs(stamp_ns - received_ns), gid)
                for seq, stamp_ns, gid in self._arrivals
                if seq == number and abs(stamp_ns - received_ns) < 1_000_000_000
            ]
        return min(matches)[1] if matches else None
