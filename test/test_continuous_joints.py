"""Continuous joints are output unwrapped (issue 20, "fix first"): a motion crossing ±π gives
continuous q and the true joint rates, in the JSON (CLI) and in the node's JointTrajectory."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.core import RobotModel
from grasp_safety_ros.core.input_checks import quat_xyzw_from_rotation
from grasp_safety_ros.core.model.robot import NO_ARMATURE_NOTE

KINOVA = ("example-robot-data:kinova", "j2s6s200_link_base", "j2s6s200_end_effector")
JOINT_1 = (2.9, 3.0, 3.15, 3.3, 3.4)
"""The issue's minimal case: joint 1 crosses π at 0.3 rad/s; the others fixed."""
OTHERS = (1.281, 1.117, -0.348, 1.643, 1.016)
TIMES_S = (0.0, 0.5, 1.0, 1.5, 2.0)


@pytest.fixture(scope="module")
def kinova() -> RobotModel:
    return RobotModel.from_urdf(*KINOVA)


def planned_points(velocities: bool) -> list[dict]:
    points = []
    for t, angle in zip(TIMES_S, JOINT_1, strict=True):
        point = {"time_s": t, "positions": [angle, *OTHERS]}
        if velocities:
            point["velocities"] = [0.25, 0.0, 0.0, 0.0, 0.0, 0.0]
        points.append(point)
    return points


def pose_entry(robot: RobotModel, positions: list[float]) -> dict:
    pose = robot.transform_tip_to_base(positions)
    return {
        "position_m": pose.translation.tolist(),
        "quat_xyzw": quat_xyzw_from_rotation(pose.rotation).tolist(),
    }


def scenario(robot: RobotModel) -> dict:
    """Grasp 0: IK from joint 1 = 3.0 to 3.3 rad (crossing π); grasps 1, 2: the planned
    trajectory, without and with the planner's velocities."""
    joint_names = list(robot.joint_names)
    return {
        "robot": {
            "urdf": KINOVA[0],
            "base_frame": KINOVA[1],
            "tip_frame": KINOVA[2],
            "seed": [3.0, *OTHERS],
        },
        "object": {"mass_kg": 0.2, "box_size_m": [0.05, 0.05, 0.05]},
        "trajectory": {
            "start": pose_entry(robot, [3.0, *OTHERS]),
            "goal": pose_entry(robot, [3.3, *OTHERS]),
            "duration_s": 2.0,
            "dt_s": 0.05,
        },
        "grasps": [
            {"name": "ik", "position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
            *(
                {
                    "name": f"planned_{kind}",
                    "position_m": [0, 0, 0],
                    "quat_xyzw": [0, 0, 0, 1],
                    "joint_trajectory": {
                        "joint_names": joint_names,
                        "points": planned_points(kind == "velocities"),
                    },
                }
                for kind in ("positions", "velocities")
            ),
        ],
        "posture": {"restarts": 0},
    }


def test_cli_json_keeps_continuous_joints_unwrapped(tmp_path: Path, kinova: RobotModel) -> None:
    path, out = tmp_path / "kinova.yaml", tmp_path / "kinova.json"
    path.write_text(yaml.safe_dump(scenario(kinova)))
    assert main(["rank", str(path), "--json", str(out)]) == 0
    ik, planned, with_velocities = json.loads(out.read_text())["grasps"]
    q = np.array(ik["samples"]["q"])
    qd = np.array(ik["samples"]["qd"])
    assert q[0, 0] == pytest.approx(3.0, abs=1e-5) and q[-1, 0] == pytest.approx(3.3, abs=1e-5)
    assert np.max(np.abs(np.diff(q[:, 0]))) < 0.05  # no 2π jump
    assert np.max(np.abs(qd[:, 0])) < 0.5  # 0.3 rad/s over 2 s, at rest at both ends
    for grasp in (planned, with_velocities):
        q = np.array(grasp["samples"]["q"])
        np.testing.assert_array_equal(q[:, 0], JOINT_1)  # the planner's own positions
    qd = np.array(planned["samples"]["qd"])
    assert np.max(np.abs(qd[:, 0])) < 0.6  # fitted through 2.9 .. 3.4 rad, not 66 rad/s
    qd = np.array(with_velocities["samples"]["qd"])
    np.testing.assert_array_equal(qd[:, 0], 0.25)  # the planner's own velocities


def test_a_seed_a_turn_away_starts_the_output_there(tmp_path: Path, kinova: RobotModel) -> None:
    """A seed of 3.0 + 2π on the continuous joint 1 (the controller's reading after a turn):
    q starts at 3.0 + 2π, not at 3.0 (which would spin the arm a full turn back)."""
    data = scenario(kinova)
    data["robot"]["seed"] = [3.0 + 2.0 * math.pi, *OTHERS]
    data["grasps"] = data["grasps"][:1]
    path, out = tmp_path / "turned.yaml", tmp_path / "turned.json"
    path.write_text(yaml.safe_dump(data))
    assert main(["rank", str(path), "--json", str(out)]) == 0
    (ik,) = json.loads(out.read_text())["grasps"]
    q = np.array(ik["samples"]["q"])  # JSON schema 2: per-sample columns
    assert q[0, 0] == pytest.approx(3.0 + 2.0 * math.pi, abs=1e-5)
    assert q[-1, 0] == pytest.approx(3.3 + 2.0 * math.pi, abs=1e-5)
    assert np.max(np.abs(np.diff(q[:, 0]))) < 0.05


def kinova_node(**parameters: object):
    """A node on the Kinova chain (no joint-state seed, a small object, no restarts)."""
    from ros_node_harness import NodeUnderTest

    return NodeUnderTest(
        {
            "urdf": KINOVA[0],
            "base_frame": KINOVA[1],
            "tip_frame": KINOVA[2],
            "use_joint_states_seed": False,
            "object.mass_kg": 0.2,
            "object.inertia_about_com_kgm2": [1e-4, 0.0, 0.0, 1e-4, 0.0, 1e-4],
            "posture.restarts": 0,
            **parameters,
        }
    )


def test_node_joint_trajectory_keeps_continuous_joints_unwrapped(kinova: RobotModel) -> None:
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import Pose, PoseArray
    from grasp_safety_msgs.srv import RankGrasps
    from ros_node_harness import book_path
    from std_msgs.msg import Header
    from test_ros_motions import planned_message
    from trajectory_msgs.msg import JointTrajectoryPoint

    harness = kinova_node(**{"response.joint_trajectories": 2})
    try:
        request = RankGrasps.Request()
        request.grasps = PoseArray(header=Header(frame_id="object"), poses=[Pose(), Pose()])
        request.object_trajectory = book_path()
        request.object_trajectory.header.frame_id = KINOVA[1]
        positions = np.array([[angle, *OTHERS] for angle in JOINT_1])
        without = planned_message(positions, np.array(TIMES_S), list(kinova.joint_names))
        with_velocities = planned_message(positions, np.array(TIMES_S), list(kinova.joint_names))
        with_velocities.points = [
            JointTrajectoryPoint(
                positions=[float(v) for v in row],
                velocities=[0.25, 0.0, 0.0, 0.0, 0.0, 0.0],
                time_from_start=Duration(sec=int(t), nanosec=round((t % 1) * 1e9)),
            )
            for row, t in zip(positions, TIMES_S, strict=True)
        ]
        request.joint_trajectories = [without, with_velocities]
        response = harness.rank(request)
        assert response.success, response.message
        first, second = (e.joint_trajectory for e in response.ranking.evaluations)
        for trajectory in (first, second):
            assert [p.positions[0] for p in trajectory.points] == list(JOINT_1)
        assert max(abs(p.velocities[0]) for p in first.points) < 0.6
        assert [p.velocities[0] for p in second.points] == [0.25] * 5
        assert all(math.isfinite(p.accelerations[0]) for p in second.points)
        values = {v.key: v.value for v in harness.node.diagnostics_status().values}
        assert values["armature"] == NO_ARMATURE_NOTE  # Kinova without armature: said once
        assert response.ranking.armature_note == NO_ARMATURE_NOTE
    finally:
        harness.close()


def test_node_seed_a_turn_away_starts_the_joint_trajectory_there(kinova: RobotModel) -> None:
    """The node's ik_seed of 3.0 + 2π on joint 1: the JointTrajectory starts at 3.0 + 2π."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Pose, PoseArray, PoseStamped
    from grasp_safety_msgs.srv import RankGrasps
    from nav_msgs.msg import Path as PathMsg
    from ros_node_harness import pose_from_yaml
    from std_msgs.msg import Header

    seed = [3.0 + 2.0 * math.pi, *OTHERS]
    harness = kinova_node(**{"ik_seed": seed, "response.joint_trajectories": 1})
    try:
        request = RankGrasps.Request()
        request.grasps = PoseArray(header=Header(frame_id="object"), poses=[Pose()])
        request.object_trajectory = PathMsg(
            header=Header(frame_id=KINOVA[1]),
            poses=[
                PoseStamped(
                    header=Header(stamp=Time(sec=sec)),
                    pose=pose_from_yaml(pose_entry(kinova, [angle, *OTHERS])),
                )
                for sec, angle in ((0, 3.0), (2, 3.3))
            ],
        )
        response = harness.rank(request)
        assert response.success, response.message
        points = response.ranking.evaluations[0].joint_trajectory.points
        assert points[0].positions[0] == pytest.approx(seed[0], abs=1e-5)
        assert points[-1].positions[0] == pytest.approx(3.3 + 2.0 * math.pi, abs=1e-5)
    finally:
        harness.close()
