"""A stand-in upstream grasp planner for test_ros_moveit.py: real moveit_msgs/srv/GraspPlanning
servers in their own process, answering known grasps.

Usage: python fake_grasp_planner.py SPEC_JSON, where SPEC_JSON maps a service name to
``{"grasps": [{"id", "frame", "position_m", "quat_xyzw", "quality"}], "delay_s": 0,
"error_code": 1, "message": ""}`` ("quality" may be NaN). Each answer copies the request's
``group_name`` and ``target.id`` into every grasp's ``allowed_touch_objects``, so the test can
tell the request was forwarded as is. Prints "ready" once every service is up, then
"request <service>" as each request arrives; runs until killed (ROS_DOMAIN_ID and discovery
from the environment).
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from moveit_msgs.msg import Grasp
from moveit_msgs.srv import GraspPlanning
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from std_msgs.msg import Header


def grasp_msg(item: dict) -> Grasp:
    x, y, z = (float(v) for v in item["position_m"])
    qx, qy, qz, qw = (float(v) for v in item["quat_xyzw"])
    pose = Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))
    return Grasp(
        id=item["id"],
        grasp_pose=PoseStamped(header=Header(frame_id=item["frame"]), pose=pose),
        grasp_quality=float(item["quality"]),
    )


def server(name: str, spec: dict):
    def answer(request: GraspPlanning.Request, response: GraspPlanning.Response):
        print(f"request {name}", flush=True)
        time.sleep(spec.get("delay_s", 0.0))
        response.grasps = [grasp_msg(item) for item in spec.get("grasps", [])]
        for grasp in response.grasps:
            grasp.allowed_touch_objects = [request.group_name, request.target.id]
        response.error_code.val = spec.get("error_code", 1)
        response.error_code.message = spec.get("message", "")
        return response

    return answer


def main() -> None:
    specs = json.loads(sys.argv[1])
    rclpy.init()
    node = rclpy.create_node("fake_grasp_planner")
    group = ReentrantCallbackGroup()  # a slow answer does not hold up the others
    for name, spec in specs.items():
        node.create_service(GraspPlanning, name, server(name, spec), callback_group=group)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    print("ready", flush=True)
    executor.spin()


if __name__ == "__main__":
    main()
