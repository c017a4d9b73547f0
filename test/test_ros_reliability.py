"""The node's bounds at the boundary, without a running node: count parameters, object
inertia, planned joint trajectories, grasp quality, subnormal floats (an int sent as a float),
the final guard against non-finite scores, and the fair compute lock."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pinocchio as pin
import pytest
import yaml
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import (
    Inertia,
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    Quaternion,
    Transform,
    Vector3,
)
from grasp_safety_msgs.msg import GraspEvaluation, GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import (
    JointTrajectory,
    JointTrajectoryPoint,
    MultiDOFJointTrajectory,
    MultiDOFJointTrajectoryPoint,
)

from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method.ranking import Grasp
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.ros import parameters
from grasp_safety_ros.ros.conversions import (
    geometry,
    grasps_with_joint_trajectories,
    object_inertia_from_msg,
    trajectory_from_msg,
)
from grasp_safety_ros.ros.parameters import check_parameter, parameter_constraints
from grasp_safety_ros.ros.robot.bundle import build_robot
from grasp_safety_ros.ros.runtime.process import join_started, settle
from grasp_safety_ros.ros.service.message_checks import (
    INT_AS_FLOAT_HINT,
    NonFiniteResultError,
    check_finite_result,
    check_no_subnormals,
    first_subnormal,
)
from grasp_safety_ros.ros.service.ranking_job import ClientWatch, FairComputeLock
from grasp_safety_ros.ros.topics.diagnostics import NodeStatus
from grasp_safety_ros.ros.topics.inputs import MAX_ABS_GRASP_QUALITY, check_quality
from grasp_safety_ros.scenario import schema as scenario

# --- Count parameters (D) ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "limit"),
    [
        ("uncertainty.samples", 10_000),
        ("max_grasps", 10_000),
        ("max_samples", 10_000_000),
        ("max_total_samples", 10_000_000),
    ],
)
def test_count_parameters_are_bounded(name: str, limit: int) -> None:
    assert check_parameter(name, limit) == limit
    with pytest.raises(InvalidInputError, match=rf"^{name}: must be in \[\d, {limit}\], got"):
        check_parameter(name, limit + 1)
    assert parameter_constraints(name).value_range[1] == limit  # ros2 param describe


# --- Object inertia (B) ------------------------------------------------------------------------


def test_huge_inertia_is_refused_naming_the_request_field() -> None:
    inertia = Inertia(m=0.34, ixx=1e300, iyy=1e300, izz=1e300)
    with pytest.raises(InvalidInputError) as error:
        object_inertia_from_msg(inertia, 1000.0)
    message = str(error.value)
    assert message.startswith("object_inertia.ixx..izz: components and principal moments must ")
    assert "at most m * 100^2 = 3400 kg m^2" in message and len(message) < 200


def test_inertia_bound_is_the_radius_of_gyration() -> None:
    # A thin rod of 100 m (radius of gyration 100 / sqrt(12) m) passes; a moment of
    # m * (100 m)^2 is the largest accepted, whatever the axes (a rotated tensor too).
    m = 2.0
    limit = m * 100.0**2
    rotation = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    tensor = rotation @ np.diag([limit / 2, limit / 2, limit * 0.999]) @ rotation.T
    components = [tensor[i, j] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))]
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    assert object_inertia_from_msg(
        Inertia(m=m, **dict(zip(keys, components, strict=True))), 1000.0
    )
    over = dict(zip(keys, [c * 1.01 for c in components], strict=True))
    with pytest.raises(InvalidInputError, match="principal moments must be at most"):
        object_inertia_from_msg(Inertia(m=m, **over), 1000.0)


def test_default_object_inertia_parameter_is_bounded() -> None:
    values = {
        "base_frame": "base",
        "tip_frame": "tool",
        "object.mass_kg": 0.34,
        "object.inertia_about_com_kgm2": [1e300, 0.0, 0.0, 1e300, 0.0, 1e300],
    }
    with pytest.raises(InvalidInputError, match=r"^object\.inertia_about_com_kgm2: components"):
        parameters.settings_from_parameters(values)


# --- Joint trajectories against max_samples (C) -------------------------------------------------


def test_joint_trajectory_longer_than_max_samples_is_refused_before_conversion() -> None:
    grasps = [Grasp(pin.SE3.Identity(), "g0")]
    point = JointTrajectoryPoint(positions=[0.0])
    message = JointTrajectory(joint_names=["j"], points=[point] * 30_001)
    with pytest.raises(
        InvalidInputError,
        match=r"^joint_trajectories\[0\]\.points: has 30001 points; at most "
        r"max_samples=20000 are allowed$",
    ):
        grasps_with_joint_trajectories(grasps, [message], max_samples=20_000)


# --- Grasp quality (A) -------------------------------------------------------------------------


def test_grasp_quality_is_bounded() -> None:
    assert check_quality([MAX_ABS_GRASP_QUALITY, -MAX_ABS_GRASP_QUALITY, 0.0], "q") is not None
    with pytest.raises(InvalidInputError, match=r"^grasp_quality: must be within \+/-1e\+09"):
        check_quality([1.7976931348623157e308, -1.7976931348623157e308, 0.0], "grasp_quality")


# --- Subnormal floats: an int sent as a float (issue 19) -----------------------------------------


def test_subnormals_are_found_with_their_field_path() -> None:
    request = RankGrasps.Request()
    request.grasps = PoseArray(poses=[Pose(), Pose(position=Point(y=5e-324))])
    assert first_subnormal(request) == ("grasps.poses[1].position.y", 5e-324)
    request.grasps.poses[1].position.y = 1.0
    request.object_trajectory = Path(
        poses=[PoseStamped(), PoseStamped(pose=Pose(orientation=Quaternion(w=1e-310)))]
    )
    assert first_subnormal(request) == ("object_trajectory.poses[1].pose.orientation.w", 1e-310)
    request.object_trajectory.poses[1].pose.orientation.w = 1.0
    request.grasp_quality = [0.5, -1e-320]
    assert first_subnormal(request) == ("grasp_quality[1]", -1e-320)
    request.grasp_quality = []
    request.joint_trajectories = [
        JointTrajectory(),
        JointTrajectory(
            points=[JointTrajectoryPoint(), JointTrajectoryPoint(velocities=[0, 4e-323])]
        ),
    ]
    assert first_subnormal(request) == ("joint_trajectories[1].points[1].velocities[1]", 4e-323)
    request.joint_trajectories = []
    request.object_inertia.m = 5e-324
    assert first_subnormal(request) == ("object_inertia.m", 5e-324)
    request.object_inertia.m = 0.0
    assert first_subnormal(request) is None  # zeros, -0.0 and normal numbers pass


def test_subnormal_refusal_names_the_field_and_the_likely_int() -> None:
    with pytest.raises(InvalidInputError) as error:
        check_no_subnormals(Float64MultiArray(data=[1.0, 5e-324]), "candidate_grasp_quality")
    assert str(error.value) == (
        f"candidate_grasp_quality.data[1]: holds the subnormal number 5e-324: {INT_AS_FLOAT_HINT}"
    )
    assert INT_AS_FLOAT_HINT.endswith("set ROS_PYTHON_CHECK_FIELDS=1 in the client")
    check_no_subnormals(Float64MultiArray(data=[np.finfo(float).tiny, 0.0, -0.0, math.nan]))


# --- The final guard (A) -----------------------------------------------------------------------


def ranking(combined: list[float], order: list[int]) -> GraspRanking:
    evaluations = [
        GraspEvaluation(
            index=k,
            name=f"grasp_{k}",
            score=1.0,
            safety_score=1.0,
            peak_effective_mass_kg=1.0,
            mean_effective_mass_kg=1.0,
            combined_score=c,
            grasp_quality=0.5,
        )
        for k, c in enumerate(combined)
    ]
    return GraspRanking(
        evaluations=evaluations,
        order=order,
        safety_order=order,
        paper_order=order,
        safety_weight=0.5,
        order_stability=math.nan,
    )


def test_a_nan_ranked_first_is_refused() -> None:
    check_finite_result(ranking([0.2, 0.061, 0.0], [0, 1, 2]))
    with pytest.raises(NonFiniteResultError, match=r"^result: grasp 0 \(grasp_0\) would be"):
        check_finite_result(ranking([math.nan, 0.061, 0.0], [0, 1, 2]))
    with pytest.raises(NonFiniteResultError, match="combined_score = inf"):
        check_finite_result(ranking([0.2, math.inf, 0.0], [0, 2]))  # not ordered, but inf
    check_finite_result(ranking([0.2, math.nan, 0.0], [0, 2]))  # NaN outside the order: fine


# --- The fair compute lock and the client watch (E) ---------------------------------------------


def test_fair_lock_hands_over_to_a_waiter_after_a_slice() -> None:
    lock = FairComputeLock()
    assert lock.acquire(timeout=1.0)
    served = []

    def small() -> None:
        assert lock.acquire(timeout=10.0)
        served.append("small")
        lock.release()

    thread = threading.Thread(target=small)
    thread.start()
    while lock.waiting() == 0:
        time.sleep(0.001)
    assert lock.share(slice_s=60.0) == 0.0  # its slice is not used up: it keeps the lock
    waited = lock.share(slice_s=0.0)  # hands over, queues, gets it back after the small one
    thread.join(timeout=10.0)
    assert served == ["small"] and waited > 0.0 and lock.locked()
    lock.release()
    assert not lock.locked()


def test_fair_lock_never_makes_a_lone_ranking_wait() -> None:
    """Past its slice, a ranking nobody waits behind keeps the lock at once (no hand-over,
    no queueing): slices cost a lone client nothing."""
    lock = FairComputeLock()
    assert lock.acquire(timeout=0.0)  # free: taken at once
    started = time.perf_counter()
    assert all(lock.share(slice_s=0.0) == 0.0 for _ in range(1000))
    assert lock.locked() and lock.waiting() == 0
    assert time.perf_counter() - started < 0.5  # 1,000 checks, no wait among them
    lock.release()


class _StartedLate(threading.Thread):
    """A thread launched whose start() was cut short: join() raises until it counts as
    started (as CPython's, "cannot join thread before it is started")."""

    def __init__(self, refusals: int) -> None:
        super().__init__()
        self.refusals, self.joined = refusals, False

    def join(self, timeout: float | None = None) -> None:
        if self.refusals > 0:
            self.refusals -= 1
            raise RuntimeError("cannot join thread before it is started")
        self.joined = True


def test_join_started_waits_for_a_thread_whose_start_was_cut_short() -> None:
    """The node's main joins its spin thread at a SIGINT; a signal that interrupted the spin
    thread's start() made that join raise (exit 1 instead of 0, the thread left spinning)."""
    with pytest.raises(RuntimeError, match="before it is started"):
        threading.Thread().join()  # what main's plain join did
    late = _StartedLate(refusals=5)
    join_started(late, 10.0)
    assert late.joined and late.refusals == 0
    started = time.monotonic()
    join_started(threading.Thread(), 0.05)  # never launched: given up after the timeout
    assert time.monotonic() - started < 5.0


class _Suspended:
    """A node's suspended request, resumed (answered) only by a callback of its executor."""

    def __init__(self) -> None:
        self.answered = threading.Event()

    @property
    def requests_waiting(self) -> int:
        return 0 if self.answered.is_set() else 1


def test_settle_spins_the_executor_when_no_spin_thread_does(context: Context) -> None:
    """A signal during start-up (wait_for_robot spins in the main thread, no spin thread yet):
    settle spins the executor itself, or a suspended request is never answered."""
    node = Node("settle_probe", context=context)
    waiting = _Suspended()
    node.create_timer(0.01, waiting.answered.set)  # a callback only a spinning executor runs
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        settle(waiting, 30.0, executor)  # type: ignore[arg-type]  (only requests_waiting)
        assert waiting.answered.is_set()
    finally:
        executor.shutdown()
        node.destroy_node()


def test_fair_lock_times_out_and_stops() -> None:
    lock = FairComputeLock()
    assert lock.acquire(timeout=0.0)
    assert not lock.acquire(timeout=0.05)  # busy
    results = []
    thread = threading.Thread(target=lambda: results.append(lock.acquire(timeout=60.0)))
    thread.start()
    while lock.waiting() == 0:
        time.sleep(0.001)
    lock.stop()
    thread.join(timeout=5.0)
    assert results == [False] and lock.waiting() == 0


def test_client_watch_follows_the_requests_client(monkeypatch: pytest.MonkeyPatch) -> None:
    from grasp_safety_ros.ros.service import ranking_job

    monkeypatch.setattr(ranking_job, "CLIENT_CHECK_PERIOD_S", 0.0)
    present = [b"a", b"b"]
    known: list[bytes | None] = [None]
    watch = ClientWatch(lambda: list(present), lambda: known[0])
    present[:] = []
    assert not watch.gone() and not watch.gone()  # not identified yet: nothing judged
    present[:] = [b"a", b"b"]
    known[0] = b"a"  # identified (its introspection event arrived)
    present[:] = [b"a", b"c"]  # another client left: not ours
    assert not watch.gone() and not watch.gone()
    present[:] = [b"c"]
    assert not watch.gone()  # the first check without it
    assert watch.gone()


def test_client_watch_without_identity_needs_every_client_gone(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from grasp_safety_ros.ros.service import ranking_job

    monkeypatch.setattr(ranking_job, "CLIENT_CHECK_PERIOD_S", 0.0)
    present = [b"a", b"b"]
    watch = ClientWatch(lambda: list(present))
    present[:] = [b"b", b"c"]  # one of them left: maybe ours is b
    assert not watch.gone() and not watch.gone()
    present[:] = [b"c"]
    assert not watch.gone()
    assert watch.gone()
    assert not ClientWatch(lambda: []).gone()  # none at arrival: never gone


def test_a_paused_pooled_ranking_leaves_the_workers_to_others() -> None:
    """A ranking that hands the compute lock over stops taking results; the pool then runs at
    most two jobs per worker ahead of it (Executor.map submitted all of them at once, so a
    request arriving meanwhile queued behind the whole ranking on the workers)."""
    from concurrent.futures import ThreadPoolExecutor

    from grasp_safety_ros.core.method.pool import evaluate_jobs

    started: list[int] = []
    lock = threading.Lock()

    def evaluate(_: object, index: int) -> int:
        with lock:
            started.append(index)
        return index

    with ThreadPoolExecutor(max_workers=2) as executor:
        stream = evaluate_jobs(None, executor, [(k,) for k in range(100)], evaluate)
        assert next(stream) == 0
        time.sleep(0.2)  # the caller pauses: the workers idle after the jobs submitted ahead
        assert len(started) <= 1 + 2 * 2, sorted(started)
        assert list(stream) == list(range(1, 100))  # then everything, in order


# --- Hostile values found by the fuzzer (issue 27) ----------------------------------------------


def test_arm_points_are_bounded_like_the_requests_points() -> None:
    """1e300 m on the arm was accepted and every later ranking failed (LinAlgError): the node
    parameter and the scenario key are refused, naming them, beyond +/-1000 m."""
    bound = geometry.MAX_ABS_POSITION_M
    assert check_parameter("whole_arm.points_m", [0.0, 0.0, bound]) == (0.0, 0.0, bound)
    for value in (1e300, 2000.0, -1000.5):
        with pytest.raises(
            InvalidInputError,
            match=r"^whole_arm\.points_m: point 1: must be within \+/-1000 m per coordinate",
        ):
            check_parameter("whole_arm.points_m", [0.0, 0.0, 0.1, 0.0, 0.0, value])


def test_scenario_arm_points_are_bounded_like_the_nodes() -> None:
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["robot"]["exposed_points_m"] = {"right_lower_forearm": [[0.0, 0.0, 1e300]]}
    with pytest.raises(
        InvalidInputError,
        match=r"^robot\.exposed_points_m\.right_lower_forearm: must be within \+/-1000 m",
    ):
        scenario.parse_scenario(data, config_file("book_baxter.yaml").parent)
    data["robot"]["exposed_points_m"] = {"right_lower_forearm": [[0.0, 0.0, 1000.0]]}
    scenario.parse_scenario(data, config_file("book_baxter.yaml").parent)


def multi_dof(x_m: float) -> MultiDOFJointTrajectory:
    points = [
        MultiDOFJointTrajectoryPoint(
            transforms=[Transform(translation=Vector3(x=x, y=0.0, z=0.5))],
            time_from_start=Duration(sec=sec),
        )
        for x, sec in ((0.6, 0), (x_m, 2))
    ]
    return MultiDOFJointTrajectory(
        header=Header(frame_id="base"), joint_names=["o"], points=points
    )


def path_to(x_m: float) -> Path:
    poses = [PoseStamped(pose=Pose(position=Point(x=x, z=0.5))) for x in (0.6, x_m)]
    return Path(header=Header(frame_id="base"), poses=poses)


@pytest.mark.parametrize("x_m", [1e30, 2000.0, -1000.001])
def test_multi_dof_trajectory_is_bounded_like_the_path(x_m: float) -> None:
    """Both object trajectory messages refuse a position beyond +/-1000 m naming the field
    (the multi-DOF one answered success with an empty order)."""
    with pytest.raises(
        InvalidInputError,
        match=r"^object_multi_dof_trajectory\.points\[1\]\.transforms\[0\]\.translation: must "
        r"be within \+/-1000 m per coordinate",
    ):
        trajectory_from_msg(multi_dof(x_m), "base", 0.1, 5.0, 20_000)
    with pytest.raises(
        InvalidInputError,
        match=r"^object_trajectory\.poses\[1\]\.pose\.position: must be within \+/-1000 m",
    ):
        trajectory_from_msg(path_to(x_m), "base", 0.1, 5.0, 20_000)
    at_bound = math.copysign(1000.0, x_m)
    trajectory_from_msg(multi_dof(at_bound), "base", 0.1, 5.0, 20_000)
    trajectory_from_msg(path_to(at_bound), "base", 0.1, 5.0, 20_000)


def test_lost_messages_are_counted_through_a_wrapped_change() -> None:
    """The middleware reported a change of 18446744071562067968 (-2^31 cast to size_t) and
    /diagnostics showed lost./joint_states = 18446744073709551620: the count is the running
    total; a wrapped change or total leaves it unchanged; a plausible change is added where
    the total is not plausible."""
    status = NodeStatus()
    assert status.record_lost("joint_states", 4, 4) == 4
    assert status.record_lost("joint_states", 4, 18446744071562067968) == 0
    assert status.lost_by_source["joint_states"] == 4
    assert status.record_lost("joint_states", 2**64 - 1, 2**64 - 1) == 0  # -1 both: nothing
    assert status.record_lost("joint_states", 2**64 - 5, 3) == 3  # total wrapped, change not
    assert status.record_lost("joint_states", 9, 2) == 2  # the total is the count again
    assert status.lost_by_source == {"joint_states": 9}
    assert status.record_lost("candidate_grasps", 2**31, 2**31) == 0  # no 32-bit count


def test_unknown_published_armature_entry_names_its_parameter() -> None:
    with pytest.raises(
        InvalidInputError, match=r"^robot\.armature_published: no published entry 'nope'"
    ):
        check_parameter("robot.armature_published", "published:nope")
    settings = parameters.settings_from_parameters(
        {
            "urdf": "example-robot-data:baxter",
            "base_frame": "base",
            "tip_frame": "right_gripper",
            "robot.armature_published": "published",
        }
    )
    with pytest.raises(
        InvalidInputError, match=r"^robot\.armature_published: no published armature for"
    ):
        build_robot(settings, None)


def test_planned_velocities_beyond_the_bound_are_refused_naming_the_request_field() -> None:
    """The node's field names reach the core's rate check: the request field, the point, the
    message column and the joint (1e30 rad/s was accepted and handed back as executable)."""
    from conftest import ARM6_AXES, serial_arm_urdf

    from grasp_safety_ros.core.method.joint_trajectory import JointSpaceTrajectory
    from grasp_safety_ros.core.model.robot import RobotModel

    robot = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    names = list(reversed(robot.joint_names))  # message column 0 is the chain's last joint
    points = [
        JointTrajectoryPoint(
            positions=[0.0] * 6,
            velocities=[1e30 if k == 50 else 0.0] + [0.0] * 5,
            time_from_start=Duration(sec=k // 10, nanosec=(k % 10) * 100_000_000),
        )
        for k in range(60)
    ]
    message = JointTrajectory(joint_names=names, points=points)
    (grasp,) = grasps_with_joint_trajectories([Grasp(pin.SE3.Identity(), "g0")], [message])
    with pytest.raises(InvalidInputError) as error:
        JointSpaceTrajectory(robot, grasp.joint_trajectory, pin.SE3.Identity())
    assert error.value.field == "joint_trajectories[0].points[50].velocities[0]"
    assert error.value.reason.startswith(f"joint '{robot.joint_names[-1]}' at 1e+30 rad/s: ")


def test_a_nan_effort_score_is_refused_only_when_it_orders() -> None:
    """Effort is on by default: a grasp of an arm without effort limits has a NaN effort score,
    an answer (not computable), unless rank_by effort orders by it."""
    result = ranking([0.2, 0.061, 0.0], [0, 1, 2])
    result.effort_criterion = "peak_fraction"
    for evaluation in result.evaluations:
        evaluation.effort_score = math.nan
    check_finite_result(result)  # rank_by safety
    result.rank_by = "effort"
    with pytest.raises(NonFiniteResultError, match="effort_score = nan"):
        check_finite_result(result)


def test_the_armature_range_orders_are_guarded_too() -> None:
    result = ranking([0.2, 0.061, 0.0], [0, 1, 2])
    result.armature_range_message = "ranking stable over the armature ranges: [0, 1, 2]"
    result.armature_order_lower = [0, 1, 2]
    for evaluation in result.evaluations:
        evaluation.score_armature_lower = evaluation.score_armature_upper = 1.0
    check_finite_result(result)
    result.evaluations[2].score_armature_upper = math.nan
    with pytest.raises(NonFiniteResultError, match="score_armature_upper = nan"):
        check_finite_result(result)
