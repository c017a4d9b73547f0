"""Quality-of-service profiles of the node's results, topic inputs and service."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

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
