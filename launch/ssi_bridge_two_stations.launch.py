"""Start ssi_bridge_node as the one master of two stations (config/ssi_bridge_two_stations.yaml).

    ros2 launch ssi_bridge ssi_bridge_two_stations.launch.py [namespace:=...]
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    params = PathJoinSubstitution(
        [FindPackageShare("ssi_bridge"), "config", "ssi_bridge_two_stations.yaml"])
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of the bridge"),
        Node(package="ssi_bridge", executable="ssi_bridge_node", name="ssi_bridge",
             namespace=LaunchConfiguration("namespace"), parameters=[params], output="screen",
             emulate_tty=True),
    ])
