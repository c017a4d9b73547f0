"""Fuzzing the node: random malformed RankGrasps requests and topic messages.

Every malformed input is answered (service: success=false; topics: a refusal on /diagnostics)
with a message that starts with the offending field; subnormal numbers (what an int sent as a
float becomes) are refused with the ROS_PYTHON_CHECK_FIELDS hint; inputs that are odd but
valid (huge but finite positions, Paths of several poses) are either ranked or refused naming
a field; nothing crashes, and no success carries a NaN or infinite score for a grasp it
orders. A known-good request is sent after each one and its answer must stay exactly the first
answer. Bounded: a fixed number of examples per test; with CI set, the "ci" settings profile
makes the examples deterministic (derandomize).
"""

from __future__ import annotations

import copy
import math
import os
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from builtin_interfaces.msg import Time
from conftest import ARM6_AXES, serial_arm_urdf
from geometry_msgs.msg import Inertia, InertiaStamped, PoseArray
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from nav_msgs.msg import Path
from ros_node_harness import (
    LATCHED,
    MAX_GRASPS,
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    book_request,
    same_messages,
)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.input_checks import QUATERNION_NORM_TOLERANCE
from grasp_safety_ros.core.method.ik import compiled_available
from grasp_safety_ros.ros.conversions import MAX_ABS_POSITION_M, transform_from_pose_msg

try:
    settings.get_profile("ci")
except InvalidArgument:  # registered here when conftest does not (same name and settings)
    settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

FUZZ = settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
REFUSE, ACCEPT, EITHER = "refuse", "accept", "either"
BAD_FLOATS = (math.nan, math.inf, -math.inf)
SUBNORMALS = (5e-324, -5e-324, 1e-310)
ODD_FLOATS = (*SUBNORMALS, sys.float_info.min, 0.0, -0.0, 1e300, -1e300, sys.float_info.max)
MAX_ABS_QUALITY = 1e9  # the node's MAX_ABS_GRASP_QUALITY
MAX_MASS_KG = 1000.0  # the parameter's default
MAX_SAMPLES = 20_000  # the parameter's default
TEXT = st.text(
    alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
    max_size=24,
)


@dataclass
class Parts:
    """What a request or the topics carry, mutated in place by a Mutation."""

    grasps: PoseArray
    path: Path
    inertia: Inertia
    inertia_frame: str
    quality: list[float]
    metric: str
    metric_point: str
    joint_trajectories: list[JointTrajectory]

    @classmethod
    def good(cls) -> Parts:
        request = book_request()
        return cls(
            request.grasps,
            request.object_trajectory,
            request.object_inertia,
            "object",
            [],
            "",
            "",
            [],
        )

    def request(self) -> RankGrasps.Request:
        return RankGrasps.Request(
            grasps=self.grasps,
            object_trajectory=self.path,
            object_inertia=self.inertia,
            grasp_quality=self.quality,
            metric=self.metric,
            metric_point=self.metric_point,
            joint_trajectories=self.joint_trajectories,
        )


@dataclass(frozen=True)
class Mutation:
    """One change of a good request: ``apply`` makes it and returns (field, expectation)."""

    label: str
    stage: int  # applied in stage order: counts (0) before values (1)
    apply: Callable[[Parts], tuple[str, str]]
    key: str  # what it changes: one mutation per key, so none undoes another

    def __repr__(self) -> str:
        return self.label


# --- Strategies ------------------------------------------------------------------------------

floats_bad_or_odd = st.sampled_from(BAD_FLOATS + ODD_FLOATS)


def _quaternion_expectation(quaternion: Any) -> str:
    values = (quaternion.x, quaternion.y, quaternion.z, quaternion.w)
    if not all(math.isfinite(v) for v in values):
        return REFUSE
    norm = math.sqrt(math.fsum(v * v for v in values))
    if abs(norm - 1.0) > 2 * QUATERNION_NORM_TOLERANCE:
        return REFUSE
    return ACCEPT if abs(norm - 1.0) < 0.5 * QUATERNION_NORM_TOLERANCE else EITHER


@st.composite
def pose_value(draw: st.DrawFn) -> Mutation:
    """A non-finite, denormal, zero or huge number in a grasp or trajectory pose."""
    where = draw(st.sampled_from(("grasps", "path")))
    index = draw(st.integers(0, 2))
    part = draw(st.sampled_from(("position", "orientation")))
    component = draw(st.sampled_from("xyzw" if part == "orientation" else "xyz"))
    value = draw(floats_bad_or_odd)

    def apply(parts: Parts) -> tuple[str, str]:
        if where == "grasps":
            poses = parts.grasps.poses
            if not poses:
                return "grasps.poses", EITHER
            k = index % len(poses)
            pose, field = poses[k], f"grasps.poses[{k}].{part}"
        else:
            poses = parts.path.poses
            if not poses:
                return "object_trajectory.poses", EITHER
            k = index % len(poses)
            pose, field = poses[k].pose, f"object_trajectory.poses[{k}].pose.{part}"
        target = getattr(pose, part)
        setattr(target, component, value)
        if is_subnormal(value):
            return f"{field}.{component}", REFUSE
        if part == "orientation":
            return field, _quaternion_expectation(target)
        if not math.isfinite(value) or abs(value) > MAX_ABS_POSITION_M:
            return field, REFUSE
        return field, ACCEPT

    return Mutation(f"{where}[{index}].{part}.{component}={value!r}", 1, apply, f"pose {where}")


@st.composite
def quaternion_scale(draw: st.DrawFn) -> Mutation:
    """A grasp or trajectory orientation scaled by k (0: the zero quaternion)."""
    where = draw(st.sampled_from(("grasps", "path")))
    index = draw(st.integers(0, 2))
    scale = draw(
        st.one_of(
            st.just(0.0),
            st.floats(0.0, 1e6, allow_nan=False),
            st.floats(1.0 - 1e-4, 1.0 + 1e-4),
        )
    )

    def apply(parts: Parts) -> tuple[str, str]:
        if where == "grasps":
            if not parts.grasps.poses:
                return "grasps.poses", EITHER
            k = index % len(parts.grasps.poses)
            quaternion = parts.grasps.poses[k].orientation
            field = f"grasps.poses[{k}].orientation"
        else:
            if not parts.path.poses:
                return "object_trajectory.poses", EITHER
            k = index % len(parts.path.poses)
            quaternion = parts.path.poses[k].pose.orientation
            field = f"object_trajectory.poses[{k}].pose.orientation"
        for c in "xyzw":
            setattr(quaternion, c, getattr(quaternion, c) * scale)
        return field, _quaternion_expectation(quaternion)

    return Mutation(f"{where}[{index}].orientation*{scale!r}", 1, apply, f"pose {where}")


@st.composite
def grasp_count(draw: st.DrawFn) -> Mutation:
    count = draw(st.one_of(st.just(0), st.integers(1, MAX_GRASPS + 60)))

    def apply(parts: Parts) -> tuple[str, str]:
        book = parts.grasps.poses
        parts.grasps.poses = [copy.deepcopy(book[i % len(book)]) for i in range(count)]
        return "grasps.poses", REFUSE if count == 0 or count > MAX_GRASPS else ACCEPT

    return Mutation(f"{count} grasps", 0, apply, "grasp count")


@st.composite
def path_count(draw: st.DrawFn) -> Mutation:
    """Paths of 0, 1 or many poses (many: accepted or refused, depending on the node)."""
    count = draw(st.sampled_from((0, 1, 3, 4, 7, 12)))

    def apply(parts: Parts) -> tuple[str, str]:
        start, goal = parts.path.poses[0], parts.path.poses[-1]
        poses = []
        for i in range(count):
            stamped = copy.deepcopy(start if i < count / 2 else goal)
            stamped.header.stamp = Time(sec=i, nanosec=0)
            poses.append(stamped)
        parts.path.poses = poses
        return "object_trajectory", REFUSE if count < 2 else EITHER

    return Mutation(f"path of {count} poses", 0, apply, "path count")


@st.composite
def stamps(draw: st.DrawFn) -> Mutation:
    """Random stamps on the trajectory poses (out of order: refused)."""
    seconds = st.one_of(st.integers(-3, 12), st.integers(-(2**31), 2**31 - 1))
    sec = draw(st.lists(seconds, min_size=2, max_size=2))
    nanosec = draw(st.lists(st.integers(0, 2**32 - 1), min_size=2, max_size=2))

    def apply(parts: Parts) -> tuple[str, str]:
        times = []
        for stamped, s, n in zip(parts.path.poses, sec, nanosec, strict=False):
            stamped.header.stamp = Time(sec=s, nanosec=n)
            times.append(s + 1e-9 * n)
        if len(times) == 2 and times[1] < times[0]:
            return "object_trajectory.poses", REFUSE
        return "object_trajectory", EITHER

    return Mutation(f"stamps {sec} {nanosec}", 1, apply, "stamps")


@st.composite
def frames(draw: st.DrawFn) -> Mutation:
    """An unknown frame_id (random, possibly non-ASCII) on the grasps, the Path or a pose."""
    where = draw(st.sampled_from(("grasps", "path", "pose", "inertia")))
    frame = draw(TEXT.filter(lambda f: f not in ("object", "base", "")))
    index = draw(st.integers(0, 1))

    def apply(parts: Parts) -> tuple[str, str]:
        if where == "grasps":
            parts.grasps.header.frame_id = frame
            return "grasps.header.frame_id", REFUSE
        if where == "path":
            parts.path.header.frame_id = frame
            return "object_trajectory.header.frame_id", REFUSE
        if where == "inertia":
            parts.inertia_frame = frame  # topic only: the service's Inertia has no header
            return "object_inertia.header.frame_id", EITHER
        if not parts.path.poses:
            return "object_trajectory.poses", EITHER
        k = index % len(parts.path.poses)
        parts.path.poses[k].header.frame_id = frame
        return f"object_trajectory.poses[{k}].header", REFUSE

    return Mutation(f"{where} frame {frame!r}", 1, apply, f"frame {where}")


@st.composite
def inertia(draw: st.DrawFn) -> Mutation:
    """Bad masses and tensors: negative, non-finite, absurd, not positive definite,
    principal moments breaking the triangle inequality, non-finite centre of mass."""
    kind = draw(
        st.sampled_from(("mass", "negative", "indefinite", "triangle", "com", "component"))
    )
    value = draw(st.one_of(floats_bad_or_odd, st.floats(-1e3, -1e-12), st.floats(1.0, 1e6)))

    def apply(parts: Parts) -> tuple[str, str]:
        i = parts.inertia
        if is_subnormal(value) and kind in ("mass", "com", "component"):
            target, name = {"mass": (i, "m"), "com": (i.com, "y"), "component": (i, "ixz")}[kind]
            setattr(target, name, value)
            return "object_inertia", REFUSE
        if kind == "mass":
            i.m = value
            if value == 0.0:
                return "object_inertia", ACCEPT  # 0: the configured object
            if not math.isfinite(value) or value < 0.0 or value > MAX_MASS_KG:
                return "object_inertia.m", REFUSE
            return "object_inertia", EITHER
        if kind == "negative":
            i.iyy = -abs(value) if math.isfinite(value) and value != 0.0 else -1.0
            return "object_inertia", REFUSE
        if kind == "indefinite":  # |ixy| > sqrt(ixx iyy)
            i.ixx, i.iyy, i.izz, i.ixy = 0.01, 0.01, 0.015, 0.02
            return "object_inertia", REFUSE
        if kind == "triangle":  # I1 > I2 + I3, positive definite
            i.ixx, i.iyy, i.izz, i.ixy, i.ixz, i.iyz = 1.0, 0.1, 0.1, 0.0, 0.0, 0.0
            return "object_inertia", REFUSE
        if kind == "com":
            i.com.y = value
            if not math.isfinite(value):
                return "object_inertia.com", REFUSE
            return "object_inertia", ACCEPT if abs(value) < 1.0 else EITHER
        i.ixz = value
        if not math.isfinite(value) or abs(value) > 1.0:
            return "object_inertia", REFUSE
        return "object_inertia", EITHER

    return Mutation(f"inertia {kind} {value!r}", 1, apply, "inertia")


@st.composite
def quality(draw: st.DrawFn) -> Mutation:
    values = draw(
        st.lists(
            st.one_of(st.floats(-10.0, 10.0), st.sampled_from(BAD_FLOATS + ODD_FLOATS)),
            max_size=8,
        )
    )

    def apply(parts: Parts) -> tuple[str, str]:
        parts.quality = list(values)
        if not values:
            return "grasp_quality", ACCEPT
        if (
            len(values) != len(parts.grasps.poses)
            or not all(math.isfinite(v) and abs(v) <= MAX_ABS_QUALITY for v in values)
            or any(is_subnormal(v) for v in values)
        ):
            return "grasp_quality", REFUSE
        return "grasp_quality", EITHER  # e.g. identical qualities

    return Mutation(f"quality {values!r}", 1, apply, "quality")


@st.composite
def strings(draw: st.DrawFn) -> Mutation:
    """Bogus (random, possibly non-ASCII) metric or metric_point strings."""
    which = draw(st.sampled_from(("metric", "metric_point")))
    valid = ("mean", "max", "integral") if which == "metric" else ("tip",)
    value = draw(st.one_of(TEXT, st.sampled_from(valid)))

    def apply(parts: Parts) -> tuple[str, str]:
        setattr(parts, which, value)
        return which, ACCEPT if value in valid or value == "" else REFUSE

    return Mutation(f"{which}={value!r}", 1, apply, which)


@st.composite
def joint_trajectories(draw: st.DrawFn) -> Mutation:
    """Planned joint trajectories: none per grasp (IK), the wrong number, more points than
    max_samples, or a point holding a subnormal (an int sent as a float)."""
    kind = draw(st.sampled_from(("empty", "count", "too_many_points", "subnormal")))
    which = draw(st.integers(0, 2))

    def apply(parts: Parts) -> tuple[str, str]:
        count = len(parts.grasps.poses)
        parts.joint_trajectories = [JointTrajectory() for _ in range(count)]
        if kind == "empty":
            return "joint_trajectories", ACCEPT if count else EITHER
        if kind == "count" or count == 0:
            parts.joint_trajectories.append(JointTrajectory())
            return "joint_trajectories", REFUSE
        k = which % count
        if kind == "too_many_points":
            point = JointTrajectoryPoint(positions=[0.0] * 7)
            parts.joint_trajectories[k].points = [point] * (MAX_SAMPLES + 1)
            return f"joint_trajectories[{k}].points", REFUSE
        parts.joint_trajectories[k].points = [JointTrajectoryPoint(positions=[0.0, 5e-324])]
        return f"joint_trajectories[{k}].points[0].positions[1]", REFUSE

    return Mutation(f"joint trajectories {kind} {which}", 1, apply, "joint trajectories")


MUTATIONS = st.one_of(
    joint_trajectories(),
    pose_value(),
    quaternion_scale(),
    grasp_count(),
    path_count(),
    stamps(),
    frames(),
    inertia(),
    quality(),
    strings(),
)


def mutated(mutations: list[Mutation]) -> tuple[Parts, list[tuple[str, str]]]:
    parts = Parts.good()
    expectations = [m.apply(parts) for m in sorted(mutations, key=lambda m: m.stage)]
    return parts, expectations


def is_subnormal(value: float) -> bool:
    return value != 0.0 and abs(value) < 2.2250738585072014e-308


def names_a_field(message: str, fields: list[str]) -> bool:
    return any(message.startswith(field) for field in fields)


def resource_refusal(message: str) -> bool:
    """Refused for time, not for the input: longer than max_compute_time_s (a long but valid
    trajectory on a loaded machine), or busy."""
    return message.startswith(("ranking abandoned after", "busy:"))


def test_absurd_positions_are_refused_before_the_ik() -> None:
    pose = Parts.good().grasps.poses[0]
    pose.position.x = 1e300  # finite, but made the IK search for seconds
    with pytest.raises(InvalidInputError, match=r"^g\.position: must be within \+/-1000 m"):
        transform_from_pose_msg(pose, "g")
    pose.position.x = -MAX_ABS_POSITION_M
    assert transform_from_pose_msg(pose, "g").translation[0] == -MAX_ABS_POSITION_M


# --- Service ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def node() -> Iterator[NodeUnderTest]:
    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


@pytest.fixture(scope="module")
def reference(node: NodeUnderTest) -> GraspRanking:
    """The known-good request's first answer."""
    response = node.rank(book_request())
    assert response.success, response.message
    return response.ranking


def assert_finite_scores(ranking: GraspRanking) -> None:
    """No grasp of an order has a NaN or infinite score; the scores of the analyses that ran
    are finite for it too; no evaluation has an infinite score."""
    ordered = {*ranking.order, *ranking.safety_order, *ranking.paper_order}
    names = ["score", "safety_score", "peak_effective_mass_kg", "mean_effective_mass_kg"]
    if math.isfinite(ranking.safety_weight):  # a quality was given
        names += ["combined_score", "grasp_quality"]
    for index in ordered:
        for name in names:
            value = getattr(ranking.evaluations[index], name)
            assert math.isfinite(value), (index, name, value)
    for evaluation in ranking.evaluations:
        assert not any(math.isinf(getattr(evaluation, name)) for name in names)


def assert_exact(got: RankGrasps.Response, reference: GraspRanking) -> None:
    """The known-good answer is exactly the first one (all fields but stamp and time)."""
    assert got.success, got.message
    for field in reference.get_fields_and_field_types():
        if field not in ("header", "compute_time_s"):
            assert same_messages(getattr(got.ranking, field), getattr(reference, field)), field


@FUZZ
@given(mutations=st.lists(MUTATIONS, min_size=1, max_size=3, unique_by=lambda m: m.key))
def test_malformed_requests_are_refused_naming_the_field(
    node: NodeUnderTest, reference: GraspRanking, mutations: list[Mutation]
) -> None:
    parts, expectations = mutated(mutations)
    fields = [field for field, _ in expectations]
    kinds = {kind for _, kind in expectations}
    response = node.rank(parts.request())
    assert not response.message.startswith("internal error"), response.message
    assert not response.message.startswith("result:"), response.message  # the final guard
    if response.success:
        assert_finite_scores(response.ranking)
    if REFUSE in kinds:
        assert not response.success, f"accepted: {mutations}"
        assert names_a_field(response.message, fields), (response.message, fields)
        assert response.ranking.evaluations == []
    elif EITHER in kinds:
        assert (
            response.success
            or names_a_field(response.message, fields)
            or resource_refusal(response.message)
        ), response.message
    else:
        assert response.success or resource_refusal(response.message), response.message
    assert_exact(node.rank(book_request()), reference)


def test_backend_is_reported_in_the_ranking_and_on_diagnostics(
    node: NodeUnderTest, reference: GraspRanking
) -> None:
    expected = "compiled" if compiled_available() else "python (numba not installed)"
    assert reference.backend == expected
    values = {kv.key: kv.value for kv in node.node.diagnostics_status().values}
    assert values["backend"] == expected


# --- Topics ----------------------------------------------------------------------------------

TOPIC_MUTATIONS = st.one_of(
    pose_value(), quaternion_scale(), grasp_count(), path_count(), stamps(), frames(), inertia()
)


def refusals(node: NodeUnderTest) -> tuple[int, str]:
    values = {kv.key: kv.value for kv in node.node.diagnostics_status().values}
    return int(values["refused_inputs"]), values["last_error"]


@pytest.fixture(scope="module")
def publishers(node: NodeUnderTest) -> Iterator[dict[str, Any]]:
    create = node.client.create_publisher
    pubs = {
        "candidate_grasps": create(PoseArray, "/grasp_safety/candidate_grasps", 10),
        "object_trajectory": create(Path, "/grasp_safety/object_trajectory", 10),
        "object_inertia": create(InertiaStamped, "/grasp_safety/object_inertia", 10),
        "candidate_grasp_quality": create(
            Float64MultiArray, "/grasp_safety/candidate_grasp_quality", 10
        ),
        "joint_states": create(JointState, "/joint_states", 10),
    }
    assert node.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
    yield pubs
    for publisher in pubs.values():
        node.client.destroy_publisher(publisher)


def publish_and_wait_for_refusal(
    node: NodeUnderTest, publisher: Any, message: Any, source: str, fields: list[str]
) -> str:
    """Publish ``message``; wait for the node to refuse it; return its /diagnostics error."""
    before, _ = refusals(node)
    publisher.publish(message)
    assert node.spin_until(lambda: refusals(node)[0] > before, 10.0), f"not refused: {source}"
    count, last_error = refusals(node)
    assert count == before + 1
    assert any(last_error.startswith(f"{source}: {field}") for field in fields), last_error
    return last_error


def topic_field(field: str) -> str:
    """The name of a service field on the candidate_grasps topic."""
    return "candidate_grasps" + field[len("grasps") :] if field.startswith("grasps") else field


@FUZZ
@given(mutations=st.lists(TOPIC_MUTATIONS, min_size=1, max_size=2, unique_by=lambda m: m.key))
def test_malformed_topic_messages_are_refused_on_diagnostics(
    node: NodeUnderTest,
    reference: GraspRanking,
    publishers: dict[str, Any],
    mutations: list[Mutation],
) -> None:
    parts, expectations = mutated(mutations)
    by_topic: dict[str, list[tuple[str, str]]] = {}
    for field, kind in expectations:
        topic = next(
            t for t in ("grasps", "object_trajectory", "object_inertia") if field.startswith(t)
        )
        by_topic.setdefault(topic, []).append((field, kind))
    for topic, found in by_topic.items():
        fields = [f for f, _ in found]
        if REFUSE not in {kind for _, kind in found}:
            continue
        if topic == "grasps":
            publish_and_wait_for_refusal(
                node,
                publishers["candidate_grasps"],
                parts.grasps,
                "candidate_grasps",
                [topic_field(f) for f in fields],
            )
        elif topic == "object_trajectory":
            publish_and_wait_for_refusal(
                node, publishers["object_trajectory"], parts.path, topic, fields
            )
        else:
            message = InertiaStamped(
                header=Header(frame_id=parts.inertia_frame), inertia=parts.inertia
            )
            publish_and_wait_for_refusal(
                node, publishers["object_inertia"], message, topic, fields
            )
    assert_exact(node.rank(book_request()), reference)


@FUZZ
@given(
    values=st.lists(
        st.one_of(st.floats(-10.0, 10.0), st.sampled_from(BAD_FLOATS + ODD_FLOATS)),
        min_size=1,
        max_size=6,
    ).filter(lambda v: not all(math.isfinite(x) for x in v))
)
def test_non_finite_quality_on_the_topic_is_refused(
    node: NodeUnderTest,
    reference: GraspRanking,
    publishers: dict[str, Any],
    values: list[float],
) -> None:
    publish_and_wait_for_refusal(
        node,
        publishers["candidate_grasp_quality"],
        Float64MultiArray(data=values),
        "candidate_grasp_quality",
        ["candidate_grasp_quality.data"],
    )
    assert_exact(node.rank(book_request()), reference)


@FUZZ
@given(
    names=st.lists(TEXT, max_size=10),
    positions=st.lists(st.sampled_from(BAD_FLOATS + ODD_FLOATS) | st.floats(-4, 4), max_size=10),
)
def test_garbage_joint_states_do_not_disturb_the_node(
    node: NodeUnderTest,
    reference: GraspRanking,
    publishers: dict[str, Any],
    names: list[str],
    positions: list[float],
) -> None:
    publishers["joint_states"].publish(JointState(name=names, position=positions))
    time.sleep(0.01)
    assert_exact(node.rank(book_request()), reference)


# --- Garbage /robot_description ---------------------------------------------------------------

GOOD_URDF = serial_arm_urdf(ARM6_AXES)
GARBAGE_DESCRIPTIONS = st.one_of(
    TEXT,
    st.binary(max_size=200).map(lambda b: b.decode("latin-1").replace("\x00", "")),
    st.integers(1, len(GOOD_URDF) - 1).map(lambda n: GOOD_URDF[:n]),  # truncated XML
    st.sampled_from(
        (
            "",
            "<robot/>",
            '<robot name="r"><link name="base_link"/></robot>',
            GOOD_URDF.replace('"tool"', '"flange"'),  # no tip frame
            GOOD_URDF.replace('<mass value="', '<mass value="-'),  # negative masses
            GOOD_URDF.replace("</robot>", "<link"),
            "<a>" * 5000 + "</a>" * 5000,  # deep nesting
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">'
            '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
            '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]><robot name="&c;"/>',
        )
    ),
)


@pytest.fixture(scope="module")
def topic_robot_node() -> Iterator[tuple[NodeUnderTest, Any, GraspRanking]]:
    """A node whose robot came from /robot_description, its publisher, and a first answer."""
    harness = NodeUnderTest(
        {"base_frame": "base_link", "tip_frame": "tool", "object.mass_kg": 0.0}
    )
    publisher = harness.client.create_publisher(String, "/robot_description", LATCHED)
    publisher.publish(String(data=GOOD_URDF))
    assert harness.spin_until(lambda: harness.node.has_robot)
    first = harness.rank(arm_request())
    assert first.success, first.message
    yield harness, publisher, first.ranking
    harness.client.destroy_publisher(publisher)
    harness.close()


def arm_request() -> RankGrasps.Request:
    request = book_request()
    request.object_trajectory.header.frame_id = "base_link"
    return request


@FUZZ
@given(description=GARBAGE_DESCRIPTIONS)
def test_garbage_robot_description_keeps_the_working_model(
    topic_robot_node: tuple[NodeUnderTest, Any, GraspRanking], description: str
) -> None:
    harness, publisher, first = topic_robot_node
    before, _ = refusals(harness)
    publisher.publish(String(data=description))
    assert harness.spin_until(lambda: refusals(harness)[0] > before, 10.0), "not refused"
    status = harness.node.diagnostics_status()
    values = {kv.key: kv.value for kv in status.values}
    assert values["last_error"].startswith("/robot_description: "), values["last_error"]
    assert values["robot_description_error"] == values["last_error"].split(": ", 1)[1]
    assert values["robot_source"] == "/robot_description"
    assert harness.node.has_robot
    assert_exact(harness.rank(arm_request()), first)
    publisher.publish(String(data=GOOD_URDF))  # the working description again: error cleared
    assert harness.spin_until(
        lambda: (
            {kv.key: kv.value for kv in harness.node.diagnostics_status().values}[
                "robot_description_error"
            ]
            == ""
        ),
        10.0,
    )


# --- Bursts and ignored messages on /diagnostics ----------------------------------------------


def diagnostics_values(node: NodeUnderTest) -> dict[str, str]:
    return {kv.key: kv.value for kv in node.node.diagnostics_status().values}


def test_an_ignored_robot_description_says_why(
    node: NodeUnderTest, reference: GraspRanking
) -> None:
    publisher = node.client.create_publisher(String, "/robot_description", LATCHED)
    try:
        publisher.publish(String(data=GOOD_URDF))
        assert node.spin_until(
            lambda: int(diagnostics_values(node)["ignored_robot_descriptions"]) >= 1, 10.0
        )
        assert diagnostics_values(node)["robot_description_error"] == (
            "ignored: the parameter urdf gives the robot (empty robot_description and urdf to "
            "take it from the topic)"
        )
        assert diagnostics_values(node)["robot_source"] == "urdf"
        assert_exact(node.rank(book_request()), reference)
    finally:
        node.client.destroy_publisher(publisher)
