"""The monitor's decisions, without rclpy: per /joint_states message the factor to publish,
or 0 with the reason in one line (fail-safe), and the watchdog on the message stream.

Fail-safe (factor 0): no robot yet, no /joint_states for longer than the timeout, a chain
joint missing, a non-finite position or velocity, or an error of the analysis. The next valid
state recovers by itself: the factor rises from 0 at that state's time, bounded by the rate
limit (``IncreaseLimiter``), so the first valid state after a fail-safe still publishes 0.
A refused payload (``refuse_payload``) is a fail-safe until a valid one is set.

In closed loop the state moves at the factor the controller applied some time ago (its
command-to-state latency), not at the last published one: the target uses the lowest
positive factor published within ``controller_latency_s`` (and the one in force at its
start). A moving state ran at a positive factor of that window (one that covers the latency),
so this one is at or below it and the unscaled motion is never under-estimated; a 0 in the
window is skipped (it would hold the factor at 0 for as long as the robot moves, and the rise
after a stop would fall back to 0 each time the motion reaches /joint_states).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

from ...core.analyses.speed_scaling import (
    IncreaseLimiter,
    SpeedScaling,
    StateScaling,
    closed_loop_factor,
)
from ...core.exceptions import GraspSafetyError
from .joint_states import JointIndex


@dataclass(frozen=True)
class Decision:
    """What to publish for one state or watchdog check.

    Attributes:
        factor: The factor to publish, in [0, 1] (rate limit applied).
        target: The factor before the rate limit (0 in a fail-safe).
        scaling: The analysis of the state (None in a fail-safe).
        fail_safe: Why the factor is 0, one line ("" when valid).
        compute_time_s: Time spent on the state [s].
    """

    factor: float
    target: float
    scaling: StateScaling | None
    fail_safe: str
    compute_time_s: float = 0.0


@dataclass
class GovernorCounters:
    """What /diagnostics reports."""

    states: int = 0
    refused: int = 0
    timeouts: int = 0
    last_compute_time_s: float = 0.0
    max_compute_time_s: float = 0.0


@dataclass
class Governor:
    """The per-message state of the monitor (one thread: the node's executor).

    Attributes:
        timeout_s: Longest gap between /joint_states messages before the factor drops to 0.
        limiter: The rate limit on increases (starts at 0); its factor is the last published.
        closed_loop: The states move at the last published factor times the unscaled motion
            (a controller applies it): the target is ``closed_loop_factor``; False: the
            state's own factor.
        controller_latency_s: The controller's command-to-state latency [s] (closed loop).
        scaling: The analysis of the current robot and payload; None: no robot yet.
        joint_index: The chain's joints in the messages (None: no robot yet).
    """

    timeout_s: float
    limiter: IncreaseLimiter
    closed_loop: bool = False
    controller_latency_s: float = 0.0
    scaling: SpeedScaling | None = None
    payload_refusal: str = ""  # why the last payload was refused ("" when the payload is valid)
    joint_index: JointIndex | None = None
    last_message_s: float | None = None
    stale: bool = False
    failed: bool = True  # the last decision was a fail-safe (or none was made yet)
    counters: GovernorCounters = field(default_factory=GovernorCounters)
    published: deque[tuple[float, float]] = field(default_factory=deque)  # (time [s], factor)

    def set_scaling(self, scaling: SpeedScaling) -> None:
        """Use ``scaling`` (a new robot or payload) from the next state on."""
        self.scaling = scaling
        self.joint_index = JointIndex(scaling.speed_model.robot.joint_names)

    def refuse_payload(self, reason: str) -> None:
        """Fail safe with ``reason`` (one line; "": a valid payload was set) until a valid
        payload arrives: the previous, maybe lighter payload is no longer the one carried."""
        self.payload_refusal = reason

    def applied_factor(self, now_s: float) -> float:
        """The lowest positive factor published within ``controller_latency_s`` before
        ``now_s``, the one in force at the window's start included (0: none positive)."""
        start = now_s - self.controller_latency_s
        while len(self.published) > 1 and self.published[1][0] <= start:
            self.published.popleft()  # superseded before the window starts
        return min((factor for _, factor in self.published if factor > 0.0), default=0.0)

    def _record(self, factor: float, now_s: float) -> float:
        self.published.append((now_s, factor))
        return factor

    def on_state(
        self,
        names: Sequence[str],
        positions: Sequence[float],
        velocities: Sequence[float],
        now_s: float,
    ) -> Decision:
        """The decision for one /joint_states message received at ``now_s`` [s, monotonic]."""
        start = time.perf_counter()
        self.last_message_s, self.stale = now_s, False
        if self.scaling is None or self.joint_index is None:
            return self.fail("no robot description yet", now_s)
        if self.payload_refusal:
            return self.fail(self.payload_refusal, now_s)
        try:
            q, qd = self.joint_index.chain_state(names, positions, velocities)
            assessed = self.scaling.assess(q, qd)
        except GraspSafetyError as error:
            self.counters.refused += 1
            return self.fail(str(error), now_s)
        if math.isnan(assessed.headroom):  # a defect, never a speed-up
            self.counters.refused += 1
            return self.fail(f"analysis gave a headroom of {assessed.headroom}", now_s)
        if self.failed:  # the rise starts now, not at the fail-safe
            self.limiter(0.0, now_s)
            self.failed = False
        target = assessed.factor
        if self.closed_loop:
            target = closed_loop_factor(self.applied_factor(now_s), assessed.headroom)
        factor = self._record(self.limiter(target, now_s), now_s)
        elapsed = time.perf_counter() - start
        self.counters.states += 1
        self.counters.last_compute_time_s = elapsed
        self.counters.max_compute_time_s = max(self.counters.max_compute_time_s, elapsed)
        return Decision(factor, target, assessed, "", elapsed)

    def check_timeout(self, now_s: float) -> Decision | None:
        """The fail-safe decision when no message came for longer than the timeout (once per
        silence), else None. Before the first message the silence counts from ``now_s``'s
        first call."""
        if self.last_message_s is None:
            self.last_message_s = now_s
        age = now_s - self.last_message_s
        if self.stale or age <= self.timeout_s:
            return None
        self.stale = True
        self.counters.timeouts += 1
        return self.fail(
            f"no /joint_states for {age:.3f} s (joint_states_timeout_s {self.timeout_s:g})", now_s
        )

    def fail(self, reason: str, now_s: float) -> Decision:
        """Factor 0 with ``reason``."""
        self._record(self.limiter(0.0, now_s), now_s)
        self.failed = True
        return Decision(0.0, 0.0, None, reason)
