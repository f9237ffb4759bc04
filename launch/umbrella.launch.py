"""
Launch one umbrella antenna: umbrella_node, robot_state_publisher with the URDF, RViz.

    ros2 launch umbrella_sim umbrella.launch.py namespace:=a1 v0:=-0.5 record:=false
    ros2 launch umbrella_sim umbrella.launch.py --show-args

A thin wrapper: what is started is decided by umbrella_sim.ros.launch_description (tested
without ROS 2's launch, which is not on PyPI).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction

from umbrella_sim.ros import launch_description as umbrella


def _setup(context, *args, **kwargs):
    return umbrella.to_launch_actions(umbrella.plan(umbrella.launch_values(context)))


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(a.name, default_value=a.default, description=a.description)
         for a in umbrella.arguments()]
        + [OpaqueFunction(function=_setup)])
