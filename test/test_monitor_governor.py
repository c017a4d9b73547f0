"""The monitor's decisions without ROS: joint states matched by name, the fail-safe (missing
joint, non-finite value, silence longer than the timeout, no robot), recovery with the rate
limit, and the monitor's parameters (shared ones are the ranking node's)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from conftest import ARM7_AXES, serial_arm_urdf

from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites
from grasp_safety_ros.core.analyses.speed_scaling import (
    IncreaseLimiter,
    SpeedScaling,
    closed_loop_factor,
    payload_speed_model,
)
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.model.robot import RobotModel
from grasp_safety_ros.ros.monitor.governor import Governor
from grasp_safety_ros.ros.monitor.joint_states import JointIndex
from grasp_safety_ros.ros.monitor.parameters import (
    MONITOR_PARAMETERS,
    SHARED,
    check_monitor_parameter,
    monitor_settings,
)
from grasp_safety_ros.ros.parameters import PARAMETERS

EPS = np.finfo(float).eps
JOINTS = ("j1", "j2", "j3", "j4", "j5", "j6", "j7")


@pytest.fixture(scope="module")
def scaling() -> SpeedScaling:
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool")
    return SpeedScaling(payload_speed_model(robot, resolve_arm_sites(robot), None, None, None))


def governor(scaling: SpeedScaling | None, rate: float = 1e9) -> Governor:
    result = Governor(0.125, IncreaseLimiter(rate, 0.0, 0.0))  # times exact in binary
    if scaling is not None:
        result.set_scaling(scaling)
    return result


def test_joints_matched_by_name_in_any_order_extra_ones_ignored() -> None:
    index = JointIndex(JOINTS)
    names = ["gripper", *reversed(JOINTS)]
    positions = [9.0, *[0.1 * k for k in range(7, 0, -1)]]
    velocities = [5.0, *[-0.2 * k for k in range(7, 0, -1)]]
    q, qd = index.chain_state(names, positions, velocities)
    np.testing.assert_array_equal(q, [0.1 * k for k in range(1, 8)])
    np.testing.assert_array_equal(qd, [-0.2 * k for k in range(1, 8)])
    velocities[0] = math.nan  # a joint beyond the chain may be anything
    index.chain_state(names, positions, velocities)


@pytest.mark.parametrize(
    ("names", "positions", "velocities", "field", "words"),
    [
        (JOINTS[:6], [0.0] * 6, [0.0] * 6, "joint_states.name", "j7 missing"),
        (("a", "b"), [0.0] * 2, [0.0] * 2, "joint_states.name", "j1, j2, j3"),
        ((*JOINTS, "j1"), [0.0] * 8, [0.0] * 8, "joint_states.name", "'j1' repeats"),
        (JOINTS, [0.0] * 7, [], "joint_states.velocity", "velocities are needed"),
        (JOINTS, [0.0] * 6, [0.0] * 7, "joint_states.position", "6 values for 7"),
        (JOINTS, [0.0] * 7, [0, 0, math.nan, 0, 0, 0, 0], "joint_states.velocity", "'j3' is nan"),
        (JOINTS, [math.inf] + [0.0] * 6, [0.0] * 7, "joint_states.position", "'j1' is inf"),
    ],
)
def test_bad_states_are_refused_in_one_line(
    names: tuple[str, ...], positions: list, velocities: list, field: str, words: str
) -> None:
    with pytest.raises(InvalidInputError, match=re.escape(field)) as raised:
        JointIndex(JOINTS).chain_state(names, positions, velocities)
    assert words in str(raised.value) and "\n" not in str(raised.value)


def test_a_bad_state_gives_0_with_the_reason_and_a_good_one_recovers(
    scaling: SpeedScaling,
) -> None:
    rate = 2.0
    monitor = governor(scaling, rate)
    slow = [0.01] * 7  # slow enough: target factor 1
    first = monitor.on_state(JOINTS, [0.3] * 7, slow, 1.0)
    assert first.target == 1.0 and first.factor == 0.0  # the rise starts at the first state
    assert monitor.on_state(JOINTS, [0.3] * 7, slow, 1.1).factor == pytest.approx(0.2, abs=EPS)
    bad = monitor.on_state(JOINTS, [0.3] * 7, [0, 0, 0, math.nan, 0, 0, 0], 1.2)
    assert (bad.factor, bad.target) == (0.0, 0.0) and bad.scaling is None
    assert "joint_states.velocity: joint 'j4' is nan" in bad.fail_safe
    again = monitor.on_state(JOINTS, [0.3] * 7, slow, 5.0)  # long after: still from 0
    assert again.factor == 0.0 and again.fail_safe == ""
    later = monitor.on_state(JOINTS, [0.3] * 7, slow, 5.25)
    assert later.factor == pytest.approx(0.5, abs=8 * EPS)
    assert monitor.counters.refused == 1 and monitor.counters.states == 4


def test_silence_longer_than_the_timeout_gives_0_once(scaling: SpeedScaling) -> None:
    monitor = governor(scaling)
    monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 1.0)
    assert monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 1.0625).factor == 1.0
    assert monitor.check_timeout(1.0625 + 0.125) is None  # at the timeout: not yet
    decision = monitor.check_timeout(1.0625 + 0.125 + 1e-6)
    assert decision is not None and decision.factor == 0.0
    assert decision.fail_safe.startswith("no /joint_states for 0.125 s")
    assert "joint_states_timeout_s 0.125" in decision.fail_safe
    assert monitor.check_timeout(2.0) is None  # reported once per silence
    assert monitor.counters.timeouts == 1
    assert monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 2.0).fail_safe == ""


def test_silence_counts_before_the_first_state_and_no_robot_fails_safe() -> None:
    monitor = governor(None)
    assert monitor.check_timeout(0.0) is None
    assert monitor.check_timeout(0.25) is not None
    decision = monitor.on_state(JOINTS, [0.0] * 7, [0.0] * 7, 0.3)
    assert decision.factor == 0.0 and decision.fail_safe == "no robot description yet"


def test_shared_parameters_are_the_ranking_nodes() -> None:
    for name in SHARED:
        assert MONITOR_PARAMETERS[name] is PARAMETERS[name]
    for name in ("urdf", "base_frame", "tip_frame", "iso_ts_15066.regions"):
        assert name in MONITOR_PARAMETERS
    assert check_monitor_parameter("use_sim_time", True) is True  # not ours: unchanged
    with pytest.raises(InvalidInputError, match=r"iso_ts_15066\.regions"):
        check_monitor_parameter("iso_ts_15066.regions", ["elbow"])


BASE = {"urdf": "example-robot-data:panda", "base_frame": "panda_link0", "tip_frame": "panda_hand"}


@pytest.mark.parametrize(
    ("values", "field"),
    [
        ({"speed_scaling.margin": 1.2}, "speed_scaling.margin"),
        ({"speed_scaling.max_increase_per_s": 0.0}, "speed_scaling.max_increase_per_s"),
        ({"joint_states_timeout_s": -1.0}, "joint_states_timeout_s"),
        ({"speed_scaling.rest_speed_m_s": 0.5}, "speed_scaling.rest_speed_m_s"),
        ({"speed_scaling.controller_latency_s": -0.01}, "speed_scaling.controller_latency_s"),
        ({"payload.mass_kg": 2000.0}, "payload.mass_kg"),
        ({"payload.box_size_m": [0.1, 0.1]}, "payload.box_size_m"),
        ({"payload.points_in_tip_m": [0.1, 0.1]}, "payload.points_in_tip_m"),
        ({"payload.com_in_tip_m": [0.0, math.nan, 0.0]}, "payload.com_in_tip_m"),
        (
            {"payload.mass_kg": 1.0, "payload.inertia_about_com_kgm2": [1, 0, 0, 1, 0, 3]},
            "payload.inertia_about_com_kgm2",
        ),
        ({"payload.box_size_m": [0.1] * 3, "payload.points_in_tip_m": [0.0] * 3}, "box"),
        ({"base_frame": ""}, "base_frame"),
    ],
)
def test_bad_monitor_parameters_are_refused_by_name(values: dict, field: str) -> None:
    with pytest.raises(InvalidInputError, match=re.escape(field)):
        monitor_settings({**BASE, **values})


def test_payload_box_corners_about_the_com_in_the_tip_frame() -> None:
    settings = monitor_settings(
        {
            **BASE,
            "payload.mass_kg": 1.0,
            "payload.com_in_tip_m": [0.0, 0.0, 0.15],
            "payload.inertia_about_com_kgm2": [0.002, 0, 0, 0.002, 0, 0.002],
            "payload.box_size_m": [0.1, 0.2, 0.3],
        }
    )
    points = settings.payload.points_in_tip_m
    assert points is not None and points.shape == (8, 3)
    np.testing.assert_allclose(points.mean(axis=0), [0.0, 0.0, 0.15], atol=1e-15)
    np.testing.assert_allclose(points.max(axis=0) - points.min(axis=0), [0.1, 0.2, 0.3])
    empty = monitor_settings({**BASE, "payload.box_size_m": [0.1, 0.2, 0.3]})
    assert empty.payload.inertia is None and empty.payload.points_in_tip_m is None


def run_against_a_scaling_controller(
    monitor: Governor, q: np.ndarray, nominal: np.ndarray, steps: int
) -> list[float]:
    """A controller that moves at the last published factor times the nominal velocity: the
    factors published for ``steps`` states (0.002 s apart)."""
    published, factor = [], 0.0
    for k in range(steps):
        decision = monitor.on_state(JOINTS, q.tolist(), (factor * nominal).tolist(), 0.002 * k)
        factor = decision.factor
        published.append(factor)
    return published


def test_closed_loop_settles_at_the_nominal_motions_factor_open_loop_does_not(
    scaling: SpeedScaling,
) -> None:
    q, nominal = np.full(7, 0.3), np.array([2.0, -1.5, 1.8, 2.2, -2.5, 1.9, 2.4])
    c = scaling.assess(q, nominal).factor  # the unscaled motion's factor
    assert 0.0 < c < 0.9
    closed = governor(scaling)
    closed.closed_loop = True
    factors = run_against_a_scaling_controller(closed, q, nominal, 8)
    # 0 (the rise starts), 1 (at rest: nothing to infer), then c for good
    assert factors[:2] == [0.0, 1.0]
    np.testing.assert_allclose(factors[2:], c, rtol=1e-12)
    at_limit = scaling.assess(q, c * nominal)  # the motion it lets through: at the limit
    assert at_limit.headroom == pytest.approx(1.0, rel=1e-12)
    opened = run_against_a_scaling_controller(governor(scaling), q, nominal, 8)
    np.testing.assert_allclose(opened[2:], [c, 1.0] * 3, rtol=1e-12)  # alternates: unsafe


def test_closed_loop_factor_at_rest_and_in_motion() -> None:
    assert closed_loop_factor(0.0, math.inf) == 1.0  # stopped: rise (rate-limited)
    assert closed_loop_factor(0.0, 0.5) == 0.0  # still moving after a 0: stay at 0
    assert closed_loop_factor(0.5, 0.8) == 0.4
    assert closed_loop_factor(0.5, 3.0) == 1.0


def rest_scaling(scaling: SpeedScaling, rest_speed_m_s: float) -> SpeedScaling:
    return SpeedScaling(scaling.speed_model, scaling.margin, rest_speed_m_s)


@pytest.mark.parametrize("rest_speed_m_s", [0.0, 0.001])
def test_noisy_rest_after_a_fail_safe_recovers_at_the_rate_limit(
    scaling: SpeedScaling, rest_speed_m_s: float
) -> None:
    rate, period = 2.0, 0.001953125  # 1/512 s: times exact in binary
    monitor = governor(rest_scaling(scaling, rest_speed_m_s), rate)
    monitor.closed_loop, monitor.controller_latency_s = True, 0.05
    monitor.fail("no /joint_states yet", 0.0)
    noise = np.random.default_rng(7).normal(0.0, 1e-5, (700, 7))  # encoder noise [rad/s]
    # the sites' speeds: at most |J| |q̇| ~ 1 m x 1e-4 rad/s, far below 0.001 m/s
    factors = [
        monitor.on_state(JOINTS, [0.3] * 7, n.tolist(), period * (k + 1)).factor
        for k, n in enumerate(noise)
    ]
    if rest_speed_m_s == 0.0:  # every site "moves": 0 x headroom stays 0 (the defect)
        assert max(factors) == 0.0
        return
    elapsed = period * np.arange(len(factors))  # the rise starts at the first state
    np.testing.assert_allclose(factors, np.minimum(1.0, rate * elapsed), rtol=0, atol=8 * EPS)


def run_against_a_lagging_controller(
    monitor: Governor, q: np.ndarray, nominal: np.ndarray, lag: int, steps: int
) -> np.ndarray:
    """A controller whose state shows the factor published ``lag`` messages before the last
    one (0 before any; lag 0: the last one, no latency): the factors it applied to the
    ``steps`` states (0.002 s apart)."""
    published: list[float] = []
    applied = np.zeros(steps)
    for k in range(steps):
        applied[k] = published[k - 1 - lag] if k > lag else 0.0
        state = (applied[k] * nominal).tolist()
        published.append(monitor.on_state(JOINTS, q.tolist(), state, 0.002 * k).factor)
    return applied


@pytest.mark.parametrize("lag", [1, 10])  # 2 ms, 20 ms
def test_a_lagging_controller_never_exceeds_the_need_within_the_latency_window(
    scaling: SpeedScaling, lag: int
) -> None:
    q, nominal = np.full(7, 0.3), np.array([2.0, -1.5, 1.8, 2.2, -2.5, 1.9, 2.4])
    need = scaling.assess(q, nominal).factor  # the unscaled motion's factor
    assert 0.0 < need < 0.9

    def worst(latency_s: float) -> tuple[float, float]:
        monitor = governor(rest_scaling(scaling, 0.001), rate=2.0)
        monitor.closed_loop, monitor.controller_latency_s = True, latency_s
        applied = run_against_a_lagging_controller(monitor, q, nominal, lag, 1000)
        return float(applied.max()) / need, float(applied[-1]) / need

    # the window covers the lag: the factor assumed applied is at or below the applied one,
    # so the target never exceeds the need; tolerance: a few roundings of the products
    peak, settled = worst(0.002 * lag + 1e-9)
    assert peak <= 1.0 + 16 * EPS
    assert settled == pytest.approx(1.0, rel=16 * EPS)  # and it reaches the need
    assert worst(0.05)[0] <= 1.0 + 16 * EPS  # a wider window: still never above the need
    assert worst(0.0)[0] > 1.0 + 1e-3  # the last published factor over-estimates the headroom


def test_a_refused_payload_gives_0_with_the_refusal_until_a_valid_one(
    scaling: SpeedScaling,
) -> None:
    monitor = governor(scaling)
    assert monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 0.0).fail_safe == ""
    refusal = "payload refused: payload.inertia: mass must be at most max_mass_kg=5"
    monitor.refuse_payload(refusal)
    decision = monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 0.0625)
    assert (decision.factor, decision.fail_safe) == (0.0, refusal)
    monitor.refuse_payload("")  # a valid payload arrived
    assert monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 0.125).fail_safe == ""
    assert monitor.on_state(JOINTS, [0.3] * 7, [0.01] * 7, 0.1875).factor == 1.0
