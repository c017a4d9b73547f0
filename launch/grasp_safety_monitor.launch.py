"""Launch the live speed-scaling monitor beside a joint_trajectory_controller (ROS 2 Jazzy).

    ros2 launch grasp_safety_ros grasp_safety_monitor.launch.py
    ros2 launch grasp_safety_ros grasp_safety_monitor.launch.py \
        controller:=scaled_joint_trajectory_controller params_file:=/path/to/params.yaml

The factor goes to /<controller>/speed_scaling_input (control_msgs/SpeedScalingFactor), which
the upstream joint_trajectory_controller reads when speed scaling is set up
(docs/ros/monitor.md). The default params file is the installed config/grasp_safety_monitor.yaml
(the Panda carrying a 1 kg box); its top-level key must be grasp_safety_monitor (or /**).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    """The node grasp_safety_monitor, its factor remapped to the controller's input."""
    params_file = DeclareLaunchArgument(
        "params_file",
        default_value=PathJoinSubstitution(
            [FindPackageShare("grasp_safety_ros"), "config", "grasp_safety_monitor.yaml"]
        ),
        description="params file of the grasp_safety_monitor node",
    )
    controller = DeclareLaunchArgument(
        "controller",
        default_value="joint_trajectory_controller",
        description="name of the joint_trajectory_controller whose speed the factor scales",
    )
    node = Node(
        package="grasp_safety_ros",
        executable="grasp_safety_monitor",
        name="grasp_safety_monitor",
        parameters=[LaunchConfiguration("params_file")],
        remappings=[
            (
                "~/speed_scaling",
                ["/", LaunchConfiguration("controller"), "/speed_scaling_input"],
            )
        ],
        output="screen",
    )
    return LaunchDescription([params_file, controller, node])
