"""The upstream interface subsets that ``make setup`` builds from ../shared/interfaces
(scripts/build_interfaces.sh, scripts/stage_interfaces.py): every built type has the ROS 2
type hash (RIHS01) of the upstream definition, three ways computed:

- the type description JSON the build generated (``share/<pkg>/msg/*.json``);
- an independent one: rosidl_adapter + rosidl_generator_type_description run here on the
  unmodified upstream .msg/.srv files (dependencies' descriptions from the wheels' JSON);
- the hash the built C type support hands the middleware (read back from the ROS graph).

And a SpeedScalingFactor published reliable + transient-local reaches a subscriber that joins
after the publication, as the joint_trajectory_controller's speed-scaling input expects.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest
from ros_domains import claim_ros_domain

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "interfaces"
SHARE = Path(sys.prefix) / "share"
PACKAGES = ("control_msgs", "moveit_msgs", "object_recognition_msgs")

control_msgs = pytest.importorskip(
    "control_msgs.msg", reason="control_msgs not built (make setup with ../shared/interfaces)"
)
moveit_msgs = pytest.importorskip("moveit_msgs.msg", reason="moveit_msgs not built")


def json_hashes(paths: list[Path], package: str) -> dict[str, str]:
    """{type name: RIHS01 hash} of the package's own types (a service's request, response
    and event included) in type description JSON files."""
    hashes = {}
    for path in paths:
        for entry in json.loads(path.read_text())["type_hashes"]:
            if entry["type_name"].startswith(package + "/"):
                assert hashes.setdefault(entry["type_name"], entry["hash_string"]) == (
                    entry["hash_string"]), entry["type_name"]
    return hashes


def built_hashes(package: str) -> dict[str, str]:
    """json_hashes of the JSON the build installed (share/<pkg>/{msg,srv}/*.json)."""
    return json_hashes(sorted((SHARE / package).glob("*/*.json")), package)


def upstream_hashes(package: str, names: list[str], includes: dict[str, Path], out: Path):
    """{type name: hash} computed from the upstream definition files of ``names``
    ("msg/X", "srv/Y"); ``includes`` maps other packages to their share dir of JSON."""
    from rosidl_adapter.msg import convert_msg_to_idl
    from rosidl_adapter.srv import convert_srv_to_idl
    from rosidl_generator_type_description import generate_type_hash

    idl_dir, json_dir = out / "idl" / package, out / "json" / package
    tuples = []
    for name in names:
        kind = name.split("/")[0]
        convert = convert_msg_to_idl if kind == "msg" else convert_srv_to_idl
        rel = Path(name + "." + kind)
        convert(SHARED / package, package, rel, idl_dir / kind)
        tuples.append(f"{idl_dir}:{kind}/{rel.stem}.idl")
    arguments = out / f"{package}_arguments.json"
    arguments.write_text(json.dumps({
        "package_name": package,
        "output_dir": str(json_dir),
        "idl_tuples": tuples,
        "include_paths": [f"{pkg}:{path}" for pkg, path in includes.items()],
    }))
    return json_hashes(generate_type_hash(str(arguments)), package), json_dir


def test_built_subsets_hold_the_types_the_project_uses():
    kept = {name.split("/", 1)[1] for pkg in PACKAGES for name in built_hashes(pkg)}
    for name in ("msg/SpeedScalingFactor", "srv/GraspPlanning", "msg/Grasp",
                 "msg/RobotTrajectory", "msg/MoveItErrorCodes", "msg/CollisionObject",
                 "msg/GripperTranslation", "msg/ObjectType"):
        assert name in kept


def test_hashes_equal_the_upstream_definitions(tmp_path: Path):
    # dependencies outside the shared tree: the wheels' JSON in the venv (share/<pkg>)
    includes = {p.name: p for p in SHARE.iterdir() if (p / "msg").is_dir()}
    for package in ("object_recognition_msgs", "control_msgs", "moveit_msgs"):  # deps first
        built = built_hashes(package)
        names = sorted(f"{p.parent.name}/{p.stem}" for p in (SHARE / package).glob("*/*.json"))
        computed, json_dir = upstream_hashes(package, names, includes, tmp_path)
        includes[package] = json_dir  # the next package's include: our own computation
        assert built and computed == built, package


@pytest.fixture(scope="module")
def context():
    import rclpy
    from rclpy.context import Context

    claim = claim_ros_domain()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=claim.domain_id)
    ctx.on_shutdown(claim.release)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_type_support_hashes_reach_the_middleware(context):
    import rclpy

    types = {
        "control_msgs/msg/SpeedScalingFactor": control_msgs.SpeedScalingFactor,
        "moveit_msgs/msg/Grasp": moveit_msgs.Grasp,
        "moveit_msgs/msg/RobotTrajectory": moveit_msgs.RobotTrajectory,
        "moveit_msgs/msg/CollisionObject": moveit_msgs.CollisionObject,
    }
    expected = {**built_hashes("control_msgs"), **built_hashes("moveit_msgs")}
    node = rclpy.create_node("hash_probe", context=context)
    try:
        for k, (name, msg_type) in enumerate(types.items()):
            node.create_publisher(msg_type, f"probe_{k}", 1)
            (info,) = node.get_publishers_info_by_topic(f"probe_{k}")
            assert info.topic_type == name
            assert str(info.topic_type_hash) == expected[name], name
    finally:
        node.destroy_node()


def test_late_transient_local_subscriber_gets_the_last_factor(context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    Factor = control_msgs.SpeedScalingFactor  # noqa: N806
    publisher_node = rclpy.create_node("factor_pub", context=context)
    subscriber_node = rclpy.create_node("factor_sub", context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        publisher = publisher_node.create_publisher(Factor, "speed_scaling", qos)
        for value in (1.0, 0.25, 0.5):  # depth 1: only the last is kept for late joiners
            publisher.publish(Factor(factor=value))
        received = []
        subscriber_node.create_subscription(
            Factor, "speed_scaling", lambda msg: received.append(msg.factor), qos)
        executor.add_node(subscriber_node)
        deadline = time.monotonic() + 10.0
        while not received and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert received == [0.5]
    finally:
        executor.shutdown()
        publisher_node.destroy_node()
        subscriber_node.destroy_node()
