"""A latched publisher that builds its message only once someone subscribes."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from rclpy.event_handler import (
    PublisherEventCallbacks,
    QoSPublisherMatchedInfo,
)
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
)

from .qos import LATCHED

GRAPH_CHECK_PERIOD_S = 0.02
GRAPH_CHECK_ATTEMPTS = 100
"""After a subscriber matches or leaves, OnDemandPublisher waits up to 100 x 0.02 s for the ROS
graph to show it (the subscribers' durabilities decide whether the kept message is sent)."""


class OnDemandPublisher:
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
