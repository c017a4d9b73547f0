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
from geometry_msgs.msg import Inertia, Point, Pose, PoseArray, PoseStamped, Quaternion
from grasp_safety_msgs.msg import GraspEvaluation, GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method.ranking import Grasp
from grasp_safety_ros.ros import parameters
from grasp_safety_ros.ros.conversions import (
    geometry,
    grasps_with_joint_trajectories,
    object_inertia_from_msg,
)
from grasp_safety_ros.ros.executor import join_started
from grasp_safety_ros.ros.message_checks import (
    INT_AS_FLOAT_HINT,
    NonFiniteResultError,
    check_finite_result,
    check_no_subnormals,
    first_subnormal,
)
from grasp_safety_ros.ros.parameters import check_parameter, parameter_constraints
from grasp_safety_ros.ros.ranking_job import ClientWatch, FairComputeLock
from grasp_safety_ros.ros.topic_inputs import MAX_ABS_GRASP_QUALITY, check_quality
from grasp_safety_ros.scenario import schema as scenario

# --- Count parameters (D) ----------------------------------------------------------------------


def test_count_parameter_limits_are_the_clis() -> None:
    assert parameters.MAX_GRASPS_LIMIT == scenario.MAX_GRASPS
    assert parameters.MAX_SAMPLES_LIMIT == scenario.MAX_GRASP_SAMPLES
    assert geometry.MAX_OBJECT_SIZE_M == scenario.MAX_OBJECT_SIZE_M


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
    from grasp_safety_ros.ros import ranking_job

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
    from grasp_safety_ros.ros import ranking_job

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
