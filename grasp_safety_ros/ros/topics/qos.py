"""Quality-of-service profiles of the node's results, topic inputs and service."""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
"""Results: late subscribers (RViz, ``ros2 topic echo``) get the last ranking."""
INPUT_DEPTHS = {
    "candidate_grasps": 10,
    "candidate_grasp_quality": 10,
    "object_trajectory": 4,
    "object_multi_dof_trajectory": 4,
    "object_inertia": 10,
}
"""Queue depth of each input topic (keep the last, reliable): what the node has not taken yet
is bounded by depth x message size (a trajectory of max_samples poses is about 1 MB at the
default 20,000: 4 of them per trajectory topic). Keeping every message (as before) let a flood
of malformed messages queue about 1 GB, never released, and the topics, served in turn, fell
behind one another. A message overwritten before the node took it is counted
(``skipped.<topic>`` on /diagnostics, topic_inputs.PublisherSequences), as is what the
middleware reports lost (``lost.<topic>``). Only the latest inputs matter: a candidate set
pairs with the trajectory received last before it (topic_inputs.TopicInputs)."""


def subscription_qos(source: str) -> QoSProfile:
    """The QoS of the node's subscription to ``source``: an input topic (INPUT_DEPTHS),
    ``/joint_states`` (sensor data: only the latest matters) or ``/robot_description``
    (LATCHED: only the latest matters, late joiners get it)."""
    if source == "/robot_description":
        return LATCHED
    if source not in INPUT_DEPTHS:
        return qos_profile_sensor_data
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=INPUT_DEPTHS[source],
        reliability=ReliabilityPolicy.RELIABLE,
    )


SERVICE = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
"""Requests wait in the service's queue until a thread takes them; the default (keep the last
10) silently dropped the oldest when more than EXECUTOR_THREADS + 10 were in flight."""
