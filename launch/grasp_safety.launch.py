"""Launch the grasp_safety node with a params file (ROS 2 Jazzy launch / launch_ros).

    ros2 launch grasp_safety_ros grasp_safety.launch.py
    ros2 launch grasp_safety_ros grasp_safety.launch.py params_file:=/path/to/params.yaml

The default params file is the installed config/grasp_safety_node.yaml (the paper's book
experiment on Baxter). The file's top-level key must be the node name, grasp_safety (or /**).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    """The node grasp_safety, its parameters from the launch argument params_file."""
    params_file = DeclareLaunchArgument(
        "params_file",
        default_value=PathJoinSubstitution(
            [FindPackageShare("grasp_safety_ros"), "config", "grasp_safety_node.yaml"]
        ),
        description="params file of the grasp_safety node",
    )
    node = Node(
        package="grasp_safety_ros",
        executable="grasp_safety_node",
        name="grasp_safety",
        parameters=[LaunchConfiguration("params_file")],
        output="screen",
    )
    return LaunchDescription([params_file, node])
