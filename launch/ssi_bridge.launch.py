"""Start ssi_bridge_node with a params file (default: the two-encoder station in config/).

    ros2 launch ssi_bridge ssi_bridge.launch.py [params_file:=...] [namespace:=...]
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    default_params = PathJoinSubstitution(
        [FindPackageShare("ssi_bridge"), "config", "ssi_bridge.yaml"])
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="ssi_bridge parameters (YAML)"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of the bridge (several can run side by side)"),
        Node(package="ssi_bridge", executable="ssi_bridge_node", name="ssi_bridge",
             namespace=LaunchConfiguration("namespace"),
             parameters=[LaunchConfiguration("params_file")], output="screen",
             emulate_tty=True),
    ])
